"""Dataset-scale batches: every clip × every variation of a plan through ``froude.flow.pipeline``, on Dask.

    clips = find_clips(["clips/", "more/*.bvh"])
    plan = load_plan("plan.yaml")
    summary = run_batch(clips, plan, "out/")            # a local Dask cluster: one process per core
    summary = run_batch(clips, plan, "out/", scheduler="tcp://host:8786")

Each clip is prepared (loaded, checked, fitted) once, in one Dask task whose result feeds all its variation
tasks; each variation task calls ``pipeline.scale`` or ``pipeline.accelerate`` and ``pipeline.write_result``
on the worker, then writes a done-marker (``OUT.done.json``, atomically, last). A task counts as done when
its marker parses, names the same parameters and the BVH and report it records exist with their recorded
sizes; a re-run skips done tasks and redoes the rest. The driver rewrites ``index.csv`` atomically at most
once a second and at the end; it can always be rebuilt from the markers.

Layout of OUTDIR::

    index.csv                         one row per (clip, variation): INDEX_COLUMNS
    <clip>/<variation>.bvh            the output motion
    <clip>/<variation>.report.json    its physics report
    <clip>/<variation>.done.json      done-marker: the index row and the sizes of the two files above

With ``scheduler=`` the workers must import froude and see the input and output paths (a shared
filesystem), as for any Dask job that reads and writes files.

The parts: the plan and the tasks in ``batch.plan``, OUTDIR's layout (done-markers, temporaries, the index) in
``batch.layout``, the workers' work and the driver in ``batch.run``; their public names are importable from here.
"""
from __future__ import annotations

from .layout import (
    INDEX_COLUMNS,
    INDEX_NAME,
    LOCK_NAME,
    MARKER_SCHEMA,
    base_row,
    clean_stale_temporaries,
    index_text,
    is_temporary,
    marker_path,
    read_done,
    temporaries,
    write_index,
    write_parquet,
)
from .plan import (
    ACCELERATION_KEYS,
    CHARACTER_NUMBERS,
    EXAMPLE_PLAN,
    MAX_TASKS,
    MAX_VARIATIONS,
    PLAN_KEYS,
    REFERENCE_KEYS,
    BatchError,
    Clip,
    Plan,
    Task,
    Variation,
    clip_id,
    find_clips,
    load_plan,
    make_tasks,
    parse_plan,
    safe_name,
)
from .run import (
    INDEX_INTERVAL_S,
    WORKER_ENV,
    Prepped,
    Summary,
    default_workers,
    prepare_clip,
    result_figures,
    run_batch,
    run_task,
    start_client,
    warm_up,
)

__all__ = [
    "ACCELERATION_KEYS", "BatchError", "CHARACTER_NUMBERS", "Clip", "EXAMPLE_PLAN", "INDEX_COLUMNS",
    "INDEX_INTERVAL_S", "INDEX_NAME", "LOCK_NAME", "MARKER_SCHEMA", "MAX_TASKS", "MAX_VARIATIONS", "PLAN_KEYS",
    "Plan", "Prepped", "REFERENCE_KEYS", "Summary", "Task", "Variation", "WORKER_ENV", "base_row",
    "clean_stale_temporaries", "clip_id", "default_workers", "find_clips", "index_text", "is_temporary",
    "load_plan", "make_tasks", "marker_path", "parse_plan", "prepare_clip", "read_done", "result_figures",
    "run_batch", "run_task", "safe_name", "start_client", "temporaries", "warm_up", "write_index", "write_parquet",
]
