"""The layout of a batch's OUTDIR: the done-markers that say a task is complete, the temporaries, and the
index (CSV, Parquet) rebuilt from the rows."""
from __future__ import annotations

import csv
import io
import json
import math
import os
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    pass

from .plan import Plan, Task

MARKER_SCHEMA = "froude.batch.done/1"
INDEX_NAME = "index.csv"
#: The file the running driver holds locked in OUTDIR.
LOCK_NAME = ".froude-batch.lock"


# ---- done-markers -------------------------------------------------------------------------------------
def marker_path(bvh_path) -> Path:
    p = Path(bvh_path)
    return p.with_name(p.stem + ".done.json")


def _task_params(task: Task, plan: Plan) -> dict:
    """What a done-marker must match: the clip (id and size: moving the data folder keeps outputs valid),
    the reference performer and the variation's parameters."""
    return {"clip": task.clip.id, "clip_bytes": os.stat(task.clip.path).st_size,
            "reference": [plan.reference_mass, plan.reference_sex, plan.length_scale], **task.variation.params()}


def read_done(outdir, task: Task, plan: Plan) -> dict | None:
    """The index row stored by a complete earlier run of ``task``, or None (missing, partial or stale)."""
    # lazy: start-up (the batch modules load no NumPy: a plan is read and checked before the pipeline)
    from ...flow.pipeline import report_path

    # lazy: start-up (the batch modules load no NumPy: a plan is read and checked before the pipeline)
    from ...io.jsonable import jsonable

    bvh = Path(outdir) / task.output
    try:
        m = json.loads(marker_path(bvh).read_text())
        ok = (m.get("schema") == MARKER_SCHEMA and m.get("params") == jsonable(_task_params(task, plan))
              and bvh.stat().st_size == m["bvh_bytes"] and report_path(bvh).stat().st_size == m["report_bytes"])
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        return None
    return dict(m["row"]) if ok else None


def is_temporary(name: str) -> bool:
    """True for a file name ``atomic_write`` uses while it writes (``io.atomic.is_temporary``), never the
    driver's lock (batch outputs never start with '.')."""
    # lazy: start-up (the batch modules load no NumPy: a plan is read and checked before the pipeline)
    from ...io.atomic import is_temporary as atomic_temporary

    return name != LOCK_NAME and atomic_temporary(name)


def temporaries(outdir) -> list[Path]:
    """Temporaries of interrupted atomic writes anywhere under OUTDIR."""
    return sorted(p for p in Path(outdir).rglob(".*") if p.is_file() and is_temporary(p.name))


def clean_stale_temporaries(outdir) -> int:
    """Remove the temporaries of interrupted atomic writes (``temporaries``); returns how many.

    Only while no task of ours can be writing: before a run, and after it when every task has finished.
    """
    n = 0
    for p in temporaries(outdir):
        try:
            p.unlink()
            n += 1
        except OSError:
            pass
    return n


# ---- the index ------------------------------------------------------------------------------------------
#: status: ok (written by this run), skipped (complete from an earlier run, kept), failed (reason),
#: pending (not run: the run was interrupted). Usable outputs: ok and skipped.
INDEX_COLUMNS = (
    "clip", "variation", "kind", "character", "height", "mass", "leg_scale", "arm_scale", "head_scale",
    "trunk_scale", "speed_factor", "target_speed_m_s", "strides", "to_factor", "to_speed_m_s", "steps",
    "within_s", "fps", "output", "status", "reason",
    "speed_m_s", "froude_U", "step_frequency_hz", "flight_gravity_m_s2", "com_rms_mm", "com_max_mm",
    "foot_skate_mm", "penetration_mm", "joint_jump_deg", "bars_met", "bars_failed",
    "char_height_m", "char_mass_kg", "L", "M", "n_frames", "duration_s", "prepare_s", "task_s", "task_cpu_s", "worker",
)
_ARG_COLUMNS = {"speed": "speed_factor", "target_speed": "target_speed_m_s", "to_speed": "to_speed_m_s",
                "within": "within_s"}


def base_row(task: Task, status: str = "pending", reason: str = "") -> dict:
    v = task.variation
    row: dict[str, Any] = {"clip": task.clip.id, "variation": v.id, "kind": v.kind,
                           "character": v.character_label, "output": task.output, "status": status,
                           "reason": reason}
    row.update(dict(v.numbers))
    row.update({_ARG_COLUMNS.get(k, k): x for k, x in v.args if k not in ("lead_steps", "hold_steps")})
    return row


def index_text(rows) -> str:
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=INDEX_COLUMNS, extrasaction="ignore", lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({k: _cell(r.get(k)) for k in INDEX_COLUMNS})
    return buf.getvalue()


def _cell(v) -> str:
    """An index cell: empty for a figure that is absent or could not be measured (None, NaN: a done-marker
    stores NaN as null, so a resumed row and a fresh one read the same)."""
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return ""
    if isinstance(v, float):
        return f"{v:.6g}"
    return str(v).replace("\n", " ")


def write_index(outdir, rows) -> Path:
    """index.csv (atomically); index.parquet too when pyarrow is installed."""
    # lazy: start-up (the batch modules load no NumPy: a plan is read and checked before the pipeline)
    from ...io.bvh import atomic_write_text

    path = Path(outdir) / INDEX_NAME
    atomic_write_text(path, index_text(rows))
    return path


def write_parquet(outdir, rows) -> Path | None:
    """index.parquet (atomically) when pyarrow is installed; None otherwise."""
    try:
        import pyarrow as pa
        import pyarrow.csv as pacsv
        import pyarrow.parquet as pq
    except ImportError:
        return None
    # lazy: start-up (the batch modules load no NumPy: a plan is read and checked before the pipeline)
    from ...io.atomic import atomic_write

    table = pacsv.read_csv(pa.py_buffer(index_text(rows).encode()))
    return atomic_write(Path(outdir) / "index.parquet", lambda tmp: pq.write_table(table, tmp))
