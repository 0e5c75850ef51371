"""A batch's plan: the YAML plan parsed and checked (characters, speeds, strides, accelerations), expanded
into variations, and the clips found and crossed with them into tasks."""
from __future__ import annotations

import glob
import itertools
import math
import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from ...errors import FroudeError

if TYPE_CHECKING:
    pass


#: Character numbers a plan may give, as ``pipeline.scale`` / ``accelerate`` keyword arguments, with the
#: short tags used in variation ids.
CHARACTER_NUMBERS = {"height": "h", "mass": "m", "leg_scale": "legs", "arm_scale": "arms",
                     "head_scale": "head", "trunk_scale": "trunk"}
PLAN_KEYS = ("characters", "speeds", "strides", "accelerations", "fps", "reference", "unlimited")
ACCELERATION_KEYS = ("to_factor", "to_speed", "steps", "within", "lead_steps", "hold_steps")
REFERENCE_KEYS = ("mass", "sex", "length_scale")
#: Largest plan and batch froude expands (a range of 1e8 steps is a typo, not a dataset): checked on the
#: counts before any list is built, so a runaway plan is one line and exit 2 at once.
MAX_VARIATIONS = 10_000
MAX_TASKS = 1_000_000
#: The plan's word for the pipeline's default output length (``pipeline.default_strides``).
AUTO = "auto"


EXAMPLE_PLAN = """\
# froude batch plan: every clip x every variation below
characters:
  - child                      # a preset (child, giant, small, troll)
  - chars/elf.yaml             # a character file (relative to this plan's folder)
  - {name: tall, height: 1.95, mass: 85}          # plain numbers
  - {height: {from: 1.0, to: 2.2, steps: 7}}      # a range: 7 characters, 1.0 m to 2.2 m
  - {base: troll, leg_scale: [0.8, 0.9, 1.0]}     # a list on top of a preset
speeds: [0.8, 1.0, 1.2, 3.5m/s]   # factors on each character's scaled speed, or absolute speeds
strides: 4                        # or a list: [2, 4]; default auto: 4, a turning take's whole turn
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
    # lazy: start-up (the batch modules load no NumPy: a plan is read and checked before the pipeline)
    from ...body.characters import list_presets, resolve_character

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
    # auto: pipeline.default_strides (4; a turning take's whole turn and a stride on)
    strides = data.get("strides", AUTO)
    strides = strides if isinstance(strides, list) else [strides]
    if not strides:
        bad("strides", "a whole number >= 1, auto, or a list of them")
    for k, n in enumerate(strides):
        if n != AUTO and (isinstance(n, bool) or not isinstance(n, int) or n < 1):
            bad(f"strides[{k}]", f"a whole number >= 1 or auto, got {n!r}")
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
            length = () if n == AUTO else (("strides", n),)
            variations.append(Variation(f"{label}_{sid}" + ("" if n == AUTO else f"_{n}str"), "scale", label, spec,
                                        numbers, sarg + length + common))
        for aid, aarg in acc_args:
            variations.append(Variation(f"{label}_{aid}", "accelerate", label, spec, numbers, aarg + common))
    _check_unique_ids(variations, bad)
    return Plan(tuple(variations), mass, sex, length_scale, source)


def _check_unique_ids(variations: list[Variation], bad) -> None:
    """Every variation id names its own files: a repeated one, or two differing only in case, is refused."""
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
    """A speed entry → (id part, scale kwargs) in froude's one speed syntax (``froude.flow.speed_goal``):
    0.8 / '0.8x' a factor, '3.5m/s' an absolute speed."""
    # lazy: start-up (the batch modules load no NumPy: a plan is read and checked before the pipeline)
    from ...flow.speed_goal import parse_speed

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
