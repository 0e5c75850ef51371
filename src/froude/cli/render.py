"""``froude render CLIP.bvh [MORE.bvh ...] -o OUT.(png|gif|mp4)``: filmstrips (the paper's Fig. 3), stills, videos."""
from __future__ import annotations

import sys
from pathlib import Path

from ..errors import FroudeError
from .common import add_load_options, load_clip, say

_EXTENSIONS = (".png", ".gif", ".mp4")


def register(sub) -> None:
    p = sub.add_parser(
        "render", help="draw motions: filmstrip PNG (Fig. 3 style), still PNG, GIF or MP4 video",
        description="Draw one or more motions as capsule figures at one common scale (a child looks small "
        "next to a giant). --filmstrip: snapshots every --interval seconds side by side, one labelled row per "
        "motion (PNG). Otherwise a video (GIF/MP4) with one panel per motion at real time, the camera "
        "following each runner, or a still PNG of that layout at --at seconds.",
    )
    p.add_argument("clips", nargs="+", metavar="CLIP", help="BVH files")
    p.add_argument("-o", "--output", required=True, metavar="OUT", help="output file: .png, .gif or .mp4")
    p.add_argument("--filmstrip", action="store_true", help="snapshots side by side, a row per motion (PNG)")
    p.add_argument("--interval", type=float, default=0.066, metavar="S",
                   help="filmstrip: seconds between snapshots (default 0.066, as in the paper's Fig. 3)")
    p.add_argument("--spacing", type=float, default=None, metavar="M",
                   help="filmstrip: extra metres between snapshots (default: enough to keep them apart; "
                   "0 = true positions, a chronophotograph)")
    p.add_argument("--camera", choices=("side", "three-quarter", "front"), default="side",
                   help="orthographic camera (default side)")
    p.add_argument("--labels", default=None, metavar="A,B",
                   help="comma-separated labels, one per clip (default: file names)")
    p.add_argument("--fps", type=float, default=30.0, help="video frame rate [Hz] (default 30)")
    p.add_argument("--width", type=int, default=None, metavar="PX",
                   help="image width [px] (default 2400 for filmstrips, 960 for videos and stills)")
    p.add_argument("--height", type=int, default=None, metavar="PX",
                   help="video/still height [px] (default 0.75 x the panel width)")
    p.add_argument("--at", type=float, default=0.0, metavar="S", help="still PNG: time [s] to show (default 0)")
    p.add_argument("--quiet", action="store_true", help="no progress or notes on stderr")
    add_load_options(p)
    p.set_defaults(func=run)


def _progress(quiet: bool):
    if quiet:
        return None

    def show(done: int, total: int) -> None:
        end = "\n" if done == total else ""
        print(f"\rrender: frame {done}/{total}", end=end, file=sys.stderr, flush=True)

    return show


def run(args) -> int:
    # check everything that needs no file before reading any: bad requests leave nothing behind
    out = Path(args.output)
    ext = out.suffix.lower()
    if ext not in _EXTENSIONS:
        raise FroudeError(f"{out}: unknown output extension '{out.suffix}'; use .png, .gif or .mp4")
    if args.filmstrip and ext != ".png":
        raise FroudeError(f"{out}: a filmstrip is a still image; write it to a .png")
    if args.width is not None and args.width < 16:
        raise FroudeError(f"--width must be at least 16 px, got {args.width}")
    parent = out.parent if str(out.parent) else Path(".")
    if not parent.is_dir():
        raise FroudeError(f"{out}: folder '{parent}' does not exist")
    labels = None
    if args.labels is not None:
        labels = [s.strip() for s in args.labels.split(",")]
        if len(labels) != len(args.clips):
            raise FroudeError(f"--labels gives {len(labels)} labels for {len(args.clips)} clips")
    for clip in args.clips:
        if not Path(clip).is_file():
            raise FroudeError(f"{clip}: no such file")

    from ..viz import render as R

    motions = [load_clip(c, args.length_scale, args.keep_all_frames, args.quiet, args.joint_map, args.up)
               for c in args.clips]
    if labels is None:
        labels = [Path(c).stem for c in args.clips]
    if args.filmstrip:
        strip = R.render_filmstrip(motions, out, labels, interval=args.interval, camera=args.camera,
                                   width=args.width or 2400, spacing=args.spacing)
        h, w = strip.image.shape[:2]
        say(f"wrote {out}: {w}x{h} px, {' + '.join(map(str, strip.n_snapshots))} snapshots every "
            f"{args.interval:g} s, spacing {strip.spacing:.2f} m", args.quiet)
    elif ext == ".png":
        image = R.render_frame(motions, out, labels, time=args.at, camera=args.camera, width=args.width or 960,
                               height=args.height)
        say(f"wrote {out}: {image.shape[1]}x{image.shape[0]} px at t = {args.at:g} s", args.quiet)
    else:
        n, h, w = R.render_video(motions, out, labels, fps=args.fps, camera=args.camera, width=args.width or 960,
                                 height=args.height, progress=_progress(args.quiet))
        say(f"wrote {out}: {n} frames {w}x{h} px at {args.fps:g} fps", args.quiet)
    return 0
