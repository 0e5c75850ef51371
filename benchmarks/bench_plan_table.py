"""Does the §5.3 transition table help ``accelerate``? Plans of the 9 CMU running clips, 0.5x and 1.3x in 8
steps, with and without ``table=``; and the angle-only (the paper's) plans the table serves.

Run:  python benchmarks/bench_plan_table.py [MOCAP_DIR]   (default: $FROUDE_MOCAP_DIR, else ../shared/data/mocap
      beside the repository)
Prints per clip and goal: the mode used, plan time best of 3 without / with the table, and the largest
difference between the two plans (apex speeds U, touchdown angles, b); then whether θ0 alone (the control the
table tabulates) reaches 0.9x and 1.1x, and the table's interpolation error against the simulator.
The answer it gave on 2026-11-25 (README, accelerate): identical plans, no time saved, θ0 alone reaches
neither 0.9x nor 1.1x; so ``pipeline.accelerate`` does not build a table.
"""
import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMEXPR_NUM_THREADS"):
    os.environ[_v] = "1"

import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from froude.errors import PlanError  # noqa: E402
from froude.flow import pipeline  # noqa: E402
from froude.machine.dynamics import step  # noqa: E402
from froude.machine.planner import plan_speed_change  # noqa: E402
from froude.machine.table import grid_around, load_or_build_table  # noqa: E402

CLIPS = ("09_01", "09_02", "09_03", "09_04", "09_05", "09_06", "09_07", "09_08", "02_03")


def timed_plan(m, goal, table, energy="auto"):
    """(plan or the PlanError's first words, best time of 3 [s])."""
    best, out = float("inf"), None
    for _ in range(3):
        t = time.perf_counter()
        try:
            out = plan_speed_change(m, goal, n_steps=8, table=table, energy=energy)
        except PlanError as e:
            out = str(e).split(":")[0]
        best = min(best, time.perf_counter() - t)
    return out, best


def compare(clip, m, table):
    for f in (0.5, 1.3):
        (a, ta), (b, tb) = timed_plan(m, f * m.U, None), timed_plan(m, f * m.U, table)
        if isinstance(a, str) or isinstance(b, str):
            said = [p if isinstance(p, str) else "ok" for p in (a, b)]
            print(f"{clip} x{f}: without: {said[0]}; with: {said[1]}")
            continue
        d = [np.abs(x - y).max() for x, y in ((a.U, b.U), (a.theta0, b.theta0), (a.b, b.b))]
        print(f"{clip} x{f}: mode {a.mode}/{b.mode}  {ta * 1e3:.0f} / {tb * 1e3:.0f} ms  "
              f"max|dU| {d[0]:.1e} max|dθ0| {np.degrees(d[1]):.1e} deg max|db| {d[2]:.1e}")
    for f in (0.9, 1.1):
        theta_only, _ = timed_plan(m, f * m.U, table, energy="theta")
        said = theta_only if isinstance(theta_only, str) else "reached"
        print(f"{clip} x{f} θ0 only (the table's control): {said}")


def interpolation_error(m, table) -> float:
    """Largest |U'_table − U'_simulator| over 50 apex speeds 0.8-1.2 × the cycle's at its H and θ0."""
    U = np.linspace(0.8 * m.U, 1.2 * m.U, 50)
    H, th = np.full_like(U, m.H), np.full_like(U, m.theta0)
    lk, r = table.lookup(U, H, th), step(U, H, th, m.control)
    ok = np.asarray(lk.feasible) & np.asarray(r.valid)
    return float(np.abs(np.asarray(lk.U_next)[ok] - np.asarray(r.U_next)[ok]).max())


def main():
    default = os.environ.get("FROUDE_MOCAP_DIR") or Path(__file__).resolve().parents[2] / "shared" / "data" / "mocap"
    mocap = Path(sys.argv[1] if len(sys.argv) > 1 else default)
    with tempfile.TemporaryDirectory() as cache:
        for clip in CLIPS:
            m = pipeline.prepare(mocap / f"{clip}.bvh").machine
            t = time.perf_counter()
            table, _ = load_or_build_table(m.control, grid_around(m.U, m.H, m.theta0, n=48), cache_dir=cache)
            print(f"{clip}: 48³ table built in {time.perf_counter() - t:.2f} s; "
                  f"interpolation error {interpolation_error(m, table):.1e}")
            compare(clip, m, table)


if __name__ == "__main__":
    main()
