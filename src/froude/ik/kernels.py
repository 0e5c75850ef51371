"""Component-major (SOA) kernels of the IK solver: quaternion products, logs and exponentials, and a batched
3 × 3-block Cholesky factorisation and solve, each NumPy operation on contiguous (F,) rows of a chunk of
frames (the layout of ``core.kinematics.fk_soa``).
"""
from __future__ import annotations

import numpy as np


# ---- component-major (SOA) helpers ---------------------------------------------------------------------
def _qmul_soa(a: np.ndarray, b: np.ndarray, out: np.ndarray | None = None, conj_a: bool = False) -> np.ndarray:
    """Hamilton product of quaternion rows a, b (4, ...) -> (4, ...) (conj(a) b with ``conj_a``), written into
    ``out`` when given (which must not overlap a or b)."""
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    if out is None:
        out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    t = np.empty(out.shape[1:])
    flip = -1 if conj_a else 1  # conj(a) negates the terms of ax, ay, az
    # each row left to right, as written: w = aw bw − ax bx − ay by − az bz, ...
    for o, terms in ((out[0], ((aw, bw, 1), (ax, bx, -flip), (ay, by, -flip), (az, bz, -flip))),
                     (out[1], ((aw, bx, 1), (ax, bw, flip), (ay, bz, flip), (az, by, -flip))),
                     (out[2], ((aw, by, 1), (ax, bz, -flip), (ay, bw, flip), (az, bx, flip))),
                     (out[3], ((aw, bz, 1), (ax, by, flip), (ay, bx, -flip), (az, bw, flip)))):
        np.multiply(terms[0][0], terms[0][1], out=o)
        for u, v, sgn in terms[1:]:
            np.multiply(u, v, out=t)
            if sgn > 0:
                o += t
            else:
                o -= t
    return out


def _log_err_soa(q: np.ndarray, q_ref: np.ndarray) -> np.ndarray:
    """log(q⁻¹ q_ref) for rows (4, ...) -> (3, ...) [rad] (the shorter way round: q and −q are one rotation)."""
    d = _qmul_soa(q, q_ref, conj_a=True)
    w, v = d[0], d[1:]
    s = np.sqrt(np.einsum("a...,a...->...", v, v))
    half = np.arctan2(s, np.abs(w))  # half the angle
    small = s < 1e-12
    if small.any():
        scale = np.where(small, 1.0, half / np.where(small, 1.0, s))
    else:
        scale = np.divide(half, s, out=half)
    scale *= 2.0
    np.negative(scale, out=scale, where=w < 0)
    v *= scale
    return v


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
        if j:  # column j from the diagonal down, less its products with the columns done (one einsum)
            L[j:, j] -= np.einsum("ikf,kf->if", L[j:, :j], L[j, :j])
        d = np.sqrt(L[j, j], out=L[j, j])
        if j < m - 1:
            L[j + 1:, j] /= d
    return L


def _block_inverses(L: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """(nb, 3, 3, F) inverses of the 3 × 3 diagonal blocks of lower Cholesky factors L (3 nb, 3 nb, F): lower
    triangular, from the closed-form inverse of a triangular 3 × 3 matrix, all blocks at once (written into
    ``out`` when given)."""
    nb, F = L.shape[0] // 3, L.shape[2]
    i = 3 * np.arange(nb)
    inv = np.empty((nb, 3, 3, F)) if out is None else out
    inv[:, 0, 1:] = 0.0
    inv[:, 1, 2] = 0.0
    for k in range(3):
        np.divide(1.0, L[i + k, i + k], out=inv[:, k, k])
    inv[:, 1, 0] = -L[i + 1, i] * inv[:, 0, 0] * inv[:, 1, 1]
    inv[:, 2, 1] = -L[i + 2, i + 1] * inv[:, 1, 1] * inv[:, 2, 2]
    inv[:, 2, 0] = -(L[i + 2, i] * inv[:, 0, 0] + L[i + 2, i + 1] * inv[:, 1, 0]) * inv[:, 2, 2]
    return inv


def _cho_solve_soa(L: np.ndarray, inv: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Solve L Lᵀ x = b for (m, m, F) lower factors and (m, F) right-hand sides, by 3 × 3 blocks (one task
    point each; ``inv``: ``_block_inverses(L)``): per block and sweep one einsum against the solved blocks
    and one with the block's inverse, instead of three NumPy calls per row."""
    nb, F = L.shape[0] // 3, b.shape[1]
    r = np.empty((3, F))
    y = np.empty_like(b)
    for B in range(nb):  # L y = b
        s = slice(3 * B, 3 * B + 3)
        if B:
            np.subtract(b[s], np.einsum("ikf,kf->if", L[s, :s.start], y[:s.start]), out=r)
        np.einsum("ikf,kf->if", inv[B], r if B else b[s], out=y[s])
    x = y  # Lᵀ x = y from the bottom up: block B of y is read before it is written
    for B in range(nb - 1, -1, -1):
        s = slice(3 * B, 3 * B + 3)
        if B < nb - 1:
            np.subtract(y[s], np.einsum("kif,kf->if", L[s.stop:, s], x[s.stop:]), out=r)
        else:
            r[:] = y[s]
        np.einsum("kif,kf->if", inv[B], r, out=x[s])
    return x


#: Cyclic axis pairs (a + 1, a + 2) mod 3 for a = x, y, z: gathering a vector's rows with these gives the
#: (2, 3) layout that ``_Lin.pairs`` contracts with (v × u over all three axes in one einsum).
_CYC = np.array([[1, 2, 0], [2, 0, 1]])


