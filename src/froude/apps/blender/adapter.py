"""The one bridge between a Blender armature and froude's Motion, without ``bpy``: NumPy arrays in, arrays out.

The add-on (``addon.py``) samples an armature's bones into arrays (rest and pose matrices in Blender's
world, +Z up, Blender units) and hands them here; ``armature_motion`` makes a Motion the way a BVH file is
read (``body.conventions.understand``: +Y up, SI units, a rest pose froude can measure), and
``armature_basis`` turns a froude Motion back into each pose bone's local basis matrix for new keyframes.

The skeleton froude sees is the armature's rest pose with every joint's zero rotation being the bone's rest
orientation (the BVH habit Blender's own BVH importer and exporter use): offsets are rest head to rest head
in world axes, a joint's local rotation is the change of its bone's world rotation from the rest, relative
to its parent's. A leaf bone's tail is an ``End Site`` (Blender's BVH importer puts a file's end sites
there and its exporter writes them from there), unless it is a placeholder the importer made for an End
Site of zero length. Leaf bones that exporters add to mark a chain's end
(``*_end``, Mixamo's ``*_End``, ``*_leaf``: ``core.rig.is_end_bone``) are end sites too, not joints.

Pose bones are similarities (rotation and one uniform scale): the new action scales each bone by the
change of length of its own segment (a child's shorter legs are shorter bones, a mesh skinned to them
follows), and Blender's default inheritance (rotation and scale inherited, local location) composes them
as ``pose_child = pose_parent · rest_parent⁻¹ · rest_child · basis_child``.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from ...body.conventions import understand
from ...core import quat
from ...core.kinematics import fk
from ...core.motion import Motion
from ...core.rig import Z_UP_TO_Y_UP, is_end_bone, placeholder_end
from ...core.skeleton import POSITION_CHANNELS, Skeleton
from ...errors import FroudeError
from ...io.bvh import synthetic_pose_frame

#: A pose bone whose scale differs from 1 by more than this is scaled in the action; froude reads rotations
#: and positions only, so such an action is refused rather than read wrongly.
SCALE_TOLERANCE = 1e-4
#: Euler rotation modes of Blender pose bones (the others: QUATERNION, AXIS_ANGLE).
EULER_MODES = ("XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX")


@dataclass(frozen=True)
class Armature:
    """An armature as sampled from Blender, in Blender's world (+Z up) and Blender units.

    names: (B,) bone names, parents first; parents: (B,) parent index or -1 (one root).
    rest_world: (B, 4, 4) each bone's rest matrix in the world (object matrix · bone.matrix_local).
    tails_rest_world: (B, 3) each bone's rest tail in the world [BU].
    connected: (B,) bool, bone.use_connect (its head sits on its parent's tail; Blender ignores its location).
    object_world: (4, 4) the armature object's world matrix.
    """

    names: tuple[str, ...]
    parents: np.ndarray
    rest_world: np.ndarray
    tails_rest_world: np.ndarray
    connected: np.ndarray
    object_world: np.ndarray

    def end_bones(self) -> np.ndarray:
        """(B,) bool: leaf bones that mark a chain's end (an exporter's "_end" or "_leaf" bones), not joints."""
        has_child = np.zeros(len(self.names), bool)
        has_child[self.parents[self.parents >= 0]] = True
        return np.array([not has_child[b] and self.parents[b] >= 0
                         and is_end_bone(n) for b, n in enumerate(self.names)])

    def joints(self) -> np.ndarray:
        """(J,) indices of the bones that are froude joints (all but the end bones), parents first."""
        return np.flatnonzero(~self.end_bones())


def _similarity(m: np.ndarray, what: str, names: Sequence[str]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(..., 4, 4) matrices -> rotation (..., 3, 3), uniform scale (...), translation (..., 3).

    Raises FroudeError naming the bone when a matrix is not a rotation times one scale (sheared or
    non-uniformly scaled)."""
    lin = m[..., :3, :3]
    col = np.linalg.norm(lin, axis=-2)  # (..., 3) column lengths
    s = col.mean(axis=-1)
    bad = np.abs(col - s[..., None]).max(axis=-1) > SCALE_TOLERANCE * np.maximum(s, 1e-12)
    R = lin / s[..., None, None]
    bad |= np.abs(R @ np.swapaxes(R, -1, -2) - np.eye(3)).max(axis=(-1, -2)) > 1e-4
    if bad.any():
        b = int(np.argwhere(bad)[0][-1])
        raise FroudeError(f"bone '{names[b]}': its {what} is scaled unevenly or sheared; froude reads bones "
                          "that rotate and move (apply the scale, Ctrl+A, first)")
    return R, s, m[..., :3, 3]


def armature_motion(arm: Armature, pose_world: np.ndarray, frame_time_s: float, *,
                    metres_per_unit: float | None, joint_map: Mapping[str, str] | None = None,
                    source: str = "Blender armature") -> Motion:
    """The armature's animation as a Motion in SI units, +Y up, as ``froude.load`` reads a BVH file.

    pose_world: (F, B, 4, 4) each bone's pose matrix in the world per frame (object matrix · pose_bone.matrix).
    frame_time_s: seconds per frame [s]. metres_per_unit: metres per Blender unit (the scene's unit scale),
    or None to detect the unit from the motion as ``froude info`` does for a file. joint_map: role -> bone
    name for bone names froude does not recognise.
    meta["first_frame"]: how many leading frames were dropped (a synthetic pose frame, as ``froude.load`` drops
    from a file), so the output starts at that sampled frame.
    Raises FroudeError (one line) for a pose froude cannot read.
    """
    names = arm.names
    joints = arm.joints()
    R_rest, s_rest, h_rest = _similarity(arm.rest_world, "rest matrix", names)
    R_pose, s_pose, h_pose = _similarity(pose_world, "pose", names)
    scaled = np.abs(s_pose / s_rest - 1.0) > SCALE_TOLERANCE
    if scaled[:, joints].any():
        f, b = (int(i) for i in np.argwhere(scaled[:, joints])[0])
        raise FroudeError(f"bone '{names[joints[b]]}' is scaled at frame {f} of the action; froude reads "
                          "bones that rotate and move, not scale")
    # world rotation of each bone relative to its rest: the joint's world rotation in froude's skeleton
    D = R_pose @ np.swapaxes(R_rest, -1, -2)[None]  # (F, B, 3, 3)
    index = {int(b): k for k, b in enumerate(joints)}
    parents = np.array([-1 if arm.parents[b] < 0 else index[int(arm.parents[b])] for b in joints])
    jn = tuple(names[b] for b in joints)
    D, h_pose, h_rest = D[:, joints], h_pose[:, joints], h_rest[joints]
    offsets = h_rest - np.where(parents[:, None] >= 0, h_rest[np.maximum(parents, 0)], 0.0)
    offsets[0] = h_rest[0]
    D_parent = D[:, np.maximum(parents, 0)]
    D_parent[:, 0] = np.eye(3)
    local = np.swapaxes(D_parent, -1, -2) @ D
    # each joint's head in its parent's frame (its offset unless the action moves the bone)
    rel = h_pose - h_pose[:, np.maximum(parents, 0)]
    rel[:, 0] = h_pose[:, 0]
    trans = np.einsum("fjba,fjb->fja", D_parent, rel)
    size = max(float(np.abs(offsets[1:]).max()) if len(offsets) > 1 else 1.0, 1e-9)
    moving = np.abs(trans - offsets).max(axis=0).max(axis=-1) > 1e-6 * size
    moving[0] = True
    rot_channels = ("Zrotation", "Yrotation", "Xrotation")
    channels = tuple(POSITION_CHANNELS + rot_channels if moving[j] else rot_channels for j in range(len(jn)))
    ends = _end_sites(arm, joints, h_rest)
    skeleton = Skeleton(jn, parents, offsets, channels, ends)
    translations = np.where(moving[None, :, None], trans, offsets[None]) if moving[1:].any() else None
    raw = Motion(skeleton, h_pose[:, 0], quat.from_matrix(local), float(frame_time_s), translations)
    # the cleaning froude.load does on a file: a synthetic pose first frame (Blender's BVH importer keeps it)
    why = synthetic_pose_frame(raw.rotations) if raw.n_frames > 2 else None
    cleaning = (f"dropped frame 0 of the action: {why}",) if why else ()
    if why:
        raw = raw.cut(1)
    try:
        motion, conv = understand(raw, joint_map=dict(joint_map) if joint_map else None,
                                  length_scale=metres_per_unit, up="Z")
    except ValueError as e:
        raise FroudeError(str(e)) from None
    if metres_per_unit is not None:
        conv["units"] = f"the scene's unit: {metres_per_unit:g} m per Blender unit"
    meta = {"source": source, "length_scale": conv["length_scale"], "units": conv["units"],
            "units_ambiguous": conv["units_ambiguous"], "up_axis": "Z", "conventions": conv["notes"],
            "cleaning": cleaning, "first_frame": 1 if why else 0}
    return motion.with_(meta=meta)


def _end_sites(arm: Armature, joints: np.ndarray, h_rest: np.ndarray) -> tuple[tuple[int, np.ndarray], ...]:
    """End sites [BU, world axes]: an end bone's head for its parent joint, else a leaf joint's tail, unless
    it is an importer's placeholder (``core.rig.placeholder_end``)."""
    end = arm.end_bones()
    index = {int(b): k for k, b in enumerate(joints)}
    _, _, heads = _similarity(arm.rest_world, "rest matrix", arm.names)
    size = float(np.ptp(heads, axis=0).max())
    candidates: dict[int, np.ndarray] = {}
    for b in np.flatnonzero(end):
        candidates.setdefault(index[int(arm.parents[b])], heads[b] - h_rest[index[int(arm.parents[b])]])
    has_child = np.zeros(len(joints), bool)
    for b in joints:
        if arm.parents[b] >= 0:
            has_child[index[int(arm.parents[b])]] = True
    for k, b in enumerate(joints):
        if not has_child[k] and k not in candidates:
            candidates[k] = arm.tails_rest_world[b] - h_rest[k]
    out = []
    for k in sorted(candidates):
        bone_index = int(joints[k])
        p = int(arm.parents[bone_index])
        parent_bone = arm.tails_rest_world[p] - heads[p] if p >= 0 else np.zeros(3)
        if not placeholder_end(candidates[k], parent_bone, size):
            out.append((k, candidates[k]))
    return tuple(out)


def _segment_ratios(before: Skeleton, after: Skeleton, first_child: np.ndarray) -> np.ndarray:
    """(J,) each joint's bone scale: the change of length of the segment to its connected child (Blender
    places it on the bone's tail), else its first non-zero child, else its end site, else its parent's
    ratio, so that a bone stays as long as its segment. first_child: (J,) the connected child or -1."""
    J = before.n_joints
    ratio = np.ones(J)
    ends_before = dict(before.end_sites)
    ends_after = dict(after.end_sites)
    for j in range(J):
        kids = before.children(j)
        if first_child[j] >= 0:
            kids = [int(first_child[j])] + [c for c in kids if c != first_child[j]]
        pairs = [(before.offsets[c], after.offsets[c]) for c in kids]
        if j in ends_before and j in ends_after:
            pairs.append((ends_before[j], ends_after[j]))
        pairs = [(a, b) for a, b in pairs if np.linalg.norm(a) > 1e-9]
        if pairs:
            ratio[j] = np.linalg.norm(pairs[0][1]) / np.linalg.norm(pairs[0][0])
        elif j > 0:
            ratio[j] = ratio[before.parents[j]]
    return ratio


def armature_basis(arm: Armature, source: Motion, motion: Motion) -> np.ndarray:
    """(F, B, 4, 4) each pose bone's local basis matrix (``pose_bone.matrix_basis``) that puts the armature
    in ``motion``'s pose, frame by frame.

    source: the Motion ``armature_motion`` read from this armature (its skeleton is the armature's rest);
    motion: froude's output on a skeleton of the same joints (offsets may be scaled per segment).
    Bones are scaled uniformly by their segment's change of length; end bones keep the identity basis.
    """
    if motion.skeleton.names != source.skeleton.names:
        raise FroudeError("froude's output has other joints than the armature's bones")
    joints = arm.joints()
    B = len(arm.names)
    scale_m = float(source.meta.get("length_scale", 1.0))
    C = Z_UP_TO_Y_UP
    p_world, R_world = fk(motion)  # [m], +Y up; rotations from the armature's rest
    p_bl = (p_world @ C) / scale_m  # back to Blender axes (C orthogonal: x = Cᵀ x') and units
    D_bl = np.swapaxes(C, 0, 1) @ R_world @ C  # (F, J, 3, 3)
    R_rest, s_rest, _ = _similarity(arm.rest_world, "rest matrix", arm.names)
    index = {int(b): k for k, b in enumerate(joints)}
    first_child = np.full(len(joints), -1)
    for k, b in enumerate(joints):
        if arm.connected[b] and arm.parents[b] >= 0:
            first_child[index[int(arm.parents[b])]] = k
    sigma = _segment_ratios(source.skeleton, motion.skeleton, first_child)
    F = motion.n_frames
    M_world = np.broadcast_to(arm.rest_world, (F, B, 4, 4)).copy()
    lin = D_bl @ R_rest[joints][None] * (s_rest[joints] * sigma)[None, :, None, None]
    M_joints = M_world[:, joints]
    M_joints[..., :3, :3] = lin
    M_joints[..., :3, 3] = p_bl
    M_world[:, joints] = M_joints
    M_arm = np.linalg.inv(arm.object_world) @ M_world  # armature space (pose_bone.matrix)
    rest_arm = np.linalg.inv(arm.object_world) @ arm.rest_world  # bone.matrix_local
    basis = np.broadcast_to(np.eye(4), (F, B, 4, 4)).copy()
    for b in joints:
        p = int(arm.parents[b])
        if p < 0:
            basis[:, b] = np.linalg.inv(rest_arm[b]) @ M_arm[:, b]
        else:
            offset = np.linalg.inv(rest_arm[p]) @ rest_arm[b]
            basis[:, b] = np.linalg.inv(offset) @ np.linalg.inv(M_arm[:, p]) @ M_arm[:, b]
    return basis


def basis_matrices(location: np.ndarray, rotation: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """(..., 4, 4) pose-bone basis matrices T(location) · R(rotation) · S(scale) in float64.

    location (..., 3) [BU], rotation (..., 4) unit quaternions (w, x, y, z), scale (..., 3)."""
    out = np.zeros(location.shape[:-1] + (4, 4))
    out[..., :3, :3] = quat.to_matrix(quat.normalize(rotation)) * scale[..., None, :]
    out[..., :3, 3] = location
    out[..., 3, 3] = 1.0
    return out


def euler_quaternions(angles_rad: np.ndarray, mode: str) -> np.ndarray:
    """(..., 4) quaternions of Blender Euler rotations: angles (..., 3) are (x, y, z) [rad] and ``mode``
    (e.g. "XYZ") the order they apply in, so R = R_z · R_y · R_x for "XYZ"."""
    order = mode[::-1].lower()
    return quat.from_euler(angles_rad[..., ["xyz".index(a) for a in order]], order)


def pose_from_basis(arm: Armature, basis: np.ndarray) -> np.ndarray:
    """(F, B, 4, 4) each bone's pose matrix in the armature's space (``pose_bone.matrix``) from its basis
    (F, B, 4, 4), composed as Blender does for bones that inherit rotation and scale with local location and
    no constraints: ``pose = pose_parent · rest_parent⁻¹ · rest · basis``; a connected bone's location is
    ignored. Float64 throughout (Blender's own matrices are float32: errors of 1e-6 down a long chain)."""
    rest = np.linalg.inv(arm.object_world) @ arm.rest_world
    pose = np.empty_like(basis)
    for b in range(len(arm.names)):
        m = basis[:, b]
        if arm.connected[b]:
            m = m.copy()
            m[:, :3, 3] = 0.0
        p = int(arm.parents[b])
        pose[:, b] = rest[b] @ m if p < 0 else pose[:, p] @ (np.linalg.inv(rest[p]) @ rest[b]) @ m
    return pose


def decompose_basis(basis: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(..., 4, 4) similarity matrices -> location (..., 3), rotation (..., 4) unit quaternions (w, x, y, z)
    made continuous along the first axis, uniform scale (...)."""
    lin = basis[..., :3, :3]
    s = np.cbrt(np.linalg.det(lin))
    q = quat.make_continuous(quat.from_matrix(lin / s[..., None, None]), axis=0)
    return basis[..., :3, 3], q, s
