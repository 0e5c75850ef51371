"""Where a turn's detail is lost between the clip's path and an output's (issue 28, heading and radius per step).

    PYTHONPATH=src python benchmarks/turn_detail.py left_normal_001 [--step 0.2]

Prints, per stretch of the clip's path (``--step`` metres of its arc length), the heading gained [deg] by:
- path: the clip's path (``take_path``: its COM averaged over one stride in time);
- COM over a length: the clip's COM averaged over one stride's length of path instead (the average an output
  walking at one speed applies to itself);
- travel line over a length: the clip's travel line (``TakePath.travel_line``, the track the output's COM is
  bent onto) averaged the same way: what an output's path can at best be;
and the clip's speed along its path. When "COM over a length" follows "path" and "travel line over a length"
does not, the detail is lost in the travel line (built from the stride-averaged path), not in the average's
being over time rather than length.
"""
from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "tests"))


def _over_length(track: np.ndarray, arc_m: np.ndarray, box_m: float) -> tuple[np.ndarray, np.ndarray]:
    """(arc length (n,) [m], heading (n,) [rad]) of track (F, 3) [m], resampled at even steps of the clip path's
    arc length arc_m (F,) [m] and averaged over box_m [m] of it (``smooth_path``)."""
    from froude.body.path import _track_geometry, smooth_path

    n = arc_m.size
    grid = np.linspace(0.0, arc_m[-1], n)
    even = np.stack([np.interp(grid, arc_m, track[:, k]) for k in range(3)], axis=-1)
    s, h, _ = _track_geometry(smooth_path(even, max(1, int(round(box_m / (arc_m[-1] / (n - 1)))))), 1.0)
    return s, h


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("clip", help="a substring of a shared turning clip's name")
    ap.add_argument("--step", type=float, default=0.2, help="stretch of the clip's path [m]")
    args = ap.parse_args(argv)
    from turns_matrix import _clips

    from froude.body.load import load_bvh
    from froude.body.model import BodyModel
    from froude.body.path import _stride_frames, unsmooth_path, unstraighten
    from froude.body.take import analysed_take

    from conftest import clip

    name = next(n for n in _clips() if args.clip in n)
    motion = load_bvh(clip(name))
    body = BodyModel.from_skeleton(motion.skeleton)
    take = analysed_take(motion, body)  # no fit: a clip that scale refuses is shown too
    cp = take.clip_path
    as_taken = unstraighten(take.motion, take.turn) if take.turn is not None else take.motion
    com, _ = body.com_and_markers(as_taken)
    s = np.maximum.accumulate(cp.arc_length_m)
    box_m = cp.path_speed_m_s * cp.stride_s
    line = unsmooth_path(cp.p_world_path, _stride_frames(cp.stride_s, cp.frame_time))
    rows = {"path": (s, cp.heading_rad), "COM over a length": _over_length(com, s, box_m),
            "travel line over a length": _over_length(line, s, box_m)}
    edges = np.arange(0.0, s[-1] - args.step, args.step)
    print(f"{name}: stride {cp.stride_s:.2f} s, {box_m:.2f} m; heading gained per {args.step} m of path [deg]")
    print(f"{'from [m]':26s}" + "".join(f"{a:6.1f}" for a in edges))
    for label, (arc, h) in rows.items():
        print(f"{label:26s}" + "".join(f"{math.degrees(np.interp(a + args.step, arc, h) - np.interp(a, arc, h)):6.1f}"
                                        for a in edges))
    speed = np.gradient(s) / cp.frame_time
    print(f"{'speed along path [m/s]':26s}" + "".join(f"{np.interp(a + args.step / 2, s, speed):6.2f}" for a in edges))
    return 0


if __name__ == "__main__":
    sys.exit(main())
