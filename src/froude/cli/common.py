"""Helpers shared by the subcommands: loading clips with a spoken summary of units and cleaning."""
from __future__ import annotations

import sys

from ..io.bvh import load_bvh
from ..motion import Motion


def say(msg: str = "", quiet: bool = False) -> None:
    """Progress and notes go to stderr, so stdout stays clean for tables and JSON."""
    if not quiet:
        print(msg, file=sys.stderr, flush=True)


def load_clip(path: str, length_scale: float | None = None, keep_all: bool = False, quiet: bool = False) -> Motion:
    """Load a BVH clip and say which units were chosen and what cleaning did."""
    motion = load_bvh(path, length_scale=length_scale, clean=not keep_all)
    say(f"{path}: {motion.n_frames} frames at {motion.fps:.0f} Hz; units: {motion.meta['units']}", quiet)
    for note in motion.meta.get("cleaning", ()):
        say(f"{path}: cleaning: {note}", quiet)
    return motion


def add_load_options(p) -> None:
    p.add_argument("--length-scale", type=float, default=None, metavar="M",
                   help="metres per file unit (default: detected from the skeleton's height)")
    p.add_argument("--keep-all-frames", action="store_true",
                   help="do not drop a synthetic T-pose frame or invalid leading/trailing rows")


def add_range_option(p) -> None:
    p.add_argument("--range", default=None, metavar="T0:T1",
                   help="model only this part of the take, in seconds (e.g. 1.2:3.0, or 1.2: to the end): its "
                   "speed, cadence and strides; speed factors then refer to it (default: the whole take, "
                   "said aloud when its speed changes)")
