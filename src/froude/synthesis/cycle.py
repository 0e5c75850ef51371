"""The reference stride cycle: one seamless stride of the clip, sampled by stride phase, that the machine's
trajectory plays back (``synthesis.timewarp``) and the IK targets are built from (``synthesis.targets``).

The reference clip (1.5-2 strides) is turned into one seamless stride cycle: every frame gets a stride
phase ψ from its foot events (touchdown of foot A at ψ = 0, liftoff of A, touchdown of B, liftoff of B,
touchdown of A at ψ = 1), and each quantity of the cycle at phase φ is the weighted mean of all the
clip's occurrences of that phase (φ, φ + 1, …), with a linear loop-closure correction so that the end
joins the start exactly. Output frames are mapped to phases stance→stance and flight→flight with the
machine's own durations (the paper's time warp), so any number of strides can be synthesised. The foot
events and phases are ``synthesis.phases``'s; the feet of the cycle (contacts, anchors, de-skating)
``synthesis.feet``'s.

Coordinates of the cycle are expressed in the *heading frame* (forward, up, lateral) so that the machine,
which lives in the sagittal plane, can be placed back in the world.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..body.gait import Gait
from ..body.model import BodyModel
from ..core import quat
from ..core.constants import UP_AXIS, heading_frame
from ..core.motion import Motion, max_joint_jump_deg
from ..errors import FitError
from .feet import contact_mask, contact_phases, foot_anchors, held_feet, rest_above
from .phases import FootEvent, event_phases, events_from_gait, loaded_events, phase_of_events, stride_durations

#: Stride-phase samples of the cycle (per stride). 240 keeps interpolation error far below a millimetre.
CYCLE_SAMPLES = 240


@dataclass(frozen=True)
class ReferenceCycle:
    """One seamless stride of the reference, sampled at K = CYCLE_SAMPLES stride phases φ = k / K.

    first_foot: foot A (0 left, 1 right) whose touchdown is φ = 0; foot B = 1 − A.
    phase_events: (4,) φ of [touchdown A, liftoff A, touchdown B, liftoff B] (the machine's force-based
        events; touchdown A = 0; in a walk B lifts after A lands, so 0 < liftoff B < touchdown B < liftoff A).
    contact_phase: (2, 2) stride phases [on, off] of each foot's ground contact as the markers see it
        (left, right); slightly wider than the force-based stance, unwrapped so that on < off.
    durations: (4,) reference durations [s] between the stride's events in ``order``: running stance A,
        flight after A, stance B, flight after B; walking double support, single support on A, double
        support, single support on B.
    order: "running" or "walking" (``EVENT_ORDERS``).
    frame: (3, 3) heading frame rows (forward, up, lateral) in world coordinates.
    rotations: (K, J, 4) local joint rotations (root orientation in world).
    root_from_com: (K, 3) root − COM [m], heading frame.
    com_height: (K,) COM height above the ground [m]; com_forward: (K,) COM forward position minus
        uniform motion at the mean speed [m]; com_lateral: (K,) lateral COM sway about the mean line [m].
    marker_rel: (K, 2, 3, 3) foot markers relative to each foot's anchor [m], heading frame (the anchor is
        the stance's contact point on the ground, or in swing a minimum-jerk blend of the previous and next
        contact points), with sliding of loaded markers removed.
    marker_from_com: (K, 2, 3, 3) foot markers relative to the COM (forward, lateral) and above the ground
        (up) [m], heading frame: how the swinging foot moves with the body.
    contact_lateral: (2,) lateral offset of each foot's contacts from the COM line [m].
    speed: mean forward speed [m/s]; stride_time [s]; leg_length [m]; ground [m].
    max_joint_jump_deg: the reference clip's own largest frame-to-frame joint rotation [deg].
    """

    first_foot: int
    phase_events: np.ndarray
    contact_phase: np.ndarray
    durations: np.ndarray
    frame: np.ndarray
    rotations: np.ndarray
    root_from_com: np.ndarray
    com_height: np.ndarray
    com_forward: np.ndarray
    com_lateral: np.ndarray
    marker_rel: np.ndarray
    marker_from_com: np.ndarray
    contact_lateral: np.ndarray
    speed: float
    stride_time: float
    leg_length: float
    ground: float
    max_joint_jump_deg: float
    order: str = "running"
    #: how far [m] ``ground`` (the median of the stances' own grounds, each its lowest marker's lowest
    #: height: the level the cycle's heights and the machine's COM are above) is above the clip's floor
    #: (``metrics.floor_height``): an output is raised by it × L, to stand on its floor as the clip does
    floor_clearance: float = 0.0
    #: (2, 3) [m] how high each foot marker rests in the clip's stances above ``ground`` (``rest_above``):
    #: where an output's foot targets rest, × L (``synthesis.targets``); None: not known
    rest_heights: np.ndarray | None = None

    @property
    def n_samples(self) -> int:
        return self.rotations.shape[0]


def extract_cycle(
    motion: Motion,
    body: BodyModel,
    gait: Gait,
    com: np.ndarray,
    markers: np.ndarray,
    events: list[FootEvent] | None = None,
    n_samples: int = CYCLE_SAMPLES,
    order: str = "running",
) -> ReferenceCycle:
    """Build the seamless reference stride cycle of a running or walking clip.

    com: (F, 3) [m]; markers: (F, 2, 3, 3) [m]; events: foot events (the fit's force-refined events are
    the most precise; default: a run's load events, ``loaded_events``, else the gait's marker contacts);
    order: "running" or "walking", the order of the foot events in a stride (``EVENT_ORDERS``).
    """
    F, dt = motion.n_frames, motion.frame_time
    if events is None:
        events = (loaded_events(gait, com, dt) if order == "running" else None) or events_from_gait(gait)
    first_foot, dur, phase_events, psi = _stride_phases(events, F, dt, order)
    T = float(dur.sum())
    t = np.arange(F, dtype=float) * dt
    Rh, com_h, speed, lat_line = _heading_measures(com, t)
    ground = float(np.nanmedian(_stance_grounds(gait, F)))
    clearance, rest = rest_above(gait, markers, body.leg_length, ground)

    # Per-frame anchors of each foot: stance contact point or a min-jerk blend between contacts, over one
    # stride along the heading [m]; a walk's swings between its sub-frame events, as its machine's (a run's
    # output swings between the cycle's marker contact phases, which are sample-rounded: left as they were)
    anchors, anchor_ok = foot_anchors(gait, psi, speed * T * Rh[0], F, subframe=order == "walking")
    rel = np.einsum("ij,fpkj->fpki", Rh, markers - anchors[:, :, None, :])  # heading frame
    from_com = np.einsum("ij,fpkj->fpki", Rh, markers - com[:, None, None, :])
    from_com[..., 1] = markers[..., UP_AXIS] - ground

    # Every phase of one stride, sampled at every occurrence in the clip and averaged.
    occ_frames, occ_w = _occurrences(psi, F, dt, n_samples)
    marker_rel = _close_loop_linear(_average_markers(rel, anchor_ok, occ_frames, occ_w))
    # 0.03 L: a little above the 0.02 L (and its hysteresis band) at which the physics report calls a
    # marker loaded, so everything the report checks is held
    contact_tol = 0.03 * body.leg_length
    # A walk's events are the markers' own contact events already (no force threshold to widen them by)
    contact_phase = contact_phases(marker_rel, phase_events, first_foot, contact_tol,
                                   max_extension=0.0 if order == "walking" else 0.15)
    held = held_feet(marker_rel, contact_mask(np.arange(n_samples) / n_samples, contact_phase), body.leg_length,
                     order)
    # the body-relative foot path carries the same de-skating correction (it fades over the swing), so
    # that IK targets blending from the ground path to it after lift-off do not jump by the correction
    # (a 10 mm jump of a tip still near the floor, 02_03 at 50 Hz)
    marker_from_com = _close_loop_linear(_average(from_com, occ_frames, occ_w)) + (held - marker_rel)

    def averaged(x):
        return _close_loop_linear(_average(x, occ_frames, occ_w))

    return ReferenceCycle(
        first_foot=first_foot, phase_events=phase_events, contact_phase=contact_phase, durations=dur, frame=Rh,
        rotations=_close_loop_quat(_average_rotations(motion.rotations, occ_frames, occ_w)),
        root_from_com=averaged((motion.root_positions - com) @ Rh.T), com_height=averaged(com_h[:, 1] - ground),
        com_forward=averaged(com_h[:, 0] - speed * t), com_lateral=averaged(com_h[:, 2] - lat_line),
        marker_rel=held, marker_from_com=marker_from_com,
        contact_lateral=_contact_lateral(gait, Rh, lat_line, t, dt), speed=speed,
        stride_time=T, leg_length=body.leg_length, ground=ground,
        max_joint_jump_deg=max_joint_jump_deg(motion), order=order, floor_clearance=clearance,
        rest_heights=rest,
    )


def _stride_phases(events: list[FootEvent], n_frames: int, frame_time: float, order: str):
    """(first_foot, durations (4,) [s], phase_events (4,), psi (F,)): the stride's foot A, the mean
    durations between its events, their phases, and the unwrapped stride phase ψ of every frame: linear
    between events, extrapolated at the nominal rate beyond them (never past the neighbouring event's)."""
    tds = [e for e in events if e.kind == "td"]
    if len(tds) < 2 or len({e.foot for e in tds}) < 2:
        raise FitError("a stride cycle needs touchdowns of both feet in the clip")
    first_foot = tds[0].foot
    dur = stride_durations(events, first_foot, frame_time, order)
    T = float(dur.sum())
    fr = np.cumsum(dur)[:3] / T  # phases of the stride's second, third and fourth events
    ev_frames = np.array([e.frame for e in events])
    ev_psi = phase_of_events(events, first_foot, fr, order)
    frames = np.arange(n_frames, dtype=float)
    psi = np.interp(frames, ev_frames, ev_psi)
    rate = 1.0 / (T / frame_time)  # phase per frame at nominal timing
    before = frames < ev_frames[0]
    psi[before] = ev_psi[0] - (ev_frames[0] - frames[before]) * rate
    after = frames > ev_frames[-1]
    psi[after] = ev_psi[-1] + (frames[after] - ev_frames[-1]) * rate
    return first_foot, dur, event_phases(order, fr), psi


def _heading_measures(com: np.ndarray, t: np.ndarray):
    """(Rh (3, 3), com_h (F, 3) [m], speed [m/s], lat_line (F,) [m]): the heading frame (rows forward, up,
    lateral) along the COM's whole displacement, the COM in it, its mean forward speed and the straight
    line its lateral position follows. com: (F, 3) [m]; t: (F,) [s]."""
    heading = com[-1] - com[0]
    heading[UP_AXIS] = 0.0
    Rh = heading_frame(heading)
    com_h = com @ Rh.T  # (F, 3) forward, up, lateral
    speed = float(np.polyfit(t, com_h[:, 0], 1)[0])
    lat_line = np.polyval(np.polyfit(t, com_h[:, 2], 1), t)
    return Rh, com_h, speed, lat_line


def _stance_grounds(gait: Gait, n_frames: int) -> np.ndarray:
    """(F, 2) [m] the ground height of each foot's stance in its frames, NaN outside stances."""
    stance_ground = np.full((n_frames, 2), np.nan)
    for s in gait.stances:
        stance_ground[s.start : s.stop, s.foot] = s.ground
    return stance_ground


def _contact_lateral(gait: Gait, Rh: np.ndarray, lat_line: np.ndarray, t: np.ndarray, frame_time: float):
    """(2,) [m] each foot's mean lateral contact offset from the COM's lateral line (0 without stances)."""
    contact_lat = np.zeros(2)
    for foot in range(2):
        c = [s.contact_point @ Rh[2] - np.interp((s.start + s.stop) / 2 * frame_time, t, lat_line)
             for s in gait.stances if s.foot == foot]
        contact_lat[foot] = np.mean(c) if c else 0.0
    return contact_lat


def _occurrences(psi: np.ndarray, n_frames: int, frame_time: float, n_samples: int):
    """(frames (N, K+1), weights (N, K+1)): the fractional clip frame of each of the K + 1 cycle phases
    φ = k / K (φ = 1 included, for the loop closure) at each of its N occurrences φ + n in the clip, and
    its weight (fading in over 0.04 s at the clip's edges, 0 outside it)."""
    grid = np.arange(n_samples + 1) / n_samples
    frames = np.arange(n_frames, dtype=float)
    n_lo, n_hi = int(np.floor(psi.min())) - 1, int(np.ceil(psi.max())) + 1
    taper = max(1.0, 0.04 / frame_time)  # frames over which occurrences near the clip's edges fade in
    frames_n: list[np.ndarray] = []
    weights_n: list[np.ndarray] = []
    for n in range(n_lo, n_hi + 1):
        target = grid + n
        inside = (target >= psi[0]) & (target <= psi[-1])
        f = np.interp(target, psi, frames)
        w = np.clip(np.minimum(f, n_frames - 1 - f) / taper, 0.0, 1.0) * inside
        if np.any(w > 0):
            frames_n.append(f)
            weights_n.append(w)
    occ_frames, occ_w = np.array(frames_n), np.array(weights_n)
    if np.any(occ_w.sum(axis=0) <= 0):
        raise FitError("the clip does not cover a whole stride: every phase must be seen at least once")
    return occ_frames, occ_w


def _lin(x: np.ndarray, f: np.ndarray) -> np.ndarray:
    """Per-frame data x (F, ...) linearly interpolated at fractional frames f (...) -> (f.shape + x.shape[1:])."""
    i0 = np.clip(np.floor(f).astype(int), 0, x.shape[0] - 2)
    w = (f - i0).reshape(f.shape + (1,) * (x.ndim - 1))
    return x[i0] * (1 - w) + x[i0 + 1] * w


def _average(x: np.ndarray, occ_frames: np.ndarray, occ_w: np.ndarray) -> np.ndarray:
    """The weighted mean over occurrences (``_occurrences``) of per-frame linear data x (F, ...) -> (K+1, ...)."""
    vals = np.stack([_lin(x, f) for f in occ_frames])
    w = occ_w.reshape(occ_w.shape + (1,) * (vals.ndim - 2))
    return np.sum(vals * w, axis=0) / np.sum(w, axis=0)


def _average_rotations(rotations: np.ndarray, occ_frames: np.ndarray, occ_w: np.ndarray) -> np.ndarray:
    """(K+1, J, 4) the weighted mean over occurrences of the joint rotations (F, J, 4), each occurrence's
    sign matched to the most weighted one's, renormalised."""
    rots = quat.make_continuous(rotations)
    q_occ = np.stack([_slerp_frames(rots, f) for f in occ_frames])  # (N, K+1, J, 4)
    ref = q_occ[np.argmax(occ_w, axis=0), np.arange(occ_w.shape[1])]  # sign reference per sample
    sign = np.where(np.sum(q_occ * ref[None], axis=-1) < 0, -1.0, 1.0)
    return quat.normalize(np.sum(q_occ * sign[..., None] * occ_w[:, :, None, None], axis=0))


def _average_markers(rel: np.ndarray, anchor_ok: np.ndarray, occ_frames: np.ndarray,
                     occ_w: np.ndarray) -> np.ndarray:
    """(K+1, 2, 3, 3) [m] the foot markers relative to their anchors (F, 2, 3, 3) averaged over the
    occurrences whose anchors are known (anchor_ok (F, 2)); a foot phase never seen with both neighbouring
    contacts falls back to every occurrence."""
    rel_vals = np.stack([_lin(rel, f) for f in occ_frames])  # (N, K+1, 2, 3, 3)
    ok_vals = np.stack([_lin(anchor_ok.astype(float), f) for f in occ_frames]) > 0.999  # (N, K+1, 2)
    w = occ_w[:, :, None] * ok_vals
    wsum = w.sum(axis=0)
    if np.any(wsum <= 0):
        w = np.where(wsum[None] <= 0, occ_w[:, :, None], w)
        wsum = w.sum(axis=0)
    return np.sum(rel_vals * w[..., None, None], axis=0) / wsum[..., None, None]


def _slerp_frames(rots: np.ndarray, f: np.ndarray) -> np.ndarray:
    F = rots.shape[0]
    i0 = np.clip(np.floor(f).astype(int), 0, F - 2)
    w = np.broadcast_to((f - i0)[:, None], (len(f), rots.shape[1]))
    return quat.slerp(rots[i0], rots[i0 + 1], w)


def _close_loop_linear(x: np.ndarray) -> np.ndarray:
    """(K+1, …) samples over φ ∈ [0, 1] → (K, …) periodic samples: the end mismatch spread linearly."""
    K = x.shape[0] - 1
    ramp = (np.arange(K + 1) / K).reshape((K + 1,) + (1,) * (x.ndim - 1))
    return (x - ramp * (x[-1] - x[0]))[:K]


def _close_loop_quat(q: np.ndarray) -> np.ndarray:
    """(K+1, J, 4) → (K, J, 4) periodic: the rotation from end to start spread linearly over the stride."""
    K = q.shape[0] - 1
    delta = quat.to_rotvec(quat.mul(quat.conj(q[-1]), q[0]))  # end -> start, local
    ramp = (np.arange(K + 1) / K)[:, None, None]
    return quat.normalize(quat.mul(q, quat.from_rotvec(ramp * delta[None])))[:K]


def nlerp_rows(q: np.ndarray, i0: np.ndarray, i1: np.ndarray, w: np.ndarray, chunk: int = 32768) -> np.ndarray:
    """(T, J, 4) normalised linear interpolation between rows i0 and i1 (T,) of q (N, J, 4) at weights w (T,).

    In chunks, so that the temporaries of a long output (an hour is 432 000 frames) stay small.
    """
    out = np.empty((len(w),) + q.shape[1:])
    for a in range(0, len(w), chunk):
        sl = slice(a, a + chunk)
        q0, q1 = q[i0[sl]], q[i1[sl]]
        w_ = w[sl, None, None]
        sign = np.where(np.sum(q0 * q1, axis=-1, keepdims=True) < 0, -1.0, 1.0)
        out[sl] = quat.normalize(q0 * (1.0 - w_) + q1 * (sign * w_))
    return out


def sample_cycle(cycle: ReferenceCycle, phi: np.ndarray, rotations: bool = True):
    """Cycle quantities at stride phases phi (T,): rotations (T, J, 4) (None if not asked) and a dict of
    linear arrays. Rotations use normalised linear interpolation: neighbouring cycle samples are a few
    degrees apart at most, where nlerp and slerp differ by < 1e-4 rad, at a third of the cost.
    """
    K = cycle.n_samples
    x = np.mod(phi, 1.0) * K
    i0 = np.floor(x).astype(int) % K
    i1 = (i0 + 1) % K
    w = x - np.floor(x)
    rot = None
    if rotations:
        rot = nlerp_rows(cycle.rotations, i0, i1, w)

    def lin(a):
        ww = w.reshape((-1,) + (1,) * (a.ndim - 1))
        return a[i0] * (1 - ww) + a[i1] * ww

    return rot, {
        "root_from_com": lin(cycle.root_from_com),
        "com_height": lin(cycle.com_height),
        "com_forward": lin(cycle.com_forward),
        "com_lateral": lin(cycle.com_lateral),
        "marker_rel": lin(cycle.marker_rel),
        "marker_from_com": lin(cycle.marker_from_com),
    }
