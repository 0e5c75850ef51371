"""Benchmark: §5.3 speed planning on one core.

Run:  python benchmarks/bench_planner.py
Prints: transition-table build and cached-load times (64³ and 32³, for a fitted real clip when
froude.machine.fit works, else a synthetic cycle), the time to plan a 0.5× deceleration and a 1.3×
acceleration over 8 steps (with the cached table, and without one), and the time of the dense
trajectory of the plan. Best of several runs; everything dimensionless.
"""
import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMEXPR_NUM_THREADS"):
    os.environ[_v] = "1"

import tempfile  # noqa: E402
import time  # noqa: E402

from froude.machine.cycle import find_limit_cycle  # noqa: E402
from froude.machine.dynamics import Control  # noqa: E402
from froude.machine.planner import plan_speed_change  # noqa: E402
from froude.machine.table import grid_around, load_or_build_table  # noqa: E402


def best_of(fn, n):
    best, out = float("inf"), None
    for _ in range(n):
        t = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t)
    return best, out


def start_cycle():
    try:
        from froude.body.load import load_bvh
        from froude.io.samples import sample_path
        from froude.machine.fit import fit_machine
        m = fit_machine(load_bvh(sample_path()))
        return m, f"fitted machine of {os.path.basename(str(sample_path()))}"
    except Exception as e:  # the fit is another module; fall back to a synthetic cycle
        lc = find_limit_cycle(1.2, 1.0, 0.40, Control(K=15, a=0.01, b=-0.03, c=0.02, T_c=0.6))
        return lc, f"synthetic cycle (fit unavailable: {type(e).__name__})"


def main():
    cyc, what = start_cycle()
    print(f"start: {what}: U={cyc.U:.4f} H={cyc.H:.4f} theta0={cyc.theta0:.4f} {cyc.control}")
    with tempfile.TemporaryDirectory() as d:
        for n in (64, 32):
            grid = grid_around(cyc.U, cyc.H, cyc.theta0, n=n)
            t = time.perf_counter()
            table, loaded = load_or_build_table(cyc.control, grid, cache_dir=d)
            build = time.perf_counter() - t
            assert not loaded
            load, _ = best_of(lambda grid=grid: load_or_build_table(cyc.control, grid, cache_dir=d), 5)
            print(f"table {n}^3: build (incl. save) {build:6.2f} s, cached load {load * 1e3:6.1f} ms, "
                  f"valid {table.valid.mean():.0%}")
        grid = grid_around(cyc.U, cyc.H, cyc.theta0, n=64)
        table, _ = load_or_build_table(cyc.control, grid, cache_dir=d)
        for factor in (0.5, 1.3):
            goal = factor * cyc.U
            tt, plan = best_of(lambda goal=goal: plan_speed_change(cyc, goal, n_steps=8, table=table), 3)
            tn, _ = best_of(lambda goal=goal: plan_speed_change(cyc, goal, n_steps=8), 3)
            tb, _ = best_of(lambda goal=goal: plan_speed_change(cyc, goal, n_steps=8, energy="b"), 3)
            print(f"plan {factor}x over 8 steps: {tt * 1e3:7.1f} ms with cached table, {tn * 1e3:7.1f} ms "
                  f"without, {tb * 1e3:7.1f} ms energy='b' (no theta0-only attempt); mode {plan.mode}, "
                  f"final U/goal = {plan.U[-1] / (factor * cyc.U):.9f}")
        plan = plan_speed_change(cyc, 0.5 * cyc.U, n_steps=8, lead_steps=2, hold_steps=4, table=table)
        td, tr = best_of(lambda: plan.trajectory(0.01), 5)
        print(f"dense trajectory of a {plan.n_steps}-step plan at dt=0.01: {td * 1e3:.1f} ms "
              f"({tr.t.size} samples)")


if __name__ == "__main__":
    main()
