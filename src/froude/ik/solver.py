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
operation on contiguous (F,) rows), with a batched Cholesky factorisation written the same way. With few
frames the cost is the number of NumPy calls rather than the arithmetic, so the kernels work on whole
blocks: FK one tree depth per einsum, the cross products of all three axes of a group of points in one
einsum, the triangular solves by 3 × 3 blocks (one task point each).

Iterations: the first step linearises at the warm start (the reference pose); later steps reuse that
factorisation with fresh errors (a chord / modified Gauss-Newton iteration: the corrections are small,
so J barely changes and each further step costs one FK pass plus two triangular solves). A frame stops
once every weighted COM/marker error is below ``tol`` (the paper's "visually imperceptible"); finished
frames leave the working set, so late iterations cost in proportion to the frames that need them.

Joints that move no mass and no marker (fingers, thumbs) and, by default, the hands are frozen: they
keep the input rotations and cost nothing. Frozen subtrees that still carry mass (the hands, the head with
"auto+head") are folded into the joint they hang from: their mass moment about it is fixed per frame,
computed once per chunk, so the iterations' FK passes skip them.
"""
from __future__ import annotations

import weakref
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from ..body.model import BodyModel
from ..core import quat
from ..core.kinematics import _quat_rows, joint_depths
from ..core.motion import Motion
from ..core.skeleton import Skeleton
from ..errors import IkError
from .kernels import _CYC, _block_inverses, _cho_solve_soa, _cholesky_soa, _exp_soa, _log_err_soa, _qmul_soa, _soa_quats
from .tasks import (
    ComTask,
    MarkerTask,
    PostureTask,
    RootTask,
    _rows,
)

__all__ = [
    "ComTask", "MarkerTask", "PostureTask", "RootTask", "IkResult", "solve_ik",
    "default_frozen_joints", "max_joint_step", "dof_weights",
]

# Defaults of the solver, tuned on the real clips (the task weights' are in ik.tasks).
DEFAULT_TOL = 1e-3  # [m] a frame is done when every COM/marker error is below this ("imperceptible")
DEFAULT_STEP_TOL = 1e-6  # [rad or m] ... or when its largest DOF increment is below this
DEFAULT_MAX_ITERS = 4
DEFAULT_MAX_ERROR = 0.02  # [m] a frame whose COM or marker error stays above this has failed
DEFAULT_MAX_STEP = 0.5  # [rad or m] largest DOF increment applied in one iteration (trust region)
DEFAULT_CHUNK = 2048  # frames processed together (memory stays O(chunk), cache-friendly rows)
#: [rad] a joint whose rotation stays this close to its first frame's through the whole reference is one the
#: reference does not use (frozen by default). Far above the rounding a joint's channels pick up on the way
#: (float32 keys in Blender and FBX: ~1e-6 rad; an exact test froze CMU's LHipJoint in the BVH and moved it,
#: 0.6 mm at the head, in the same clip with its rotations perturbed by 1e-6 rad: issue 26), far below any
#: joint a clip uses (the shared clips' least-moving used joint turns 0.025 rad; unused ones 0 or 3e-8).
UNUSED_JOINT_TOL = 1e-4


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
        parts = [f"{self.motion.n_frames} frames",
                 f"iterations mean {self.iterations.mean():.2f} max {self.iterations.max(initial=0)}"]
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
    rotation stays within UNUSED_JOINT_TOL of its first frame's in ``reference`` (e.g. CMU's
    LHipJoint/RHipJoint: a correction should not start moving a joint the reference never uses; it would move
    the hip centre against the pelvis; a tolerance, not bit equality, so that rounding in the input's last
    bits does not unfreeze it), and optionally the head (neck and head joints)."""
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
        rot = reference.rotations
        frozen |= quat.angle_between(rot, rot[:1]).max(axis=0) <= UNUSED_JOINT_TOL
    frozen[0] = False
    return [int(j) for j in np.flatnonzero(frozen)]


def _resolve_frozen(skel: Skeleton, body: BodyModel | None, freeze, reference: Motion) -> list[int]:
    if freeze is None or (isinstance(freeze, str) and freeze in ("auto", "auto+head")):
        body = BodyModel.from_skeleton(skel) if body is None else body  # the default freeze needs the roles
        return default_frozen_joints(body, reference, freeze_head=freeze == "auto+head")
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
    span: slice = field(init=False)  # the points as a slice (they are consecutive in plan order)
    runs: tuple = field(init=False)  # (active joints, group joints) slice pairs of consecutive joints

    def __post_init__(self):
        object.__setattr__(self, "span", slice(self.rows.start // 3, self.rows.stop // 3))
        j = np.asarray(self.joints)
        cut = np.flatnonzero(np.diff(j) != 1) + 1  # per-joint sums go back in a few slice additions
        runs = [(slice(int(j[a]), int(j[b - 1]) + 1), slice(int(a), int(b)))
                for a, b in zip(np.r_[0, cut], np.r_[cut, len(j)])]
        object.__setattr__(self, "runs", tuple(runs))


@dataclass(frozen=True, eq=False)
class _Plan:
    sub: np.ndarray  # (Jn,) original indices of the joints FK must compute
    parents: np.ndarray  # (Jn,) parents in sub numbering
    offsets: np.ndarray  # (Jn, 3)
    act: np.ndarray  # (K,) active joints in sub numbering (act[0] == 0, the root)
    act_orig: np.ndarray  # (K,) original indices
    d_rot: np.ndarray  # (K,) inverse rotation weights [rad²]
    d_pos: float  # inverse root position weight [m²]
    seg_joint: np.ndarray  # (S,) the FK joint carrying each segment, sub numbering (folded: the attach joint)
    seg_local: np.ndarray  # (S, 3)
    seg_mass: np.ndarray  # (S,)
    m_sub: np.ndarray  # (Jn,) subtree mass [kg] (folded segments included)
    has_com: bool
    mk_order: np.ndarray  # (P,) marker indices (caller's order) in plan (group) order
    mk_joint: np.ndarray  # (P,) sub numbering, plan order
    mk_local: np.ndarray  # (P, 3), plan order
    groups: tuple  # of _Group
    pairs: tuple  # (g1, g2, i1, i2): common joints of groups g1 <= g2 as positions in each union
    w_own: np.ndarray  # (Jn, 3, 12) first mass moment of each joint's own segments from its FK rows [kg m]
    w_com: np.ndarray  # (3, 12 Jn) the same summed over joints, plus the folded masses at their attach joints
    w_mk: np.ndarray  # (P, 3, 12) each marker from its joint's FK rows (R entries, then P) [m]
    subtree: np.ndarray  # (K, Jn) 1.0 where joint j is in the subtree of active joint k
    cyc_rows: np.ndarray  # (Σu, 2, 3) rows v[_CYC] of (K, 3) per-joint vectors v, every group's joints
    cyc_spans: tuple  # per group its slice of cyc_rows
    fk_frozen: np.ndarray  # FK joints (sub numbering) not active: their local rotations are converted once
    fk_levels: tuple  # ``_depth_levels`` of the FK joints (local rotation rows: active ones, then fk_frozen)
    # Folded joints (needed only for the mass they carry, see _make_plan), as a small skeleton whose
    # root 0 stands for the FK joint each subtree hangs from:
    fold_orig: np.ndarray  # (Nf,) original indices of the folded joints (small-skeleton joints 1..Nf)
    fold_levels: tuple  # ``_depth_levels`` of the small skeleton (local rotation rows: its joint indices)
    fold_attach: np.ndarray  # (Na,) sub numbering: the joints folded subtrees hang from
    fold_w: np.ndarray  # (3 Na, 12 (Nf + 1)) their folded segments' first mass moment from the small FK rows
    fold_mass: np.ndarray  # (Na,) folded mass per attach joint [kg]


#: Plans already made, per body model (the studio and long batches solve the same body many times; a plan
#: costs about a millisecond of Python). Weak keys: a plan goes with its body.
_PLANS: weakref.WeakKeyDictionary[BodyModel, dict] = weakref.WeakKeyDictionary()


def _cached_plan(skel: Skeleton, body: BodyModel | None, frozen, w_pos: float, w_rot: np.ndarray,
                 mk_joint: np.ndarray, mk_local: np.ndarray, has_com: bool) -> _Plan:
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


# Long because it builds the component-major index tables of the kernels, each derived from the ones
# before it (needed → active → FK order → DOF columns → marker and COM rows).
def _make_plan(skel: Skeleton, body: BodyModel | None, frozen: list[int], w_pos: float, w_rot: np.ndarray,
               mk_joint: np.ndarray, mk_local: np.ndarray, has_com: bool) -> _Plan:
    J = skel.n_joints
    needed = np.zeros(J, bool)
    needed[0] = True
    if has_com:
        assert body is not None, "a COM task needs the body model"
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
    # Subtrees without an active joint or a marker (the head, the hands when frozen) only add mass at
    # a fixed pose relative to the joint they hang from: they are folded into that joint's mass moment
    # once per chunk (``_fold_moments``) instead of being part of every FK pass.
    steered = active.copy()
    steered[mk_joint] = True
    for j in range(J - 1, 0, -1):
        steered[skel.parents[j]] |= steered[j]
    folded = needed & ~steered if has_com else np.zeros(J, bool)
    # FK joints numbered depth by depth (then in skeleton order): each depth is a contiguous block of
    # rows, which ``_fk_levels`` writes in place
    depth = np.zeros(J, np.int64)
    for j in range(1, J):
        depth[j] = depth[skel.parents[j]] + 1
    sub = np.flatnonzero(needed & ~folded)
    sub = sub[np.argsort(depth[sub], kind="stable")]
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
        assert body is not None
        seg_all = np.asarray(body.seg_joint, np.int64)
        seg_local, seg_mass = np.asarray(body.seg_local, float), np.asarray(body.seg_mass, float)
    else:
        seg_all, seg_local, seg_mass = np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros(0)
    # folded joints: a small skeleton of their own under a fixed root (index 0) standing for the joint
    # they hang from ("attach" joint, in sub numbering)
    fold_depth = np.zeros(J, np.int64)  # depth below the attach joint
    for j in range(1, J):
        fold_depth[j] = fold_depth[skel.parents[j]] + 1 if folded[j] else 0
    fold_orig = np.flatnonzero(folded)
    fold_orig = fold_orig[np.argsort(fold_depth[fold_orig], kind="stable")]
    in_fold = -np.ones(J, np.int64)
    in_fold[fold_orig] = 1 + np.arange(len(fold_orig))
    fold_parents = np.zeros(len(fold_orig) + 1, np.int64)
    fold_parents[0] = -1
    attach_of = np.zeros(J, np.int64)  # per folded joint: its attach joint (sub numbering)
    for i, jf in enumerate(fold_orig):
        pj = skel.parents[jf]
        fold_parents[i + 1] = in_fold[pj] if folded[pj] else 0
        attach_of[jf] = attach_of[pj] if folded[pj] else new[pj]
    fold_attach = np.unique(attach_of[fold_orig])
    seg_fold = folded[seg_all]
    seg_joint = np.where(seg_fold, attach_of[seg_all], new[seg_all])  # the FK joint carrying each segment
    m_sub = np.zeros(len(sub))
    np.add.at(m_sub, seg_joint, seg_mass)
    for j in range(len(sub) - 1, 0, -1):
        m_sub[parents[j]] += m_sub[j]
    # per attach joint the folded segments' moment Σ m (R l + p) over the small skeleton's FK rows
    fold_w = np.zeros((len(fold_attach), 3, len(fold_orig) + 1, 12))
    fold_mass = np.zeros(len(fold_attach))
    for seg in np.flatnonzero(seg_fold):
        a, q, m = np.searchsorted(fold_attach, seg_joint[seg]), in_fold[seg_all[seg]], seg_mass[seg]
        fold_mass[a] += m
        for r in range(3):
            fold_w[a, r, q, 3 * r:3 * r + 3] += m * seg_local[seg]
            fold_w[a, r, q, 9 + r] += m
    mk_order = np.array(order, np.int64)
    # Task points are linear in a joint's FK rows (R row-major, then P): x = R l + p. Per joint, the
    # own segments' mass moment Σ m (p + R l) = W_own [R; p]; per marker W_mk [R; p].
    Jn = len(sub)
    w_own = np.zeros((Jn, 3, 12))
    for seg in np.flatnonzero(~seg_fold):
        j, m = seg_joint[seg], seg_mass[seg]
        for r in range(3):
            w_own[j, r, 3 * r:3 * r + 3] += m * seg_local[seg]
            w_own[j, r, 9 + r] += m
    w_com = w_own.copy()
    for a, m in zip(fold_attach, fold_mass):  # the folded segments' m_a p_a (their R_a v_a varies per frame)
        w_com[a, :, 9:] += m * np.eye(3)
    w_com = np.ascontiguousarray(w_com.transpose(1, 0, 2).reshape(3, 12 * Jn))
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
    fk_frozen = np.setdiff1d(np.arange(Jn), new[act_orig])
    lrow = np.empty(Jn, np.int64)
    lrow[new[act_orig]] = np.arange(K)
    lrow[fk_frozen] = K + np.arange(len(fk_frozen))
    fk_levels = _depth_levels(parents, np.asarray(skel.offsets, float)[sub], lrow)
    fold_offsets = np.concatenate([np.zeros((1, 3)), np.asarray(skel.offsets, float)[fold_orig]])
    fold_levels = _depth_levels(fold_parents, fold_offsets, np.arange(len(fold_parents)))
    cyc_rows = np.concatenate([3 * g.joints[:, None, None] + _CYC for g in groups])
    ends = np.cumsum([len(g.joints) for g in groups])
    cyc_spans = tuple(slice(int(e - len(g.joints)), int(e)) for g, e in zip(groups, ends))
    return _Plan(
        sub, parents, np.asarray(skel.offsets)[sub], new[act_orig], act_orig, 1.0 / w_rot[act_orig], 1.0 / w_pos,
        seg_joint, seg_local, seg_mass, m_sub, has_com, mk_order,
        new[np.asarray(mk_joint, np.int64)[mk_order]] if len(mk_order) else np.zeros(0, np.int64),
        np.asarray(mk_local, float)[mk_order] if len(mk_order) else np.zeros((0, 3)),
        tuple(groups), tuple(pairs), w_own, w_com, w_mk, subtree, cyc_rows, cyc_spans, fk_frozen, fk_levels,
        fold_orig, fold_levels, fold_attach, fold_w.reshape(3 * len(fold_attach), 12 * (len(fold_orig) + 1)),
        fold_mass,
    )


# ---- one chunk of frames -----------------------------------------------------------------------------
def _depth_levels(parents: np.ndarray, offsets: np.ndarray, lrow: np.ndarray) -> tuple:
    """Joints by depth below the root, for ``_fk_levels``: per depth (its joints as a slice: the joints must
    be numbered depth by depth, their parents, their rows in the local rotation store (``lrow``), both as
    slices where consecutive, their offsets (m, 3) [m]). All joints of one depth are one batch of array
    operations (their parents are done): ~7 batches instead of ~20 joints' worth of small ones."""
    parents = np.asarray(parents)
    depth = joint_depths(parents)
    if np.any(np.diff(depth) < 0):
        raise ValueError("joints must be numbered depth by depth")
    levels = []
    for d in range(1, int(depth.max(initial=0)) + 1):
        js = np.flatnonzero(depth == d)
        levels.append((_as_slice(js), _as_slice(parents[js]), _as_slice(np.asarray(lrow)[js]),
                       np.ascontiguousarray(np.asarray(offsets, float)[js])))
    return tuple(levels)


def _as_slice(idx: np.ndarray):
    """Indices idx as a slice when they are consecutive (indexing then gives a view, not a copy)."""
    idx = np.asarray(idx, np.int64)
    if len(idx) and np.all(np.diff(idx) == 1):
        return slice(int(idx[0]), int(idx[-1]) + 1)
    return idx


def _fk_levels(T: np.ndarray, L: np.ndarray, levels: tuple, tr_T: np.ndarray | None = None) -> None:
    """Forward kinematics below the root, in place: T (J, 12, n) world rows (rotation row-major, then
    position [m]) from the root's rows T[0], the local rotation rows L (9, ·, n) and ``_depth_levels``;
    tr_T: per-frame local translations (J, 3, n) [m] instead of the offsets. Each depth is two einsums
    written straight into its block of T: the rotations R_j = R_p B_j (sums over k = 0, 1, 2 in order, as
    fk_soa's) and the positions p_j = R_p o_j + p_p."""
    n = T.shape[2]
    for js, ps, rows, off in levels:
        m = len(off)
        A = T[ps, :9].reshape(m, 3, 3, n)  # the parents' world rotations (a view or a gathered copy)
        B = L[:, rows].reshape(3, 3, m, n)  # the joints' local rotations
        np.einsum("mrkf,kcmf->mrcf", A, B, out=T[js, :9].reshape(m, 3, 3, n))
        P = T[js, 9:]
        if tr_T is None:
            np.einsum("mrkf,mk->mrf", A, off, out=P)
        else:
            np.einsum("mrkf,mkf->mrf", A, tr_T[js], out=P)
        P += T[ps, 9:]


class _FK:
    """``kinematics.fk_soa`` with buffers kept across the iterations of a chunk: the outputs are written in
    place (fresh multi-megabyte arrays every iteration cost as much in page faults as the arithmetic) and
    the local rotation matrices of frozen joints, which never change, are converted once. Joints of one
    depth are one batch (``_fk_levels``) and the active joints' local rotations are converted in one batch
    from (4, K, F) quaternion rows. Same rotations as fk_soa entry for entry; positions sum the same terms
    in another order (checked against it in the tests).

    Outputs live in one (Jn, 12, F) array T: rows 0-8 the world rotation (row-major), rows 9-11 the
    world position [m], so task points and mass moments are small matrix products over T's rows.
    """

    def __init__(self, plan: _Plan, rot_T: np.ndarray, extra: Sequence[tuple[str, int]] = (),
                 fold: np.ndarray | None = None):
        Jn, F = len(plan.parents), rot_T.shape[-1]
        self.fold = fold  # (Na, 3, F) ``_fold_moments`` of the frames (needed by _evaluate when the plan folds)
        #: (Jn, 3, F) each FK joint's own segments' first mass moment [kg m], set by ``_evaluate(moments=True)``
        self.s_own: np.ndarray | None = None
        K = len(plan.act)
        self.plan = plan
        self.F = F
        self.K = K
        self.n: int = F  # frames of the current working set (``_view``)
        # Local rotations of all FK joints in one (9, K + frozen, F) store, entry-major so that each
        # conversion step writes one contiguous block: the active joints first (rewritten every call), then
        # the frozen ones (converted once); plan.fk_levels index it.
        fro = plan.fk_frozen
        # One work area for the whole chunk (FK outputs and temporaries, plus the ``extra`` (name, rows)
        # areas of the caller: the system matrix, ...), each region re-viewed contiguous over its first
        # n frames when the working set shrinks. One allocation instead of a dozen: freshly mapped memory
        # costs a page fault per 4 kB, as much as the arithmetic on it.
        regions = [("T", Jn * 12), ("L", 9 * (K + len(fro))), ("tq", 3 * K)]
        regions += list(extra)
        self._work = np.empty(sum(r for _, r in regions) * F)
        self._regions, off = {}, 0
        for name, r in regions:
            self._regions[name] = (off, r)
            off += r * F
        self._view(F)
        if len(fro):  # all frozen joints in one batch: (4, f, F) rows -> (9, f, F) rows
            _quat_rows(rot_T[fro].transpose(1, 0, 2), self.L[:, K:], np.empty((3, len(fro), F)))

    def area(self, name: str, shape: tuple[int, ...]) -> np.ndarray:
        """The work area ``name`` as a contiguous (*shape, n) array over the current n frames."""
        off, rows = self._regions[name]
        n = self.n
        size = int(np.prod(shape, dtype=np.int64)) * n
        assert size <= rows * self.F
        return self._work[off:off + size].reshape(*shape, n)

    def _view(self, n: int) -> None:
        Jn, K = len(self.plan.parents), len(self.plan.act)
        self.n = n
        self.T = self.area("T", (Jn, 12))
        self.L = self.area("L", (9, Jn))
        self.tq = self.area("tq", (3, K))

    @property
    def P(self) -> np.ndarray:
        return self.T[:, 9:12]

    @property
    def R(self) -> np.ndarray:
        return self.T[:, :9]

    def compact(self, keep: np.ndarray) -> None:
        """Keep only the frames ``keep`` (the working set shrank)."""
        frozen = self.L[:, self.K:][:, :, keep]  # a copy: the store is re-viewed over fewer frames below
        self._view(len(keep))
        self.L[:, self.K:] = frozen
        if self.fold is not None:
            self.fold = self.fold[:, :, keep]

    def __call__(self, root_T, rot_T, tr_T, q_act=None):
        """FK of the plan's joints: P (Jn, 3, F) [m], R (Jn, 9, F) (views of ``T``). The active joints'
        local rotations come from ``q_act`` (4, K, F) when given, else from rot_T (Jn, 4, F); tr_T: per-frame
        local translations (Jn, 3, F) [m] or None (the skeleton's offsets)."""
        plan, T, L = self.plan, self.T, self.L
        if q_act is None:
            q_act = rot_T[plan.act].transpose(1, 0, 2)
        _quat_rows(q_act, L[:, :self.K], self.tq)
        T[0, :9] = L[:, 0]  # the root is active joint 0
        T[0, 9:] = root_T
        _fk_levels(T, L, plan.fk_levels, tr_T)
        return self.P, self.R


def _evaluate(plan: _Plan, root_T, rot_T, tr_T, fk: _FK, q_act=None, moments: bool = True):
    """FK of the needed joints and the task points (``fk``: the chunk's _FK, with its kept buffers and, when
    the plan folds joints, their ``_fold_moments``).

    Returns P (Jn, 3, F), R (Jn, 9, F) and x (npts, 3, F) task points (COM first) [m]. With a ComTask and
    ``moments``, ``fk.s_own`` (Jn, 3, F) holds each joint's own (and folded) segments' first mass moment
    [kg m] at this pose (``_linearize`` needs them); without, the COM is one matrix product.
    """
    P, R = fk(root_T, rot_T, tr_T, q_act)
    T = fk.T
    Jn, _, F = T.shape
    npts = (1 if plan.has_com else 0) + len(plan.mk_joint)
    x = np.empty((npts, 3, F))
    if plan.has_com:
        a = plan.fold_attach
        if moments:
            s_own = fk.area("s_own", (Jn, 3)) if "s_own" in fk._regions else None
            own = fk.s_own = np.matmul(plan.w_own, T, out=s_own)  # (Jn, 3, F): one stacked matrix product
            if len(a):  # folded subtrees: R_a v_a + m_a p_a at their attach joints a
                assert fk.fold is not None  # a plan that folds gets the fold moments
                fold = np.einsum("arcf,acf->arf", T[a, :9].reshape(len(a), 3, 3, F), fk.fold)
                fold += plan.fold_mass[:, None, None] * T[a, 9:]
                own[a] += fold
            np.add.reduce(own, axis=0, out=x[0])
        else:  # Σ_j W_own,j T_j + Σ_a m_a p_a in one product, plus Σ_a R_a v_a
            np.matmul(plan.w_com, T.reshape(Jn * 12, F), out=x[0])
            if len(a):
                assert fk.fold is not None  # a plan that folds gets the fold moments
                x[0] += np.einsum("arcf,acf->rf", T[a, :9].reshape(len(a), 3, 3, F), fk.fold)
        x[0] *= 1.0 / plan.m_sub[0]
    if len(plan.mk_joint):  # the markers: one stacked matrix product over their joints' FK rows
        np.matmul(plan.w_mk, T[plan.mk_joint], out=x[npts - len(plan.mk_joint):])
    return P, R, x


def _fold_moments(plan: _Plan, rotations: np.ndarray, translations: np.ndarray | None) -> np.ndarray | None:
    """(Na, 3, f) first mass moment [kg m] of the folded subtrees hanging from each of ``plan.fold_attach``,
    in that joint's frame (their joints keep the input rotations, so it is fixed per frame).
    rotations: (f, J, 4) input rotations; translations: (f, J, 3) local translations [m] or None."""
    n = len(plan.fold_orig)
    if not n:
        return None
    f = rotations.shape[0]
    L = np.empty((9, n + 1, f))  # local rotation rows of the small skeleton (joint 0 unused)
    q = np.ascontiguousarray(np.take(rotations, plan.fold_orig, axis=1).transpose(2, 1, 0))  # (4, n, f) rows
    _quat_rows(q, L[:, 1:], np.empty((3, n, f)))
    T = np.empty((n + 1, 12, f))
    T[0] = np.array([1.0, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0])[:, None]  # the attach joint's own frame
    tr = None
    if translations is not None:
        tr = np.zeros((n + 1, 3, f))
        tr[1:] = np.take(translations, plan.fold_orig, axis=1).transpose(1, 2, 0)
    _fk_levels(T, L, plan.fold_levels, tr)
    return (plan.fold_w @ T.reshape(-1, f)).reshape(-1, 3, f)


def _com_levers(plan: _Plan, P_act, s_own, scale) -> np.ndarray:
    """(K, 3, F) COM levers of the active joints times ``scale`` (F,): (s_k − m_k p_k) / M with s_k the first
    mass moment of joint k's subtree (``kinematics.com_jacobian``'s trick: the cost is O(J F), not O(J S F)).
    P_act: (K, 3, F) the active joints' positions [m]; s_own: (Jn, 3, F) each joint's own (and folded)
    segments' mass moment (``_evaluate``'s)."""
    Jn, _, F = s_own.shape
    out = (plan.subtree @ s_own.reshape(Jn, 3 * F)).reshape(-1, 3, F)
    out -= plan.m_sub[plan.act][:, None, None] * P_act
    out *= scale * (1.0 / plan.m_sub[0])
    return out


@dataclass(frozen=True, eq=False)
class _Lin:
    """A linearisation of the tasks at one pose, reused by the chord steps (frame axis last).

    pairs: per group (g, u, 2, 3, F) the weighted levers ũ as cross-product pairs: [..., 0, a] = ũ[a+2],
        [..., 1, a] = −ũ[a+1] (a = x, y, z, indices mod 3). With vectors v gathered as v[_CYC] (rows
        v[a+1], v[a+2]), one einsum gives Σ_u v_u × ũ_pu (or −Σ_p ũ_pu × v_p) for all three axes [m].
    R: (K, 3, 3, F) world rotations of the active joints.
    L: (m, m, F) the lower Cholesky factor of K' (``_cholesky_soa``; the strict upper triangle is unset).
    inv: (m / 3, 3, 3, F) the inverses of L's 3 × 3 diagonal blocks (``_block_inverses``).
    """

    pairs: list
    R: np.ndarray
    L: np.ndarray
    inv: np.ndarray

    def take(self, keep: np.ndarray) -> _Lin:
        """The frames ``keep``."""
        return _Lin([np.take(c, keep, axis=-1) for c in self.pairs], np.take(self.R, keep, axis=-1),
                    _take_lower(self.L, keep), np.take(self.inv, keep, axis=-1))


def _lin_regions(plan: _Plan, npts: int) -> list[tuple[str, int]]:
    """The work-area regions (name, rows per frame) a linearisation lives in: K' and its factor (m × m), the
    active joints' rotations (9 K), the lever pairs (6 per point and joint of each group) and the factor's
    3 × 3 block inverses (9 per point)."""
    pairs = 6 * sum(len(g.points) * len(g.joints) for g in plan.groups)
    return [("A", 9 * npts * npts), ("Ra", 9 * len(plan.act)), ("pairs", pairs), ("inv", 9 * npts)]


def _linearize(plan: _Plan, P, R, x, sw, s_own=None, fk=None) -> _Lin:
    """Linearise at a pose: per group the weighted levers ũ (as ``_Lin.pairs``), the active joints' world
    rotations and the factorisation of K' = J̃ D⁻¹ J̃ᵀ + I. ``fk``: a _FK whose work area has the regions
    ``_lin_regions`` to hold them (fresh arrays when None). s_own: ``_evaluate``'s mass moments (needed
    with a ComTask)."""
    F = x.shape[2]
    npts = x.shape[0]
    m = 3 * npts
    neg_d = -plan.d_rot
    P_act = P[plan.act]
    levers, neg_dlevers = [], []
    for g in plan.groups:
        if plan.has_com and g.points[0] == 0:
            U = _com_levers(plan, P_act, s_own, sw[0])[None]  # (1, K, 3, F)
        else:
            U = x[g.span][:, None] - P_act[g.joints][None]  # (g, u, 3, F)
            U *= g.mask
            U *= sw[g.span][:, None, None, :]
        levers.append(U)
        neg_dlevers.append(U * neg_d[g.joints][None, :, None, None])
    # K' blocks Σ_k d_k ((ũ_p·ũ_q) I − ũ_q ũ_pᵀ) + d_pos √(w_p w_q) I (+ I on the diagonal), written
    # straight into the lower triangle: rows of group g2, columns of group g1 (g1 <= g2). Every pair of
    # groups shares the root, so the blocks cover the lower triangle (else it starts from zeros).
    ng = len(plan.groups)
    K = len(plan.act)
    n_pairs = dict(_lin_regions(plan, npts))["pairs"]
    if fk is None:
        A = np.zeros((m, m, F))
        Ra = R[plan.act]
        pair_rows = np.empty((n_pairs, F))
        inv = None
    else:  # the chunk's work area: no fresh multi-megabyte arrays per linearisation
        A = fk.area("A", (m, m))
        if len(plan.pairs) < ng * (ng + 1) // 2:
            A.fill(0.0)
        Ra = np.take(R, plan.act, axis=0, out=fk.area("Ra", (K, 9)), mode="clip")  # unbuffered: valid indices
        pair_rows = fk.area("pairs", (n_pairs,))
        inv = fk.area("inv", (npts, 3, 3))
    for g1, g2, i1, i2 in plan.pairs:
        G1, G2 = plan.groups[g1], plan.groups[g2]
        n1, n2 = len(G1.points), len(G2.points)
        V = A[G2.rows, G1.rows].reshape(n2, 3, n1, 3, F)  # V[q, b, p, a]: row (q, b), column (p, a)
        # −Σ_k d_k ũ_q[a] ũ_p[b] over the common joints, then the diagonal a = b gets
        # Σ_k d_k ũ_p·ũ_q (minus the trace of the former) + d_pos √(w_p w_q) (+ 1 for p = q)
        np.einsum("quaf,pubf->qbpaf", neg_dlevers[g2][:, i2], levers[g1][:, i1], out=V)
        diag = sw[G2.span][:, None] * sw[G1.span][None]
        diag *= plan.d_pos
        diag -= V[:, 0, :, 0]
        diag -= V[:, 1, :, 1]
        diag -= V[:, 2, :, 2]
        if g1 == g2:
            diag.reshape(n1 * n1, F)[::n1 + 1] += 1.0
        for c in range(3):
            V[:, c, :, c] += diag
    pairs, row = [], 0
    for U in levers:
        g, u = U.shape[:2]
        cross = pair_rows[row:row + 6 * g * u].reshape(g, u, 2, 3, F)
        row += 6 * g * u
        np.take(U, _CYC[::-1], axis=2, out=cross, mode="clip")  # [ũ[a+2], ũ[a+1]] ...
        np.negative(cross[:, :, 1], out=cross[:, :, 1])  # ... [ũ[a+2], −ũ[a+1]]
        pairs.append(cross)
    L = _cholesky_soa(A)
    return _Lin(pairs, Ra.reshape(K, 3, 3, F), L, _block_inverses(L, inv))


def _step(plan: _Plan, lin: _Lin, e, eps, eps_t, sw):
    """One damped-least-squares step dq = ε + D⁻¹ J̃ᵀ K'⁻¹ W½ (e − J ε) at a linearisation ``lin``.

    e: (npts, 3, F) task errors [m]; eps: (3, K, F) posture errors [rad]; eps_t: (3, F) root position
    error [m]; sw: (npts, F) square-root task weights. Returns dl (3, K, F) local rotation increments
    [rad] and dt (3, F) root translation increment [m].
    """
    K = len(plan.act)
    npts, _, F = e.shape
    rhs = e * sw[:, None, :] if eps is None else (e - eps_t[None]) * sw[:, None, :]
    if eps is not None:
        # J̃ ε = Σ_u (R_u ε_u) × ũ_pu: world posture rotations, then one contraction per group
        w = np.einsum("krcf,ckf->krf", lin.R, eps)
        wc = np.take(w.reshape(3 * K, F), plan.cyc_rows, axis=0)  # (Σu, 2, 3, F) as ``_Lin.pairs`` needs
        for g, c, span in zip(plan.groups, lin.pairs, plan.cyc_spans):
            rhs[g.span] -= np.einsum("usaf,pusaf->paf", wc[span], c)
    z = _cho_solve_soa(lin.L, lin.inv, rhs.reshape(-1, F))
    # J̃ᵀ z: world torque-like ω_u = Σ_p ũ_pu × z_p (the contraction gives −ω), then to local axes
    zc = np.take(z, 3 * np.arange(npts)[:, None, None] + _CYC, axis=0)  # (npts, 2, 3, F)
    neg_omega = np.zeros((K, 3, F))
    for g, c in zip(plan.groups, lin.pairs):
        o = np.einsum("pusaf,psaf->uaf", c, zc[g.span])
        for dst, src in g.runs:
            neg_omega[dst] += o[src]
    dl = np.einsum("kbcf,kbf->ckf", lin.R, neg_omega)
    dl *= -plan.d_rot[None, :, None]
    dt = np.einsum("paf,pf->af", z.reshape(npts, 3, F), sw)
    dt *= plan.d_pos
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
        np.take(L[r, :r + 1], keep, axis=1, out=out[r, :r + 1], mode="clip")  # unbuffered: valid indices
    return out


# Long because the Gauss-Newton iteration (linearise, factorise, step, compact the working set) shares
# its in-place buffers between stages; split, every stage would take a dozen arrays.
def _solve_chunk(plan: _Plan, root_T, rot_T, tr_T, ref_root_T, ref_act, target, sw,
                 tol: float, step_tol: float, max_iters: int, max_step: float, refresh: bool,
                 start_is_reference: bool = False, q_start=None, fold=None):
    """Gauss-Newton on one chunk, in place on root_T (3, F).

    rot_T: (Jn, 4, F) input rotations of the FK joints (any strides; read only: the frozen joints' are
    used, and the active joints' when ``q_start`` (4, K, F) is None). ref_act: (4, K, F) reference
    rotations of the active joints; target: (npts, 3, F) task targets [m]; sw: (npts, F) square-root
    weights. A frame stops when every weighted task point is within ``tol`` [m] of its target, or when its
    step is below ``step_tol``. The first step linearises at the warm start; later steps reuse that
    factorisation (a chord / modified Gauss-Newton iteration) unless ``refresh``. Frames that have stopped
    drop out of the working set (compacted when at most three quarters remain), so late iterations cost in
    proportion to the frames that still need them. fold: (Na, 3, F) ``_fold_moments`` (None when the plan
    folds no joint). Returns iterations (F,), converged (F,), the final task points (npts, 3, F), the
    largest active-joint deviation (F,) [rad] and the active joints' rotations (4, K, F).
    """
    F = root_T.shape[1]
    K = len(plan.act)
    npts = target.shape[0]
    iterations = np.zeros(F, np.int64)
    converged = np.zeros(F, bool)
    x_final = np.empty_like(target)
    fk = _FK(plan, rot_T, extra=_lin_regions(plan, npts) + [("s_own", 3 * len(plan.parents)), ("qa", 4 * K),
                                                            ("qb", 4 * K), ("ex", 4 * K)], fold=fold)
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
        P, R, x = _evaluate(plan, w_root, None, w_tr, fk, w_q, moments=lin is None or refresh)
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
            lin = lin.take(keep)
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
# Long because it is the public entry: argument and task checks, the plan, the chunk loop and the
# result assembly in the order a reader follows; the numerical work is in _solve_chunk and the kernels.
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
            raise IkError(f"reference motion has {r.n_frames} frames / {r.skeleton.n_joints} joints; "
                          f"expected {F} / {J}")
    # targets and weights, validated once
    com_target = com_w = None
    if com_task is not None:
        com_target = np.asarray(com_task.target, float)
        if com_target.shape != (F, 3):
            raise IkError(f"COM target must be (F, 3) = ({F}, 3); got {com_target.shape}")
        com_w = _rows(com_task.weight, F, (), com_task.name)
    mk_joint = (np.concatenate([np.asarray(t.joints, np.int64).reshape(-1) for t in markers]) if markers
                else np.zeros(0, np.int64))
    mk_local = (np.concatenate([np.asarray(t.p_local, float).reshape(-1, 3) for t in markers]) if markers
                else np.zeros((0, 3)))
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
    for what, given in (("COM target", com_target), ("marker targets", mk_target)):
        if given is not None and not np.all(np.isfinite(given)):
            f = int(np.flatnonzero(~np.all(np.isfinite(given.reshape(F, -1)), axis=1))[0])
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
    trans = motion.translations  # (F, J, 3) or None
    start_is_reference = ref_pose is motion and ref_root is motion
    for a in range(0, F, chunk):
        b = min(F, a + chunk)
        root_T = np.ascontiguousarray(out_root[a:b].T)
        # the FK joints' input rotations as a (Jn, 4, f) view: only the frozen ones are read, once
        rot_T = np.take(motion.rotations[a:b], plan.sub, axis=1).transpose(1, 2, 0)
        tr_T = np.ascontiguousarray(trans[a:b, plan.sub].transpose(1, 2, 0)) if trans is not None else None
        ref_root_T = np.ascontiguousarray(ref_root.root_positions[a:b].T)
        ref_act = _soa_quats(ref_pose.rotations[a:b], plan.act_orig)
        if ref_root is not ref_pose:
            ref_act[:, 0] = ref_root.rotations[a:b, 0].T
        q_start = ref_act if start_is_reference else _soa_quats(motion.rotations[a:b], plan.act_orig)
        target = np.empty((npts, 3, b - a))
        sw = np.empty((npts, b - a))
        if com_target is not None and com_w is not None:
            target[0] = com_target[a:b].T
            sw[0] = np.sqrt(com_w[a:b])
        if mk_target is not None and mk_w is not None:
            target[npts - len(mk_joint):] = mk_target[a:b, plan.mk_order].transpose(1, 2, 0)
            sw[npts - len(mk_joint):] = np.sqrt(mk_w[a:b, plan.mk_order].T)
        its, conv, x, dev, q_act = _solve_chunk(plan, root_T, rot_T, tr_T, ref_root_T, ref_act, target, sw,
                                                tol, step_tol, max_iters, max_step, refresh_jacobian,
                                                start_is_reference, q_start,
                                                _fold_moments(plan, motion.rotations[a:b],
                                                              trans[a:b] if trans is not None else None))
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
    residuals: dict[str, np.ndarray] = {}
    if com_task is not None:
        residuals[com_task.name] = errors[:, 0]
    off = 0
    for t in markers:
        Pm = len(np.asarray(t.joints).reshape(-1))
        residuals[t.name] = errors[:, npts - len(mk_joint) + off:npts - len(mk_joint) + off + Pm].max(axis=1)
        off += Pm
    residuals[posture.name] = posture_dev
    residuals[root.name] = np.linalg.norm(out_root - ref_root.root_positions, axis=1)
    return IkResult(out, ref_pose, iterations, converged, failed, com_err, mk_err, residuals,
                    tuple(skel.names[j] for j in frozen), tuple(int(j) for j in plan.act_orig), com_out)

