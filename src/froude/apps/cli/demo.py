"""``froude demo``: the paper's Figure 2 and Figure 3 on the embedded sample clip, in one folder."""
from __future__ import annotations

import time

from .common import add_quiet, check_inputs, guard_outputs, number, say

#: Strides per synthesised row froude's demo accepts.
DEMO_STRIDES = (1, 20)


#: The one-line summary ``froude --help`` lists.
HELP = "reproduce the paper's Fig. 2 and Fig. 3 on the bundled clip (start here)"


def register(sub) -> None:
    p = sub.add_parser(
        "demo", help=HELP,
        description="Fit the simple machine to the bundled CMU running clip and write, into one folder: "
        "Figure 2 (the fit), the Figure 3 rows (original, 1.2x speed, deceleration to half speed, troll, "
        "child at 0.7x) as BVH files with physics reports, filmstrips, an MP4 and a Markdown report table. "
        "The files appear together when everything is done (nothing is left if it fails or is stopped).",
    )
    p.add_argument("-o", "--output", default="froude-demo", metavar="FOLDER",
                   help="output folder (default ./froude-demo; created if missing, its parent must exist)")
    p.add_argument("--clip", default=None, help="use another running clip instead of the bundled one")
    p.add_argument("--strides", type=number(*DEMO_STRIDES, "strides", integer=True), default=3,
                   help=f"strides per synthesised row, {DEMO_STRIDES[0]}-{DEMO_STRIDES[1]} (default 3)")
    p.add_argument("--no-video", action="store_true", help="skip the MP4")
    add_quiet(p)
    p.set_defaults(func=run)


def run(args) -> int:
    from pathlib import Path

    from ...io.atomic import atomic_group  # lazy: start-up (froude --help imports every verb module and no NumPy)
    from ..demo import demo_files, run_demo  # lazy: start-up (froude --help imports every verb module and no NumPy)

    check_inputs(args.clip)
    out = Path(args.output)
    guard_outputs([out / name for name in demo_files(video=not args.no_video)], [args.clip], folders=[out])
    t0 = time.perf_counter()
    created = not out.exists()
    try:
        with atomic_group():  # every file lands at the end, or none
            files = run_demo(out, args.clip, strides=args.strides, video=not args.no_video,
                             say=lambda s: say(s, args.quiet))
    except BaseException:
        if created:  # the group removed its temporaries: the folder it made is empty again
            try:
                out.rmdir()
            except OSError:
                pass
        raise
    print(f"froude demo: wrote {len(files)} files to {args.output}/ in {time.perf_counter() - t0:.1f} s")
    for key in ("report", "fig2", "fig3", "fig3_child_vs_naive", "video", "machine"):
        if key in files:
            print(f"  {files[key]}")
    print(f"Explore it live:  froude view {args.clip or ''}".rstrip())
    return 0
