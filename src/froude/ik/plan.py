"""The IK problem build: which joints the solver moves or freezes, the DOF weights, and the plan (index
tables of the kernels: needed → active → FK order → DOF columns → marker and COM rows), cached per body."""
from __future__ import annotations

import weakref
from dataclasses import dataclass, field

import numpy as np

from ..body.model import BodyModel
from ..core import quat
from ..core.motion import Motion
from ..core.skeleton import Skeleton
from ..errors import IkError
from .fk import _depth_levels
from .kernels import _CYC
from .tasks import PostureTask, RootTask

#: [rad] a joint whose rotation stays this close to its first frame's through the whole reference is one the
#: reference does not use (frozen by default). Far above the rounding a joint's channels pick up on the way
#: (float32 keys in Blender and FBX: ~1e-6 rad; an exact test froze CMU's LHipJoint in the BVH and moved it,
#: 0.6 mm at the head, in the same clip with its rotations perturbed by 1e-6 rad: issue 26), far below any
#: joint a clip uses (the shared clips' least-moving used joint turns 0.025 rad; unused ones 0 or 3e-8).
UNUSED_JOINT_TOL = 1e-4


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


