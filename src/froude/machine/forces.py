"""Ground force from the motion (Pollard 1999 §4, eq. 1), stance geometry and line-of-action shares.

Differentiation (documented choice, see docs/force_shares.md):

* The whole-body COM (de Leva model) is low-passed with a **2nd-order Butterworth filter run forward
  and backward** (``filtfilt`` here, the same as SciPy's ``sosfiltfilt``: zero lag, effective 4th order, −6 dB at
  ``CUTOFF_HZ`` = 8 Hz), then
  differentiated twice by central differences. 8 Hz is the trade-off measured on the nine running
  clips: lower cutoffs smear the touchdown force rise into the flight phases, higher ones pass the
  capture jitter (the flight residual grows monotonically above 8 Hz; see the docs for the table).
* **Edges**: a zero-lag filter needs data beyond both ends. The clip is extended by
  ``EDGE_PAD_S`` on each side with the quadratic (constant-acceleration) least-squares fit of its first /
  last ``EDGE_FIT_S`` seconds — a ballistic continuation when the clip starts or ends in flight, a
  mild one in stance. (Odd reflection, the usual default, forces a zero acceleration at the edge,
  i.e. a −1 BW force error there.) Stances that touch the clip's edge are flagged partial and never
  used for fitting.
* Eq. 1: f(t) = m (a_com(t) − g) with g = G_WORLD (pointing down), so a body at rest feels +m g.

Events: the marker-threshold contacts of :mod:`froude.body.gait` are ±1–2 frames rough. Each touchdown
and liftoff is refined to the (linearly interpolated) time at which the filtered vertical force
crosses ``EVENT_THRESHOLD_BW`` = 0.5 body weights nearest the marker event (within
``EVENT_SEARCH_S``); if no crossing is found there, the marker event is kept.

Frames: the machine is sagittal. The sagittal plane is spanned by the travel direction ``heading``
(horizontal unit vector, world) and UP; ``lateral`` = heading × UP, the runner's right
(``constants.heading_frame``). Sagittal coordinates: x = (p − origin) · heading, y = p · UP − ground.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..body.com_force import (  # the eq. 1 force's one home is the body layer (the gait decision uses it)
    CUTOFF_HZ,
    EDGE_FIT_S,
    EDGE_PAD_S,
    FILTER_ORDER,
    butter_lowpass,
    filtfilt,
    ground_force,
    smooth_com,
)
from ..core.constants import GRAVITY, UP_AXIS, heading_frame
from ..errors import FitError

__all__ = [
    "CUTOFF_HZ", "FILTER_ORDER", "EDGE_PAD_S", "EDGE_FIT_S", "EVENT_THRESHOLD_BW", "EVENT_SEARCH_S",
    "smooth_com", "ground_force", "butter_lowpass", "filtfilt", "refine_events", "StanceGeometry",
    "stance_geometry", "force_shares", "flight_residual", "ClipCom", "clip_com",
]

@dataclass(frozen=True)
class ClipCom:
    """What both machines' fits measure of a clip first (:func:`clip_com`), SI, world axes.

    times (F,) [s]; p, v (F, 3) the zero-lag filtered COM [m], [m/s]; f (F, 3) the eq. 1 ground force [N];
    heading, lateral (3,) the unit forward and lateral (right) directions of travel.
    """

    times: np.ndarray
    p: np.ndarray
    v: np.ndarray
    f: np.ndarray
    heading: np.ndarray
    lateral: np.ndarray


def clip_com(com: np.ndarray, frame_time: float, mass: float, heading: np.ndarray,
             cutoff_hz: float = CUTOFF_HZ) -> ClipCom:
    """The filtered COM, its eq. 1 force and the heading frame of a clip (the opening of the running and the
    walking fit). com: (F, 3) body COM [m]; frame_time [s]; mass [kg]; heading (3,) the gait's direction of
    travel (``body.gait`` summary); cutoff_hz: the filter's cutoff."""
    p, v, acc = smooth_com(com, frame_time, cutoff_hz)
    fwd, _, lateral = heading_frame(heading)
    return ClipCom(times=np.arange(com.shape[0]) * frame_time, p=p, v=v, f=ground_force(acc, mass), heading=fwd,
                   lateral=lateral)


#: Vertical-force threshold for touchdown / liftoff [body weights].
EVENT_THRESHOLD_BW = 0.5
#: How far from a marker event the force crossing is searched [s].
EVENT_SEARCH_S = 0.1


def _crossing(fy_bw: np.ndarray, lo: int, hi: int, rising: bool, near: float) -> float | None:
    """Fractional frame where fy_bw crosses EVENT_THRESHOLD_BW (rising or falling) in [lo, hi), nearest `near`."""
    lo = max(lo, 0)
    hi = min(hi, fy_bw.shape[0] - 1)
    if hi <= lo:
        return None
    f0 = fy_bw[lo:hi] - EVENT_THRESHOLD_BW
    f1 = fy_bw[lo + 1:hi + 1] - EVENT_THRESHOLD_BW
    hit = (f0 < 0) & (f1 >= 0) if rising else (f0 >= 0) & (f1 < 0)
    idx = np.flatnonzero(hit)
    if idx.size == 0:
        return None
    frac = lo + idx + f0[idx] / (f0[idx] - f1[idx])
    return float(frac[np.argmin(np.abs(frac - near))])


def refine_events(fy_bw: np.ndarray, start: int, stop: int, frame_time: float, partial: bool = False):
    """Force-refined (touchdown, liftoff) of one marker stance [start, stop) as fractional frames.

    fy_bw: (F,) vertical ground force [body weights]. Returns (td, lo, refined_td, refined_lo).
    Touchdown at frame 0 / liftoff at the last frame of a partial stance stay where the clip cuts them.
    """
    w = int(round(EVENT_SEARCH_S / frame_time))
    F = fy_bw.shape[0]
    td = None if start == 0 else _crossing(fy_bw, start - w, start + w, True, start - 0.5)
    lo = None if stop >= F else _crossing(fy_bw, stop - w, stop + w, False, stop - 0.5)
    return (float(start) if td is None else td, float(stop - 1) if lo is None else lo,
            td is not None, lo is not None)


@dataclass(frozen=True)
class StanceGeometry:
    """Measured properties of one stance (SI; times from the clip's first frame).

    foot: 0 left, 1 right; partial: cut by the clip's edge (not used for fits).
    t_touchdown, t_liftoff: force-refined events [s]; duration = t_liftoff − t_touchdown [s].
    frames: (N,) frame indices inside [t_touchdown, t_liftoff] (the samples of the fit).
    ground: ground height under the stance [m]; p_world_contact: (3,) contact point on the ground [m]
        (vertical-force-weighted mean of the foot's lowest marker, dropped to ``ground``).
    tau: (N,) stance phase (t − t_touchdown)/duration [-]; l: (N,) sagittal leg length contact → COM [m];
    f_leg: (N,) measured force along the sagittal leg, + pushing the COM away [N];
    f_world: (N, 3) the measured force [N]; u_world_leg: (N, 3) unit 3-D leg vector contact → COM.
    l0: sagittal leg length at touchdown [m] (interpolated at t_touchdown).
    theta_touchdown, theta_liftoff: sagittal leg angle from vertical [rad], + when the foot is ahead
        of the COM (touchdown > 0, liftoff < 0).
    com_drop: COM height at touchdown − lowest COM height in stance [m].
    peak_vertical_force: [N]. lateral_offset: contact point − mean COM, along ``lateral`` [m].
    """

    foot: int
    partial: bool
    t_touchdown: float
    t_liftoff: float
    frames: np.ndarray
    ground: float
    p_world_contact: np.ndarray
    tau: np.ndarray
    l: np.ndarray
    f_leg: np.ndarray
    f_world: np.ndarray
    u_world_leg: np.ndarray
    l0: float
    theta_touchdown: float
    theta_liftoff: float
    com_drop: float
    peak_vertical_force: float
    lateral_offset: float

    @property
    def duration(self) -> float:
        return self.t_liftoff - self.t_touchdown


def _interp_rows(x: np.ndarray, frac: float) -> np.ndarray:
    """Linear interpolation of rows of x (F, ...) at fractional frame frac."""
    i = int(np.clip(np.floor(frac), 0, x.shape[0] - 2))
    w = frac - i
    return (1 - w) * x[i] + w * x[i + 1]


def stance_geometry(stance, td_frame: float, lo_frame: float, p_world_com: np.ndarray, f_world: np.ndarray,
                    markers: np.ndarray, heading: np.ndarray, lateral: np.ndarray, frame_time: float,
                    com_mean_lateral: float) -> StanceGeometry:
    """Geometry of one stance from fractional touchdown/liftoff frames.

    stance: a gait.Stance (foot, ground, partial); p_world_com (F, 3) smoothed COM [m]; f_world (F, 3) [N];
    markers (F, 2, 3, 3) foot markers [m]; heading, lateral (3,) unit vectors.
    """
    F = p_world_com.shape[0]
    first = int(np.ceil(td_frame - 1e-9))
    last = int(np.floor(lo_frame + 1e-9))
    frames = np.arange(max(first, 0), min(last, F - 1) + 1)
    if frames.size < 4:
        raise FitError(f"stance of the {('left', 'right')[stance.foot]} foot at frame {stance.start} is too "
                       f"short to measure ({frames.size} frames)")
    fy = np.maximum(f_world[frames, UP_AXIS], 0.0)
    mk = markers[frames, stance.foot]  # (N, 3 markers, 3)
    lowest = mk[np.arange(frames.size), np.argmin(mk[..., UP_AXIS], axis=1)]  # (N, 3)
    wsum = fy.sum()
    p_contact = (fy @ lowest) / wsum if wsum > 0 else lowest.mean(axis=0)
    p_contact = p_contact.copy()
    p_contact[UP_AXIS] = stance.ground
    rel = p_world_com[frames] - p_contact  # (N, 3)
    x = rel @ heading
    y = rel[:, UP_AXIS]
    l_sag = np.hypot(x, y)
    f = f_world[frames]
    fx = f @ heading
    f_leg = (fx * x + f[:, UP_AXIS] * y) / l_sag
    u3 = rel / np.linalg.norm(rel, axis=1, keepdims=True)
    rel_td = _interp_rows(p_world_com, td_frame) - p_contact
    rel_lo = _interp_rows(p_world_com, lo_frame) - p_contact
    x_td, y_td = rel_td @ heading, rel_td[UP_AXIS]
    x_lo, y_lo = rel_lo @ heading, rel_lo[UP_AXIS]
    tau = (frames - td_frame) / (lo_frame - td_frame)
    h_td = _interp_rows(p_world_com[:, UP_AXIS], td_frame)
    return StanceGeometry(
        foot=int(stance.foot), partial=bool(stance.partial), t_touchdown=td_frame * frame_time,
        t_liftoff=lo_frame * frame_time, frames=frames, ground=float(stance.ground),
        p_world_contact=p_contact, tau=tau, l=l_sag, f_leg=f_leg, f_world=f, u_world_leg=u3,
        l0=float(np.hypot(x_td, y_td)), theta_touchdown=float(np.arctan2(-x_td, y_td)),
        theta_liftoff=float(np.arctan2(-x_lo, y_lo)),
        com_drop=float(h_td - p_world_com[frames, UP_AXIS].min()),
        peak_vertical_force=float(f[:, UP_AXIS].max()),
        lateral_offset=float(p_contact @ lateral - com_mean_lateral),
    )


def force_shares(stances) -> dict:
    """Share of the measured stance force captured by the two line-of-action models of §4.

    Over the samples of the given (full) stances, with f the measured 3-D force and f_m the model's
    part of it (orthogonal projection on the 3-D leg line contact → COM, or on the vertical):
      share   = 1 − Σ|f − f_m| / Σ|f|      (fraction of the force magnitude left unexplained, removed)
      share_sq = Σ|f_m|² / Σ|f|²           (fraction of the squared force, "variance" share)
    Returns {"leg": share, "vertical": share, "leg_sq": ..., "vertical_sq": ...}.
    """
    f = np.concatenate([s.f_world for s in stances])
    u = np.concatenate([s.u_world_leg for s in stances])
    f_leg = np.sum(f * u, axis=1, keepdims=True) * u
    f_ver = np.zeros_like(f)
    f_ver[:, UP_AXIS] = f[:, UP_AXIS]
    tot = np.linalg.norm(f, axis=1)
    out = {}
    for name, fm in (("leg", f_leg), ("vertical", f_ver)):
        out[name] = float(1.0 - np.linalg.norm(f - fm, axis=1).sum() / tot.sum())
        out[name + "_sq"] = float(np.sum(fm * fm) / np.sum(tot * tot))
    return out


def flight_residual(f_world: np.ndarray, mass: float, flight_mask: np.ndarray) -> float:
    """RMS of |f| over the flight samples [body weights] (0 for a perfect ballistic COM)."""
    if not flight_mask.any():
        return float("nan")
    return float(np.sqrt(np.mean(np.sum(f_world[flight_mask] ** 2, axis=1))) / (mass * GRAVITY))
