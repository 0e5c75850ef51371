"""Benchmark: 64³ transition table build / cached load, and step() throughput, on one core.

Run:  python benchmarks/bench_table.py
Targets (docs/architecture.md): build ≤ 5 s, cached load ≤ 0.2 s.
"""
import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMEXPR_NUM_THREADS"):
    os.environ[_v] = "1"

import tempfile  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

from froude.machine.cycle import find_limit_cycle  # noqa: E402
from froude.machine.dynamics import Control, step  # noqa: E402
from froude.machine.table import grid_around, load_or_build_table  # noqa: E402


def best_of(fn, n):
    best = float("inf")
    for _ in range(n):
        t = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t)
    return best


def main():
    # A realistic running cycle (U ≈ 1.15, i.e. ~3.5 m/s for l0 = 0.95 m).
    lc = find_limit_cycle(1.15, 1.0, 0.40, Control(K=15.0, a=0.02, b=0.01, c=-0.02, T_c=0.6))
    print(f"cycle: U={lc.U:.4f} H={lc.H:.4f} theta0={lc.theta0:.4f} {lc.control} "
          f"residual={lc.residual:.1e}")
    grid = grid_around(lc.U, lc.H, lc.theta0, n=64)
    with tempfile.TemporaryDirectory() as d:
        t = time.perf_counter()
        table, loaded = load_or_build_table(lc.control, grid, cache_dir=d)
        build = time.perf_counter() - t
        assert not loaded
        load = best_of(lambda: load_or_build_table(lc.control, grid, cache_dir=d), 5)
    n = table.valid.size
    print(f"table 64^3 = {n} cells, valid {table.valid.mean():.1%}")
    print(f"build (incl. save): {build:.2f} s   target <= 5 s   {'OK' if build <= 5 else 'MISS'}")
    print(f"cached load:        {load * 1e3:.1f} ms  target <= 200 ms {'OK' if load <= 0.2 else 'MISS'}")

    c = lc.control
    single = best_of(lambda: step(lc.U, lc.H, lc.theta0, c), 20)
    print(f"step single call:   {single * 1e3:.2f} ms  ({1 / single:.0f} steps/s)")
    rng = np.random.default_rng(0)
    for m in (10, 100, 1000, 10000, 100000):
        U = lc.U * rng.uniform(0.9, 1.1, m)
        H = lc.H + rng.uniform(-0.01, 0.01, m)
        th = lc.theta0 + rng.uniform(-0.03, 0.03, m)
        tb = best_of(lambda U=U, H=H, th=th: step(U, H, th, c), 3 if m <= 10000 else 1)
        print(f"step batch {m:>6}:  {tb * 1e3:8.2f} ms  ({m / tb:,.0f} steps/s)")
    t = time.perf_counter()
    lc2 = find_limit_cycle(1.15, 1.0, 0.40, Control(K=15.0, a=0.02, b=0.01, c=-0.02, T_c=0.6))
    print(f"limit cycle search: {(time.perf_counter() - t) * 1e3:.0f} ms ({lc2.iterations} iterations)")


if __name__ == "__main__":
    main()
