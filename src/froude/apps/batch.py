"""Dataset-scale batches: every clip × every variation of a plan through ``froude.pipeline``, on Dask.

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
"""
from __future__ import annotations

import csv
import glob
import io
import itertools
import json
import math
import os
import re
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..errors import FroudeError

if TYPE_CHECKING:
    from ..prepared import Prepared

#: Character numbers a plan may give, as ``pipeline.scale`` / ``accelerate`` keyword arguments, with the
#: short tags used in variation ids.
CHARACTER_NUMBERS = {"height": "h", "mass": "m", "leg_scale": "legs", "arm_scale": "arms",
                     "head_scale": "head", "trunk_scale": "trunk"}
PLAN_KEYS = ("characters", "speeds", "strides", "accelerations", "fps", "reference", "unlimited")
ACCELERATION_KEYS = ("to_factor", "to_speed", "steps", "within", "lead_steps", "hold_steps")
REFERENCE_KEYS = ("mass", "sex", "length_scale")
#: Environment of every local worker process: one thread for every numerical library.
WORKER_ENV = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1",
              "NUMEXPR_NUM_THREADS": "1", "VECLIB_MAXIMUM_THREADS": "1"}
MARKER_SCHEMA = "froude.batch.done/1"
INDEX_NAME = "index.csv"
#: Seconds between index rewrites while a batch runs (always rewritten at the end and on interrupt).
INDEX_INTERVAL_S = 1.0
#: Largest plan and batch froude expands (a range of 1e8 steps is a typo, not a dataset): checked on the
#: counts before any list is built, so a runaway plan is one line and exit 2 at once.
MAX_VARIATIONS = 10_000
MAX_TASKS = 1_000_000
#: The file the running driver holds locked in OUTDIR.
LOCK_NAME = ".froude-batch.lock"

EXAMPLE_PLAN = """\
# froude batch plan: every clip x every variation below
characters:
  - child                      # a preset (child, giant, small, troll)
  - chars/elf.yaml             # a character file (relative to this plan's folder)
  - {name: tall, height: 1.95, mass: 85}          # plain numbers
  - {height: {from: 1.0, to: 2.2, steps: 7}}      # a range: 7 characters, 1.0 m to 2.2 m
  - {base: troll, leg_scale: [0.8, 0.9, 1.0]}     # a list on top of a preset
speeds: [0.8, 1.0, 1.2, 3.5m/s]   # factors on each character's scaled speed, or absolute speeds
strides: 4                        # or a list: [2, 4]
accelerations:                    # speed changes (each character x each entry)
  - {to_factor: 1.3, steps: 30}
  - {to_speed: 2.5, steps: 20, lead_steps: 2, hold_steps: 4}
fps: null                         # output frame rate (default: the clip's)
unlimited: false                  # true: allow runs past the human range for each character's size
reference: {mass: 70, sex: male, length_scale: null}   # the performer in the clips
"""


class BatchError(FroudeError):
    """A bad plan, bad inputs or an unusable output folder or cluster (one line, exit 2 from the CLI)."""


# ---- the plan -----------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Variation:
    """One change applied to every clip. kind: "scale" or "accelerate".

    character: preset name or character file path, or None (numbers only / the clip's own body);
    numbers: character numbers (CHARACTER_NUMBERS keys) on top of it; args: the keyword arguments of
    ``pipeline.scale`` (speed | target_speed, strides, fps) or ``pipeline.accelerate`` (to_factor | to_speed,
    steps, within, lead_steps, hold_steps, fps).
    """

    id: str
    kind: str
    character_label: str
    character: str | None
    numbers: tuple[tuple[str, float], ...]
    args: tuple[tuple[str, object], ...]

    def params(self) -> dict:
        """Everything that determines the output (stored in the done-marker and compared on re-runs)."""
        return {"kind": self.kind, "character": self.character, **dict(self.numbers), **dict(self.args)}


@dataclass(frozen=True)
class Plan:
    variations: tuple[Variation, ...]
    reference_mass: float = 70.0
    reference_sex: str = "male"
    length_scale: float | None = None
    source: str = ""


def load_plan(path) -> Plan:
    """Read and check a plan YAML file (format: EXAMPLE_PLAN, docs/batch.md). Raises BatchError."""
    import yaml

    path = Path(path)
    try:
        text = path.read_text()
    except OSError as e:
        raise BatchError(f"{path}: cannot read the plan: {e.strerror or e}") from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as e:
        mark = getattr(e, "problem_mark", None)
        where = f"{path}:{mark.line + 1}" if mark is not None else str(path)
        raise BatchError(f"{where}: YAML syntax error: {getattr(e, 'problem', None) or e}".splitlines()[0]) from None
    return parse_plan(data, source=str(path), base_dir=path.parent)


def parse_plan(data, source: str = "plan", base_dir=None) -> Plan:
    """A Plan from the parsed YAML mapping; every problem is one BatchError line naming the key."""
    from ..body.characters import list_presets, resolve_character

    def bad(where, msg):
        raise BatchError(f"{source}: {where}: {msg}")

    if not isinstance(data, dict):
        raise BatchError(f"{source}: a plan is a YAML mapping with keys {', '.join(PLAN_KEYS)}")
    unknown = sorted(set(map(str, data)) - set(PLAN_KEYS))
    if unknown:
        bad(unknown[0], f"unknown key (known: {', '.join(PLAN_KEYS)})")
    ref = data.get("reference") or {}
    if not isinstance(ref, dict) or set(map(str, ref)) - set(REFERENCE_KEYS):
        bad("reference", f"a mapping with keys {', '.join(REFERENCE_KEYS)}")
    mass = _positive(ref.get("mass", 70.0), "reference.mass", bad)
    sex = str(ref.get("sex", "male"))
    if sex not in ("male", "female"):
        bad("reference.sex", f"male or female, got '{sex}'")
    length_scale = (None if ref.get("length_scale") is None
                    else _positive(ref["length_scale"], "reference.length_scale", bad))
    fps = None if data.get("fps") is None else _positive(data["fps"], "fps", bad)

    chars = data.get("characters")
    if chars is None:
        chars = [None]  # the clip's own body
    if not isinstance(chars, list) or not chars:
        bad("characters", "a non-empty list of presets, files or mappings of numbers")
    characters = []  # (label, spec, numbers)
    presets = set(list_presets())
    for i, entry in enumerate(chars):
        for label, spec, numbers in _expand_character(entry, f"characters[{i}]", bad, presets, base_dir):
            try:  # check now (one line, exit 2) rather than in every task
                resolve_character(spec, **dict(numbers))
            except FroudeError as e:
                bad(f"characters[{i}]", str(e).splitlines()[0])
            characters.append((label, spec, numbers))

    has_acc = data.get("accelerations") not in (None, [])
    speeds = data.get("speeds", None if has_acc else [1.0])
    speeds = [] if speeds is None else speeds if isinstance(speeds, list) else [speeds]
    speed_args = [_speed(s, f"speeds[{k}]", bad) for k, s in enumerate(speeds)]
    strides = data.get("strides", 4)
    strides = strides if isinstance(strides, list) else [strides]
    if not strides:
        bad("strides", "a whole number >= 1 or a list of them")
    for k, n in enumerate(strides):
        if isinstance(n, bool) or not isinstance(n, int) or n < 1:
            bad(f"strides[{k}]", f"a whole number >= 1, got {n!r}")
    accs = data.get("accelerations") or []
    if not isinstance(accs, list):
        bad("accelerations", "a list of mappings such as {to_factor: 1.3, steps: 30}")
    acc_args = [_acceleration(a, f"accelerations[{k}]", bad) for k, a in enumerate(accs)]
    if not speed_args and not acc_args:
        bad("speeds", "the plan has no variations: give speeds and/or accelerations")

    fps_arg = () if fps is None else (("fps", fps),)
    unlimited = data.get("unlimited", False)
    if not isinstance(unlimited, bool):
        bad("unlimited", f"true or false, got {unlimited!r}")
    # keyword arguments of every variation (scale's and accelerate's alike)
    common = fps_arg + ((("unlimited", True),) if unlimited else ())
    n_var = len(characters) * (len(speed_args) * len(strides) + len(acc_args))
    if n_var > MAX_VARIATIONS:
        bad("characters", f"the plan expands to {n_var:,} variations; at most {MAX_VARIATIONS:,}")
    variations = []
    for label, spec, numbers in characters:
        for (sid, sarg), n in itertools.product(speed_args, strides):
            variations.append(Variation(f"{label}_{sid}_{n}str", "scale", label, spec, numbers,
                                        sarg + (("strides", n),) + common))
        for aid, aarg in acc_args:
            variations.append(Variation(f"{label}_{aid}", "accelerate", label, spec, numbers, aarg + common))
    seen: dict[str, tuple[str, dict]] = {}
    for v in variations:
        key = v.id.lower()  # ids name files: on a case-insensitive filesystem "Tall" and "tall" are one
        if key in seen:
            if seen[key] == (v.id, v.params()):
                bad("characters", f"variation '{v.id}' is listed twice")
            bad("characters", f"two different variations get the id '{seen[key][0]}'"
                + (f" / '{v.id}' (ids are compared ignoring case)" if seen[key][0] != v.id else "")
                + ": give the characters distinct names")
        seen[key] = (v.id, v.params())
    return Plan(tuple(variations), mass, sex, length_scale, source)


def _positive(v, where, bad) -> float:
    try:
        x = float(v)
    except (TypeError, ValueError):
        bad(where, f"a number, got {v!r}")
    if isinstance(v, bool) or not (math.isfinite(x) and x > 0):
        bad(where, f"a number > 0, got {v!r}")
    return x


def _count_values(v) -> int:
    """How many values ``_values`` would make of v (without making them: a range may be huge)."""
    if isinstance(v, dict):
        n = v.get("steps")
        return n if isinstance(n, int) and not isinstance(n, bool) and n > 0 else 1
    return len(v) if isinstance(v, list) else 1


def _values(v, where, bad) -> list[float]:
    """A number, a list of numbers, or a range {from, to, steps} (steps values, ends included)."""
    if isinstance(v, dict):
        if set(v) != {"from", "to", "steps"}:
            bad(where, "a range is {from: A, to: B, steps: N}")
        a, b = _positive(v["from"], where + ".from", bad), _positive(v["to"], where + ".to", bad)
        n = v["steps"]
        if isinstance(n, bool) or not isinstance(n, int) or n < 1 or (n == 1 and a != b):
            bad(where + ".steps", f"a whole number >= 2 (1 only when from == to), got {n!r}")
        if n > MAX_VARIATIONS:
            bad(where + ".steps", f"at most {MAX_VARIATIONS:,} (a plan may have at most {MAX_VARIATIONS:,} "
                f"variations), got {n:,}")
        return [a + (b - a) * k / (n - 1) for k in range(n)] if n > 1 else [a]
    if isinstance(v, list):
        if not v:
            bad(where, "an empty list")
        return [_positive(x, f"{where}[{k}]", bad) for k, x in enumerate(v)]
    return [_positive(v, where, bad)]


def _expand_character(entry, where, bad, presets, base_dir):
    """(label, spec, numbers) of each character an entry stands for (a range stands for several)."""
    if entry is None:
        return [("same", None, ())]
    if isinstance(entry, str):
        return [(_label_of_spec(entry), _spec_path(entry, presets, base_dir), ())]
    if not isinstance(entry, dict):
        bad(where, f"a preset name, a file or a mapping of numbers, got {entry!r}")
    known = {"name", "base", *CHARACTER_NUMBERS}
    extra = sorted(set(map(str, entry)) - known)
    if extra:
        bad(f"{where}.{extra[0]}", f"unknown key (known: {', '.join(sorted(known))})")
    base = entry.get("base")
    if base is not None and not isinstance(base, str):
        bad(f"{where}.base", "a preset name or a character file")
    spec = None if base is None else _spec_path(base, presets, base_dir)
    name = entry.get("name")
    if name is not None and not re.fullmatch(r"[A-Za-z0-9][A-Za-z0-9._-]*", str(name)):
        bad(f"{where}.name", "letters, digits, '.', '_' and '-', starting with a letter or digit (it names "
            f"files), got {name!r}")
    keys = [k for k in CHARACTER_NUMBERS if k in entry]
    n_combos = math.prod(_count_values(entry[k]) for k in keys)
    if n_combos > MAX_VARIATIONS:
        bad(where, f"expands to {n_combos:.3g} characters; a plan may have at most {MAX_VARIATIONS:,} variations")
    grids = [_values(entry[k], f"{where}.{k}", bad) for k in keys]
    ranged = [k for k, g in zip(keys, grids) if len(g) > 1]
    out = []
    for combo in itertools.product(*grids):
        numbers = tuple(zip(keys, (round(x, 9) for x in combo)))
        # the label: the name (or base) plus the numbers that tell the characters of this entry apart
        shown = numbers if name is None else tuple((k, x) for k, x in numbers if k in ranged)
        tags = "".join(f"{CHARACTER_NUMBERS[k]}{x:.4g}" for k, x in shown)
        head = str(name) if name is not None else (_label_of_spec(base) if base is not None else "")
        label = "-".join(p for p in (head, tags) if p) or "same"
        out.append((label, spec, numbers))
    return out


def _label_of_spec(spec: str) -> str:
    return safe_name(Path(spec).stem if spec.lower().endswith((".yaml", ".yml", ".bvh")) else spec)


def safe_name(text: str) -> str:
    """text as one safe file-name part: letters, digits, '.', '_' and '-' only (others become '_'), not
    starting with '.' (no '.', '..' or hidden names: leading dots become '_'), never empty."""
    name = re.sub(r"[^A-Za-z0-9._-]", "_", text)
    name = re.sub(r"^\.+", lambda m: "_" * len(m.group()), name)
    return name or "_"


def _spec_path(spec: str, presets, base_dir) -> str:
    """Presets stay names; relative files are found next to the plan first, then in the working folder."""
    looks_like_file = spec.lower().endswith((".yaml", ".yml", ".bvh"))
    if spec in presets or not looks_like_file or base_dir is None or Path(spec).is_absolute():
        return spec
    p = Path(base_dir) / spec
    return str(p.resolve()) if p.exists() else str(Path(spec).resolve())


def _speed(s, where, bad) -> tuple[str, tuple]:
    """A speed entry → (id part, scale kwargs) in froude's one speed syntax (``froude.speed_goal``):
    0.8 / '0.8x' a factor, '3.5m/s' an absolute speed."""
    from ..speed_goal import parse_speed

    try:
        goal = parse_speed(s, where)
    except FroudeError as e:
        bad(where, str(e).removeprefix(f"{where}: "))
    if goal.factor is not None:
        return f"x{goal.factor:g}", (("speed", goal.factor),)
    return f"v{goal.m_s:g}ms", (("target_speed", goal.m_s),)


def _acceleration(a, where, bad) -> tuple[str, tuple]:
    if not isinstance(a, dict):
        bad(where, "a mapping such as {to_factor: 1.3, steps: 30}")
    extra = sorted(set(map(str, a)) - set(ACCELERATION_KEYS))
    if extra:
        bad(f"{where}.{extra[0]}", f"unknown key (known: {', '.join(ACCELERATION_KEYS)})")
    if ("to_factor" in a) == ("to_speed" in a):
        bad(where, "give exactly one goal: to_factor or to_speed")
    if ("steps" in a) == ("within" in a):
        bad(where, "give exactly one length: steps or within [s]")
    args = []
    for k in ("to_factor", "to_speed", "within"):
        if k in a:
            args.append((k, _positive(a[k], f"{where}.{k}", bad)))
    for k in ("steps", "lead_steps", "hold_steps"):
        if k in a:
            n = a[k]
            if isinstance(n, bool) or not isinstance(n, int) or n < (1 if k == "steps" else 0):
                bad(f"{where}.{k}", f"a whole number >= {1 if k == 'steps' else 0}, got {n!r}")
            args.append((k, n))
    d = dict(args)
    goal = f"to{d['to_factor']:g}x" if "to_factor" in d else f"to{d['to_speed']:g}ms"
    length = f"{d['steps']}steps" if "steps" in d else f"in{d['within']:g}s"
    extra_id = "".join(f"_{k[0]}{d[k]}" for k in ("lead_steps", "hold_steps") if k in d)
    return f"{goal}_{length}{extra_id}", tuple(args)


# ---- inputs and tasks -----------------------------------------------------------------------------------
@dataclass(frozen=True)
class Clip:
    """An input clip: id (its path relative to the inputs' common folder, without .bvh) and path."""

    id: str
    path: str


def find_clips(inputs, exclude=None) -> list[Clip]:
    """Files, folders (every .bvh below them) and globs → clips, sorted, each once. Raises BatchError.

    exclude: a folder (OUTDIR) whose files are never inputs: folders holding it and globs skip them; a
    file or folder named explicitly inside it (or OUTDIR itself) is an error (a re-run would otherwise
    take the previous outputs for new clips).
    Clip ids are safe relative paths (``safe_name`` per part: nothing can escape OUTDIR) and unique
    ignoring case (``a.bvh`` and ``a.BVH`` would share one output folder: refused, naming both).
    """
    ex = None if exclude is None else Path(exclude).resolve()

    def inside(p) -> bool:
        return ex is not None and Path(p).resolve().is_relative_to(ex)

    paths: list[str | Path] = []
    for item in inputs:
        item = str(item)
        if any(c in item for c in "*?["):
            hits = [p for p in glob.glob(item, recursive=True) if Path(p).is_file() and not inside(p)]
            if not hits:
                raise BatchError(f"{item}: no file matches" + (" outside the output folder" if ex else ""))
            paths += hits
        elif Path(item).is_dir():
            if inside(item):
                raise BatchError(f"{item}: is the output folder {exclude} or inside it: outputs are not inputs "
                                 "(write the outputs elsewhere, e.g. a subfolder)")
            found = sorted(p for p in Path(item).rglob("*")
                           if p.suffix.lower() == ".bvh" and p.is_file() and not inside(p))
            if not found:
                raise BatchError(f"{item}: no .bvh file in this folder" + (" outside the output folder" if ex else ""))
            paths += found
        elif Path(item).is_file():
            if inside(item):
                raise BatchError(f"{item}: is inside the output folder {exclude}: outputs are not inputs")
            paths.append(item)
        else:
            raise BatchError(f"{item}: no such file or folder")
    unique = sorted({str(Path(p).resolve()) for p in paths})
    if not unique:
        raise BatchError("no input clips")
    root = Path(os.path.commonpath([str(Path(p).parent) for p in unique]))
    clips = [Clip(clip_id(Path(p).relative_to(root)), p) for p in unique]
    seen: dict[str, Clip] = {}
    for c in clips:
        other = seen.setdefault(c.id.lower(), c)
        if other is not c:
            raise BatchError(f"{other.path} and {c.path} would share the output folder '{other.id}' (clip ids "
                             "are compared ignoring case, and unsafe characters become '_'): rename one")
    return clips


def clip_id(relative: Path) -> str:
    """A clip's id from its path relative to the inputs' folder: without the .bvh suffix, every part a
    ``safe_name`` (so ``...bvh`` is ``__``, never ``..``), '/'-separated."""
    parts = list(relative.with_suffix("").parts) if relative.suffix.lower() == ".bvh" else list(relative.parts)
    return "/".join(safe_name(part) for part in parts)


@dataclass(frozen=True)
class Task:
    """One (clip, variation): its output path relative to OUTDIR is ``<clip id>/<variation id>.bvh``."""

    clip: Clip
    variation: Variation

    @property
    def output(self) -> str:
        return f"{self.clip.id}/{self.variation.id}.bvh"


def make_tasks(clips, plan: Plan) -> list[Task]:
    n = len(clips) * len(plan.variations)
    if n > MAX_TASKS:
        raise BatchError(f"{len(clips):,} clips x {len(plan.variations):,} variations = {n:,} tasks; a batch "
                         f"may have at most {MAX_TASKS:,}: split it")
    return [Task(c, v) for c in clips for v in plan.variations]


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
    from ..io.jsonable import jsonable
    from ..pipeline import report_path

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
    from ..io.atomic import is_temporary as atomic_temporary

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


# ---- work done on the workers ---------------------------------------------------------------------------
@dataclass
class Prepped:
    """A prepare task's result: the Prepared clip or the one-line reason it failed, and its time [s]."""

    prep: Prepared | None  # None when the clip failed (error says why)
    error: str
    seconds: float


def prepare_clip(path: str, mass: float, sex: str, length_scale) -> Prepped:
    """Worker task: ``pipeline.prepare`` of one clip (fit once; its result feeds all the clip's variations)."""
    from .. import pipeline

    t0 = time.perf_counter()
    try:
        prep = pipeline.prepare(path, mass=mass, sex=sex, length_scale=length_scale)
        return Prepped(prep, "", time.perf_counter() - t0)
    except Exception as e:  # noqa: BLE001 - a bad clip fails its own tasks, never the batch
        return Prepped(None, _reason(e), time.perf_counter() - t0)


def run_task(prepped: Prepped, task: Task, plan: Plan, outdir: str) -> dict:
    """Worker task: one variation of one prepared clip → BVH + report (atomic), done-marker last; its index row."""
    from .. import pipeline
    from ..io.bvh import atomic_write_text
    from ..io.jsonable import dumps

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
    """The index's physics figures of a pipeline Result (report key figures, character, bars)."""
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
    from ..io.bvh import atomic_write_text

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
    from ..io.atomic import atomic_write

    table = pacsv.read_csv(pa.py_buffer(index_text(rows).encode()))
    return atomic_write(Path(outdir) / "index.parquet", lambda tmp: pq.write_table(table, tmp))


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

    from .signals import ignoring

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
    import froude.machine.fit  # noqa: F401
    import froude.pipeline  # noqa: F401


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

    from .signals import interrupt_on_signals

    levels = {n: logging.getLogger(n).level for n in _NOISY_LOGGERS}

    def quiet():
        for n in _NOISY_LOGGERS:
            logging.getLogger(n).setLevel(logging.CRITICAL)

    return interrupt_on_signals(quiet), levels


def _restore_handlers(handlers) -> None:
    import logging

    from .signals import restore_signals

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
