"""Running a batch: the work done on the Dask workers (prepare a clip, run one task) and the driver
(cluster, submission, progress, interrupts, the lock, the index as it goes)."""
from __future__ import annotations

import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ...errors import FroudeError

if TYPE_CHECKING:
    from ...flow.prepared import Prepared

from ..signals import ignoring, interrupt_on_signals, restore_signals
from .layout import (
    INDEX_NAME,
    LOCK_NAME,
    MARKER_SCHEMA,
    _task_params,
    base_row,
    clean_stale_temporaries,
    marker_path,
    read_done,
    write_index,
    write_parquet,
)
from .plan import BatchError, Plan, Task, make_tasks

#: Environment of every local worker process: one thread for every numerical library.
WORKER_ENV = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1",
              "NUMEXPR_NUM_THREADS": "1", "VECLIB_MAXIMUM_THREADS": "1"}
#: Seconds between index rewrites while a batch runs (always rewritten at the end and on interrupt).
INDEX_INTERVAL_S = 1.0


# ---- work done on the workers ---------------------------------------------------------------------------
@dataclass
class Prepped:
    """A prepare task's result: the Prepared clip or the one-line reason it failed, and its time [s]."""

    prep: Prepared | None  # None when the clip failed (error says why)
    error: str
    seconds: float


def prepare_clip(path: str, mass: float, sex: str, length_scale) -> Prepped:
    """Worker task: ``pipeline.prepare`` of one clip (fit once; its result feeds all the clip's variations)."""
    from ...flow import pipeline  # lazy: workers only (the client process never loads the pipeline)

    t0 = time.perf_counter()
    try:
        prep = pipeline.prepare(path, mass=mass, sex=sex, length_scale=length_scale)
        return Prepped(prep, "", time.perf_counter() - t0)
    except Exception as e:  # noqa: BLE001 - a bad clip fails its own tasks, never the batch
        return Prepped(None, _reason(e), time.perf_counter() - t0)


def run_task(prepped: Prepped, task: Task, plan: Plan, outdir: str) -> dict:
    """Worker task: one variation of one prepared clip → BVH + report (atomic), done-marker last; its index row."""
    from ...flow import pipeline  # lazy: workers only (the client process never loads the pipeline)
    from ...io.bvh import atomic_write_text  # lazy: workers only (the client process never loads the pipeline)
    from ...io.jsonable import dumps  # lazy: workers only (the client process never loads the pipeline)

    t0, c0 = time.perf_counter(), time.process_time()
    row = base_row(task)
    row["prepare_s"] = prepped.seconds
    row["worker"] = _worker_name()
    if prepped.error:
        row.update(status="failed", reason=prepped.error, task_s=time.perf_counter() - t0)
        return row
    v = task.variation
    out = Path(outdir) / task.output
    try:
        assert prepped.prep is not None  # a failed prepare returned above
        kwargs: dict[str, Any] = {**dict(v.numbers), **dict(v.args)}
        if v.kind == "scale":
            res = pipeline.scale(prepped.prep, v.character, **kwargs)
        else:
            res = pipeline.accelerate(prepped.prep, v.character, **kwargs)
        bvh, rep = pipeline.write_result(res, out)
        row.update(result_figures(res), status="ok", reason="")
    except Exception as e:  # noqa: BLE001
        row.update(status="failed", reason=_reason(e), task_s=time.perf_counter() - t0)
        return row
    row["task_s"], row["task_cpu_s"] = time.perf_counter() - t0, time.process_time() - c0
    marker = {"schema": MARKER_SCHEMA, "params": _task_params(task, plan), "row": row,
              "bvh_bytes": bvh.stat().st_size, "report_bytes": rep.stat().st_size}
    atomic_write_text(marker_path(out), dumps(marker, indent=1) + "\n")  # strict JSON: NaN → null
    return row


def _reason(e: BaseException) -> str:
    """One line: the message of a FroudeError; class name and message for anything unexpected."""
    msg = (str(e).strip().splitlines() or [""])[0]
    return msg if isinstance(e, FroudeError) else f"{type(e).__name__}: {msg}"


def _worker_name() -> str:
    try:
        from distributed import get_worker

        return str(get_worker().name)
    except (ImportError, ValueError):
        return f"pid{os.getpid()}"


def result_figures(res) -> dict:
    """The index's physics figures of a pipeline Output (report key figures, character, bars)."""
    r = res.report
    fails = r.check_bars()
    return {
        "char_height_m": res.retarget.body.stature, "char_mass_kg": res.retarget.body.total_mass,
        "L": res.retarget.L, "M": res.retarget.M, "n_frames": r.n_frames, "duration_s": r.duration_s,
        "speed_m_s": r.mean_speed_m_s, "froude_U": r.froude_U, "step_frequency_hz": r.step_frequency_hz,
        "flight_gravity_m_s2": r.flight_gravity_m_s2, "com_rms_mm": r.com_tracking_rms_mm,
        "com_max_mm": r.com_tracking_max_mm, "foot_skate_mm": r.foot_skate_mm, "penetration_mm": r.penetration_mm,
        "joint_jump_deg": r.max_joint_jump_deg, "bars_met": "no" if fails else "yes", "bars_failed": "; ".join(fails),
    }


# ---- the driver -----------------------------------------------------------------------------------------
@dataclass
class Summary:
    """What a run did. rows: one per task, in task order; elapsed_s from the first submission."""

    rows: list
    ran: int = 0
    elapsed_s: float = 0.0
    startup_s: float = 0.0
    interrupted: bool = False
    index: str = ""

    def count(self, status: str) -> int:
        return sum(r["status"] == status for r in self.rows)

    @property
    def tasks_per_s(self) -> float:
        return self.ran / self.elapsed_s if self.elapsed_s > 0 else float("nan")

    def failures(self) -> dict[str, list[str]]:
        """reason → ["clip/variation", ...]"""
        out: dict[str, list[str]] = {}
        for r in self.rows:
            if r["status"] == "failed":
                out.setdefault(r["reason"], []).append(f"{r['clip']}/{r['variation']}")
        return out

    def text(self) -> str:
        lines = [
            f"{len(self.rows)} tasks: {self.count('ok')} succeeded, {self.count('failed')} failed, "
            f"{self.count('skipped')} skipped (already done), {self.count('pending')} not run"
            + (" (interrupted)" if self.interrupted else ""),
            f"ran {self.ran} task(s) in {self.elapsed_s:.1f} s ({self.tasks_per_s:.2f} tasks/s; "
            f"cluster start {self.startup_s:.1f} s)",
        ]
        bars = [r for r in self.rows if r["status"] in ("ok", "skipped") and r.get("bars_met") == "no"]
        if bars:
            lines.append(f"{len(bars)} output(s) miss a physics bar (see bars_failed in the index)")
        for reason, which in sorted(self.failures().items(), key=lambda kv: -len(kv[1])):
            more = f", … ({len(which)} tasks)" if len(which) > 3 else ""
            lines.append(f"failed: {reason} [{', '.join(which[:3])}{more}]")
        if self.index:
            lines.append(f"index: {self.index}")
        return "\n".join(lines)


def default_workers() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:
        return os.cpu_count() or 1


def start_client(scheduler: str | None = None, n_workers: int | None = None):
    """A dask.distributed Client: to ``scheduler`` if given, else to a new local cluster of ``n_workers``
    single-threaded worker processes (default: one per core). Returns (client, cluster or None)."""
    try:
        import dask
        from dask.distributed import Client, LocalCluster
    except ImportError:
        raise BatchError("froude batch needs Dask: pip install 'froude[batch]'") from None
    if scheduler:
        try:
            return Client(scheduler, timeout="20s"), None
        except (OSError, TimeoutError, ValueError) as e:
            raise BatchError(f"cannot reach the Dask scheduler at {scheduler}: {e}".splitlines()[0]) from None
    import logging
    import signal

    n = n_workers or default_workers()
    env = {**dask.config.get("distributed.nanny.pre-spawn-environ", {}), **WORKER_ENV}
    # Ctrl-C reaches the whole foreground process group: the worker processes ignore it (they inherit
    # SIG_IGN at spawn) and the driver alone stops the batch, cancels and closes the cluster.
    with ignoring(signal.SIGINT):
        with dask.config.set({"distributed.nanny.pre-spawn-environ": env}):
            # no dashboard; the scheduler's small HTTP server on a free port (8787 may be taken)
            cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=None,
                                   scheduler_kwargs={"dashboard_address": "127.0.0.1:0"},
                                   silence_logs=logging.CRITICAL)  # our rows carry every error
    return Client(cluster), cluster


def warm_up(client) -> None:
    """Import the pipeline's dependencies on every worker before work starts (scipy.signal costs seconds)."""
    client.run(_import_pipeline)


def _import_pipeline() -> None:
    import froude.flow.pipeline  # noqa: F401  # lazy: run on each worker by warm_up: its point is to import there
    import froude.machine.fit  # noqa: F401


def run_batch(clips, plan: Plan, outdir, *, client=None, scheduler: str | None = None, n_workers: int | None = None,
              progress: bool = True, redo: bool = False, log=None) -> Summary:
    """Run every (clip, variation) not done yet; return the Summary. The index is rewritten as tasks finish.

    client: an existing dask.distributed Client (else one is started: ``scheduler`` or a local cluster).
    redo: ignore done-markers and recompute everything. Ctrl-C: pending tasks are cancelled, the index is
    written (their rows say pending) and KeyboardInterrupt is re-raised.
    """
    log = log or (lambda msg: print(msg, file=sys.stderr, flush=True))
    outdir = Path(outdir).resolve()
    tasks = make_tasks(clips, plan)
    # Nothing is created before the cluster answers: an unreachable scheduler leaves no OUTDIR behind.
    # (A first look at the markers decides whether Dask is needed at all; they are read again under the lock.)
    own = None
    t0 = time.perf_counter()
    if client is None and any(redo or read_done(outdir, t, plan) is None for t in tasks):
        log(f"starting Dask ({scheduler or f'a local cluster of {n_workers or default_workers()} worker(s)'}) ...")
        own = start_client(scheduler, n_workers)
        client = own[0]
    startup_s = time.perf_counter() - t0
    lock = handlers = None
    try:
        try:
            outdir.mkdir(parents=True, exist_ok=True)
        except OSError as e:
            raise BatchError(f"{outdir}: cannot create the output folder: {e.strerror or e}") from None
        lock = _lock(outdir)
        handlers = _interrupt_handlers()
        n_tmp = clean_stale_temporaries(outdir)
        if n_tmp:
            log(f"removed {n_tmp} temporary file(s) of an interrupted run")
        rows = []
        todo = []
        for i, t in enumerate(tasks):
            done = None if redo else read_done(outdir, t, plan)
            if done is not None:
                done.update(status="skipped", output=t.output)
                rows.append(done)
            else:
                rows.append(base_row(t))
                todo.append(i)
        summary = Summary(rows, index=str(outdir / INDEX_NAME), startup_s=startup_s)
        write_index(outdir, rows)
        if todo:
            try:
                _run_on_dask(tasks, todo, plan, outdir, summary, client, progress)
            except KeyboardInterrupt:
                _close(own)  # our local workers end here: nothing of ours writes any more
                # tasks that finished while the cluster closed wrote their markers: the index says so
                for i in todo:
                    if rows[i]["status"] == "pending":
                        done = read_done(outdir, tasks[i], plan)
                        if done is not None:
                            rows[i] = {**done, "status": "ok", "output": tasks[i].output}
                if own is not None and own[1] is not None:
                    clean_stale_temporaries(outdir)
                write_index(outdir, rows)
                raise
        # every task has finished (a killed worker's task too, retried or failed): a temporary left now is
        # an orphan of a worker killed mid-write
        clean_stale_temporaries(outdir)
        write_index(outdir, rows)
        write_parquet(outdir, rows)
        return summary
    finally:
        _close(own)
        _restore_handlers(handlers)
        _unlock(lock)


def _close(own) -> None:
    """Close a (client, cluster) pair this run started (idempotent)."""
    if own is None:
        return
    client, cluster = own
    client.close()
    if cluster is not None:
        cluster.close()


#: Loggers that report Dask's own teardown noise after an interrupt (e.g. tornado callbacks of
#: cancelled sync calls); quiet while we stop, restored afterwards.
_NOISY_LOGGERS = ("tornado.application", "distributed", "asyncio")


def _interrupt_handlers():
    """SIGINT and SIGTERM → KeyboardInterrupt (``apps.signals``), Dask's teardown messages silenced when
    one arrives; returns what ``_restore_handlers`` puts back."""
    import logging

    levels = {n: logging.getLogger(n).level for n in _NOISY_LOGGERS}

    def quiet():
        for n in _NOISY_LOGGERS:
            logging.getLogger(n).setLevel(logging.CRITICAL)

    return interrupt_on_signals(quiet), levels


def _restore_handlers(handlers) -> None:
    import logging

    if handlers is None:  # stopped before they were installed
        return
    previous, levels = handlers
    restore_signals(previous)
    for n, level in levels.items():
        logging.getLogger(n).setLevel(level)


def _run_on_dask(tasks, todo, plan, outdir, summary, client, progress):
    from dask.distributed import as_completed

    rows = summary.rows
    t0 = time.perf_counter()
    bar = None
    futures = {}
    try:
        t_start = time.perf_counter()
        by_clip: dict[str, list[int]] = {}
        for i in todo:
            by_clip.setdefault(tasks[i].clip.path, []).append(i)
        length_scale = plan.length_scale
        for path, idx in by_clip.items():
            prep = client.submit(prepare_clip, path, plan.reference_mass, plan.reference_sex, length_scale,
                                 pure=False, key=f"prepare-{tasks[idx[0]].clip.id}-{os.getpid()}-{time.time_ns()}")
            for i in idx:
                futures[client.submit(run_task, prep, tasks[i], plan, str(outdir), pure=False)] = i
            del prep  # the variation futures keep it alive exactly as long as they need it
        bar = _progress_bar(len(futures), progress)
        last_index = time.perf_counter()
        n_ok = n_fail = 0
        for fut in as_completed(list(futures)):
            i = futures.pop(fut)
            if fut.status == "finished":
                row = fut.result()
            else:  # a task the pipeline could not even return from: a killed worker, a lost connection
                try:
                    exc = fut.exception()
                    reason = f"{type(exc).__name__}: {(str(exc).splitlines() or [''])[0]}"
                except Exception as e:  # noqa: BLE001
                    reason = f"{fut.status}: {e}"
                # the worker may have died after its done-marker (the last write): the task is then done
                done = read_done(outdir, tasks[i], plan)
                row = dict(done, status="ok", output=tasks[i].output) if done else base_row(tasks[i], "failed", reason)
            rows[i] = row
            summary.ran += 1
            n_ok += row["status"] == "ok"
            n_fail += row["status"] == "failed"
            if bar is not None:
                bar.set_postfix_str(f"ok={n_ok} failed={n_fail}", refresh=False)
                bar.update(1)
            if time.perf_counter() - last_index >= INDEX_INTERVAL_S:
                write_index(outdir, rows)
                last_index = time.perf_counter()
        summary.elapsed_s = time.perf_counter() - t_start
    except KeyboardInterrupt:
        summary.interrupted = True
        summary.elapsed_s = time.perf_counter() - t0
        for fut in futures:
            fut.cancel()
        write_index(outdir, rows)
        raise
    finally:
        if bar is not None:
            bar.close()
        futures.clear()


def _progress_bar(total: int, enabled: bool):
    if not enabled:
        return None
    try:
        from tqdm import tqdm
    except ImportError:
        return None
    return tqdm(total=total, file=sys.stderr, unit="task", desc="froude batch", dynamic_ncols=True,
                smoothing=0.1)


def _lock(outdir: Path):
    """An exclusive lock on OUTDIR for this run (released by the OS if the driver dies)."""
    try:
        import fcntl
    except ImportError:  # not POSIX: no lock
        return None
    f = open(outdir / LOCK_NAME, "w")
    try:
        fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        f.close()
        raise BatchError(f"{outdir}: another froude batch is writing to this folder") from None
    return f


def _unlock(f) -> None:
    if f is not None:
        f.close()
