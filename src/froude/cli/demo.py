"""``froude demo``: the paper's Figure 2 and Figure 3 on the embedded sample clip, in one folder."""
from __future__ import annotations

import time

from .common import say


def register(sub) -> None:
    p = sub.add_parser(
        "demo", help="reproduce the paper's Fig. 2 and Fig. 3 on the bundled clip (start here)",
        description="Fit the simple machine to the bundled CMU running clip and write, into one folder: "
        "Figure 2 (the fit), the Figure 3 rows (original, 1.2x speed, deceleration to half speed, troll, "
        "child at 0.7x) as BVH files with physics reports, filmstrips, an MP4 and a Markdown report table.",
    )
    p.add_argument("-o", "--output", default="froude-demo", help="output folder (default ./froude-demo)")
    p.add_argument("--clip", default=None, help="use another running clip instead of the bundled one")
    p.add_argument("--strides", type=int, default=3, help="strides per synthesised row (default 3)")
    p.add_argument("--no-video", action="store_true", help="skip the MP4")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress on stderr")
    p.set_defaults(func=run)


def run(args) -> int:
    from ..demo import run_demo

    t0 = time.perf_counter()
    files = run_demo(args.output, args.clip, strides=args.strides, video=not args.no_video,
                     say=lambda s: say(s, args.quiet))
    print(f"froude demo: wrote {len(files)} files to {args.output}/ in {time.perf_counter() - t0:.1f} s")
    for key in ("report", "fig2", "fig3", "fig3_child_vs_naive", "video", "machine"):
        if key in files:
            print(f"  {files[key]}")
    print(f"Explore it live:  froude view {args.clip or ''}".rstrip())
    return 0
