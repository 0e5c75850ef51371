"""``froude batch``: every clip × every variation of a plan, on Dask (a local cluster or ``--scheduler``)."""
from __future__ import annotations

import argparse

from .common import add_quiet, number, say

#: Local Dask worker processes froude starts at most.
MAX_WORKERS = 256


#: The one-line summary ``froude --help`` lists.
HELP = "many clips x many characters, speeds and accelerations, on Dask"


def register(sub) -> None:
    from ..batch import EXAMPLE_PLAN, INDEX_NAME  # lazy: start-up

    p = sub.add_parser(
        "batch", help=HELP,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description="Run every (clip, variation) of PLAN through the same pipeline as 'froude scale' and "
        "'froude accelerate': each clip is fitted once, its variations run as Dask tasks (a local cluster "
        "of single-threaded worker processes, one per core, unless --scheduler is given). Writes "
        f"OUTDIR/<clip>/<variation>.bvh, .report.json and .done.json, and OUTDIR/{INDEX_NAME} (one row per "
        "task: parameters, output, status ok/skipped/failed/pending, reason, physics figures, bars met, "
        "timing). Re-running the same command skips the tasks that are done and redoes the rest. "
        "Exit status: 0 all tasks done, 1 some failed, 2 bad plan or inputs, 130 interrupted.",
        epilog="Example plan (see docs/batch.md):\n\n" + EXAMPLE_PLAN
        + "\nExample: froude batch 'clips/*.bvh' more_clips/ --plan plan.yaml -o out/",
    )
    p.add_argument("inputs", nargs="+", metavar="INPUT", help="BVH files, folders (searched recursively) or globs")
    p.add_argument("--plan", required=True, metavar="PLAN.yaml", help="the variations (YAML; format below)")
    p.add_argument("-o", "--output", required=True, metavar="OUTDIR", help="output folder")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="an existing Dask scheduler (tcp://host:8786); its workers must see INPUTS and OUTDIR")
    p.add_argument("--workers", type=number(1, MAX_WORKERS, "workers", integer=True), default=None, metavar="N",
                   help=f"local worker processes, 1-{MAX_WORKERS} (default: one per core; 1 thread each)")
    p.add_argument("--dry-run", action="store_true", help="list the tasks (and which are done), run nothing")
    p.add_argument("--redo", action="store_true", help="recompute tasks that are already done")
    add_quiet(p)
    p.set_defaults(func=run)


def run(args) -> int:
    from .. import batch  # lazy: start-up (froude --help imports every verb module and no NumPy)

    plan = batch.load_plan(args.plan)
    clips = batch.find_clips(args.inputs, exclude=args.output)
    if args.dry_run:
        return _dry_run(clips, plan, args)
    say(f"{len(clips)} clip(s) x {len(plan.variations)} variation(s) = {len(clips) * len(plan.variations)} tasks "
        f"-> {args.output}", args.quiet)
    # Ctrl-C and SIGTERM stop the run cleanly (run_batch): pending tasks cancelled, index written, exit 130
    summary = batch.run_batch(clips, plan, args.output, scheduler=args.scheduler, n_workers=args.workers,
                              progress=not args.quiet, redo=args.redo, log=lambda m: say(m, args.quiet))
    print(summary.text())
    return 1 if summary.count("failed") else 0


def _dry_run(clips, plan, args) -> int:
    from .. import batch  # lazy: start-up (froude --help imports every verb module and no NumPy)

    tasks = batch.make_tasks(clips, plan)
    n_done = 0
    print("clip\tvariation\tkind\tparameters\toutput\tstate")
    for t in tasks:
        done = not args.redo and batch.read_done(args.output, t, plan) is not None
        n_done += done
        v = t.variation
        params = " ".join(f"{k}={x}" for k, x in (("character", v.character), *v.numbers, *v.args) if x is not None)
        print(f"{t.clip.id}\t{v.id}\t{v.kind}\t{params}\t{t.output}\t{'done' if done else 'to do'}")
    say(f"{len(tasks)} tasks ({len(clips)} clips x {len(plan.variations)} variations): {n_done} done, "
        f"{len(tasks) - n_done} to do (dry run: nothing ran)", args.quiet)
    return 0
