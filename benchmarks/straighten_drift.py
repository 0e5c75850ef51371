"""How far ``body.path.straighten`` moves planted feet, on every shared turning clip (issue 28).

    PYTHONPATH=src python benchmarks/straighten_drift.py            # ~1 min, one core

Per full stance (``body.gait``), the largest horizontal move [mm] of the stance foot's lowest marker (the one
lowest at mid-stance) over the frames where it is within 1 cm of its lowest height in that stance, from its
mean position there: in the take as taken (the clip's own roll and noise) and straightened along its path.
Also the straightened take's heading change (by ``take_path``, should be near 0) and its COM track's length
against the path's. The clips: as benchmarks/turns_matrix.py finds them.
"""
from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_v] = "1"

import math  # noqa: E402
import sys  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "tests"))
sys.path.insert(0, str(HERE))

#: A marker this close to its lowest height in the stance [m] counts as on the floor.
ON_FLOOR_M = 0.01


def planted_drift_mm(markers: np.ndarray, stance) -> float:
    """Largest horizontal move [mm] of a stance's planted marker from its mean place (see the module)."""
    from froude.core.constants import HORIZONTAL_AXES, UP_AXIS

    a, b = stance.start, stance.stop
    mid = (a + b - 1) // 2
    k = int(np.argmin(markers[mid, stance.foot, :, UP_AXIS]))
    h = markers[a:b, stance.foot, k, UP_AXIS]
    x = markers[a:b, stance.foot, k][:, HORIZONTAL_AXES][h <= h.min() + ON_FLOOR_M]
    return 1000.0 * float(np.max(np.linalg.norm(x - x.mean(axis=0), axis=1)))


def main() -> int:
    from turns_matrix import _clips

    from froude.body.gait import detect_gait
    from froude.body.load import load_bvh
    from froude.body.model import BodyModel
    from froude.body.path import straighten, take_path
    from froude.body.take import running_take

    from conftest import clip

    print(f"{'clip':40s} {'stances':>7s}  {'as taken med/max':>17s}  {'straightened med/max':>21s}  "
          f"{'turn left':>9s}  {'length/path':>11s}")
    for name in _clips():
        motion = load_bvh(clip(name))
        body = BodyModel.from_skeleton(motion.skeleton)
        motion, _ = running_take(motion, body)
        com, markers = body.com_and_markers(motion)
        gait = detect_gait(motion, body, markers, com)
        path = take_path(motion, body, com, gait)
        flat = straighten(motion, path)
        com_s, markers_s = body.com_and_markers(flat)
        full = [st for st in gait.stances if not st.partial]
        d0 = [planted_drift_mm(markers, st) for st in full]
        d1 = [planted_drift_mm(markers_s, st) for st in full]
        left = take_path(flat, body, com_s, detect_gait(flat, body, markers_s, com_s))
        length = take_path(flat, body, com_s, gait).length_m / path.length_m
        print(f"{name.split('/')[-1].replace('dataset-2_walk-turn-', ''):40s} {len(full):7d}  "
              f"{np.median(d0):8.1f}/{max(d0):6.1f}   {np.median(d1):12.1f}/{max(d1):6.1f}  "
              f"{math.degrees(left.heading_change_rad):+8.1f}°  {length:11.3f}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
