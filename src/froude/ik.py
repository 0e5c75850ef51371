"""Whole-body inverse kinematics for every frame at once (paper §6, eq. 6).

For every frame the solver moves the whole-body centre of mass and the foot markers toward their
targets while pulling the root translation, the root orientation and the joint angles toward a
reference pose. The problem is over-constrained and weighted, as in the paper; per frame it minimises

    Σ_points w_p |x_p*(t) − x_p(q)|²                      COM and markers [m]      (tasks)
  + w_root_pos |p_ref − p_root|²                            root translation [m]     (RootTask)
  + w_root_rot |log(q_ref,0⁻¹ q_0)|²                        root orientation [rad]   (RootTask)
  + Σ_joints w_j |log(q_ref,j⁻¹ q_j)|²                      joint rotations [rad]    (PostureTask)

with Gauss-Newton steps from the reference pose (the warm start). Weights are in [1/m²] for positions
and [1/rad²] for rotations: only their ratios matter. The defaults make a 1 rad joint deviation cost
as much as a 1 cm marker error, so targets are met to a small fraction of the requested displacement
while the null space (e.g. how the trunk and arms share a COM shift) follows the reference pose.

Each Gauss-Newton step is solved in the dual ("kernel") form of damped least squares: with the
posture metric D = diag(weights) and the row-scaled task Jacobian J̃ = W^½ J (m = 3 + 3 P rows),

    dq = ε + D⁻¹ J̃ᵀ (J̃ D⁻¹ J̃ᵀ + I)⁻¹ W^½ (e − J ε),      ε = posture error, e = task error,

an m × m system per frame instead of an n × n one (n = 3 + 3 × active joints). Because every joint's
posture weight is isotropic, the 3 × 3 blocks of J̃ D⁻¹ J̃ᵀ need no joint axes at all:
Σ_k d_k ((ũ_p·ũ_q) I − ũ_q ũ_pᵀ) over the joints k moving both points, ũ the (weighted) lever from the
joint to the point (for the COM the subtree mass moment, see ``kinematics.com_jacobian``). All frames of
a chunk are processed together in the component-major layout of ``kinematics.fk_soa`` (each NumPy
operation on contiguous (F,) rows), with a batched Cholesky factorisation written the same way.

Iterations: the first step linearises at the warm start (the reference pose); later steps reuse that
factorisation with fresh errors (a chord / modified Gauss-Newton iteration: the corrections are small,
so J barely changes and each further step costs one FK pass plus two triangular solves). A frame stops
once every weighted COM/marker error is below ``tol`` (the paper's "visually imperceptible"); finished
frames leave the working set, so late iterations cost in proportion to the frames that need them.

Joints that move no mass and no marker (fingers, thumbs) and, by default, the hands are frozen: they
keep the input rotations and cost nothing.
"""
from __future__ import annotations

import weakref
from dataclasses import dataclass, field
from typing import Mapping, Sequence

import numpy as np

from . import quat
from .body import BodyModel
from .errors import IkError
from .kinematics import _quat_rows, com_jacobian, forward_kinematics, point_jacobian
from .motion import Motion
from .skeleton import Skeleton

__all__ = [
    "ComTask", "MarkerTask", "PostureTask", "RootTask", "IkResult", "solve_ik",
    "default_frozen_joints", "max_joint_step", "dof_weights",
]

# Defaults, tuned on the real clips (see benchmarks/bench_ik.py and tests/test_ik.py).
DEFAULT_JOINT_WEIGHT = 1e-4  # [1/rad²] posture pull per joint
DEFAULT_ROOT_POSITION_WEIGHT = 1e-4  # [1/m²]
DEFAULT_ROOT_ORIENTATION_WEIGHT = 1e-4  # [1/rad²]
DEFAULT_TOL = 1e-3  # [m] a frame is done when every COM/marker error is below this ("imperceptible")
DEFAULT_STEP_TOL = 1e-6  # [rad or m] ... or when its largest DOF increment is below this
DEFAULT_MAX_ITERS = 4
DEFAULT_MAX_ERROR = 0.02  # [m] a frame whose COM or marker error stays above this has failed
DEFAULT_MAX_STEP = 0.5  # [rad or m] largest DOF increment applied in one iteration (trust region)
DEFAULT_CHUNK = 2048  # frames processed together (memory stays O(chunk), cache-friendly rows)


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
    def feet(cls, body: BodyModel, target: np.ndarray, weight: float | np.ndarray = 1.0, name: str = "feet") -> "MarkerTask":
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


# ---- result ------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class IkResult:
    """The corrected motion and how well each frame met its tasks.

    motion: the corrected motion (same skeleton, frame time and meta plus meta["ik"]).
    reference: the posture reference motion.
    iterations: (F,) Gauss-Newton steps applied per frame (0 = the start pose already met ``tol``).
    converged: (F,) the last step was below ``tol`` (False: stopped at ``max_iters``).
    failed: (F,) a COM or marker error above ``max_error`` (only returned with on_failure="flag").
    com_error: (F,) |COM target − COM| [m] (None without a ComTask).
    marker_error: (F, P) |marker target − marker| [m], markers of all MarkerTasks in order (None without).
    com: (F, 3) the COM of each solved pose [m] (the solver's last evaluation; None without a ComTask).
    residuals: task name -> (F,) largest residual per frame: [m] for the COM, each MarkerTask (largest
        marker) and the root translation; [rad] for the posture (largest deviation of any active joint,
        root orientation included).
    frozen: names of the joints kept at their input rotations; active: indices of the solved joints.
    """

    motion: Motion
    reference: Motion
    iterations: np.ndarray
    converged: np.ndarray
    failed: np.ndarray
    com_error: np.ndarray | None
    marker_error: np.ndarray | None
    residuals: Mapping[str, np.ndarray]
    frozen: tuple[str, ...] = field(default=())
    active: tuple[int, ...] = field(default=())
    com: np.ndarray | None = None  # (F, 3) the whole-body COM at the solved pose [m] (None without a ComTask)

    @property
    def ok(self) -> bool:
        """No frame failed."""
        return not bool(np.any(self.failed))

    def __repr__(self) -> str:
        parts = [f"{self.motion.n_frames} frames", f"iterations mean {self.iterations.mean():.2f} max {self.iterations.max(initial=0)}"]
        if self.com_error is not None:
            parts.append(f"COM error max {self.com_error.max(initial=0) * 1e3:.2f} mm")
        if self.marker_error is not None:
            parts.append(f"marker error max {self.marker_error.max(initial=0) * 1e3:.2f} mm")
        parts.append(f"failed {int(self.failed.sum())}")
        return f"IkResult({', '.join(parts)})"

    def max_joint_step(self, active_only: bool = True) -> float:
        """Largest frame-to-frame rotation [rad] of any (active) joint in the corrected motion."""
        return max_joint_step(self.motion, self.active if active_only else None)

    def reference_max_joint_step(self, active_only: bool = True) -> float:
        """The same for the reference motion [rad]: the continuity bar is a small multiple of it."""
        return max_joint_step(self.reference, self.active if active_only else None)


def max_joint_step(motion: Motion, joints: Sequence[int] | None = None) -> float:
    """Largest frame-to-frame rotation angle [rad] of any joint's local rotation (root orientation included)."""
    rot = motion.rotations if joints is None else motion.rotations[:, list(joints)]
    if motion.n_frames < 2:
        return 0.0
    out = 0.0
    step = 4096  # bounded temporaries on long motions
    for a in range(0, motion.n_frames - 1, step):
        b = min(a + step + 1, motion.n_frames)
        out = max(out, float(np.max(quat.angle_between(rot[a:b - 1], rot[a + 1:b]))))
    return out


# ---- joint selection -----------------------------------------------------------------------------------
def default_frozen_joints(body: BodyModel, reference: Motion | None = None, freeze_head: bool = False) -> list[int]:
    """Joints the solver keeps at their input rotation by default: the hands and everything below them
    (fingers, thumbs), every joint that moves no segment mass and no foot marker, every joint whose
    rotation never changes (bit for bit) in ``reference`` (e.g. CMU's LHipJoint/RHipJoint: a correction
    should not start moving a joint the reference never uses; it would move the hip centre against the
    pelvis), and optionally the head (neck and head joints)."""
    skel = body.skeleton
    J = skel.n_joints
    frozen = np.zeros(J, bool)
    roots = [body.roles[r] for r in ("left_wrist", "right_wrist") if r in body.roles]
    if freeze_head:
        roots += [body.roles[r] for r in ("neck", "head") if r in body.roles]
    for j in range(J):
        k = j
        while k >= 0:
            if k in roots:
                frozen[j] = True
                break
            k = skel.parents[k]
    # Joints whose subtree carries no mass and no marker have zero Jacobian columns.
    carries = np.zeros(J, bool)
    carries[body.seg_joint] = True
    carries[body.marker_joint.ravel()] = True
    for j in range(J - 1, 0, -1):
        carries[skel.parents[j]] |= carries[j]
    frozen |= ~carries
    if reference is not None and reference.n_frames > 1:
        rot = reference.rotations  # max == min over frames, per joint and component (exact)
        frozen |= np.all(rot.max(axis=0) == rot.min(axis=0), axis=-1)
    frozen[0] = False
    return [int(j) for j in np.flatnonzero(frozen)]


def _resolve_frozen(skel: Skeleton, body: BodyModel, freeze, reference: Motion) -> list[int]:
    if freeze is None or (isinstance(freeze, str) and freeze == "auto"):
        return default_frozen_joints(body, reference)
    if isinstance(freeze, str) and freeze == "auto+head":
        return default_frozen_joints(body, reference, freeze_head=True)
    out = set()
    for f in freeze:
        if isinstance(f, str):
            if f not in skel.names:
                raise IkError(f"cannot freeze unknown joint '{f}'")
            out.add(skel.names.index(f))
        else:
            out.add(int(f))
    if 0 in out:
        raise IkError("the root joint cannot be frozen (give it a large RootTask weight instead)")
    return sorted(out)


def dof_weights(skeleton: Skeleton, posture: PostureTask, root: RootTask) -> tuple[float, np.ndarray]:
    """(root position weight [1/m²], (J,) rotation weights [1/rad²] with joint 0 = root orientation)."""
    w = posture.weights(skeleton)
    w[0] = root.orientation_weight
    if not (root.position_weight > 0 and root.orientation_weight > 0):
        raise IkError("root weights must be > 0")
    return float(root.position_weight), w


# ---- component-major (SOA) helpers ---------------------------------------------------------------------
def _qmul_soa(a: np.ndarray, b: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """Hamilton product of quaternion rows a, b (4, ...) -> (4, ...), written into ``out`` when given
    (which must not overlap a or b)."""
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    if out is None:
        out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    t = np.empty(out.shape[1:])
    # each row left to right, as written: w = aw bw − ax bx − ay by − az bz, ...
    for o, terms in ((out[0], ((aw, bw, 1), (ax, bx, -1), (ay, by, -1), (az, bz, -1))),
                     (out[1], ((aw, bx, 1), (ax, bw, 1), (ay, bz, 1), (az, by, -1))),
                     (out[2], ((aw, by, 1), (ax, bz, -1), (ay, bw, 1), (az, bx, 1))),
                     (out[3], ((aw, bz, 1), (ax, by, 1), (ay, bx, -1), (az, bw, 1)))):
        np.multiply(terms[0][0], terms[0][1], out=o)
        for u, v, sgn in terms[1:]:
            np.multiply(u, v, out=t)
            if sgn > 0:
                o += t
            else:
                o -= t
    return out


def _log_err_soa(q: np.ndarray, q_ref: np.ndarray) -> np.ndarray:
    """log(q⁻¹ q_ref) for rows (4, ...) -> (3, ...) [rad]."""
    qw, qx, qy, qz = q
    rw, rx, ry, rz = q_ref
    w = qw * rw + qx * rx + qy * ry + qz * rz
    x = qw * rx - qx * rw - qy * rz + qz * ry
    y = qw * ry + qx * rz - qy * rw - qz * rx
    z = qw * rz - qx * ry + qy * rx - qz * rw
    s = np.sqrt(x * x + y * y + z * z)
    sign = np.where(w < 0, -1.0, 1.0)
    angle = 2.0 * np.arctan2(s, np.abs(w))
    small = s < 1e-12
    scale = np.where(small, 2.0, angle / np.where(small, 1.0, s)) * sign
    return np.stack([x * scale, y * scale, z * scale])


def _exp_soa(v: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """Quaternion rows (4, ...) of rotation vectors (3, ...) [rad], written into ``out`` when given."""
    if out is None:
        out = np.empty((4,) + v.shape[1:])
    angle = v[0] * v[0]
    t = np.multiply(v[1], v[1], out=out[1])
    angle += t
    np.multiply(v[2], v[2], out=t)
    angle += t
    np.sqrt(angle, out=angle)
    half = np.multiply(angle, 0.5, out=out[2])
    np.cos(half, out=out[0])
    small = angle < 1e-8
    if small.any():
        scale = np.where(small, 0.5 - angle * angle / 48.0, np.sin(half) / np.where(small, 1.0, angle))
    else:
        scale = np.sin(half, out=out[3])
        scale /= angle
    np.multiply(v[0], scale, out=out[1])
    np.multiply(v[1], scale, out=out[2])
    np.multiply(v[2], scale, out=out[3])
    return out


def _soa_quats(rotations: np.ndarray, joints: np.ndarray) -> np.ndarray:
    """(4, K, F) contiguous quaternion rows of the joints ``joints`` (K,) of rotations (F, J, 4)."""
    F = rotations.shape[0]
    g = np.take(rotations, joints, axis=1).reshape(F, 4 * len(joints)).T.copy()  # (K·4, F)
    return g.reshape(len(joints), 4, F).transpose(1, 0, 2).copy()


def _cholesky_soa(A: np.ndarray) -> np.ndarray:
    """Lower Cholesky factor of a batch of SPD matrices stored (m, m, F) (frame axis last), written over
    A's lower triangle (returned: A itself; its strict upper triangle is neither read nor written). One
    NumPy call works on whole (k, F) blocks; no second m × m × F array is touched."""
    m = A.shape[0]
    L = A
    for j in range(m):
        Lj = L[j, :j]
        d = L[j, j]
        if j:
            d -= np.einsum("kf,kf->f", Lj, Lj)
        np.sqrt(d, out=d)
        if j < m - 1:
            col = L[j + 1:, j]
            if j:
                col -= np.einsum("ikf,kf->if", L[j + 1:, :j], Lj)
            col /= d
    return L


def _cho_solve_soa(L: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Solve L Lᵀ x = b for (m, m, F) factors and (m, F) right-hand sides."""
    m = L.shape[0]
    y = np.empty_like(b)
    for j in range(m):
        v = b[j] - np.einsum("kf,kf->f", L[j, :j], y[:j]) if j else b[j].copy()
        v /= L[j, j]
        y[j] = v
    x = np.empty_like(b)
    for j in range(m - 1, -1, -1):
        v = y[j] - np.einsum("kf,kf->f", L[j + 1:, j], x[j + 1:]) if j < m - 1 else y[j].copy()
        v /= L[j, j]
        x[j] = v
    return x


# ---- the solver plan: which joints, which levers ------------------------------------------------------
@dataclass(frozen=True, eq=False)
class _Group:
    """Task points that share joints: the COM (one point, every active joint) or the markers on one branch
    off the root. Levers are kept padded over the union of the points' active ancestors (zero where a joint
    does not move a point), so one NumPy call handles a whole group."""

    points: np.ndarray  # (g,) point indices (0 = COM when present, then markers in plan order)
    joints: np.ndarray  # (u,) indices into the active joints
    mask: np.ndarray  # (g, u, 1, 1) 1.0 where the joint moves the point
    rows: slice  # rows of the group's points in the reduced system


@dataclass(frozen=True, eq=False)
class _Plan:
    sub: np.ndarray  # (Jn,) original indices of the joints FK must compute
    parents: np.ndarray  # (Jn,) parents in sub numbering
    offsets: np.ndarray  # (Jn, 3)
    act: np.ndarray  # (K,) active joints in sub numbering (act[0] == 0, the root)
    act_orig: np.ndarray  # (K,) original indices
    d_rot: np.ndarray  # (K,) inverse rotation weights [rad²]
    d_pos: float  # inverse root position weight [m²]
    seg_joint: np.ndarray  # (S,) sub numbering
    seg_local: np.ndarray  # (S, 3)
    seg_mass: np.ndarray  # (S,)
    m_sub: np.ndarray  # (Jn,) subtree mass [kg]
    has_com: bool
    mk_order: np.ndarray  # (P,) marker indices (caller's order) in plan (group) order
    mk_joint: np.ndarray  # (P,) sub numbering, plan order
    mk_local: np.ndarray  # (P, 3), plan order
    groups: tuple  # of _Group
    pairs: tuple  # (g1, g2, i1, i2): common joints of groups g1 <= g2 as positions in each union
    w_own: np.ndarray  # (Jn, 3, 12) first mass moment of each joint's own segments from its FK rows [kg m]
    w_mk: np.ndarray  # (P, 3, 12) each marker from its joint's FK rows (R entries, then P) [m]
    subtree: np.ndarray  # (K, Jn) 1.0 where joint j is in the subtree of active joint k


#: Plans already made, per body model (the studio and long batches solve the same body many times; a plan
#: costs about a millisecond of Python). Weak keys: a plan goes with its body.
_PLANS: "weakref.WeakKeyDictionary[BodyModel, dict]" = weakref.WeakKeyDictionary()


def _cached_plan(skel: Skeleton, body: BodyModel | None, frozen, w_pos: float, w_rot: np.ndarray,
                 mk_joint: np.ndarray, mk_local: np.ndarray, has_com: bool) -> "_Plan":
    """``_make_plan``, remembered per body model for the same skeleton, joints, weights and markers."""
    if body is None:
        return _make_plan(skel, body, frozen, w_pos, w_rot, mk_joint, mk_local, has_com)
    key = (np.asarray(skel.parents).tobytes(), np.asarray(skel.offsets, float).tobytes(), tuple(int(j) for j in frozen),
           float(w_pos), np.asarray(w_rot, float).tobytes(), np.asarray(mk_joint, np.int64).tobytes(),
           np.asarray(mk_local, float).tobytes(), bool(has_com))
    plans = _PLANS.setdefault(body, {})
    plan = plans.get(key)
    if plan is None:
        plan = plans[key] = _make_plan(skel, body, frozen, w_pos, w_rot, mk_joint, mk_local, has_com)
    return plan


def _make_plan(skel: Skeleton, body: BodyModel | None, frozen: list[int], w_pos: float, w_rot: np.ndarray,
               mk_joint: np.ndarray, mk_local: np.ndarray, has_com: bool) -> _Plan:
    J = skel.n_joints
    needed = np.zeros(J, bool)
    needed[0] = True
    if has_com:
        needed[body.seg_joint] = True
    needed[mk_joint] = True
    active = np.ones(J, bool)
    active[frozen] = False
    seen = needed.copy()  # an active joint matters only if it moves something the tasks see
    for j in range(J - 1, 0, -1):
        seen[skel.parents[j]] |= seen[j]
    active &= seen
    active[0] = True
    needed |= active
    for j in range(J - 1, 0, -1):  # close under ancestors
        if needed[j]:
            needed[skel.parents[j]] = True
    sub = np.flatnonzero(needed)
    new = -np.ones(J, np.int64)
    new[sub] = np.arange(len(sub))
    parents = np.array([-1] + [new[skel.parents[j]] for j in sub[1:]], np.int64)
    act_orig = np.flatnonzero(active)
    K = len(act_orig)
    pos_in_act = -np.ones(J, np.int64)
    pos_in_act[act_orig] = np.arange(K)

    def chain(j):
        ch = []
        k = int(j)
        while k >= 0:
            if active[k]:
                ch.append(pos_in_act[k])
            k = skel.parents[k]
        return ch[::-1]

    chains = [chain(j) for j in mk_joint]
    # group markers by the branch they hang from (first active joint below the root)
    branch = [ch[1] if len(ch) > 1 else 0 for ch in chains]
    order = sorted(range(len(chains)), key=lambda i: (branch[i], i))
    groups = []
    row = 0
    if has_com:
        groups.append(_Group(np.array([0]), np.arange(K), np.ones((1, K, 1, 1)), slice(0, 3)))
        row = 3
    base = 1 if has_com else 0
    plan_pos = {orig: n for n, orig in enumerate(order)}
    for b in sorted(set(branch)):
        members = [i for i in order if branch[i] == b]
        union = sorted(set().union(*[chains[i] for i in members]))
        mask = np.array([[1.0 if u in chains[i] else 0.0 for u in union] for i in members])[:, :, None, None]
        pts = np.array([base + plan_pos[i] for i in members])
        groups.append(_Group(pts, np.array(union, np.int64), mask, slice(row, row + 3 * len(members))))
        row += 3 * len(members)
    pairs = []
    for g1 in range(len(groups)):
        for g2 in range(g1, len(groups)):
            common = np.intersect1d(groups[g1].joints, groups[g2].joints)
            if len(common):
                i1 = np.searchsorted(groups[g1].joints, common)
                i2 = np.searchsorted(groups[g2].joints, common)
                pairs.append((g1, g2, i1, i2))
    if has_com:
        seg_joint = new[body.seg_joint]
        seg_local, seg_mass = np.asarray(body.seg_local, float), np.asarray(body.seg_mass, float)
    else:
        seg_joint, seg_local, seg_mass = np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros(0)
    m_sub = np.zeros(len(sub))
    np.add.at(m_sub, seg_joint, seg_mass)
    for j in range(len(sub) - 1, 0, -1):
        m_sub[parents[j]] += m_sub[j]
    mk_order = np.array(order, np.int64)
    # Task points are linear in a joint's FK rows (R row-major, then P): x = R l + p. Per joint, the
    # own segments' mass moment Σ m (p + R l) = W_own [R; p]; per marker W_mk [R; p].
    Jn = len(sub)
    w_own = np.zeros((Jn, 3, 12))
    for seg in range(len(seg_mass)):
        j, m = seg_joint[seg], seg_mass[seg]
        for r in range(3):
            w_own[j, r, 3 * r:3 * r + 3] += m * seg_local[seg]
            w_own[j, r, 9 + r] += m
    mk_local_plan = np.asarray(mk_local, float)[mk_order] if len(mk_order) else np.zeros((0, 3))
    w_mk = np.zeros((len(mk_order), 3, 12))
    for k in range(len(mk_order)):
        for r in range(3):
            w_mk[k, r, 3 * r:3 * r + 3] = mk_local_plan[k]
            w_mk[k, r, 9 + r] = 1.0
    in_sub = np.eye(Jn)
    for j in range(Jn - 1, 0, -1):  # children have larger indices than their parents
        in_sub[parents[j]] = np.maximum(in_sub[parents[j]], in_sub[j])
    subtree = np.ascontiguousarray(in_sub[new[act_orig]])
    return _Plan(
        sub, parents, np.asarray(skel.offsets)[sub], new[act_orig], act_orig, 1.0 / w_rot[act_orig], 1.0 / w_pos,
        seg_joint, seg_local, seg_mass, m_sub, has_com, mk_order,
        new[np.asarray(mk_joint, np.int64)[mk_order]] if len(mk_order) else np.zeros(0, np.int64),
        np.asarray(mk_local, float)[mk_order] if len(mk_order) else np.zeros((0, 3)),
        tuple(groups), tuple(pairs), w_own, w_mk, subtree,
    )


# ---- one chunk of frames -----------------------------------------------------------------------------
class _FK:
    """``kinematics.fk_soa`` with buffers kept across the iterations of a chunk: the outputs are written in
    place (fresh multi-megabyte arrays every iteration cost as much in page faults as the arithmetic) and
    the local rotation matrices of frozen joints, which never change, are converted once. The arithmetic
    is fk_soa's, entry for entry and in the same order (checked against it in the tests), but each joint's
    3 × 3 product and offset are a handful of broadcast operations on (3, 3, F) / (3, F) blocks, and the
    active joints' local rotations are converted in one batch from (4, K, F) quaternion rows.

    Outputs live in one (Jn, 12, F) array T: rows 0-8 the world rotation (row-major), rows 9-11 the
    world position [m], so task points and mass moments are small matrix products over T's rows.
    """

    def __init__(self, plan: "_Plan", rot_T: np.ndarray, extra: Sequence[tuple[str, int]] = ()):
        Jn, F = len(plan.parents), rot_T.shape[-1]
        K = len(plan.act)
        self.plan = plan
        self.F = F
        frozen = np.ones(Jn, bool)
        frozen[plan.act] = False
        fro = np.flatnonzero(frozen)
        self.K = K
        # Local rotations of all FK joints in one (K + frozen, 9, F) store: the active joints' rows first
        # (rewritten every call), then the frozen ones' (converted once). lrow[j]: joint j's row.
        self.lrow = np.empty(Jn, np.int64)
        self.lrow[plan.act] = np.arange(K)
        self.lrow[fro] = K + np.arange(len(fro))
        # Joints by depth below the root: all joints of one depth are one batch of array operations
        # (their parents are done), ~8 batches instead of ~25 joints' worth of small operations.
        depth = np.zeros(Jn, np.int64)
        for j in range(1, Jn):
            depth[j] = depth[plan.parents[j]] + 1
        self.levels = []
        for d in range(1, int(depth.max(initial=0)) + 1):
            js = np.flatnonzero(depth == d)
            off = np.asarray(plan.offsets, float)[js]
            self.levels.append((js, plan.parents[js], self.lrow[js], off[:, 0, None, None], off[:, 1, None, None],
                                off[:, 2, None, None]))
        # One work area for the whole chunk (FK outputs and temporaries, plus the ``extra`` (name, rows)
        # areas of the caller: the system matrix, ...), each region re-viewed contiguous over its first
        # n frames when the working set shrinks. One allocation instead of a dozen: freshly mapped memory
        # costs a page fault per 4 kB, as much as the arithmetic on it.
        regions = [("T", Jn * 12), ("L", 9 * (K + len(fro))), ("tq", 3 * K), ("t33", 9), ("t3", 3)]
        regions += list(extra)
        self._work = np.empty(sum(r for _, r in regions) * F)
        self._regions, off = {}, 0
        for name, r in regions:
            self._regions[name] = (off, r)
            off += r * F
        self._view(F)
        for i, j in enumerate(fro):
            _quat_rows(rot_T[j], self.L[K + i], self.t3)

    def area(self, name: str, shape: tuple[int, ...]) -> np.ndarray:
        """The work area ``name`` as a contiguous (*shape, n) array over the current n frames."""
        off, rows = self._regions[name]
        n = getattr(self, "n", self.F)
        size = int(np.prod(shape, dtype=np.int64)) * n
        assert size <= rows * self.F
        return self._work[off:off + size].reshape(*shape, n)

    def _view(self, n: int) -> None:
        Jn, K = len(self.plan.parents), len(self.plan.act)
        self.n = n
        self.T = self.area("T", (Jn, 12))
        self.L = self.area("L", (Jn, 9))
        self.tq = self.area("tq", (3, K))
        self.t33 = self.area("t33", (3, 3))
        self.t3 = self.area("t3", (3,))

    @property
    def P(self) -> np.ndarray:
        return self.T[:, 9:12]

    @property
    def R(self) -> np.ndarray:
        return self.T[:, :9]

    def compact(self, keep: np.ndarray) -> None:
        """Keep only the frames ``keep`` (the working set shrank)."""
        frozen = self.L[self.K:][:, :, keep]  # a copy: the store is re-viewed over fewer frames below
        self._view(len(keep))
        self.L[self.K:] = frozen

    def __call__(self, root_T, rot_T, tr_T, q_act=None):
        """FK of the plan's joints: P (Jn, 3, F) [m], R (Jn, 9, F) (views of ``T``). The active joints'
        local rotations come from ``q_act`` (4, K, F) when given, else from rot_T (Jn, 4, F)."""
        plan, T, L = self.plan, self.T, self.L
        n = self.n
        if q_act is None:
            q_act = rot_T[plan.act].transpose(1, 0, 2)
        _quat_rows(q_act, L[:self.K].transpose(1, 0, 2), self.tq)
        T[0, :9] = L[self.lrow[0]]
        T[0, 9:] = root_T
        if tr_T is not None:
            return self._per_joint(tr_T)
        for js, ps, rows, ox, oy, oz in self.levels:
            m = len(js)
            A = T[ps, :9].reshape(m, 3, 3, n)  # parents' world rotations (a gathered copy)
            B = L[rows].reshape(m, 3, 3, n)  # the joints' local rotations
            # C[r, c] = A[r, 0] B[0, c] + A[r, 1] B[1, c] + A[r, 2] B[2, c], in fk_soa's order
            C = A[:, :, 0:1] * B[:, 0:1]
            C += A[:, :, 1:2] * B[:, 1:2]
            C += A[:, :, 2:3] * B[:, 2:3]
            T[js, :9] = C.reshape(m, 9, n)
            P = A[:, :, 0] * ox  # p_j = A o + p_parent (terms of zero offsets add an exact zero)
            P += T[ps, 9:]
            P += A[:, :, 1] * oy
            P += A[:, :, 2] * oz
            T[js, 9:] = P
        return self.P, self.R

    def _per_joint(self, tr_T):
        """The joint-by-joint FK with per-frame local translations tr_T (Jn, 3, F) [m]."""
        plan, T, L, t33, t3 = self.plan, self.T, self.L, self.t33, self.t3
        n = self.n
        for j in range(1, len(plan.parents)):
            pj = plan.parents[j]
            A = T[pj, :9].reshape(3, 3, n)
            B = L[self.lrow[j]].reshape(3, 3, n)
            C = T[j, :9].reshape(3, 3, n)
            np.multiply(A[:, 0:1], B[0:1], out=C)
            np.multiply(A[:, 1:2], B[1:2], out=t33)
            C += t33
            np.multiply(A[:, 2:3], B[2:3], out=t33)
            C += t33
            Pj, Pp = T[j, 9:], T[pj, 9:]
            t = tr_T[j]
            np.multiply(A[:, 0], t[0], out=t3)
            np.add(Pp, t3, out=Pj)
            np.multiply(A[:, 1], t[1], out=t3)
            Pj += t3
            np.multiply(A[:, 2], t[2], out=t3)
            Pj += t3
        return self.P, self.R


def _evaluate(plan: _Plan, root_T, rot_T, tr_T, fk=None, q_act=None):
    """FK of the needed joints and the task points (``fk``: a _FK with kept buffers, else a fresh one).

    Returns P (Jn, 3, F), R (Jn, 9, F) and x (npts, 3, F) task points (COM first) [m]; with a ComTask,
    ``fk.s_own`` (Jn, 3, F) holds each joint's own segments' first mass moment [kg m] at this pose.
    """
    if fk is None:
        fk = _FK(plan, rot_T)
    P, R = fk(root_T, rot_T, tr_T, q_act)
    T = fk.T
    F = T.shape[2]
    npts = (1 if plan.has_com else 0) + len(plan.mk_joint)
    x = np.empty((npts, 3, F))
    if plan.has_com:
        s_own = fk.area("s_own", (T.shape[0], 3)) if "s_own" in fk._regions else None
        fk.s_own = np.matmul(plan.w_own, T, out=s_own)  # (Jn, 3, F): one stacked matrix product
        np.add.reduce(fk.s_own, axis=0, out=x[0])
        x[0] *= 1.0 / plan.m_sub[0]
    n0 = npts - len(plan.mk_joint)
    for k in range(len(plan.mk_joint)):
        np.matmul(plan.w_mk[k], T[plan.mk_joint[k]], out=x[n0 + k])
    return P, R, x


def _com_levers(plan: _Plan, P, R, s_own=None) -> np.ndarray:
    """(K, 3, F) COM levers of the active joints: (s_k − m_k p_k) / M with s_k the first mass moment of
    joint k's subtree (``kinematics.com_jacobian``'s trick: the cost is O(J F), not O(J S F)).
    s_own: (Jn, 3, F) each joint's own segments' mass moment (``_evaluate``'s), computed when None."""
    Jn, _, F = P.shape
    if s_own is None:
        T = np.concatenate([R, P], axis=1)
        s_own = np.matmul(plan.w_own, T)
    out = (plan.subtree @ s_own.reshape(Jn, 3 * F)).reshape(-1, 3, F)
    out -= plan.m_sub[plan.act][:, None, None] * P[plan.act]
    out *= 1.0 / plan.m_sub[0]
    return out


def _linearize(plan: _Plan, P, R, x, sw, s_own=None, fk=None):
    """Linearise at a pose: per group the weighted levers ũ (g, u, 3, F), the active joints' world
    rotations (K, 9, F) and the Cholesky factor of K' = J̃ D⁻¹ J̃ᵀ + I (``fk``: a _FK whose work area
    has regions "A" (m × m rows) and "Ra" (9 K rows) to hold the last two; fresh arrays when None)."""
    F = x.shape[2]
    npts = x.shape[0]
    m = 3 * npts
    d = plan.d_rot
    lev_com = _com_levers(plan, P, R, s_own) if plan.has_com else None
    levers, dlevers = [], []
    for g in plan.groups:
        if plan.has_com and g.points[0] == 0:
            U = lev_com[None] * sw[0]  # (1, K, 3, F)
        else:
            U = x[g.points][:, None] - P[plan.act[g.joints]][None]  # (g, u, 3, F)
            U *= g.mask
            U *= sw[g.points][:, None, None, :]
        levers.append(U)
        dlevers.append(U * d[g.joints][None, :, None, None])
    # K' blocks Σ_k d_k ((ũ_p·ũ_q) I − ũ_q ũ_pᵀ) + d_pos √(w_p w_q) I (+ I on the diagonal), written
    # straight into the lower triangle: rows of group g2, columns of group g1 (g1 <= g2).
    if fk is None:
        A = np.zeros((m, m, F))
        Ra = R[plan.act]
    else:
        A = fk.area("A", (m, m))
        A.fill(0.0)
        Ra = np.take(R, plan.act, axis=0, out=fk.area("Ra", (len(plan.act), 9)))
    for g1, g2, i1, i2 in plan.pairs:
        G1, G2 = plan.groups[g1], plan.groups[g2]
        n1, n2 = len(G1.points), len(G2.points)
        V = A[G2.rows, G1.rows].reshape(n2, 3, n1, 3, F)  # V[q, b, p, a]: row (q, b), column (p, a)
        # row (q, b), column (p, a) = δ_ab (ũ_p·ũ_q) − ũ_q[a] ũ_p[b], summed with weights d over common joints
        np.einsum("quaf,pubf->qbpaf", dlevers[g2][:, i2], levers[g1][:, i1], out=V)
        tr = V[:, 0, :, 0] + V[:, 1, :, 1] + V[:, 2, :, 2]
        V *= -1.0
        V2 = A[G2.rows, G1.rows].reshape(n2, 3, n1, 3, F)
        for c in range(3):
            V2[:, c, :, c] += tr
    # the root translation couples every pair of points: d_pos √(w_p w_q) I; the identity on the diagonal
    for c in range(3):
        blkdiag = A[c::3, c::3]  # (npts, npts, F) view
        blkdiag += plan.d_pos * sw[:, None, :] * sw[None, :, :]
    for r in range(m):
        A[r, r] += 1.0
    return levers, Ra, _cholesky_soa(A)


def _step(plan: _Plan, lin, e, eps, eps_t, sw):
    """One damped-least-squares step dq = ε + D⁻¹ J̃ᵀ K'⁻¹ W½ (e − J ε) at a linearisation ``lin``.

    e: (npts, 3, F) task errors [m]; eps: (3, K, F) posture errors [rad]; eps_t: (3, F) root position
    error [m]; sw: (npts, F) square-root task weights. Returns dl (3, K, F) local rotation increments
    [rad] and dt (3, F) root translation increment [m].
    """
    levers, Ra, L = lin
    K = len(plan.act)
    F = e.shape[2]
    rhs = e * sw[:, None, :] if eps is None else (e - eps_t[None]) * sw[:, None, :]
    if eps is not None:
        # J̃ ε = Σ_u (R_u ε_u) × ũ_pu: world posture rotations first, then one cross product per group
        w0 = np.empty((K, 3, F))
        for r in range(3):
            np.einsum("kcf,ckf->kf", Ra[:, 3 * r:3 * r + 3], eps, out=w0[:, r])
        for g, U in zip(plan.groups, levers):
            w = w0[g.joints]
            out = rhs[g.points]
            for a in range(3):
                i, j = (a + 1) % 3, (a + 2) % 3
                out[:, a] -= np.einsum("uf,puf->pf", w[:, i], U[:, :, j])
                out[:, a] += np.einsum("uf,puf->pf", w[:, j], U[:, :, i])
            rhs[g.points] = out
    z = _cho_solve_soa(L, rhs.reshape(-1, F)).reshape(-1, 3, F)
    # J̃ᵀ z: world torque-like ω_u = Σ_p ũ_pu × z_p, then back to each joint's local axes
    omega = np.zeros((K, 3, F))
    for g, U in zip(plan.groups, levers):
        zg = z[g.points]
        o = np.empty((len(g.joints), 3, F))
        for a in range(3):
            i, j = (a + 1) % 3, (a + 2) % 3
            np.einsum("puf,pf->uf", U[:, :, i], zg[:, j], out=o[:, a])
            o[:, a] -= np.einsum("puf,pf->uf", U[:, :, j], zg[:, i])
        omega[g.joints] += o
    dl = np.empty((3, K, F))
    for c in range(3):
        np.einsum("kbf,kbf->kf", Ra[:, c::3], omega, out=dl[c])
    dt = plan.d_pos * (z * sw[:, None, :]).sum(axis=0)
    dl *= plan.d_rot[None, :, None]
    if eps is not None:
        dt += eps_t
        dl += eps
    return dl, dt


def _take_lower(L: np.ndarray, keep: np.ndarray) -> np.ndarray:
    """The frames ``keep`` of a batch of lower-triangular factors (m, m, F): only the lower triangle is
    copied (the strict upper one of the result is left unset; ``_cho_solve_soa`` never reads it)."""
    m = L.shape[0]
    out = np.empty((m, m, len(keep)))
    for r in range(m):
        np.take(L[r, :r + 1], keep, axis=1, out=out[r, :r + 1])
    return out


def _solve_chunk(plan: _Plan, root_T, rot_T, tr_T, ref_root_T, ref_act, target, sw,
                 tol: float, step_tol: float, max_iters: int, max_step: float, refresh: bool,
                 start_is_reference: bool = False, q_start=None):
    """Gauss-Newton on one chunk, in place on root_T (3, F).

    rot_T: (Jn, 4, F) input rotations of the FK joints (any strides; read only: the frozen joints' are
    used, and the active joints' when ``q_start`` (4, K, F) is None). ref_act: (4, K, F) reference
    rotations of the active joints; target: (npts, 3, F) task targets [m]; sw: (npts, F) square-root
    weights. A frame stops when every weighted task point is within ``tol`` [m] of its target, or when its
    step is below ``step_tol``. The first step linearises at the warm start; later steps reuse that
    factorisation (a chord / modified Gauss-Newton iteration) unless ``refresh``. Frames that have stopped
    drop out of the working set (compacted when at most three quarters remain), so late iterations cost in
    proportion to the frames that still need them. Returns iterations (F,), converged (F,), the final task
    points (npts, 3, F), the largest active-joint deviation (F,) [rad] and the active joints' rotations
    (4, K, F).
    """
    F = root_T.shape[1]
    K = len(plan.act)
    npts = target.shape[0]
    iterations = np.zeros(F, np.int64)
    converged = np.zeros(F, bool)
    x_final = np.empty_like(target)
    fk = _FK(plan, rot_T, extra=(("A", 9 * npts * npts), ("Ra", 9 * K), ("s_own", 3 * len(plan.parents)),
                                 ("qa", 4 * K), ("qb", 4 * K), ("ex", 4 * K)))
    q_all = fk.area("qa", (4, K))  # (4, K, F) active joint rotations
    if q_start is None:
        q_start = rot_T[plan.act].transpose(1, 0, 2)
    q_all[:] = q_start
    q_spare, q_exp = fk.area("qb", (4, K)), fk.area("ex", (4, K))
    work = None  # None: every frame; else the chunk indices still iterating (working copies below)
    w_root, w_tr, w_q = root_T, tr_T, q_all
    w_target, w_sw, w_refr, w_refa = target, sw, ref_root_T, ref_act
    lin = None

    def flush():
        if work is not None:
            root_T[:, work] = w_root
            q_all[:, :, work] = w_q

    stopped = None  # (n,) frames of the working set whose last step was below step_tol (they stay put)
    for it in range(max_iters + 1):
        P, R, x = _evaluate(plan, w_root, None, w_tr, fk, w_q)
        e = w_target - x
        err2 = np.where(w_sw > 0, (e * e).sum(axis=1), 0.0).max(axis=0)  # (n,) largest squared error
        done = err2 <= tol * tol
        if work is None:
            x_final[:] = x
            converged |= done
        else:
            x_final[:, :, work] = x
            converged[work] |= done
        if stopped is not None:
            done |= stopped
        if it == max_iters or done.all():
            break
        if lin is None or refresh:
            lin = _linearize(plan, P, R, x, w_sw, fk.s_own if plan.has_com else None, fk)
        live = ~done
        compacted = live.sum() <= 0.75 * len(live)
        if compacted:
            # compact the working set before the step: finished frames cost nothing from here on (a
            # finished frame would only get a zero step: its pose, hence its errors, do not change)
            flush()
            keep = np.flatnonzero(live)
            work = keep if work is None else work[keep]
            w_root = root_T[:, work]
            w_tr = None if tr_T is None else tr_T[:, :, work]
            w_q = q_all[:, :, work]
            q_spare, q_exp = np.empty_like(w_q), np.empty_like(w_q)
            w_target, w_sw, w_refr, w_refa = target[:, :, work], sw[:, work], ref_root_T[:, work], ref_act[:, :, work]
            e = e[:, :, keep]
            levers, Ra, L = lin
            lin = ([np.take(U, keep, axis=-1) for U in levers], np.take(Ra, keep, axis=-1), _take_lower(L, keep))
            fk.compact(keep)
        if it == 0 and start_is_reference:
            eps, eps_t = None, None  # ε = 0 at the warm start: skip the log map and J ε
        else:
            eps, eps_t = _log_err_soa(w_q, w_refa), w_refr - w_root
        dl, dt = _step(plan, lin, e, eps, eps_t, w_sw)
        big = np.maximum(np.abs(dl).max(axis=(0, 1)), np.abs(dt).max(axis=0))
        stopped = big <= step_tol
        if not compacted:
            stopped |= done  # finished frames still in the working set: they keep their pose
        if work is None:
            converged |= stopped
        else:
            converged[work] |= stopped
        live = ~stopped
        scale = np.where(live & np.isfinite(big), np.minimum(1.0, max_step / np.maximum(big, 1e-300)), 0.0)
        dl *= scale
        dt *= scale
        # products of unit quaternions: no renormalisation needed
        w_q, q_spare = _qmul_soa(w_q, _exp_soa(dl, out=q_exp), out=q_spare), w_q
        w_root += dt
        if work is None:
            iterations += live
            q_all = w_q
        else:
            iterations[work] += live
        if not live.any():
            break
    flush()
    dot = np.abs((q_all * ref_act).sum(axis=0)).min(axis=0)
    return iterations, converged, x_final, 2.0 * np.arccos(np.minimum(dot, 1.0)), q_all


# ---- the public entry point -------------------------------------------------------------------------
def solve_ik(
    motion: Motion,
    tasks: Sequence,
    *,
    body: BodyModel | None = None,
    freeze="auto",
    tol: float = DEFAULT_TOL,
    step_tol: float = DEFAULT_STEP_TOL,
    max_iters: int = DEFAULT_MAX_ITERS,
    max_error: float = DEFAULT_MAX_ERROR,
    max_step: float = DEFAULT_MAX_STEP,
    on_failure: str = "raise",
    chunk: int = DEFAULT_CHUNK,
    refresh_jacobian: bool = False,
) -> IkResult:
    """Correct a motion (or a single pose: a 1-frame Motion) with whole-body IK, all frames at once.

    motion: the reference and warm start (F frames); its pose is also the posture/root reference unless a
        PostureTask/RootTask gives another. tasks: any of ComTask (at most one), MarkerTask (any number),
        PostureTask, RootTask (at most one each; defaults are used when absent).
    body: the body model, needed to choose the default frozen joints (taken from a ComTask if omitted).
    freeze: "auto" (hands, fingers, thumbs, mass-less joints and joints the posture reference never
        rotates; see ``default_frozen_joints``), "auto+head", or a list of joint names/indices.
    tol: a frame is done when all its COM and marker errors are below tol [m] (the paper's "visually
        imperceptible"; the over-constrained optimum itself may lie a little beyond it), or
    step_tol: when its largest DOF increment is below step_tol [rad or m].
    max_iters: Gauss-Newton steps at most per frame (the first linearises at the warm start, later ones
        reuse that factorisation unless refresh_jacobian). max_step: trust region per step [rad or m].
    max_error: a frame whose COM or any weighted marker error exceeds this [m] after solving has failed
        (points with zero weight in that frame are ignored): on_failure="raise" raises IkError naming the
        first such frame, the point and its residual; "flag" returns the best effort (finite, unit
        quaternions) with ``result.failed`` set.
    chunk: frames solved together. Memory besides the input is the output motion plus O(chunk)
        buffers (measured: 583 MB above the inputs for 432 000 frames, of which 456 MB is the result).
    refresh_jacobian: re-linearise at every step (plain Gauss-Newton) instead of the chord iteration.

    Defaults (task weights 1 /m², posture and root weights 1e-4, tol 1 mm, at most 4 steps) meet the
    issue's bench problem (COM +2 cm, feet +1 cm on 09_01) to < 1 mm in 1-3 steps per frame.
    """
    if on_failure not in ("raise", "flag"):
        raise IkError(f"on_failure must be 'raise' or 'flag', got '{on_failure}'")
    skel = motion.skeleton
    F, J = motion.n_frames, skel.n_joints
    coms = [t for t in tasks if isinstance(t, ComTask)]
    markers = [t for t in tasks if isinstance(t, MarkerTask)]
    postures = [t for t in tasks if isinstance(t, PostureTask)]
    roots = [t for t in tasks if isinstance(t, RootTask)]
    others = [t for t in tasks if not isinstance(t, (ComTask, MarkerTask, PostureTask, RootTask))]
    if others or len(coms) > 1 or len(postures) > 1 or len(roots) > 1:
        raise IkError("tasks: at most one ComTask, PostureTask and RootTask, any number of MarkerTasks")
    com_task = coms[0] if coms else None
    posture = postures[0] if postures else PostureTask()
    root = roots[0] if roots else RootTask()
    if body is None:
        body = com_task.body if com_task else None
    if body is None and (freeze == "auto" or freeze == "auto+head"):
        body = BodyModel.from_skeleton(skel)
    if body is not None and body.skeleton.n_joints != J:
        raise IkError("body model and motion have different skeletons")
    ref_pose = posture.reference if posture.reference is not None else motion
    ref_root = root.reference if root.reference is not None else motion
    for r in (ref_pose, ref_root):
        if r.n_frames != F or r.skeleton.n_joints != J:
            raise IkError(f"reference motion has {r.n_frames} frames / {r.skeleton.n_joints} joints; expected {F} / {J}")
    # targets and weights, validated once
    com_target = com_w = None
    if com_task is not None:
        com_target = np.asarray(com_task.target, float)
        if com_target.shape != (F, 3):
            raise IkError(f"COM target must be (F, 3) = ({F}, 3); got {com_target.shape}")
        com_w = _rows(com_task.weight, F, (), com_task.name)
    mk_joint = np.concatenate([np.asarray(t.joints, np.int64).reshape(-1) for t in markers]) if markers else np.zeros(0, np.int64)
    mk_local = np.concatenate([np.asarray(t.p_local, float).reshape(-1, 3) for t in markers]) if markers else np.zeros((0, 3))
    mk_target = mk_w = None
    if markers:
        tl, wl = [], []
        for t in markers:
            Pm = len(np.asarray(t.joints).reshape(-1))
            tg = np.asarray(t.target, float)
            if tg.shape != (F, Pm, 3):
                raise IkError(f"{t.name}: targets must be (F, P, 3) = ({F}, {Pm}, 3); got {tg.shape}")
            tl.append(tg)
            wl.append(_rows(t.weight, F, (Pm,), t.name))
        mk_target = np.concatenate(tl, axis=1)
        mk_w = np.concatenate(wl, axis=1)
        if np.any((mk_joint < 0) | (mk_joint >= J)):
            raise IkError("marker joint index out of range")
    for what, a in (("COM target", com_target), ("marker targets", mk_target)):
        if a is not None and not np.all(np.isfinite(a)):
            f = int(np.flatnonzero(~np.all(np.isfinite(a.reshape(F, -1)), axis=1))[0])
            raise IkError(f"{what} are not finite at frame {f}")
    if not (np.all(np.isfinite(motion.rotations)) and np.all(np.isfinite(motion.root_positions))):
        raise IkError("the input motion is not finite")
    frozen = _resolve_frozen(skel, body, freeze, ref_pose)
    w_pos, w_rot = dof_weights(skel, posture, root)
    plan = _cached_plan(skel, body, frozen, w_pos, w_rot, mk_joint, mk_local, com_task is not None)

    out_root = np.array(motion.root_positions, float)
    out_rot = np.array(motion.rotations, float)
    iterations = np.zeros(F, np.int64)
    converged = np.zeros(F, bool)
    npts = (1 if com_task is not None else 0) + len(mk_joint)
    errors = np.zeros((F, npts))
    com_out = np.zeros((F, 3)) if com_task is not None else None
    posture_dev = np.zeros(F)
    failed = np.zeros(F, bool)
    chunk = max(1, int(chunk))
    has_tr = motion.translations is not None
    start_is_reference = ref_pose is motion and ref_root is motion
    for a in range(0, F, chunk):
        b = min(F, a + chunk)
        root_T = np.ascontiguousarray(out_root[a:b].T)
        # the FK joints' input rotations as a (Jn, 4, f) view: only the frozen ones are read, once
        rot_T = np.take(motion.rotations[a:b], plan.sub, axis=1).transpose(1, 2, 0)
        tr_T = np.ascontiguousarray(motion.translations[a:b, plan.sub].transpose(1, 2, 0)) if has_tr else None
        ref_root_T = np.ascontiguousarray(ref_root.root_positions[a:b].T)
        ref_act = _soa_quats(ref_pose.rotations[a:b], plan.act_orig)
        if ref_root is not ref_pose:
            ref_act[:, 0] = ref_root.rotations[a:b, 0].T
        q_start = ref_act if start_is_reference else _soa_quats(motion.rotations[a:b], plan.act_orig)
        target = np.empty((npts, 3, b - a))
        sw = np.empty((npts, b - a))
        if com_task is not None:
            target[0] = com_target[a:b].T
            sw[0] = np.sqrt(com_w[a:b])
        if len(mk_joint):
            target[npts - len(mk_joint):] = mk_target[a:b, plan.mk_order].transpose(1, 2, 0)
            sw[npts - len(mk_joint):] = np.sqrt(mk_w[a:b, plan.mk_order].T)
        its, conv, x, dev, q_act = _solve_chunk(plan, root_T, rot_T, tr_T, ref_root_T, ref_act, target, sw,
                                                tol, step_tol, max_iters, max_step, refresh_jacobian,
                                                start_is_reference, q_start)
        iterations[a:b] = its
        converged[a:b] = conv
        posture_dev[a:b] = dev
        # frames that did not move keep the input bit-for-bit
        moved = np.flatnonzero(its > 0)
        out_root[a + moved] = root_T.T[moved]
        if len(moved) == b - a:
            out_rot[a:b, plan.act_orig] = q_act.transpose(2, 1, 0)
        else:
            out_rot[np.ix_(a + moved, plan.act_orig)] = q_act[:, :, moved].transpose(2, 1, 0)
        err = np.sqrt(((target - x) ** 2).sum(axis=1)).T  # (f, npts) in plan order
        if com_out is not None:
            com_out[a:b] = x[0].T
        # only weighted points can fail (a zero weight switches a marker off for that frame)
        over = np.where(sw.T > 0, err, 0.0)
        if len(mk_joint):  # back to the caller's marker order
            n0 = npts - len(mk_joint)
            for arr in (err, over):
                tmp = np.empty((b - a, len(mk_joint)))
                tmp[:, plan.mk_order] = arr[:, n0:]
                arr[:, n0:] = tmp
        errors[a:b] = err
        bad = ~np.all(over <= max_error, axis=1)  # NaN-safe: a non-finite error is a failure
        failed[a:b] = bad
        if on_failure == "raise" and np.any(bad):
            f = int(np.flatnonzero(bad)[0])
            worst = int(np.argmax(np.nan_to_num(over[f], nan=np.inf)))
            what = "COM" if (com_task is not None and worst == 0) else f"marker {worst - (npts - len(mk_joint))}"
            raise IkError(
                f"IK cannot reach its targets at frame {a + f}: {what} error {err[f, worst] * 1e3:.1f} mm > "
                f"max_error {max_error * 1e3:.1f} mm after {its[f]} iterations ({int(bad.sum())} such frames in "
                f"frames {a}-{b - 1}); pass on_failure='flag' for a best effort")
    if not (np.all(np.isfinite(out_rot)) and np.all(np.isfinite(out_root))):  # defensive: never NaN
        raise IkError("IK produced a non-finite pose")
    meta = dict(motion.meta)
    meta["ik"] = {"frozen": [skel.names[j] for j in frozen], "max_iterations": int(iterations.max(initial=0)),
                  "failed_frames": int(failed.sum())}
    out = motion.with_(root_positions=out_root, rotations=out_rot, meta=meta)
    com_err = errors[:, 0] if com_task is not None else None
    mk_err = errors[:, npts - len(mk_joint):] if len(mk_joint) else None
    residuals = {}
    if com_task is not None:
        residuals[com_task.name] = com_err
    off = 0
    for t in markers:
        Pm = len(np.asarray(t.joints).reshape(-1))
        residuals[t.name] = mk_err[:, off:off + Pm].max(axis=1)
        off += Pm
    residuals[posture.name] = posture_dev
    residuals[root.name] = np.linalg.norm(out_root - ref_root.root_positions, axis=1)
    return IkResult(out, ref_pose, iterations, converged, failed, com_err, mk_err, residuals,
                    tuple(skel.names[j] for j in frozen), tuple(int(j) for j in plan.act_orig), com_out)
