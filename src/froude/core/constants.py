"""Physical and axis conventions, defined once.

Internal units are SI (m, s, kg, rad, N). The world up axis is +Y (BVH, glTF convention).
"""
import numpy as np

from ..errors import FitError

#: Magnitude of gravitational acceleration [m/s^2].
GRAVITY = 9.81
#: Index of the up axis in world coordinates (+Y).
UP_AXIS = 1
#: Indices of the two horizontal world axes (x, z), for ground-plane speeds and distances.
HORIZONTAL_AXES = [a for a in range(3) if a != UP_AXIS]
#: Unit up vector in world coordinates, shape (3,).
UP = np.array([0.0, 1.0, 0.0])
#: Gravity vector in world coordinates [m/s^2], shape (3,).
G_WORLD = -GRAVITY * UP


def heading_frame(heading: np.ndarray) -> np.ndarray:
    """(3, 3) rows forward, up, lateral: unit vectors (world) of the heading frame of a travel direction.

    heading: (3,) any vector with a horizontal part (its vertical part is dropped). lateral = forward × UP,
    the runner's right: the one lateral sign of the package. The rows form a rotation (det +1), so
    ``p_world = p_heading @ frame`` and ``p_heading = p_world @ frame.T``.
    Raises FitError when the heading has no horizontal part.
    """
    fwd = np.asarray(heading, float).copy()
    fwd[UP_AXIS] = 0.0
    n = np.linalg.norm(fwd)
    if not n > 0:
        raise FitError("no horizontal travel direction: cannot define the heading frame")
    fwd /= n
    return np.stack([fwd, UP, np.cross(fwd, UP)])
