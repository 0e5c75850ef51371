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

The parts: the problem build (joint selection, weights, the plan's index tables) in ``ik.plan``, the FK by
tree depth in ``ik.fk``, the batched linear algebra in ``ik.kernels``, the tasks in ``ik.tasks``; this
module linearises, steps and iterates.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from ..body.model import BodyModel
from ..core import quat
from ..core.kinematics import _quat_rows
from ..core.motion import Motion
from ..errors import IkError
from .fk import _FK, _fk_levels
from .kernels import _CYC, _block_inverses, _cho_solve_soa, _cholesky_soa, _exp_soa, _log_err_soa, _qmul_soa, _soa_quats
from .plan import UNUSED_JOINT_TOL, _cached_plan, _Plan, _resolve_frozen, default_frozen_joints, dof_weights
from .tasks import (
    ComTask,
    MarkerTask,
    PostureTask,
    RootTask,
    _rows,
)

__all__ = [
    "ComTask", "MarkerTask", "PostureTask", "RootTask", "IkResult", "solve_ik",
    "default_frozen_joints", "max_joint_step", "dof_weights", "UNUSED_JOINT_TOL",
]

# Defaults of the solver, tuned on the real clips (the task weights' are in ik.tasks).
DEFAULT_TOL = 1e-3  # [m] a frame is done when every COM/marker error is below this ("imperceptible")
DEFAULT_STEP_TOL = 1e-6  # [rad or m] ... or when its largest DOF increment is below this
DEFAULT_MAX_ITERS = 4
DEFAULT_MAX_ERROR = 0.02  # [m] a frame whose COM or marker error stays above this has failed
DEFAULT_MAX_STEP = 0.5  # [rad or m] largest DOF increment applied in one iteration (trust region)
DEFAULT_CHUNK = 2048  # frames processed together (memory stays O(chunk), cache-friendly rows)


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
    return quat.max_step_angle(motion.rotations if joints is None else motion.rotations[:, list(joints)])



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

