"""Physical and axis conventions, defined once.

Internal units are SI (m, s, kg, rad, N). The world up axis is +Y (BVH, glTF convention).
"""
import numpy as np

#: Magnitude of gravitational acceleration [m/s^2].
GRAVITY = 9.81
#: Index of the up axis in world coordinates (+Y).
UP_AXIS = 1
#: Unit up vector in world coordinates, shape (3,).
UP = np.array([0.0, 1.0, 0.0])
#: Gravity vector in world coordinates [m/s^2], shape (3,).
G_WORLD = -GRAVITY * UP
