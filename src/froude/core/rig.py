"""A rig's file conventions that need only names and numbers: the change of axes between a Z-up file and
froude's +Y up, and the leaf bones an exporter adds to mark where a chain ends.

The conventions read from a motion with the body's joint roles (units, up axis, a standing reference pose)
are ``froude.body.conventions``'; this module is what the readers and writers of files (``froude.io``) use
without knowing a body. All functions are pure.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from . import quat
from .motion import Motion

#: File axes -> froude's (+Y up): a Z-up file's (x, y, z) is (x, z, -y) here (Blender's BVH importer
#: reads files the same way with its axis_up="Y", axis_forward="-Z" conversion inverted).
Z_UP_TO_Y_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])

#: Name endings of the leaf bones exporters add to mark where a chain ends (Blender's FBX exporter: "_end",
#: Mixamo's "_End"; Blender's glTF exporter: "_leaf"): end sites, not joints.
END_BONE_SUFFIXES = ("_end", "_leaf")
#: An end point that repeats its parent bone within these (length ratio, angle) or is shorter than this
#: fraction of the skeleton's extent is a placeholder, not a marked end point (``placeholder_end``).
PLACEHOLDER_LENGTH_RATIO = 0.01
PLACEHOLDER_ANGLE_DEG = 3.0
PLACEHOLDER_STUB = 0.005


def is_end_bone(name: str) -> bool:
    """Whether a leaf bone's name marks it as an exporter's chain end (END_BONE_SUFFIXES, any case)."""
    return name.lower().endswith(END_BONE_SUFFIXES)


def placeholder_end(end: np.ndarray, parent_bone: np.ndarray, size: float) -> bool:
    """Whether an end point (3,) is a placeholder rather than a marked end point; all vectors in one frame.

    end: from the leaf joint to its end point; parent_bone: the bone before it (from the leaf's parent joint
    to the leaf joint); size: the skeleton's extent, same unit. Blender's BVH importer cannot make a bone of
    zero length: for an ``End Site`` written as ``0 0 0`` (the Bandai rig's five) it repeats the parent
    bone's vector, nudged by a tenth of the import scale, or leaves a stub of that nudge, and its exporters
    then write that tail as the chain's end. froude reads a zero End Site as marking nothing (the body
    model estimates the head top, the toe tip); reading the invented tail instead would give the body other
    feet and head. A real end point (a head top, a toe or finger tip) is neither that short nor a copy of
    the bone before it.
    """
    length = float(np.linalg.norm(end))
    if length < PLACEHOLDER_STUB * size:
        return True
    ref = float(np.linalg.norm(parent_bone))
    if ref <= 0 or abs(length / ref - 1.0) > PLACEHOLDER_LENGTH_RATIO:
        return False
    cos = float(end @ parent_bone) / (length * ref)
    return bool(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))) <= PLACEHOLDER_ANGLE_DEG)


def change_basis(motion: Motion, C: np.ndarray) -> Motion:
    """The same motion with every length and rotation expressed in new axes ``x' = C x`` (C proper).

    Offsets, end sites, root positions and translations are rotated; local rotations are conjugated
    (R' = C R Cᵀ), so the world motion is the same up to the rigid change of axes and every joint keeps
    its channels. A reference pose is conjugated too.
    """
    qc = quat.from_matrix(C)
    sk = motion.skeleton
    conj = lambda q: quat.mul(quat.mul(qc, q), quat.conj(qc))  # noqa: E731
    skel = replace(
        sk,
        offsets=sk.offsets @ C.T,
        end_sites=tuple((j, np.asarray(o) @ C.T) for j, o in sk.end_sites),
        reference_pose=None if sk.reference_pose is None else conj(sk.reference_pose),
    )
    tr = None if motion.translations is None else motion.translations @ C.T
    return replace(motion, skeleton=skel, root_positions=motion.root_positions @ C.T,
                   rotations=conj(motion.rotations), translations=tr)
