"""Time a 4 s MP4 render at 30 fps (09_01 slowed to 4 s) and a 2-panel GIF; prints seconds."""
import os

for v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[v] = "1"
import sys
import time

import numpy as np

import froude
from froude import load_bvh
from froude.viz.render import render_video

m = load_bvh(froude.sample_path())
slow = m.time_warp(np.linspace(0, m.duration, 481), frame_time=1 / 120)  # 4.0 s
jump = load_bvh(os.path.join(os.path.dirname(__file__), "..", "..", "shared", "data", "mocap", "02_04.bvh"))
small = m.with_(skeleton=m.skeleton.scaled(0.6), root_positions=m.root_positions * 0.6)
out = sys.argv[1] if len(sys.argv) > 1 else "/tmp/froude-render-bench"
os.makedirs(out, exist_ok=True)
for name, motions, kw in [
    ("run_4s.mp4", [slow], {}),
    ("jump_4s.mp4", [jump], {}),
    ("run_vs_small_4s.mp4", [slow, small.time_warp(np.linspace(0, m.duration, 481), frame_time=1 / 120)], {}),
    ("run_vs_small.gif", [m, small], {"width": 640}),
]:
    t = time.perf_counter()
    n, h, w = render_video(motions, os.path.join(out, name), fps=30, **kw)
    dt = time.perf_counter() - t
    print(f"{name}: {n} frames {w}x{h}: {dt:.2f} s ({n / dt:.0f} frames/s)")
