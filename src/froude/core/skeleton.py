"""The skeleton: joint names, a parents array, rest offsets in metres and the BVH channel layout."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .constants import UP_AXIS
from .kinematics import forward_kinematics

POSITION_CHANNELS = ("Xposition", "Yposition", "Zposition")
ROTATION_CHANNELS = ("Xrotation", "Yrotation", "Zrotation")


@dataclass(frozen=True, eq=False)
class Skeleton:
    """A joint hierarchy in rest pose.

    names: (J,) joint names, in file (depth-first) order.
    parents: (J,) int array, parents[0] == -1 and parents[j] < j for every other joint.
    offsets: (J, 3) rest translation of each joint in its parent's frame [m].
    channels: per joint, the BVH channel names in file order (e.g. ("Zrotation", "Yrotation", "Xrotation")).
    end_sites: ((joint index, (3,) offset [m]), ...) — BVH ``End Site`` blocks, in file order.
    reference_pose: None when the zero-rotation rest pose stands upright (+Y up, the CMU habit); else
        (J, 4) local unit quaternions of a pose that does, read from the motion (rigs whose rest pose
        is folded by bind orientations, the Maya/MotionBuilder habit). The body model is built in it.
    file_up: the up axis of the file the skeleton was read from ("Y" or "Z"); offsets here are +Y up
        whatever it is, and writers turn them back.
    joint_map: ((role, joint name), ...) given by the user for names froude does not recognise; the
        body model uses it (``body.find_roles``).
    """

    names: tuple[str, ...]
    parents: np.ndarray
    offsets: np.ndarray
    channels: tuple[tuple[str, ...], ...]
    end_sites: tuple[tuple[int, np.ndarray], ...] = field(default=())
    reference_pose: np.ndarray | None = None
    file_up: str = "Y"
    joint_map: tuple[tuple[str, str], ...] | None = None

    def __post_init__(self):
        parents = np.asarray(self.parents, dtype=np.int64)
        offsets = np.asarray(self.offsets, dtype=float)
        object.__setattr__(self, "parents", parents)
        object.__setattr__(self, "offsets", offsets)
        n = len(self.names)
        if parents.shape != (n,) or offsets.shape != (n, 3) or len(self.channels) != n:
            raise ValueError("names, parents, offsets and channels must all have one entry per joint")
        if n == 0 or parents[0] != -1 or np.any(parents[1:] < 0) or np.any(parents[1:] >= np.arange(1, n)):
            raise ValueError("parents must satisfy parents[0] == -1 and 0 <= parents[j] < j")
        parents.setflags(write=False)
        offsets.setflags(write=False)
        if self.reference_pose is not None:
            pose = np.array(self.reference_pose, dtype=float)
            if pose.shape != (n, 4):
                raise ValueError("reference_pose must be (J, 4) quaternions")
            pose.setflags(write=False)
            object.__setattr__(self, "reference_pose", pose)

    @property
    def n_joints(self) -> int:
        return len(self.names)

    def index(self, name: str) -> int:
        """Index of the joint called ``name`` (KeyError listing nothing else if absent)."""
        try:
            return self.names.index(name)
        except ValueError:
            raise KeyError(name) from None

    def rotation_order(self, j: int) -> str:
        """Intrinsic Euler order of joint j's rotation channels, e.g. "zyx" ("" if it has none)."""
        return "".join(c[0].lower() for c in self.channels[j] if c in ROTATION_CHANNELS)

    def has_translation_channels(self, j: int) -> bool:
        return any(c in POSITION_CHANNELS for c in self.channels[j])

    @property
    def n_channels(self) -> int:
        return sum(len(c) for c in self.channels)

    def children(self, j: int) -> list[int]:
        return [int(c) for c in np.flatnonzero(self.parents == j)]

    def rest_positions(self) -> np.ndarray:
        """(J, 3) world joint positions [m] with every rotation at identity and the root at the origin."""
        p = np.zeros((self.n_joints, 3))
        for j in range(1, self.n_joints):
            p[j] = p[self.parents[j]] + self.offsets[j]
        return p

    def reference_world(self) -> tuple[np.ndarray, np.ndarray]:
        """World joint positions (J, 3) [m] and rotations (J, 3, 3) of the upright reference pose (the
        rest pose when ``reference_pose`` is None), root at the origin."""
        if self.reference_pose is None:
            return self.rest_positions(), np.broadcast_to(np.eye(3), (self.n_joints, 3, 3)).copy()
        p, R = forward_kinematics(self, np.zeros((1, 3)), self.reference_pose[None])
        return p[0], R[0]

    def rest_end_sites(self) -> np.ndarray:
        """(E, 3) world end-site positions [m] in the rest pose (root at the origin)."""
        p = self.rest_positions()
        return np.array([p[j] + off for j, off in self.end_sites]).reshape(-1, 3)

    def standing_height(self) -> float:
        """Vertical extent [m] of the rest pose (joints and end sites): the character's stature."""
        pts = np.concatenate([self.rest_positions(), self.rest_end_sites()], axis=0)
        return float(pts[:, UP_AXIS].max() - pts[:, UP_AXIS].min())

    def scaled(self, factor: float | np.ndarray) -> Skeleton:
        """A copy with every offset multiplied by ``factor`` (scalar or per-joint (J,) array)."""
        f = np.asarray(factor, dtype=float)
        per_joint = f.reshape(-1, 1) if f.ndim == 1 else f
        ends = tuple(
            (j, np.asarray(off) * (f[j] if f.ndim == 1 else f)) for j, off in self.end_sites
        )
        return Skeleton(self.names, self.parents, self.offsets * per_joint, self.channels, ends,
                        self.reference_pose, self.file_up, self.joint_map)

    def with_offsets(self, offsets: np.ndarray, end_sites=None) -> Skeleton:
        """A copy with new offsets (J, 3) [m] (and optionally new end sites)."""
        return Skeleton(
            self.names, self.parents, offsets, self.channels,
            self.end_sites if end_sites is None else tuple(end_sites), self.reference_pose, self.file_up,
            self.joint_map,
        )

    def with_(self, **changes) -> Skeleton:
        """A copy with fields replaced (dataclasses.replace)."""
        from dataclasses import replace

        return replace(self, **changes)

    def same_topology(self, other: Skeleton) -> str | None:
        """None if ``other`` has the same joint names and parents, else a description of the first mismatch."""
        for j in range(max(self.n_joints, other.n_joints)):
            if j >= self.n_joints:
                return f"extra joint '{other.names[j]}' (joint {j})"
            if j >= other.n_joints:
                return f"missing joint '{self.names[j]}' (joint {j})"
            if self.names[j] != other.names[j]:
                return f"joint {j} is '{other.names[j]}', expected '{self.names[j]}'"
            if self.parents[j] != other.parents[j]:
                pa = self.names[self.parents[j]] if self.parents[j] >= 0 else "(none)"
                pb = other.names[other.parents[j]] if other.parents[j] >= 0 else "(none)"
                return f"joint '{self.names[j]}' has parent '{pb}', expected '{pa}'"
        return None
