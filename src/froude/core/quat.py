"""Quaternions as arrays of shape (..., 4), scalar first: (w, x, y, z). Hamilton product, active rotations.

Every function broadcasts over leading axes. Rotation matrices are (..., 3, 3) and act on column vectors.
Euler angles appear only at the BVH boundary (``from_euler`` / ``to_euler``), composed intrinsically in
the order given (``"zyx"`` means R = Rz(a0) @ Ry(a1) @ Rx(a2)).
"""
from __future__ import annotations

import warnings

import numpy as np

_AXIS_INDEX = {"x": 0, "y": 1, "z": 2}


def identity(shape: tuple[int, ...] = ()) -> np.ndarray:
    """Identity quaternions of shape ``shape + (4,)``."""
    q = np.zeros(tuple(shape) + (4,))
    q[..., 0] = 1.0
    return q


def normalize(q: np.ndarray) -> np.ndarray:
    """Unit quaternions (..., 4)."""
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def conj(q: np.ndarray) -> np.ndarray:
    """Conjugate (= inverse for unit quaternions), (..., 4)."""
    return q * np.array([1.0, -1.0, -1.0, -1.0])


def mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product a ⊗ b, broadcasting (..., 4)."""
    aw, ax, ay, az = a[..., 0], a[..., 1], a[..., 2], a[..., 3]
    bw, bx, by, bz = b[..., 0], b[..., 1], b[..., 2], b[..., 3]
    return np.stack(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ],
        axis=-1,
    )


def rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate vectors v (..., 3) by unit quaternions q (..., 4)."""
    w = q[..., :1]
    u = q[..., 1:]
    t = 2.0 * np.cross(u, v)
    return v + w * t + np.cross(u, t)


def from_axis_angle(axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Quaternion from unit axis (..., 3) and angle (...) [rad]."""
    half = 0.5 * np.asarray(angle)[..., None]
    return np.concatenate([np.cos(half), np.sin(half) * axis], axis=-1)


def from_rotvec(rv: np.ndarray) -> np.ndarray:
    """Quaternion from rotation vectors (..., 3) [rad] (exponential map)."""
    angle = np.linalg.norm(rv, axis=-1)
    half = 0.5 * angle
    # sin(half)/angle with a series expansion near zero (no division by zero)
    small = angle < 1e-8
    scale = np.where(small, 0.5 - angle**2 / 48.0, np.sin(half) / np.where(small, 1.0, angle))
    return np.concatenate([np.cos(half)[..., None], rv * scale[..., None]], axis=-1)


def to_rotvec(q: np.ndarray) -> np.ndarray:
    """Rotation vectors (..., 3) [rad] of unit quaternions (logarithm map, angle in [0, π])."""
    q = np.where(q[..., :1] < 0.0, -q, q)
    v = q[..., 1:]
    s = np.linalg.norm(v, axis=-1)
    angle = 2.0 * np.arctan2(s, q[..., 0])
    small = s < 1e-12
    scale = np.where(small, 2.0, angle / np.where(small, 1.0, s))
    return v * scale[..., None]


def to_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) of unit quaternions (..., 4)."""
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    xx, yy, zz = x * x, y * y, z * z
    xy, xz, yz = x * y, x * z, y * z
    wx, wy, wz = w * x, w * y, w * z
    m = np.empty(q.shape[:-1] + (3, 3))
    m[..., 0, 0] = 1.0 - 2.0 * (yy + zz)
    m[..., 0, 1] = 2.0 * (xy - wz)
    m[..., 0, 2] = 2.0 * (xz + wy)
    m[..., 1, 0] = 2.0 * (xy + wz)
    m[..., 1, 1] = 1.0 - 2.0 * (xx + zz)
    m[..., 1, 2] = 2.0 * (yz - wx)
    m[..., 2, 0] = 2.0 * (xz - wy)
    m[..., 2, 1] = 2.0 * (yz + wx)
    m[..., 2, 2] = 1.0 - 2.0 * (xx + yy)
    return m


def from_matrix(m: np.ndarray) -> np.ndarray:
    """Unit quaternions (..., 4) with w ≥ 0 from rotation matrices (..., 3, 3) (Shepperd's method)."""
    from scipy.spatial.transform import Rotation

    shape = m.shape[:-2]
    xyzw = Rotation.from_matrix(m.reshape(-1, 3, 3)).as_quat()
    q = np.concatenate([xyzw[:, 3:], xyzw[:, :3]], axis=-1).reshape(shape + (4,))
    return np.where(q[..., :1] < 0.0, -q, q)


def from_euler(angles_rad: np.ndarray, order: str) -> np.ndarray:
    """Quaternions (..., 4) from intrinsic Euler angles (..., 3) [rad] composed in ``order`` (e.g. "zyx").

    R = R_{order[0]}(angles[...,0]) @ R_{order[1]}(angles[...,1]) @ R_{order[2]}(angles[...,2]).
    """
    q = None
    for i, axis_name in enumerate(order.lower()):
        axis = np.zeros(3)
        axis[_AXIS_INDEX[axis_name]] = 1.0
        qi = from_axis_angle(axis, angles_rad[..., i])
        q = qi if q is None else mul(q, qi)
    assert q is not None, "order names no axis"
    return q


def to_euler(q: np.ndarray, order: str) -> np.ndarray:
    """Intrinsic Euler angles (..., 3) [rad] in ``order`` of unit quaternions (..., 4).

    The canonical solution: first and last angle in (-π, π], the middle in [-π/2, π/2] for Tait–Bryan
    orders (SciPy's decomposition), which is what motion-capture exporters write.
    """
    from scipy.spatial.transform import Rotation

    shape = q.shape[:-1]
    flat = q.reshape(-1, 4)
    rot = Rotation.from_quat(np.concatenate([flat[:, 1:], flat[:, :1]], axis=-1))
    with warnings.catch_warnings():
        # At gimbal lock SciPy returns a valid decomposition (third angle 0) and warns; a pose with a
        # joint bent exactly 90 degrees is ordinary in animation, so the warning is only noise.
        warnings.filterwarnings("ignore", message="Gimbal lock detected")
        return rot.as_euler(order.upper()).reshape(shape + (3,))


def make_continuous(q: np.ndarray, axis: int = 0) -> np.ndarray:
    """Flip signs along ``axis`` (time) so consecutive quaternions have non-negative dot products.

    q: (F, ..., 4). Returns a new array describing the same rotations, free of sign jumps, which
    interpolation and finite differences need.
    """
    q = np.moveaxis(q, axis, 0)
    dots = np.sum(q[1:] * q[:-1], axis=-1)
    flips = np.concatenate([np.zeros((1,) + dots.shape[1:], bool), dots < 0.0], axis=0)
    sign = np.where(np.cumsum(flips, axis=0) % 2 == 1, -1.0, 1.0)
    return np.moveaxis(q * sign[..., None], 0, axis)


def slerp(q0: np.ndarray, q1: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Spherical interpolation between unit quaternions q0, q1 (..., 4) at fractions t (...) in [0, 1]."""
    t = np.asarray(t, dtype=float)[..., None]
    dot = np.sum(q0 * q1, axis=-1, keepdims=True)
    q1 = np.where(dot < 0.0, -q1, q1)
    dot = np.abs(dot)
    theta = np.arccos(np.clip(dot, -1.0, 1.0))
    sin_theta = np.sin(theta)
    near = sin_theta < 1e-6
    safe = np.where(near, 1.0, sin_theta)
    w0 = np.where(near, 1.0 - t, np.sin((1.0 - t) * theta) / safe)
    w1 = np.where(near, t, np.sin(t * theta) / safe)
    return normalize(w0 * q0 + w1 * q1)


def angle_between(q0: np.ndarray, q1: np.ndarray) -> np.ndarray:
    """Rotation angle (...) [rad] in [0, π] between unit quaternions (..., 4)."""
    dot = np.abs(np.sum(q0 * q1, axis=-1))
    return 2.0 * np.arccos(np.clip(dot, 0.0, 1.0))
