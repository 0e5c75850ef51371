"""Helpers shared by the subcommands: loading clips with a spoken summary of units and cleaning."""
from __future__ import annotations

import sys

from ..io.bvh import load_bvh
from ..motion import Motion


def say(msg: str = "", quiet: bool = False) -> None:
    """Progress and notes go to stderr, so stdout stays clean for tables and JSON."""
    if not quiet:
        print(msg, file=sys.stderr, flush=True)


def load_clip(path: str, length_scale: float | None = None, keep_all: bool = False, quiet: bool = False,
              joint_map: str | None = None, up: str | None = None) -> Motion:
    """Load a BVH clip and say which units and conventions were read and what cleaning did.

    joint_map: a YAML file 'role: JointName' (``body.load_joint_map``); up: "Y"/"Z" (None: detected)."""
    from ..body import load_joint_map

    jm = load_joint_map(joint_map) if joint_map else None
    motion = load_bvh(path, length_scale=length_scale, clean=not keep_all, joint_map=jm, up=up)
    say(f"{path}: {motion.n_frames} frames at {motion.fps:.3f} Hz; units: {motion.meta['units']}", quiet)
    for note in motion.meta.get("conventions", ()):
        say(f"{path}: {note}", quiet)
    for note in motion.meta.get("cleaning", ()):
        say(f"{path}: cleaning: {note}", quiet)
    return motion


def add_load_options(p) -> None:
    p.add_argument("--length-scale", type=float, default=None, metavar="M",
                   help="metres per file unit (default: detected from the motion: the flight gravity, else the most human stature)")
    p.add_argument("--joint-map", default=None, metavar="FILE.yaml",
                   help="joint roles for unusual joint names, lines 'role: JointName' (e.g. left_knee: Shin_L)")
    p.add_argument("--up", default=None, choices=("Y", "Z"), type=str.upper,
                   help="the file's up axis (default: detected from the motion)")
    p.add_argument("--keep-all-frames", action="store_true",
                   help="do not drop a synthetic T-pose frame or invalid leading/trailing rows")
