"""The IK tasks (what the solver is asked): the whole-body COM, foot (or any) markers, the posture and
the root, each with its targets and weights, per frame. Units in brackets: weights [1/m²] for positions,
[1/rad²] for rotations (only their ratios matter; see ``ik.solver``).
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from ..body.model import BodyModel
from ..core import quat
from ..core.kinematics import com_jacobian, forward_kinematics, point_jacobian
from ..core.motion import Motion
from ..core.skeleton import Skeleton
from ..errors import IkError

__all__ = ["ComTask", "MarkerTask", "PostureTask", "RootTask", "DEFAULT_JOINT_WEIGHT",
           "DEFAULT_ROOT_POSITION_WEIGHT", "DEFAULT_ROOT_ORIENTATION_WEIGHT"]

# Defaults, tuned on the real clips (see benchmarks/bench_ik.py and tests/test_ik.py).
DEFAULT_JOINT_WEIGHT = 1e-4  # [1/rad²] posture pull per joint
DEFAULT_ROOT_POSITION_WEIGHT = 1e-4  # [1/m²]
DEFAULT_ROOT_ORIENTATION_WEIGHT = 1e-4  # [1/rad²]


def _rows(w, F: int, shape: tuple[int, ...], what: str) -> np.ndarray:
    """Broadcast a weight given as a scalar or array to (F, *shape), checking it is finite and >= 0."""
    w = np.asarray(w, dtype=float)
    try:
        if w.ndim and w.shape[0] == F and w.ndim == len(shape) + 1:
            out = np.broadcast_to(w, (F,) + shape)
        else:
            out = np.broadcast_to(w, shape)
            out = np.broadcast_to(out, (F,) + shape)
    except ValueError:
        raise IkError(f"{what}: weight of shape {w.shape} does not fit (F={F}, {shape})") from None
    if not np.all(np.isfinite(out)) or np.any(out < 0):
        raise IkError(f"{what}: weights must be finite and >= 0")
    return out


# ---- tasks -------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class ComTask:
    """Move the whole-body centre of mass to ``target``.

    body: the body model (segment masses) of the motion's skeleton.
    target: (F, 3) desired COM [m].
    weight: scalar or (F,) [1/m²].
    """

    body: BodyModel
    target: np.ndarray
    weight: float | np.ndarray = 1.0
    name: str = "com"

    def current(self, motion: Motion) -> np.ndarray:
        """(F, 3) COM of the motion [m]."""
        return self.body.com(motion)

    def error(self, motion: Motion) -> np.ndarray:
        """(F, 3) target − current [m]."""
        return np.asarray(self.target, float) - self.current(motion)

    def jacobian(self, motion: Motion) -> np.ndarray:
        """(F, 3, 3 + 3J) d COM / d q in the DOF layout of ``kinematics``."""
        p, R = forward_kinematics(motion.skeleton, motion.root_positions, motion.rotations, motion.translations)
        seg = self.body.segment_points(p, R)
        return com_jacobian(motion.skeleton, p, R, self.body.seg_mass, self.body.seg_joint, seg)[1]


@dataclass(frozen=True, eq=False)
class MarkerTask:
    """Move P points fixed in joint frames (markers) to targets.

    joints: (P,) joint each marker is fixed to; p_local: (P, 3) marker in that joint's frame [m];
    target: (F, P, 3) desired positions [m]; weight: scalar, (P,) or (F, P) [1/m²].
    """

    joints: np.ndarray
    p_local: np.ndarray
    target: np.ndarray
    weight: float | np.ndarray = 1.0
    name: str = "markers"

    @classmethod
    def feet(cls, body: BodyModel, target: np.ndarray, weight: float | np.ndarray = 1.0,
             name: str = "feet") -> MarkerTask:
        """The body model's three markers per foot.

        target: (F, 2, 3, 3) [m], (left, right) x (ankle, toe, toe end) x xyz, as ``BodyModel.foot_markers``.
        weight: scalar, (2,) per foot, (2, 3) per marker, (F, 2) per frame and foot or (F, 2, 3) [1/m²].
        """
        target = np.asarray(target, float)
        if target.ndim != 4 or target.shape[1:] != (2, 3, 3):
            raise IkError(f"foot marker targets must be (F, 2, 3, 3); got {target.shape}")
        F = target.shape[0]
        w = np.asarray(weight, float)
        if w.shape == (2,) or (w.ndim == 2 and w.shape == (F, 2) and w.shape != (2, 3)):
            w = w[..., None]
        w = _rows(w, F, (2, 3), name).reshape(F, 6)
        return cls(body.marker_joint.reshape(6), body.marker_local.reshape(6, 3), target.reshape(F, 6, 3), w, name)

    def current(self, motion: Motion) -> np.ndarray:
        """(F, P, 3) marker positions of the motion [m]."""
        p, R = forward_kinematics(motion.skeleton, motion.root_positions, motion.rotations, motion.translations)
        return p[:, self.joints] + np.einsum("fpab,pb->fpa", R[:, self.joints], np.asarray(self.p_local, float))

    def error(self, motion: Motion) -> np.ndarray:
        """(F, P, 3) target − current [m]."""
        return np.asarray(self.target, float) - self.current(motion)

    def jacobian(self, motion: Motion) -> np.ndarray:
        """(F, P, 3, 3 + 3J) d marker / d q."""
        p, R = forward_kinematics(motion.skeleton, motion.root_positions, motion.rotations, motion.translations)
        x = self.current(motion)
        return point_jacobian(motion.skeleton, p, R, np.asarray(self.joints), x)


def _log_rotation_error(q: np.ndarray, q_ref: np.ndarray) -> np.ndarray:
    """Local rotation vectors (..., 3) [rad] taking q to q_ref by right-multiplication: log(q⁻¹ q_ref)."""
    return quat.to_rotvec(quat.mul(quat.conj(q), q_ref))


@dataclass(frozen=True, eq=False)
class PostureTask:
    """Pull the joint rotations (joints 1..J-1) toward a reference pose.

    weight: scalar, (J,) per joint (entry 0 unused: the root orientation is the RootTask's) or a mapping
        joint name -> weight (others get ``DEFAULT_JOINT_WEIGHT``) [1/rad²]. Must be > 0 for active joints.
    reference: the reference motion (same skeleton and frame count); None = the motion given to solve_ik.
    """

    weight: float | np.ndarray | Mapping[str, float] = DEFAULT_JOINT_WEIGHT
    reference: Motion | None = None
    name: str = "posture"

    def weights(self, skeleton: Skeleton) -> np.ndarray:
        """(J,) per-joint weights [1/rad²]."""
        J = skeleton.n_joints
        if isinstance(self.weight, Mapping):
            w = np.full(J, DEFAULT_JOINT_WEIGHT)
            for n, v in self.weight.items():
                if n not in skeleton.names:
                    raise IkError(f"posture weight for unknown joint '{n}'")
                w[skeleton.names.index(n)] = v
        else:
            w = np.broadcast_to(np.asarray(self.weight, float), (J,)).copy()
        if not np.all(np.isfinite(w[1:])) or np.any(w[1:] <= 0):
            raise IkError("posture weights must be finite and > 0 (freeze a joint instead of a zero weight)")
        return w

    def error(self, motion: Motion) -> np.ndarray:
        """(F, J, 3) local rotation vectors [rad] from the current rotations to the reference's (joint 0 zero)."""
        ref = motion if self.reference is None else self.reference
        e = _log_rotation_error(motion.rotations, ref.rotations)
        e[:, 0] = 0.0
        return e

    def jacobian(self, motion: Motion) -> np.ndarray:
        """(F, 3J, 3 + 3J) selection of the joint rotation increments (rows of joint 0 zero)."""
        F, J = motion.n_frames, motion.skeleton.n_joints
        jac = np.zeros((3 * J, 3 + 3 * J))
        jac[3:, 6:] = np.eye(3 * J - 3)
        return np.broadcast_to(jac, (F,) + jac.shape)


@dataclass(frozen=True, eq=False)
class RootTask:
    """Pull the root translation and orientation toward the reference.

    position_weight [1/m²], orientation_weight [1/rad²]: both > 0.
    reference: None = the motion given to solve_ik.
    """

    position_weight: float = DEFAULT_ROOT_POSITION_WEIGHT
    orientation_weight: float = DEFAULT_ROOT_ORIENTATION_WEIGHT
    reference: Motion | None = None
    name: str = "root"

    def error(self, motion: Motion) -> np.ndarray:
        """(F, 6): reference − current root position [m], then local rotation vector to the reference [rad]."""
        ref = motion if self.reference is None else self.reference
        return np.concatenate(
            [ref.root_positions - motion.root_positions,
             _log_rotation_error(motion.rotations[:, 0], ref.rotations[:, 0])], axis=-1)

    def jacobian(self, motion: Motion) -> np.ndarray:
        """(F, 6, 3 + 3J): selection of the root translation and root rotation increments."""
        F, J = motion.n_frames, motion.skeleton.n_joints
        jac = np.zeros((6, 3 + 3 * J))
        jac[:, :6] = np.eye(6)
        return np.broadcast_to(jac, (F,) + jac.shape)


