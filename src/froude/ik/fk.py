"""The IK's FK kernel: forward kinematics by tree depth on the component-major rows of a chunk of frames, with
buffers kept across the iterations (``_FK``)."""
from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from ..core.kinematics import _depth_batches, _quat_rows, joint_depths

if TYPE_CHECKING:  # the plan module builds its FK levels here: the type only, no import circle
    from .plan import _Plan


# ---- FK by tree depth ---------------------------------------------------------------------------------
def _depth_levels(parents: np.ndarray, offsets: np.ndarray, lrow: np.ndarray) -> tuple:
    """Joints by depth below the root, for ``_fk_levels``: per depth (its joints as a slice: the joints must
    be numbered depth by depth, their parents, their rows in the local rotation store (``lrow``), both as
    slices where consecutive, their offsets (m, 3) [m]). All joints of one depth are one batch of array
    operations (their parents are done): ~7 batches instead of ~20 joints' worth of small ones."""
    if np.any(np.diff(joint_depths(np.asarray(parents))) < 0):
        raise ValueError("joints must be numbered depth by depth")
    return tuple((_as_slice(js), _as_slice(ps), _as_slice(np.asarray(lrow)[js]),
                  np.ascontiguousarray(np.asarray(offsets, float)[js])) for js, ps in _depth_batches(parents))


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


