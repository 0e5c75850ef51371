"""Throughput of ``froude batch`` on a local Dask cluster: tasks/s with 1 and with 2 worker processes.

    .venv/bin/python benchmarks/bench_batch.py [--strides 12] [--repeat 2] [--workers 1 2]

Each worker is one process with one thread (OMP/OPENBLAS/MKL_NUM_THREADS=1 in its environment, checked
below). The clusters are started and warmed up (imports done on every worker) before the clock starts; the
time is from the first submission to the last result, i.e. what ``froude batch`` reports as tasks/s, and
includes each clip's prepare task and the writing of every output. Per-task work is a 12-stride output
(≈0.3 s CPU) so Dask's per-task overhead (a few ms) does not dominate. Bar (docs/architecture.md): 2 workers ≥ 1.8 × 1.
The machine is shared: the load average is printed beside the figures.
"""
from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_v] = "1"

import argparse  # noqa: E402
import shutil  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

from froude.apps import batch  # noqa: E402

MOCAP = Path(os.environ.get("FROUDE_MOCAP_DIR", Path(__file__).resolve().parents[2] / "shared" / "data" / "mocap"))
CLIPS = ("09_01", "09_02", "09_03", "09_04", "09_05", "09_06", "09_07", "09_08")


def _worker_threads() -> dict:
    """What a worker sees: its thread-count variables and (if threadpoolctl is there) its BLAS pools."""
    import threading

    out = {k: os.environ.get(k) for k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")}
    out["python_threads_running_tasks"] = 1
    try:
        from threadpoolctl import threadpool_info

        out["blas_threads"] = sorted({p["num_threads"] for p in threadpool_info()})
    except ImportError:
        out["blas_threads"] = "threadpoolctl not installed"
    out["active_threads"] = threading.active_count()
    return out


def _spin(n: int = 5_000_000) -> float:
    x = 0
    for i in range(n):
        x += i * i
    return float(x)


def machine_ceiling() -> float:
    """Speed-up of a pure-Python CPU loop in 2 processes over 1: what this machine can give right now
    (≈ 2.0 on an idle 2-core machine; lower while other programs use the cores)."""
    import multiprocessing as mp

    t = time.perf_counter()
    _spin()
    one = time.perf_counter() - t
    with mp.get_context("spawn").Pool(2) as pool:
        pool.map(_spin, [10, 10])
        t = time.perf_counter()
        pool.map(_spin, [5_000_000] * 2)
        two = time.perf_counter() - t
    return 2 * one / two


_PREP = None


def _init_prep(path: str) -> None:
    global _PREP
    from froude.flow import pipeline

    _PREP = pipeline.prepare(path)


def _scale_once(strides: int) -> float:
    from froude.flow import pipeline

    c = time.process_time()
    pipeline.scale(_PREP, "giant", speed=1.0, strides=strides)
    return time.process_time() - c


def pipeline_ceiling(path: str, strides: int, n_tasks: int = 16) -> tuple[float, float]:
    """The same kind of task (pipeline.scale) in 2 plain processes vs 1, no Dask: the speed-up this machine
    gives this (NumPy, memory-heavy) work right now, and the CPU-time inflation when both cores are busy."""
    import multiprocessing as mp

    walls, cpus = {}, {}
    for n in (1, 2):
        with mp.get_context("spawn").Pool(n, initializer=_init_prep, initargs=(path,)) as pool:
            pool.map(_scale_once, [1] * n)  # warm up
            t = time.perf_counter()
            cpus[n] = sum(pool.map(_scale_once, [strides] * n_tasks, chunksize=1))
            walls[n] = time.perf_counter() - t
    return walls[1] / walls[2], cpus[2] / cpus[1]


def _cpu_times() -> list[int]:
    with open("/proc/stat") as f:
        return [int(x) for x in f.readline().split()[1:]]


def _busy_elsewhere(before, after, own_cpu_s: float, wall_s: float) -> float:
    """Share of the machine's CPU [0-1] used by other programs during a run (from /proc/stat)."""
    d = [b - a for a, b in zip(before, after)]
    hz = os.sysconf("SC_CLK_TCK")
    busy = (sum(d) - d[3] - d[4]) / hz  # all but idle and iowait [CPU s]
    return max(0.0, busy - own_cpu_s) / (wall_s * (os.cpu_count() or 1))


def measure(n_workers: int, clips, plan, repeat: int) -> dict:
    """The fastest of ``repeat`` runs on a warmed-up local cluster of ``n_workers``: elapsed [s], tasks,
    CPU seconds spent in the variation tasks and in the driver process, and a worker's thread settings."""
    client, cluster = batch.start_client(n_workers=n_workers)
    try:
        batch.warm_up(client)
        env = next(iter(client.run(_worker_threads).values()))
        nthreads = client.nthreads()
        assert len(nthreads) == n_workers and set(nthreads.values()) == {1}, nthreads
        best = {"elapsed": float("inf")}
        for _ in range(repeat):
            out = Path(tempfile.mkdtemp(prefix="froude-bench-batch-"))
            c0 = time.process_time()  # the driver: client, scheduler (in this process), index writes
            stat0 = _cpu_times()
            try:
                s = batch.run_batch(clips, plan, out, client=client, progress=False, log=lambda m: None)
            finally:
                shutil.rmtree(out, ignore_errors=True)
            driver_cpu = time.process_time() - c0
            stat1 = _cpu_times()
            if s.count("failed"):
                raise SystemExit(f"{s.count('failed')} task(s) failed: {next(iter(s.failures()))}")
            if s.elapsed_s < best["elapsed"]:
                best = {"elapsed": s.elapsed_s, "ran": s.ran, "task_cpu": sum(r["task_cpu_s"] for r in s.rows),
                        "driver_cpu": driver_cpu, "env": env}
                best["others"] = _busy_elsewhere(stat0, stat1, best["task_cpu"] + driver_cpu, s.elapsed_s)
        return best
    finally:
        client.close()
        cluster.close()


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--strides", type=int, default=12)
    ap.add_argument("--repeat", type=int, default=2, help="runs per worker count; the fastest counts")
    ap.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--clips", nargs="+", default=list(CLIPS))
    a = ap.parse_args(argv)
    clips = batch.find_clips([MOCAP / f"{c}.bvh" for c in a.clips])
    plan = batch.parse_plan({"characters": ["child", "giant", "small"], "speeds": [0.9, 1.1], "strides": a.strides})
    n_tasks = len(clips) * len(plan.variations)
    print(f"froude batch throughput: {len(clips)} clips x {len(plan.variations)} variations = {n_tasks} tasks "
          f"({a.strides} strides each) + {len(clips)} prepare tasks; best of {a.repeat}; {os.cpu_count()} cores")
    print(f"  machine ceiling now: a pure-Python loop runs {machine_ceiling():.2f}x faster in 2 processes than in 1")
    speedup, inflation = pipeline_ceiling(clips[0].path, a.strides)
    print(f"  pipeline ceiling now (no Dask, plain processes): {speedup:.2f}x; CPU time per task x{inflation:.2f} "
          "when both cores work")
    rates = {}
    for n in a.workers:
        load0 = os.getloadavg()[0]
        m = measure(n, clips, plan, a.repeat)
        t, ran, env = m["elapsed"], m["ran"], m["env"]
        rates[n] = ran / t
        # CPU seconds the variation tasks got / (workers x wall time): < 1 when other programs take the cores
        share = m["task_cpu"] / (n * t)
        print(f"  {n} worker(s): {ran} tasks in {t:6.2f} s = {rates[n]:5.2f} tasks/s   "
              f"(task CPU {m['task_cpu']:.1f} s = {share:.0%} of {n} core(s); driver CPU {m['driver_cpu']:.1f} s; "
              f"other programs {m['others']:.0%} of the machine; load avg before {load0:.2f}; "
              f"worker OMP/OPENBLAS/MKL threads {env['OMP_NUM_THREADS']}/"
              f"{env['OPENBLAS_NUM_THREADS']}/{env['MKL_NUM_THREADS']}, BLAS pools {env['blas_threads']})")
        sys.stdout.flush()
    if 1 in rates and 2 in rates:
        ratio = rates[2] / rates[1]
        print(f"  speed-up 2 vs 1 worker: {ratio:.2f}x  (bar >= 1.8x: {'met' if ratio >= 1.8 else 'NOT met'})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
