"""``froude render CLIP.bvh [MORE.bvh ...] -o OUT.(png|gif|mp4)``: filmstrips (the paper's Fig. 3), stills, videos."""
from __future__ import annotations

import sys
from pathlib import Path

from ...errors import FroudeError
from .common import (
    add_force,
    add_load_options,
    add_quiet,
    bound_work,
    check_inputs,
    guard_outputs,
    load_clip,
    number,
    say,
)

_EXTENSIONS = (".png", ".gif", ".mp4")
#: Image sizes [px] and filmstrip settings froude draws.
WIDTH_RANGE_PX = (16, 8192)
HEIGHT_RANGE_PX = (16, 8192)
INTERVAL_RANGE_S = (0.001, 10.0)
SPACING_RANGE_M = (0.0, 100.0)
VIDEO_FPS_RANGE_HZ = (1.0, 240.0)
#: A filmstrip snapshot narrower than this [px] is no picture: the interval or the width is refused.
MIN_SNAPSHOT_PX = 8
#: Pixels drawn at most without --force (frames x width x height; a 20 s 960x720 video at 30 Hz is 4e8).
MAX_PIXELS = 4e9


#: The one-line summary ``froude --help`` lists.
HELP = "draw motions: filmstrip PNG (Fig. 3 style), still PNG, GIF or MP4 video"


def register(sub) -> None:
    p = sub.add_parser(
        "render", help=HELP,
        description="Draw one or more motions as capsule figures at one common scale (a child looks small "
        "next to a giant). --filmstrip: snapshots every --interval seconds side by side, one labelled row per "
        "motion (PNG). Otherwise a video (GIF/MP4) with one panel per motion at real time, the camera "
        "following each runner, or a still PNG of that layout at --at seconds.",
    )
    p.add_argument("clips", nargs="+", metavar="CLIP", help="BVH files")
    p.add_argument("-o", "--output", required=True, metavar="OUT", help="output file: .png, .gif or .mp4")
    p.add_argument("--filmstrip", action="store_true", help="snapshots side by side, a row per motion (PNG)")
    p.add_argument("--interval", type=number(*INTERVAL_RANGE_S, "s"), default=0.066, metavar="S",
                   help="filmstrip: seconds between snapshots, 0.001-10 (default 0.066, as in the paper's Fig. 3)")
    p.add_argument("--spacing", type=number(*SPACING_RANGE_M, "m"), default=None, metavar="M",
                   help="filmstrip: extra metres between snapshots, 0-100 (default: enough to keep them apart; "
                   "0 = true positions, a chronophotograph)")
    p.add_argument("--camera", choices=("side", "three-quarter", "front"), default="side",
                   help="orthographic camera (default side)")
    p.add_argument("--labels", default=None, metavar="A,B",
                   help="comma-separated labels, one per clip (default: file names)")
    p.add_argument("--fps", type=number(*VIDEO_FPS_RANGE_HZ, "Hz"), default=30.0,
                   help="video frame rate [Hz], 1-240 (default 30)")
    p.add_argument("--width", type=number(*WIDTH_RANGE_PX, "px", integer=True), default=None, metavar="PX",
                   help=f"image width [px], {WIDTH_RANGE_PX[0]}-{WIDTH_RANGE_PX[1]} "
                   "(default 2400 for filmstrips, 960 for videos and stills)")
    p.add_argument("--height", type=number(*HEIGHT_RANGE_PX, "px", integer=True), default=None, metavar="PX",
                   help=f"video/still height [px], {HEIGHT_RANGE_PX[0]}-{HEIGHT_RANGE_PX[1]} "
                   "(default 0.75 x the panel width)")
    p.add_argument("--at", type=number(0.0, 1e6, "s"), default=0.0, metavar="S",
                   help="still PNG: time [s] to show, within the longest clip (default 0)")
    add_force(p)
    add_quiet(p)
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
    labels = None
    if args.labels is not None:
        labels = [s.strip() for s in args.labels.split(",")]
        if len(labels) != len(args.clips):
            raise FroudeError(f"--labels gives {len(labels)} labels for {len(args.clips)} clips")
    check_inputs(*args.clips)
    guard_outputs([out], args.clips)

    from ...viz import render as R  # lazy: start-up (froude --help imports every verb module and no NumPy)

    motions = [load_clip(c, args.length_scale, args.keep_all_frames, args.quiet, args.joint_map, args.up)
               for c in args.clips]
    longest = max(m.duration for m in motions)
    if not args.filmstrip and ext == ".png" and args.at > longest:
        raise FroudeError(f"--at {args.at:g} s is after the end of the longest clip ({longest:.3f} s); "
                          f"give 0 to {longest:.3f}")
    _bound(args, motions, ext, longest)
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


def _bound(args, motions, ext: str, longest: float) -> None:
    """Refuse a render whose pixels (or, for a GIF, frames held in memory) are out of proportion."""
    if args.filmstrip:
        width = args.width or 2400
        per_row = max(int(m.duration / args.interval) + 1 for m in motions)
        if per_row > width // MIN_SNAPSHOT_PX:
            raise FroudeError(f"--interval {args.interval:g} s gives {per_row} snapshots in a row of {width} px; "
                              f"at most {width // MIN_SNAPSHOT_PX} ({MIN_SNAPSHOT_PX} px each): use a longer "
                              "--interval or a larger --width")
        return
    if ext == ".png":
        return
    width = args.width or 960
    height = args.height or int(0.75 * width / max(len(motions), 1))
    frames = int(longest * args.fps) + 1
    pixels = float(frames) * width * height
    # a GIF keeps every frame in memory (RGB, 3 bytes a pixel) until it is encoded
    if pixels > MAX_PIXELS and not args.force:
        raise FroudeError(f"{frames} frames of {width}x{height} px is beyond the {MAX_PIXELS:.0e}-pixel bound; "
                          "lower --fps/--width/--height or add --force")
    bound_work(frames, 0, args.force, "froude render", args.quiet, extra_bytes=3 * pixels if ext == ".gif" else 0)
