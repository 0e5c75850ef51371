"""Characters: who the motion is retargeted to.

A character is a stature, a mass and proportions relative to the reference skeleton (legs, arms, head,
trunk scale factors, optional de Leva mass-fraction overrides). It comes from a preset, a YAML file, a
target BVH skeleton with the same joint topology, or plain numbers (``--height``, ``--mass``,
``--leg-scale`` …). Applying it to a reference skeleton gives the target skeleton and body model, and the
two numbers dynamic similarity needs: the relative leg length L and the relative mass M (paper §5.1).

YAML format (all keys but ``name`` optional; presets in ``froude/data/characters/`` are examples)::

    name: troll
    description: short legs, long heavy arms
    height: 2.3            # stature [m]; default: the reference's × the scale factors
    mass: 250              # [kg]; default: the reference mass × (stature ratio)^3 (same build)
    sex: male              # de Leva table: male | female
    proportions:           # bone-length factors relative to the reference, before scaling to `height`
      legs: 0.8            # knee, ankle, toe bones
      arms: 1.3            # elbow, wrist, hand bones
      head: 0.9            # neck and head bones
      trunk: 1.15          # spine, pelvis and shoulder girdle
    mass_fractions:        # de Leva overrides, fractions of total mass; limb names apply to both sides
      upper_arm: 0.04
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..core.skeleton import Skeleton
from ..errors import CharacterError, FroudeError
from .load import load_bvh
from .model import SIDES, BodyModel
from .presets import HEIGHT_RANGE_M, MASS_RANGE_KG, PART_SCALE_RANGE, PRESET_DIR, list_presets

PARTS = ("legs", "arms", "head", "trunk")
_LIMB_SEGMENTS = ("upper_arm", "forearm", "hand", "thigh", "shank", "foot")


@dataclass(frozen=True)
class Character:
    """A target character. height [m] and mass [kg] may be None (derived from the reference)."""

    name: str
    height: float | None = None
    mass: float | None = None
    sex: str = "male"
    proportions: Mapping[str, float] = field(default_factory=dict)
    mass_fractions: Mapping[str, float] = field(default_factory=dict)
    description: str = ""
    skeleton: Skeleton | None = None  # an explicit target skeleton (from a BVH), overrides proportions

    def __post_init__(self):
        def check(value, what: str, limits: tuple, unit: str) -> None:
            lo, hi = limits
            if not (np.isfinite(value) and value > 0):
                raise CharacterError(f"character '{self.name}': {what} must be > 0{unit} (froude supports "
                                     f"{lo:g}-{hi:g}{unit}), got {value}")
            if not lo <= value <= hi:
                raise CharacterError(f"character '{self.name}': {what} {value:g}{unit} is outside what froude "
                                     f"supports, {lo:g}-{hi:g}{unit}")

        if self.height is not None:
            check(self.height, "height", HEIGHT_RANGE_M, " m")
        if self.mass is not None:
            check(self.mass, "mass", MASS_RANGE_KG, " kg")
        if self.sex not in ("male", "female"):
            raise CharacterError(f"character '{self.name}': sex must be male or female, got '{self.sex}'")
        for k, v in self.proportions.items():
            if k not in PARTS:
                raise CharacterError(f"character '{self.name}': unknown proportion '{k}' (use {', '.join(PARTS)})")
            check(v, f"proportion '{k}'", PART_SCALE_RANGE, "")


def load_character(spec: str | Path) -> Character:
    """A preset name, a character YAML file, or a BVH file (its skeleton is the target)."""
    spec = str(spec)
    if spec in list_presets():
        return _from_yaml(PRESET_DIR / f"{spec}.yaml")
    path = Path(spec)
    if path.suffix.lower() in (".yaml", ".yml"):
        if not path.exists():
            raise CharacterError(f"{path}: no such character file")
        return _from_yaml(path)
    if path.suffix.lower() == ".bvh":
        target = load_bvh(path)
        return Character(name=path.stem, skeleton=target.skeleton, description=f"skeleton of {path.name}")
    raise CharacterError(
        f"unknown character '{spec}': use a preset ({', '.join(list_presets())}), a .yaml file or a .bvh skeleton"
    )


def _from_yaml(path: Path) -> Character:
    import yaml

    try:
        data = yaml.safe_load(path.read_text())
    except OSError as e:
        raise CharacterError(f"{path}: cannot read character: {e.strerror or e}") from None
    except yaml.YAMLError as e:
        mark = getattr(e, "problem_mark", None)
        where = f"{path}:{mark.line + 1}" if mark is not None else f"{path}"
        what = getattr(e, "problem", None) or str(e).splitlines()[0]
        raise CharacterError(f"{where}: not valid YAML: {what}") from None
    if not isinstance(data, dict):
        raise CharacterError(f"{path}: a character file is a YAML mapping (name, height, mass, proportions…)")
    known = {"name", "description", "height", "mass", "sex", "proportions", "mass_fractions"}
    unknown = set(map(str, data)) - known
    if unknown:
        raise CharacterError(f"{path}: unknown key(s) {', '.join(sorted(unknown))}; known: {', '.join(sorted(known))}")

    def number(value, key: str, unit: str = "") -> float:
        # YAML reads "tall" as a string and "1_0" as 10: only plain numbers are numbers here
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise CharacterError(f"{path}: {key} must be a number{unit}, got {value!r}")
        return float(value)

    def numbers(value, key: str) -> dict:
        if value is None:
            return {}
        if not isinstance(value, dict):
            raise CharacterError(f"{path}: {key} must be a mapping (part: factor), got {value!r}")
        return {str(k): number(v, f"{key}.{k}") for k, v in value.items()}

    try:
        return _yaml_character(data, path, number, numbers)
    except CharacterError as e:
        raise CharacterError(f"{path}: {e}") from None


def _yaml_character(data: dict, path: Path, number, numbers) -> Character:
    return Character(
        name=str(data.get("name", path.stem)),
        height=None if data.get("height") is None else number(data["height"], "height", " in metres"),
        mass=None if data.get("mass") is None else number(data["mass"], "mass", " in kg"),
        sex=str(data.get("sex", "male")),
        proportions=numbers(data.get("proportions"), "proportions"),
        mass_fractions=numbers(data.get("mass_fractions"), "mass_fractions"),
        description=str(data.get("description", "")),
    )


def joint_parts(skeleton: Skeleton, roles: Mapping[str, int]) -> list[str]:
    """The body part ('legs', 'arms', 'head', 'trunk') that each joint's OFFSET (its bone) belongs to."""
    J = skeleton.n_joints
    part = ["trunk"] * J

    def subtree(j):
        out, stack = [], [j]
        while stack:
            k = stack.pop()
            out.append(k)
            stack.extend(skeleton.children(k))
        return out

    for side in SIDES:
        for j in subtree(roles[f"{side}_hip"]):
            if j != roles[f"{side}_hip"]:
                part[j] = "legs"  # the hip joint's own offset is pelvis width: trunk
        for j in subtree(roles[f"{side}_shoulder"]):
            if j != roles[f"{side}_shoulder"]:
                part[j] = "arms"
    head_root = roles.get("neck", roles["head"])
    for j in subtree(head_root):
        if j != head_root or "neck" not in roles:
            part[j] = "head"
    return part


def scale_skeleton_parts(skeleton: Skeleton, roles: Mapping[str, int], factors: Mapping[str, float]) -> Skeleton:
    """A copy with each bone scaled by the factor of its part (end sites follow their joint's part)."""
    parts = joint_parts(skeleton, roles)
    f = np.array([factors.get(p, 1.0) for p in parts])
    ends = tuple((j, np.asarray(off) * factors.get(parts[j], 1.0)) for j, off in skeleton.end_sites)
    return skeleton.with_offsets(skeleton.offsets * f[:, None], ends)


@dataclass(frozen=True)
class Retarget:
    """A character applied to a reference: target skeleton and body, and the similarity factors.

    L: relative leg length (target / reference); M: relative mass (target / reference).
    """

    character: Character
    skeleton: Skeleton
    body: BodyModel
    L: float
    M: float


def apply_character(character: Character, reference_body: BodyModel) -> Retarget:
    """Build the target skeleton and body model of ``character`` for a reference body model."""
    ref_skel = reference_body.skeleton
    overrides = _expand_fractions(character.mass_fractions)
    if character.skeleton is not None:
        problem = ref_skel.same_topology(character.skeleton)
        if problem:
            raise CharacterError(f"target skeleton '{character.name}' does not match the clip's: {problem}")
        skel = character.skeleton
        probe = BodyModel.from_skeleton(skel)
        if character.height is not None:
            skel = skel.scaled(character.height / probe.stature)
    else:
        skel = scale_skeleton_parts(ref_skel, reference_body.roles, character.proportions)
        probe = BodyModel.from_skeleton(skel)
        if character.height is not None:
            skel = skel.scaled(character.height / probe.stature)
    stature_ratio = BodyModel.from_skeleton(skel).stature / reference_body.stature
    mass = character.mass if character.mass is not None else reference_body.total_mass * stature_ratio**3
    try:
        body = BodyModel.from_skeleton(skel, mass=mass, sex=character.sex, overrides=overrides or None)
    except FroudeError as e:
        raise CharacterError(f"character '{character.name}': {e}") from None
    return Retarget(character, skel, body, body.leg_length / reference_body.leg_length,
                    mass / reference_body.total_mass)


def _expand_fractions(fracs: Mapping[str, float]) -> dict[str, float]:
    out = {}
    for k, v in fracs.items():
        if k in _LIMB_SEGMENTS:
            for side in SIDES:
                out[f"{side}_{k}"] = v
        else:
            out[k] = v
    return out


def character_from_numbers(
    base: Character | None = None,
    height: float | None = None,
    mass: float | None = None,
    leg_scale: float | None = None,
    arm_scale: float | None = None,
    head_scale: float | None = None,
    trunk_scale: float | None = None,
) -> Character:
    """A character from command-line numbers, optionally on top of a preset or file (numbers win)."""
    base = base or Character(name="custom")
    props = dict(base.proportions)
    for key, v in (("legs", leg_scale), ("arms", arm_scale), ("head", head_scale), ("trunk", trunk_scale)):
        if v is not None:
            props[key] = v
    changed = any(v is not None for v in (height, mass, leg_scale, arm_scale, head_scale, trunk_scale))
    name = base.name if not changed or base.name != "custom" else "custom"
    return Character(
        name=name,
        height=base.height if height is None else height,
        mass=base.mass if mass is None else mass,
        sex=base.sex,
        proportions=props,
        mass_fractions=base.mass_fractions,
        description=base.description,
        skeleton=base.skeleton,
    )


def resolve_character(character=None, *, height=None, mass=None, leg_scale=None, arm_scale=None,
                      head_scale=None, trunk_scale=None) -> Character:
    """A Character from a preset name / file / Character plus optional numbers (numbers win)."""
    base = character if isinstance(character, Character) else (load_character(character) if character else None)
    if base is None and all(v is None for v in (height, mass, leg_scale, arm_scale, head_scale, trunk_scale)):
        return Character(name="same")
    return character_from_numbers(base, height, mass, leg_scale, arm_scale, head_scale, trunk_scale)
