"""The body model: segment masses and centres of mass (de Leva 1996), joint roles, COM and foot markers.

Joint *roles* name the anatomical joints the model needs (``left_hip`` is the hip joint centre, i.e. the
joint whose rotation swings the thigh). Roles are found from joint names for the CMU, Mixamo and common
namings, or given by a user map (a dict or a YAML file ``role: JointName``). Each segment's centre of
mass is a point fixed in one joint's frame, computed once in the rest pose, so the whole-body COM of a
motion is a weighted sum of transformed points (see ``kinematics``).
"""
from __future__ import annotations

import functools
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..core.constants import UP_AXIS
from ..core.kinematics import fk_soa, from_soa, to_soa
from ..core.motion import Motion
from ..core.skeleton import Skeleton
from ..errors import FroudeError


class JointMapError(FroudeError):
    """Joint roles could not be found in a skeleton; the message names them."""


# de Leva (1996) Table 4: mass fraction (male, female), COM fraction from the first endpoint (male, female).
DE_LEVA = {
    "head": ((0.0694, 0.0668), (0.5002, 0.4841)),  # vertex -> C7 (alternative endpoints)
    "trunk": ((0.4346, 0.4257), (0.4310, 0.3782)),  # mid-shoulder JC -> mid-hip JC (alternative)
    "upper_trunk": ((0.1596, 0.1545), (0.2999, 0.2077)),  # suprasternale -> xiphion
    "middle_trunk": ((0.1633, 0.1465), (0.4502, 0.4512)),  # xiphion -> omphalion
    "lower_trunk": ((0.1117, 0.1247), (0.6115, 0.4920)),  # omphalion -> mid-hip
    "upper_arm": ((0.0271, 0.0255), (0.5772, 0.5754)),
    "forearm": ((0.0162, 0.0138), (0.4574, 0.4559)),
    "hand": ((0.0061, 0.0056), (0.7900, 0.7474)),
    "thigh": ((0.1416, 0.1478), (0.4095, 0.3612)),
    "shank": ((0.0433, 0.0481), (0.4395, 0.4352)),
    "foot": ((0.0137, 0.0129), (0.4415, 0.4014)),
}
# Lengths of de Leva's three trunk parts as fractions of the whole trunk line, from the bottom
# (mid-hip) up; male mean lengths lower 145.7 mm, middle 215.5 mm, upper 170.7 mm.
_TRUNK_PARTS = (("lower_trunk", 0.0, 0.2739), ("middle_trunk", 0.2739, 0.6791), ("upper_trunk", 0.6791, 1.0))

SIDES = ("left", "right")
LIMB_ROLES = ("hip", "knee", "ankle", "toe", "shoulder", "elbow", "wrist")
REQUIRED_ROLES = ("pelvis", "head") + tuple(f"{s}_{r}" for s in SIDES for r in LIMB_ROLES)
OPTIONAL_ROLES = ("neck", "head_end") + tuple(f"{s}_{r}" for s in SIDES for r in ("toe_end", "hand_end"))

# Core words (name without side, prefix and punctuation, lower case) for each limb role, in priority
# order. A joint takes one role per side: SMPL's "L_Foot" (the toe joint) is left to the toe once
# "L_Ankle" has taken the ankle.
_CORE_WORDS = {
    "hip": ("upleg", "thigh", "upperleg", "femur", "hip"),
    "knee": ("leg", "shin", "calf", "lowerleg", "knee", "tibia", "shank"),
    "ankle": ("ankle", "foot"),
    "toe": ("toebase", "toe", "toes", "ball", "football", "foot"),
    "toe_end": ("toeend", "toesend", "toetip", "toebaseend"),
    "shoulder": ("arm", "upperarm", "humerus", "shoulder"),
    "elbow": ("forearm", "lowerarm", "elbow"),
    "wrist": ("hand", "wrist"),
    "hand_end": ("handmiddle1", "handindex1", "handend", "fingerbase"),
}
_CENTRAL_WORDS = {
    "head": ("head",),
    "head_end": ("headtopend", "headend", "headtop", "headsite"),
    "neck": ("neck", "neck1", "neck01", "necktwist01"),
}
_SIDE_TOKENS = {"l": "left", "left": "left", "lf": "left", "r": "right", "right": "right", "rt": "right"}
# Side inside a word: "LeftUpLeg", "upperlegleft"; a bare leading letter ("LThigh", "RShin") counts only
# when the rest is a known joint word, so that "lowerarm" or "ribs" are not read as sides.
_STRONG_SIDE = (("left", re.compile(r"^left|left$")), ("right", re.compile(r"^right|right$")))
_WEAK_SIDE = (("left", re.compile(r"^l(?=[a-z])")), ("right", re.compile(r"^r(?=[a-z])")))
_KNOWN_CORES = {w for words in _CORE_WORDS.values() for w in words}


def _normalize(name: str) -> str:
    """Lower case, namespace ("mixamorig:") and path ("|") prefixes removed, only [a-z0-9_.] kept."""
    name = name.split(":")[-1].split("|")[-1]
    return re.sub(r"[^a-z0-9_.]", "", name.lower())


def _side_and_cores(name: str) -> tuple[str | None, tuple[str, ...]]:
    """(side or None, core candidates longest first) of a joint name.

    The side is a token of its own ("thigh_l", "thigh.L", "CC_Base_L_Thigh", "L_Hip") or a word at
    either end ("LeftUpLeg"). The cores are the remaining tokens joined, and the same without leading
    tokens, so that a rig prefix ("CC_Base_", "Bip01_") does not hide the joint word.
    """
    tokens = [t for t in re.split(r"[_.]+", _normalize(name)) if t]
    side = None
    for i, t in enumerate(tokens):
        if t in _SIDE_TOKENS and len(tokens) > 1:
            side = _SIDE_TOKENS[t]
            del tokens[i]
            break
    if side is None and tokens:
        for pats, need_known in ((_STRONG_SIDE, False), (_WEAK_SIDE, True)):
            for s, pat in pats:
                for k in (len(tokens) - 1, 0):  # the word at either end carries the side
                    rest = pat.sub("", tokens[k], count=1)
                    if rest != tokens[k] and rest and (not need_known or rest in _KNOWN_CORES):
                        tokens = tokens[:k] + [rest] + tokens[k + 1:]
                        side = s
                        break
                if side:
                    break
            if side:
                break
    cores = tuple("".join(tokens[i:]) for i in range(len(tokens)))
    return side, cores


def _side_and_core(name: str) -> tuple[str | None, str]:
    """(side or None, the whole core) of a joint name."""
    side, cores = _side_and_cores(name)
    return side, cores[0] if cores else ""


def find_roles(skeleton: Skeleton, joint_map: Mapping[str, str] | None = None) -> dict[str, int]:
    """Role -> joint index for a skeleton, from its joint names and an optional user map (role -> name).

    The pelvis is the joint where the two legs meet (a static reference root above it is skipped).
    Raises JointMapError naming every required role that could not be found, with the likeliest joints.
    """
    # Remembered by names: every retarget of a clip (an editor makes one per slider step) has its names.
    if joint_map is None:
        joint_map = dict(skeleton.joint_map or ())
    jm = tuple(sorted(joint_map.items())) if joint_map else None
    return dict(_roles_of_names(tuple(skeleton.names), tuple(int(p) for p in skeleton.parents), jm))


def _common_ancestor(parents: tuple[int, ...], a: int, b: int) -> int:
    chain = set()
    while a >= 0:
        chain.add(a)
        a = parents[a]
    while b >= 0 and b not in chain:
        b = parents[b]
    return max(b, 0)


@functools.lru_cache(maxsize=64)
def _roles_of_names(names: tuple[str, ...], parents: tuple[int, ...],
                    joint_map: tuple[tuple[str, str], ...] | None) -> dict[str, int]:
    """``find_roles`` for joint names, parents and a joint map as sorted (role, name) pairs."""
    chosen = dict(joint_map) if joint_map else {}
    for role, name in chosen.items():
        if role not in REQUIRED_ROLES + OPTIONAL_ROLES:
            raise JointMapError(
                f"unknown role '{role}' in the joint map; roles are: {', '.join(REQUIRED_ROLES + OPTIONAL_ROLES)}"
            )
        if name not in names:
            raise JointMapError(f"joint map: role '{role}' names joint '{name}', which the skeleton lacks")
    roles: dict[str, int] = {r: names.index(n) for r, n in chosen.items()}
    parsed = [_side_and_cores(n) for n in names]
    for side in SIDES:
        used = {roles[f"{side}_{r}"] for r in _CORE_WORDS if f"{side}_{r}" in roles}
        for role, words in _CORE_WORDS.items():
            if f"{side}_{role}" in roles:
                continue
            for w in words:
                # the whole core first ("foot_l" before "ik_foot_l"), then a core under a rig prefix
                hits = ([j for j, (s, c) in enumerate(parsed) if s == side and c[:1] == (w,) and j not in used]
                        or [j for j, (s, c) in enumerate(parsed) if s == side and w in c and j not in used])
                if hits:
                    roles[f"{side}_{role}"] = hits[0]
                    used.add(hits[0])
                    break
    for role, words in _CENTRAL_WORDS.items():
        if role in roles:
            continue
        for w in words:
            hits = ([j for j, (s, c) in enumerate(parsed) if s is None and c[:1] == (w,)]
                    or [j for j, (s, c) in enumerate(parsed) if s is None and w in c])
            if hits:
                roles[role] = hits[0]
                break
    # Some skeletons (CMU) name the clavicle "Shoulder" and the upper arm "Arm"; others name the
    # shoulder joint "Shoulder". The priority order above prefers "arm".
    if "pelvis" not in roles and "left_hip" in roles and "right_hip" in roles:
        roles["pelvis"] = _common_ancestor(parents, roles["left_hip"], roles["right_hip"])
    missing = [r for r in REQUIRED_ROLES if r not in roles]
    if missing:
        raise JointMapError(_missing_roles_message(names, parsed, missing, set(roles.values())))
    return roles


def _missing_roles_message(names, parsed, missing, assigned) -> str:
    """A few lines: the missing roles, the likeliest joints for each (joints without a role, on the
    role's side, whose name is nearest a word of the role), and how to give a joint map."""
    import difflib

    lines = [f"cannot find the joints for {len(missing)} role(s) among the skeleton's {len(names)} joints; "
             "give them with --joint-map FILE.yaml (lines 'role: JointName'):"]
    for role in missing:
        side, _, base = role.partition("_") if role.split("_")[0] in SIDES else (None, "", role)
        words = _CORE_WORDS.get(base) or _CENTRAL_WORDS.get(base) or (base,)
        scored = []
        for j, (s, cores) in enumerate(parsed):
            if (side is not None and s not in (side, None)) or j in assigned:
                continue
            best = max((difflib.SequenceMatcher(None, w, c).ratio() for w in words for c in cores), default=0.0)
            scored.append((best + (0.2 if s == side else 0.0), j))
        likely = [names[j] for _, j in sorted(scored, key=lambda t: (-t[0], t[1]))[:3]]
        lines.append(f"  {role}: likeliest {', '.join(likely) if likely else '(none)'}")
    return "\n".join(lines)


def load_joint_map(path: str | Path) -> dict[str, str]:
    """Read a YAML joint map ``role: JointName``."""
    import yaml

    try:
        data = yaml.safe_load(Path(path).read_text())
    except (OSError, yaml.YAMLError) as e:
        raise JointMapError(f"{path}: cannot read joint map: {e}") from None
    if not isinstance(data, dict) or not all(isinstance(k, str) and isinstance(v, str) for k, v in data.items()):
        raise JointMapError(f"{path}: a joint map is a YAML mapping 'role: JointName'")
    return data


#: Frames per forward-kinematics pass in BodyModel.com / com_and_markers (bounds memory on long clips).
FK_CHUNK = 16384


@dataclass
class _RestLandmarks:
    """A skeleton's joints by role in its upright reference pose (rest: (J, 3) world positions [m]; R_ref:
    (J, 3, 3) world rotations; ends: joint -> its first non-zero end site, world-rotated [m]), and the notes
    (estimates made) that reading them collects, in the order made."""

    skeleton: Skeleton
    roles: Mapping[str, int]
    rest: np.ndarray
    R_ref: np.ndarray
    ends: dict
    notes: list

    def pos(self, role: str) -> np.ndarray:
        """Rest position (3,) [m] of a role's joint."""
        return self.rest[self.roles[role]]

    def end_point(self, role: str, end_role: str, fallback_from: str) -> np.ndarray:
        """Rest position (3,) [m] of an end point: a mapped joint, the joint's end site, or an estimate."""
        rest, skeleton = self.rest, self.skeleton
        if end_role in self.roles:
            return rest[self.roles[end_role]]
        j = self.roles[role]
        if j in self.ends:
            return rest[j] + self.ends[j]
        kids = skeleton.children(j)
        if kids:
            return rest[kids[0]] if np.linalg.norm(skeleton.offsets[kids[0]]) > 0 else rest[j]
        # estimate: continue the parent bone by half its length
        direction = rest[j] - self.pos(fallback_from)
        if f"no end point for '{skeleton.names[j]}': estimated" not in self.notes:
            self.notes.append(f"no end point for '{skeleton.names[j]}': estimated")
        return rest[j] + 0.5 * direction

    def mean_leg(self):
        """Mean over the sides of hip -> knee -> ankle [m] in the reference pose."""
        pos = self.pos
        return np.mean([np.linalg.norm(pos(s + "_knee") - pos(s + "_hip"))
                        + np.linalg.norm(pos(s + "_ankle") - pos(s + "_knee")) for s in SIDES])


def _rest_landmarks(skeleton: Skeleton, joint_map: Mapping[str, str] | None) -> _RestLandmarks:
    """The skeleton's :class:`_RestLandmarks` (roles found by name or joint_map)."""
    roles = find_roles(skeleton, joint_map)
    # Built in the upright reference pose: the zero-rotation rest pose for most rigs, a pose read from
    # the motion for rigs whose rest pose is folded by bind orientations (see Skeleton.reference_pose).
    rest, R_ref = skeleton.reference_world()
    # first end site wins; zero-length end sites (some exporters write "OFFSET 0 0 0") mark nothing
    ends = {j: R_ref[j] @ np.asarray(off) for j, off in reversed(skeleton.end_sites)
            if np.linalg.norm(off) > 1e-9}
    return _RestLandmarks(skeleton, roles, rest, R_ref, ends, [])


def _segment(name: str, joint: int, prox, dist, key: str, k: int) -> tuple:
    """(name, joint, rest COM point (3,) [m], de Leva key) of a segment from its proximal to its distal
    landmark (3,) [m], de Leva's COM fraction for sex index k (0 male, 1 female)."""
    return (name, joint, prox + DE_LEVA[key][1][k] * (dist - prox), key)


def _head_vertex(lm: _RestLandmarks):
    """(vertex (3,) [m], C7 (3,) [m]): the head+neck segment's ends. Vertex = head end site; C7 ≈ the neck
    joint (or the head joint)."""
    roles, skeleton, pos = lm.roles, lm.skeleton, lm.pos
    c7 = pos("neck") if "neck" in roles else pos("head")
    head_j = roles["head"]
    vertex: np.ndarray | None = None
    if ("head_end" in roles or head_j in lm.ends or "neck" not in roles
            or any(np.linalg.norm(skeleton.offsets[c]) > 0 for c in skeleton.children(head_j))):
        vertex = lm.end_point("head", "head_end", "neck" if "neck" in roles else "pelvis")
    if "neck" in roles and "head_end" not in roles:
        # de Leva's proportions: C7 -> vertex is 0.285 of the leg (hip -> ankle), along neck -> head. It
        # stands in when the rig marks no point above the head joint, and when its end site falls short
        # of it: a nominal bone tip (one Bandai export writes 10 cm end sites, another none, and the
        # same actor's rig then read 1.42 and 1.49 m), not the top of the head.
        leg_mean = lm.mean_leg()
        d = pos("head") - c7
        d = (d / np.linalg.norm(d) if np.linalg.norm(d) > 1e-9
             else body_up(skeleton, lm.rest, lm.rest[0], lm.rest[0] + np.eye(3)[UP_AXIS]))
        estimate = c7 + 0.285 * leg_mean * d
        if vertex is None or (vertex - c7) @ d < (estimate - c7) @ d:
            lm.notes.append(f"no end point for '{skeleton.names[head_j]}'" if vertex is None else
                            f"the end site of '{skeleton.names[head_j]}' falls short of the head's extent")
            lm.notes[-1] += ": the head vertex estimated from the leg length"
            vertex = estimate
    assert vertex is not None  # "neck" or "head_end" missing: the end point above
    return vertex, c7


def _spine_path(skeleton: Skeleton, roles: Mapping[str, int]) -> list:
    """The joints from the pelvis up to the head (indices); joints above the pelvis (a static reference root)
    carry no mass."""
    path = []
    j = roles["head"]
    while j >= 0:
        path.append(j)
        if j == roles["pelvis"]:
            break
        j = skeleton.parents[j]
    return path[::-1]  # pelvis ... head


def _trunk_segments(lm: _RestLandmarks, path: list, mid_hip, mid_sh, up, k: int) -> list:
    """The three trunk parts along mid-hip JC -> mid-shoulder JC (3,) [m], each fixed to the spine joint (of
    path) below its COM along up (3,); k the sex index."""
    rest = lm.rest
    segs = []
    for key, lo, hi in _TRUNK_PARTS:
        bottom = mid_hip + lo * (mid_sh - mid_hip)
        top = mid_hip + hi * (mid_sh - mid_hip)
        c = top + DE_LEVA[key][1][k] * (bottom - top)  # fractions are measured from the top landmark
        below = [p for p in path[:-1] if rest[p] @ up <= c @ up + 1e-9] or [path[0]]
        segs.append((key, below[-1], c, key))
    return segs


def _limb_segments(lm: _RestLandmarks, k: int) -> list:
    """The arms' and legs' segments (upper arm, forearm, hand, thigh, shank, foot), left side first."""
    roles, pos = lm.roles, lm.pos
    segs = []
    for side in SIDES:
        s = side + "_"
        segs.append(_segment(s + "upper_arm", roles[s + "shoulder"], pos(s + "shoulder"), pos(s + "elbow"),
                             "upper_arm", k))
        segs.append(_segment(s + "forearm", roles[s + "elbow"], pos(s + "elbow"), pos(s + "wrist"), "forearm", k))
        hand_end = lm.end_point(s + "wrist", s + "hand_end", s + "elbow")
        segs.append(_segment(s + "hand", roles[s + "wrist"], pos(s + "wrist"), hand_end, "hand", k))
        segs.append(_segment(s + "thigh", roles[s + "hip"], pos(s + "hip"), pos(s + "knee"), "thigh", k))
        segs.append(_segment(s + "shank", roles[s + "knee"], pos(s + "knee"), pos(s + "ankle"), "shank", k))
        toe_end = lm.end_point(s + "toe", s + "toe_end", s + "ankle")
        segs.append(_segment(s + "foot", roles[s + "ankle"], pos(s + "ankle"), toe_end, "foot", k))
    return segs


def _mass_fractions(names: tuple, keys: list, k: int, overrides: Mapping[str, float] | None) -> np.ndarray:
    """(S,) mass fractions of the segments (names, de Leva keys), summing to 1, with overrides fixed and the
    rest rescaled. FroudeError for an unknown segment or fractions outside [0, 1)."""
    fractions = np.array([DE_LEVA[key][0][k] for key in keys])
    fractions = fractions / fractions.sum()  # female table sums to 0.9999
    if overrides:
        for name, frac in overrides.items():
            if name not in names:
                raise FroudeError(f"unknown segment '{name}' in mass overrides; segments: {', '.join(names)}")
            if not 0 <= frac < 1:
                raise FroudeError(f"mass fraction of '{name}' must be in [0, 1), got {frac}")
        fixed = np.array([n in overrides for n in names])
        fixed_total = sum(overrides.values())
        if fixed_total >= 1:
            raise FroudeError("mass overrides sum to 1 or more")
        fractions[~fixed] *= (1 - fixed_total) / fractions[~fixed].sum()
        fractions[fixed] = [overrides[n] for n in np.array(names)[fixed]]
    return fractions


def _foot_markers(lm: _RestLandmarks):
    """(marker_joint (2, 3) int, marker_local (2, 3, 3) [m]): per side the ankle, toe and toe tip markers, as
    joint and offset in that joint's frame (the ankle's and toe's at the joint itself)."""
    roles, R_ref, rest = lm.roles, lm.R_ref, lm.rest
    marker_joint = np.zeros((2, 3), dtype=np.int64)
    marker_local = np.zeros((2, 3, 3))
    for i, side in enumerate(SIDES):
        s = side + "_"
        a, t = roles[s + "ankle"], roles[s + "toe"]
        marker_joint[i] = (a, t, t)
        marker_local[i, 2] = R_ref[t].T @ (lm.end_point(s + "toe", s + "toe_end", s + "ankle") - rest[t])
    return marker_joint, marker_local


@dataclass(frozen=True, eq=False)
class BodyModel:
    """Segment masses and COM points of a skeleton, and its foot markers.

    seg_names: (S,) segment names; seg_joint: (S,) joint index each segment is fixed to;
    seg_local: (S, 3) segment COM in that joint's frame [m]; seg_mass: (S,) [kg].
    marker_joint: (2, 3) joint of each foot marker (left, right) x (ankle, toe, toe end);
    marker_local: (2, 3, 3) marker positions in their joint frames [m].
    roles: role -> joint index. leg_length: mean hip-knee-ankle bone length [m]. stature: [m].
    """

    skeleton: Skeleton
    total_mass: float
    sex: str
    seg_names: tuple[str, ...]
    seg_joint: np.ndarray
    seg_local: np.ndarray
    seg_mass: np.ndarray
    marker_joint: np.ndarray
    marker_local: np.ndarray
    roles: Mapping[str, int]
    leg_length: float
    stature: float
    notes: tuple[str, ...] = field(default=())

    @classmethod
    def from_skeleton(
        cls,
        skeleton: Skeleton,
        mass: float = 70.0,
        sex: str = "male",
        overrides: Mapping[str, float] | None = None,
        joint_map: Mapping[str, str] | None = None,
    ) -> BodyModel:
        """Build the de Leva model for a skeleton.

        mass: total body mass [kg]; sex: "male" or "female" (de Leva's tables);
        overrides: segment name -> mass fraction (e.g. {"head": 0.10}); the remaining fractions are
            rescaled so that the total stays 1. Segment names: head, upper_trunk, middle_trunk,
            lower_trunk, and left_/right_ upper_arm, forearm, hand, thigh, shank, foot.
        joint_map: role -> joint name, for skeletons whose names are not recognised (default: the
            skeleton's own, given when it was read).
        """
        if not (np.isfinite(mass) and mass > 0):
            raise FroudeError(f"body mass must be > 0 kg, got {mass}")
        if sex not in ("male", "female"):
            raise FroudeError(f"sex must be 'male' or 'female', got '{sex}'")
        k = 0 if sex == "male" else 1
        lm = _rest_landmarks(skeleton, joint_map)
        roles, rest, R_ref = lm.roles, lm.rest, lm.R_ref
        vertex, c7 = _head_vertex(lm)
        segs = [_segment("head", roles["head"], vertex, c7, "head", k)]
        # Trunk: three parts along mid-hip JC -> mid-shoulder JC, each fixed to the spine joint below it.
        mid_hip = 0.5 * (lm.pos("left_hip") + lm.pos("right_hip"))
        mid_sh = 0.5 * (lm.pos("left_shoulder") + lm.pos("right_shoulder"))
        up = body_up(skeleton, rest, mid_hip, mid_sh)
        path = _spine_path(skeleton, roles)
        segs += _trunk_segments(lm, path, mid_hip, mid_sh, up, k)
        segs += _limb_segments(lm, k)
        names = tuple(n for n, _, _, _ in segs)
        fractions = _mass_fractions(names, [key for _, _, _, key in segs], k, overrides)
        seg_joint = np.array([j for _, j, _, _ in segs])
        seg_local = np.array([R_ref[j].T @ (c - rest[j]) for _, j, c, _ in segs])
        marker_joint, marker_local = _foot_markers(lm)
        leg_length = float(lm.mean_leg())
        if skeleton.reference_pose is None:
            trunk = None  # upright rest pose: measured as it stands
        else:  # a pose from the motion: the spine straightened, like the legs (it flexes from frame to frame)
            trunk = float(sum(np.linalg.norm(skeleton.offsets[p]) for p in path[1:])
                          + np.linalg.norm(vertex - rest[roles["head"]]))
        stature = _stature(roles, rest, up, vertex, marker_local, R_ref, leg_length, trunk)
        return cls(
            skeleton, float(mass), sex, names, seg_joint, seg_local, fractions * mass,
            marker_joint, marker_local, dict(roles), leg_length, stature, tuple(lm.notes),
        )

    # ---- evaluation on motions -------------------------------------------------------------------
    def fk(self, motion: Motion):
        """Component-major FK of a motion: P (J, 3, F) [m], R (J, 9, F)."""
        rp, rot, tr = to_soa(motion.root_positions, motion.rotations, motion.translations)
        return fk_soa(self.skeleton.parents, self.skeleton.offsets, rp, rot, tr)

    def com_soa(self, P: np.ndarray, R: np.ndarray) -> np.ndarray:
        """Whole-body COM (3, F) [m] from component-major FK outputs."""
        F = P.shape[2]
        acc = np.zeros((3, F))
        for s in range(len(self.seg_mass)):
            j = self.seg_joint[s]
            m = self.seg_mass[s]
            lx, ly, lz = self.seg_local[s] * m
            for r in range(3):
                acc[r] += P[j, r] * m + R[j, 3 * r] * lx + R[j, 3 * r + 1] * ly + R[j, 3 * r + 2] * lz
        return acc / self.total_mass

    def joint_positions(self, motion: Motion, joints) -> np.ndarray:
        """(F, len(joints), 3) world positions [m] of some joints (FK in chunks of FK_CHUNK frames).

        Only the joints and their ancestors are evaluated (the hips cost two joints, not the skeleton).
        """
        joints = [int(j) for j in joints]
        parents = self.skeleton.parents
        keep = np.zeros(len(parents), bool)
        for j in joints:
            while j >= 0 and not keep[j]:
                keep[j] = True
                j = parents[j]
        sub = np.flatnonzero(keep)  # parents come before their children, so the order is kept
        new = -np.ones(len(parents), np.int64)
        new[sub] = np.arange(len(sub))
        sub_parents = np.where(parents[sub] >= 0, new[np.maximum(parents[sub], 0)], -1)
        F = motion.n_frames
        out = np.empty((F, len(joints), 3))
        for a in range(0, max(F, 1), FK_CHUNK):
            b = min(a + FK_CHUNK, F)
            tr = None if motion.translations is None else motion.translations[a:b, sub]
            rp, rot, tr = to_soa(motion.root_positions[a:b], motion.rotations[a:b, sub], tr)
            P, _ = fk_soa(sub_parents, self.skeleton.offsets[sub], rp, rot, tr)
            out[a:b] = P[new[joints]].transpose(2, 0, 1)
        return out

    def com(self, motion: Motion) -> np.ndarray:
        """Whole-body centre of mass (F, 3) [m] of every frame (in chunks: memory O(FK_CHUNK))."""
        return self._fk_pass(motion, markers=False)[0]

    def segment_points(self, p_world_joint: np.ndarray, R_world_joint: np.ndarray) -> np.ndarray:
        """(F, S, 3) world segment COMs [m] from frame-major FK outputs."""
        R = R_world_joint[:, self.seg_joint]
        return p_world_joint[:, self.seg_joint] + np.einsum("fsab,sb->fsa", R, self.seg_local)

    def foot_markers(self, motion: Motion) -> np.ndarray:
        """(F, 2, 3, 3) foot markers [m]: (left, right) x (ankle, toe, toe end) x xyz."""
        return self.com_and_markers(motion)[1]

    def foot_markers_soa(self, P: np.ndarray, R: np.ndarray) -> np.ndarray:
        """(F, 2, 3, 3) foot markers [m] from component-major FK outputs."""
        F = P.shape[2]
        out = np.empty((F, 2, 3, 3))
        for i in range(2):
            for k in range(3):
                j = self.marker_joint[i, k]
                lx, ly, lz = self.marker_local[i, k]
                for r in range(3):
                    out[:, i, k, r] = P[j, r] + R[j, 3 * r] * lx + R[j, 3 * r + 1] * ly + R[j, 3 * r + 2] * lz
        return out

    def com_and_markers(self, motion: Motion) -> tuple[np.ndarray, np.ndarray]:
        """COM (F, 3) [m] and foot markers (F, 2, 3, 3) [m] from one FK pass."""
        com, mk = self._fk_pass(motion, markers=True)
        assert mk is not None
        return com, mk

    def _fk_pass(self, motion: Motion, markers: bool) -> tuple[np.ndarray, np.ndarray | None]:
        """COM (F, 3) [m] and foot markers (F, 2, 3, 3) [m] (None if markers=False) from one FK pass.

        Frames are processed FK_CHUNK at a time: FK of all joints costs ~3 kB per frame, an hour at
        120 Hz would otherwise need 1.3 GB at once; the chunks are large enough to keep the speed.
        """
        F = motion.n_frames
        com = np.empty((F, 3))
        mk = np.empty((F, 2, 3, 3)) if markers else None
        for a in range(0, max(F, 1), FK_CHUNK):
            b = min(a + FK_CHUNK, F)
            tr = None if motion.translations is None else motion.translations[a:b]
            rp, rot, tr = to_soa(motion.root_positions[a:b], motion.rotations[a:b], tr)
            P, R = fk_soa(self.skeleton.parents, self.skeleton.offsets, rp, rot, tr)
            com[a:b] = self.com_soa(P, R).T
            if mk is not None:
                mk[a:b] = self.foot_markers_soa(P, R)
        return com, mk

    def world(self, motion: Motion):
        """Frame-major FK: p_world_joint (F, J, 3) [m], R_world_joint (F, J, 3, 3)."""
        return from_soa(*self.fk(motion))


#: Ankle height above the toe joints per leg length, for rigs measured in a pose from the motion.
ANKLE_HEIGHT_PER_LEG = 0.033


def body_up(skeleton: Skeleton, rest: np.ndarray, mid_hip: np.ndarray, mid_shoulder: np.ndarray) -> np.ndarray:
    """(3,) unit "up" of the body in its reference pose: world +Y for an upright rest pose; the trunk line
    (mid-hip -> mid-shoulder) in a pose read from the motion, so that a forward lean while running does
    not shorten the stature or reorder the spine joints."""
    if skeleton.reference_pose is None:
        return np.eye(3)[UP_AXIS]
    d = mid_shoulder - mid_hip
    return d / max(float(np.linalg.norm(d)), 1e-12)


def _stature(roles, rest, up, vertex, marker_local, R_ref, leg_length, trunk) -> float:
    """Standing height [m]: the limbs straightened (rest poses of mocap skeletons often splay the legs).

    Sum of: the ankle's height above the sole (the larger of the toe markers' drop below the ankle in the
    rest pose; ANKLE_HEIGHT_PER_LEG of the leg in a pose read from the motion), shank and
    thigh lengths, the hip joint centres' drop below the pelvis, and the extent from the pelvis up to the
    head vertex, all along the body's up (``body_up``). ``trunk`` [m], when given, replaces that last
    extent (the spine chain's length plus the head's, for a pose read from the motion).
    """
    if trunk is None:  # the upright rest pose
        ankle_height = 0.0
        for side in SIDES:
            a = rest[roles[side + "_ankle"]]
            t = rest[roles[side + "_toe"]]
            tip = t + R_ref[roles[side + "_toe"]] @ marker_local[0, 2]  # (the left toe tip offset: as before)
            ankle_height = max(ankle_height, a @ up - t @ up, a @ up - tip @ up)
    else:
        # A pose from the motion: how far the ankle stands above the toes depends on the frame (and on an
        # estimated toe tip), which would make the stature differ between a clip and froude's own output
        # of it. The proportion of the upright CMU rest poses is used instead (their toe-joint drop below
        # the ankle is 0.030-0.037 of the leg).
        ankle_height = ANKLE_HEIGHT_PER_LEG * leg_length
    pelvis = rest[roles["pelvis"]]
    hip_drop = pelvis @ up - 0.5 * (rest[roles["left_hip"]] @ up + rest[roles["right_hip"]] @ up)
    if trunk is None:
        trunk = vertex @ up - pelvis @ up
    return float(ankle_height + leg_length + hip_drop + trunk)
