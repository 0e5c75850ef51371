"""The geometry of a walk's foot contacts, as the walking fit (:mod:`froude.machine.walk_fit`) measures them.

A walking foot rolls: the centre of pressure travels from the heel to the toes. Each stance's contact is the
least-squares line x_touchdown + roll·τ through the foot's lowest marker (τ = 0 … 1 over the stance); the
touchdown leg length and angle are the COM's distance and direction from the touchdown point.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..core.constants import UP_AXIS

__all__ = ["WalkStance", "measure_stance"]


@dataclass(frozen=True)
class WalkStance:
    """One foot contact of a walk (SI, sagittal; times from the clip's first frame).

    foot 0 left / 1 right; partial: cut by the clip's edge; t_touchdown, t_liftoff [s] (marker events,
    see module doc); ground [m]; the centre of pressure rolls along the line x_touchdown + roll·τ [m]
    (least squares of the foot's lowest marker over the stance, τ = 0 … 1); l0: COM distance from the
    touchdown point at touchdown [m]; theta_touchdown: leg angle from vertical there [rad], + ahead.
    """

    foot: int
    partial: bool
    t_touchdown: float
    t_liftoff: float
    ground: float
    x_touchdown: float
    roll: float
    l0: float
    theta_touchdown: float

    @property
    def duration(self) -> float:
        return self.t_liftoff - self.t_touchdown

    def contact_x(self, t):
        """Centre of pressure [m] (forward) at times t [s]."""
        return self.x_touchdown + self.roll * (np.asarray(t, float) - self.t_touchdown) / self.duration


def measure_stance(st, td, lo, x_fwd, y_com, markers, heading, dt) -> WalkStance:
    """Geometry of one marker stance [td, lo] (fractional frames); x_fwd, y_com (F,) COM [m]."""
    frames = np.arange(int(math.ceil(td)), int(math.floor(lo)) + 1)
    mk = markers[frames, st.foot]  # (N, 3 markers, 3)
    low = mk[np.arange(frames.size), np.argmin(mk[..., UP_AXIS], axis=1)] @ heading
    tau = (frames - td) / (lo - td)
    roll, x0 = np.polyfit(tau, low, 1)
    fr = np.arange(x_fwd.size)
    rx = x0 - np.interp(td, fr, x_fwd)
    ry = np.interp(td, fr, y_com) - st.ground
    return WalkStance(foot=int(st.foot), partial=bool(st.partial), t_touchdown=td * dt, t_liftoff=lo * dt,
                      ground=float(st.ground), x_touchdown=float(x0), roll=float(roll), l0=float(np.hypot(rx, ry)),
                      theta_touchdown=float(np.arctan2(rx, ry)))
