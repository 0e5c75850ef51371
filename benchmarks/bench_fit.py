"""Benchmark: §4 fit of 09_01.bvh (load excluded) on one core. Target ≤ 50 ms median.

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/bench_fit.py [clip.bvh] [repeats]
"""
import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_v] = "1"

import statistics  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

from froude.body.load import load_bvh  # noqa: E402
from froude.io.samples import sample_path  # noqa: E402
from froude.machine.fit import fit_machine  # noqa: E402


def main():
    path = sys.argv[1] if len(sys.argv) > 1 else str(sample_path())
    n = int(sys.argv[2]) if len(sys.argv) > 2 else 30
    motion = load_bvh(path)
    fit_machine(motion)  # warm-up (imports, first-call costs); nothing is cached between runs
    ts = []
    for _ in range(n):
        t = time.perf_counter()
        m = fit_machine(motion)
        ts.append(time.perf_counter() - t)
    med = statistics.median(ts) * 1e3
    print(f"fit {os.path.basename(path)} ({motion.n_frames} frames): median {med:.1f} ms, min {min(ts) * 1e3:.1f} ms, "
          f"max {max(ts) * 1e3:.1f} ms over {n} runs; {m.iterations} simulator calls; target <= 50 ms: "
          f"{'PASS' if med <= 50 else 'FAIL'}")


if __name__ == "__main__":
    main()
