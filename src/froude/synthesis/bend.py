"""Bending a straight output back onto the clip's path (issue 28): the machines run along a straightened
take (``body.path.straighten``), and their output's targets are rolled back onto the path, scaled.

A point of the straight output at distance a along its travel direction and offset r (sideways and up)
goes to C(a) + Rot(Δψ(a)) r, where the centreline C turns as the clip's path does: Δψ(a) is the heading
the clip's path has gained at arc length a / L (the path scaled by L about the start; a speed change keeps
it in metres), and C is the integral of the turned travel direction. A point that stays (a planted foot)
stays, so the IK in the world frame plants the feet where the map puts them; the COM's offset from the
path (its sway, its lean into the turn) is turned with the path, so the lateral dynamics are the clip's.
Before the start and past the clip's end the centreline runs straight on.
"""
from __future__ import annotations

from dataclasses import dataclass
from dataclasses import replace as _replace

import numpy as np

__all__ = ["Centreline", "bend", "bend_points"]

from ..body.path import TakePath, yaw_quat
from ..constants import UP, UP_AXIS
from ..core import quat
from .targets import Targets
from .timewarp import MachinePath


@dataclass(frozen=True)
class Centreline:
    """The output's path: a_m (K,) arc length [m]; dpsi_rad (K,) heading gained there [rad] (+ = left);
    p_world (K, 3) its points (height 0) from origin; fwd0 (3,) the straight output's travel direction."""

    a_m: np.ndarray
    dpsi_rad: np.ndarray
    p_world: np.ndarray
    fwd0: np.ndarray

    @staticmethod
    def of(clip: TakePath, L: float, origin: np.ndarray, fwd0: np.ndarray) -> Centreline:
        """The clip's path scaled by L, starting at origin (3,) [m] along fwd0 (3,) (the straight output's)."""
        s = np.maximum.accumulate(clip.arc_length_m)
        keep = np.concatenate([[True], np.diff(s) > 0])  # strictly increasing for the interpolation
        a = L * s[keep]
        dpsi = (clip.heading_rad - clip.heading_rad[0])[keep]
        dirs = quat.rotate(yaw_quat(dpsi), np.broadcast_to(fwd0, (a.size, 3)))
        steps = 0.5 * (dirs[1:] + dirs[:-1]) * np.diff(a)[:, None]  # trapezoid
        p = np.concatenate([np.zeros((1, 3)), np.cumsum(steps, axis=0)]) + origin * (1 - UP)
        return Centreline(a, dpsi, p, fwd0)

    def at(self, a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(point (..., 3) [m], heading gained (...,) [rad]) at arc lengths a (...) [m], straight beyond."""
        a = np.asarray(a, float)
        dpsi = np.interp(a, self.a_m, self.dpsi_rad)
        base = np.stack([np.interp(np.clip(a, self.a_m[0], self.a_m[-1]), self.a_m, self.p_world[:, k])
                         for k in range(3)], axis=-1)
        over = a - np.clip(a, self.a_m[0], self.a_m[-1])  # < 0 before the start, > 0 past the end
        d = quat.rotate(yaw_quat(dpsi), np.broadcast_to(self.fwd0, a.shape + (3,)))
        return base + over[..., None] * d, dpsi


def bend_points(x: np.ndarray, line: Centreline, origin: np.ndarray) -> np.ndarray:
    """(..., 3) straight-output points [m] (NaN kept) moved onto the centreline (see the module)."""
    rel = x - origin * (1 - UP)
    a = rel @ line.fwd0
    r = rel - a[..., None] * line.fwd0
    r[..., UP_AXIS] = x[..., UP_AXIS]
    finite = np.isfinite(a)
    out = np.full_like(x, np.nan)
    c, dpsi = line.at(a[finite])
    out[finite] = c * (1 - UP) + quat.rotate(yaw_quat(dpsi), r[finite])
    return out


def bend(targets: Targets, path: MachinePath, clip: TakePath, L: float,
         origin: np.ndarray) -> tuple[Targets, MachinePath]:
    """The straight output's IK targets and machine path rolled onto the clip's path scaled by L.

    COM, foot markers, the machine's COM and contact points are moved point by point; the initial motion's
    pose (the IK's start and the pose it is pulled toward) is moved rigidly with its COM target, turned
    by the heading gained there. origin: (3,) [m] where the straight output starts (``Prepared.origin``).
    """
    line = Centreline.of(clip, L, origin, path.frame[0])
    com = bend_points(targets.com, line, origin)
    markers = bend_points(targets.markers, line, origin)
    init = targets.initial
    # the pose moved rigidly with its COM target: turned by the heading gained there, about it (a rig's root
    # may lie far from the body: Bandai's joint_Root, 2.4 m ahead of the COM in a straightened turn)
    _, dpsi = line.at((targets.com - origin * (1 - UP)) @ line.fwd0)
    q = yaw_quat(dpsi)
    root = com + quat.rotate(q, init.root_positions - targets.com)
    rot = init.rotations.copy()
    rot[:, 0] = quat.mul(q, rot[:, 0])
    initial = _replace(init, root_positions=root, rotations=rot)
    new_targets = _replace(targets, com=com, markers=markers, initial=initial)
    new_path = _replace(path, com=bend_points(path.com, line, origin),
                        contacts=bend_points(path.contacts, line, origin))
    return new_targets, new_path


