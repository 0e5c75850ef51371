"""The rig of a render: which points of a skeleton are drawn and the capsules between them (widths, sides),
from the body model's roles."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..body.model import BodyModel
from ..core.constants import UP
from ..core.kinematics import ancestor_mask, points_world

# Capsule diameters as fractions of stature (an adult of 1.75 m: thigh 13 cm, upper arm 8 cm ...).
_WIDTH = {
    "torso": 0.13, "neck": 0.05, "hip": 0.07, "thigh": 0.075, "shank": 0.055, "foot": 0.036,
    "clavicle": 0.04, "upper_arm": 0.046, "forearm": 0.038, "hand": 0.03,
}
_HEAD_RADIUS = 0.058  # head disc radius / stature
LEFT, RIGHT, CENTRE = 0, 1, 2


# ---- the rig: which points and capsules to draw ------------------------------------------------------
@dataclass(frozen=True, eq=False)
class Rig:
    """What to draw of a skeleton.

    point_joint: (P,) joint each drawn point is fixed to; point_local: (P, 3) point in that joint's frame [m]
    (points 0..J-1 are the joints themselves; extra points are toe tips, hand ends, the head centre).
    bone_a, bone_b: (B,) point indices of each capsule's ends; bone_width: (B,) capsule diameter [m];
    bone_side: (B,) LEFT, RIGHT or CENTRE; head: point index of the head centre; head_radius [m];
    stature [m]; pelvis: point index of the pelvis.
    """

    point_joint: np.ndarray
    point_local: np.ndarray
    bone_a: np.ndarray
    bone_b: np.ndarray
    bone_width: np.ndarray
    bone_side: np.ndarray
    head: int
    head_radius: float
    stature: float
    pelvis: int

    def points(self, p_world_joint: np.ndarray, R_world_joint: np.ndarray) -> np.ndarray:
        """(F, P, 3) world positions [m] of the drawn points."""
        return points_world(p_world_joint, R_world_joint, self.point_joint, self.point_local)


def _nonzero_end_sites(sk) -> dict[int, np.ndarray]:
    """joint -> its first end site offset (3,) [m] in the joint's frame; zero-length end sites ("OFFSET 0 0 0")
    mark nothing."""
    ends: dict[int, np.ndarray] = {}
    for j, off in sk.end_sites:
        if np.linalg.norm(off) > 0:
            ends.setdefault(int(j), np.asarray(off, dtype=float))
    return ends


def _joint_sides(anc: np.ndarray, roles) -> np.ndarray:
    """(J,) LEFT / RIGHT / CENTRE of each joint: a joint is left when it lies in the subtree of left_hip or
    left_shoulder, or on the chain leading to one of them that carries neither the head nor the other side.
    anc (J, J): anc[b, k] when k is b or an ancestor of b."""
    side = np.full(anc.shape[0], CENTRE)
    for s, code in (("left", LEFT), ("right", RIGHT)):
        other = "right" if s == "left" else "left"
        mine = anc[:, roles[f"{s}_hip"]] | anc[:, roles[f"{s}_shoulder"]]
        for limb in ("hip", "shoulder"):
            chain = anc[roles[f"{s}_{limb}"]]  # ancestors of this limb's root
            shared = anc[roles["head"]] | anc[roles[f"{other}_hip"]] | anc[roles[f"{other}_shoulder"]]
            mine |= chain & ~shared
        side[mine] = code
    return side


def _finger_mask(anc: np.ndarray, roles) -> np.ndarray:
    """(J,) bool: the joints below the wrists and the head (fingers, face), which are not drawn."""
    fingers = np.zeros(anc.shape[0], dtype=bool)
    for s in ("left", "right"):
        fingers |= anc[:, roles[f"{s}_wrist"]]
        fingers[roles[f"{s}_wrist"]] = False
    fingers |= anc[:, roles["head"]]
    fingers[roles["head"]] = False
    return fingers


def _bone_kind(child: int, roles, anc: np.ndarray, side: np.ndarray) -> str:
    """The kind (a key of _WIDTH) of the bone that ends at joint child."""
    for s in ("left", "right"):
        r = {k: roles[f"{s}_{k}"] for k in ("hip", "knee", "ankle", "shoulder", "elbow", "wrist")}
        if child == r["knee"]:
            return "thigh"
        if child == r["ankle"]:
            return "shank"
        if anc[:, r["ankle"]][child]:
            return "foot"
        if anc[:, r["hip"]][child] or (side[child] == (LEFT if s == "left" else RIGHT) and anc[r["hip"], child]):
            return "hip"
        if child == r["elbow"]:
            return "upper_arm"
        if child == r["wrist"]:
            return "forearm"
        if side[child] == (LEFT if s == "left" else RIGHT) and anc[r["shoulder"], child]:
            return "clavicle"
    neck = roles.get("neck", roles["head"])
    return "torso" if anc[neck, child] else "neck"


class _Points:
    """The rig's drawn points as (joint, offset (3,) [m] in its frame): every joint itself first, then added
    ones."""

    def __init__(self, n_joints: int):
        self.joint = list(range(n_joints))
        self.local = [np.zeros(3) for _ in range(n_joints)]

    def add(self, joint, local) -> int:
        """Index of a new point at local (3,) [m] in joint's frame."""
        self.joint.append(int(joint))
        self.local.append(np.asarray(local, dtype=float))
        return len(self.joint) - 1


def _limb_end_bones(sk, roles, ends: dict, min_len: float, points: _Points) -> list:
    """The toe -> toe end and wrist -> hand end bones (a mapped joint, an end site, or for the hand the first
    child longer than min_len [m]) as (a, b, kind, side), adding their end points to points."""
    bones = []
    for s in ("left", "right"):
        code = LEFT if s == "left" else RIGHT
        toe, wrist = roles[f"{s}_toe"], roles[f"{s}_wrist"]
        if f"{s}_toe_end" in roles:
            bones.append((toe, roles[f"{s}_toe_end"], "foot", code))
        elif toe in ends:
            bones.append((toe, points.add(toe, ends[toe]), "foot", code))
        # the hand: wrist -> hand end (a finger joint or an end site); fingers themselves are not drawn
        b: int | None
        if f"{s}_hand_end" in roles:
            b = roles[f"{s}_hand_end"]  # a finger joint: follows the fingers' rotation
        elif wrist in ends:
            b = points.add(wrist, ends[wrist])
        else:
            kids = [k for k in sk.children(wrist) if np.linalg.norm(sk.offsets[k]) >= min_len]
            b = points.add(wrist, sk.offsets[kids[0]]) if kids else None
        if b is not None:
            bones.append((wrist, b, "hand", code))
    return bones


def _head_centre_local(roles, rest, R_ref, ends: dict, stature: float):
    """(centre (3,) [m] of the head disc in the head joint's frame, its radius [m]): the disc touches the
    vertex (head end, end site, or 0.12 stature up), its centre one radius below it along the head's axis."""
    head = roles["head"]
    if "head_end" in roles:
        vertex_local = R_ref[head].T @ (rest[roles["head_end"]] - rest[head])
    elif head in ends:
        vertex_local = ends[head]
    else:
        vertex_local = R_ref[head].T @ (np.asarray(UP, dtype=float) * 0.12 * stature)
    radius = _HEAD_RADIUS * stature
    vlen = np.linalg.norm(vertex_local)
    return vertex_local * max(vlen - radius, 0.35 * vlen) / max(vlen, 1e-12), radius


def build_rig(body: BodyModel) -> Rig:
    """The capsules of a skeleton: bones parent→child, minus fingers and zero-length bones.

    Sides come from the roles: a joint is left when it lies in the subtree of left_hip or left_shoulder,
    or on the chain leading to one of them that carries neither the head nor the other side (CMU's
    LHipJoint, LeftShoulder clavicle).
    """
    sk = body.skeleton
    roles = body.roles
    anc = ancestor_mask(sk)  # anc[b, k]: k is b or an ancestor of b
    stature = body.stature
    rest, R_ref = sk.reference_world()  # the upright reference pose (the rest pose unless it is folded)
    ends = _nonzero_end_sites(sk)
    side = _joint_sides(anc, roles)
    fingers = _finger_mask(anc, roles)
    points = _Points(sk.n_joints)
    bones = []  # (a, b, kind, side)
    min_len = 1e-3 * stature
    body_joints = anc[:, roles["pelvis"]]  # a static or ground-level reference root above it is not drawn
    for j in range(1, sk.n_joints):
        if fingers[j] or np.linalg.norm(sk.offsets[j]) < min_len or j == roles["pelvis"] or not body_joints[j]:
            continue
        bones.append((int(sk.parents[j]), j, _bone_kind(j, roles, anc, side), side[j]))
    bones += _limb_end_bones(sk, roles, ends, min_len, points)
    centre_local, radius = _head_centre_local(roles, rest, R_ref, ends, stature)
    head_pt = points.add(roles["head"], centre_local)
    bone_a, bone_b, kinds, sides = zip(*bones)
    return Rig(
        np.array(points.joint), np.array(points.local), np.array(bone_a), np.array(bone_b),
        np.array([_WIDTH[k] * stature for k in kinds]), np.array(sides), head_pt, radius, stature,
        roles["pelvis"],
    )

