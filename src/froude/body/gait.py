"""Ground height, foot contacts (stance intervals), flight phases and the gait summary of a motion: the one
decision about what a clip is (running, walking, the in-between grounded running, in place, unknown), which
``info``, ``fit`` and every verb take from here.

Thresholds scale with the leg length L so that a child and a giant are judged alike:
a foot is a contact candidate while its slowest marker moves horizontally slower than 0.3 √(g L)
(≈ 0.87 m/s for an adult) and its lowest marker is within 0.05 L (≈ 4 cm) of the ground under it.
The floor of real captures is uneven by a few centimetres, so the ground is estimated per stance.

The feet are one witness, the COM the other: the vertical ground force of eq. 1 (``body.com_force``) is
below FLIGHT_FORCE_BW in a flight and above it whenever a foot bears the body. A gap between the feet's
contacts in which the COM force never falls below it is no flight (a toe marker placed higher than the
thresholds expect, a foot rolling off slowly): the weight passes from one foot to the other there, and the
contacts are joined where the landing foot comes lower than the leaving one (``reconcile_contacts``).
Walking and grounded running both keep a foot on the ground; they differ in the COM's path over a single
support: a walk vaults (highest in mid single support), a run bounces (lowest there).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from ..core.constants import GRAVITY, HORIZONTAL_AXES, UP_AXIS
from ..core.motion import Motion
from ..errors import NotARunningMotion
from .com_force import vertical_force_bw
from .model import SIDES, BodyModel

#: Vertical ground force of eq. 1 [body weights] below which the body is in flight: a gap between the feet's
#: contacts is a flight only where the COM force falls below it, and a double support a time when it is above.
FLIGHT_FORCE_BW = 0.2
#: The kinds of motion the walking machine models (a foot always on the ground); "running" gets the running
#: machine; the others are refused with their reason.
WALKING_MACHINE_KINDS = ("walking", "grounded running")


@dataclass(frozen=True)
class Stance:
    """One foot contact: frames [start, stop) of ``foot`` (0 left, 1 right).

    ground: ground height under this stance [m]; contact_point: (3,) mean position of the foot's
    lowest marker over the stance [m]; partial: True when the stance touches the clip's edge.
    """

    foot: int
    start: int
    stop: int
    ground: float
    contact_point: np.ndarray
    partial: bool
    #: sub-frame touchdown / liftoff [frames]: where the contact test became true before ``start`` and false
    #: after ``stop - 1`` (linear interpolation of the foot's height and speed between frames); so step
    #: times do not carry a frame's quantisation (a 33 ms frame is 10 % of a step at 30 Hz).
    t_on: float = float("nan")
    t_off: float = float("nan")

    @property
    def side(self) -> str:
        return SIDES[self.foot]

    def duration(self, frame_time: float) -> float:
        return (self.stop - self.start) * frame_time


@dataclass(frozen=True)
class Gait:
    """Contacts and phases of a motion.

    contact: (F, 2) bool per foot; stances: sorted by start; flights: ((start, stop), ...) frame intervals
    with no foot on the ground that lie between two stances; ground: median stance ground height [m];
    frame_time [s]; leg_length [m]; ball: (F, 2, 3) world path of each foot's ball (the toe joint, the
    foot's middle marker) [m], for the midstance times (``midstance_times``); None if not known.
    """

    contact: np.ndarray
    stances: tuple[Stance, ...]
    flights: tuple[tuple[int, int], ...]
    ground: float
    frame_time: float
    leg_length: float
    double_support_fraction: float
    ball: np.ndarray | None = None

    @property
    def full_stances(self) -> tuple[Stance, ...]:
        return tuple(s for s in self.stances if not s.partial)

    def stance_times(self) -> np.ndarray:
        return np.array([s.duration(self.frame_time) for s in self.full_stances])

    def flight_times(self) -> np.ndarray:
        return np.array([(b - a) * self.frame_time for a, b in self.flights])


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """[start, stop) intervals where a 1-D bool array is True."""
    d = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return list(zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1)))


def _close_gaps(mask: np.ndarray, max_gap: int) -> np.ndarray:
    out = mask.copy()
    for a, b in _runs(~mask):
        if 0 < a and b < len(mask) and b - a <= max_gap:
            out[a:b] = True
    return out


def _rise(x: np.ndarray, i: int, limit: float) -> float:
    """Where x rises through ``limit`` between frames i and i + 1, as a fraction in [0, 1] of the way
    (linear): 0 if x[i] is already at or above it, 1 if x[i + 1] is still below."""
    a, b = float(x[i]), float(x[i + 1])
    if a >= limit:
        return 0.0
    if b < limit:
        return 1.0
    return float((limit - a) / (b - a))


def _subframe_events(h: np.ndarray, v: np.ndarray, h_lim: float, v_lim: float, s0: int, s1: int) -> tuple[float, float]:
    """Sub-frame (touchdown, liftoff) [frames] of a contact on frames [s0, s1).

    A foot is down while it is both low (h < h_lim) and slow (v < v_lim): it lands when the later of the
    two tests becomes true between frames s0 − 1 and s0, and lifts when the first of them fails between
    s1 − 1 and s1. h, v: (F,) lowest-marker height [m] and slowest-marker horizontal speed [m/s].
    At the clip's edges the frame is kept.
    """
    F = len(h)
    t_on = float(s0)
    if s0 > 0:  # falling through the limits: a rise of −x
        t_on = s0 - 1 + max(_rise(-h, s0 - 1, -h_lim), _rise(-v, s0 - 1, -v_lim))
    t_off = float(s1 - 1)
    if s1 < F:
        t_off = s1 - 1 + min(_rise(h, s1 - 1, h_lim), _rise(v, s1 - 1, v_lim))
    return float(t_on), float(t_off)


#: How far beyond the clip's edge a stance cut by it may have its midstance extrapolated [s]: the COM
#: passes over a planted ball at nearly constant speed, so a few frames' extrapolation is exact to a
#: fraction of a millisecond, and a clip that ends a frame earlier (another rate) keeps the same steps.
MIDSTANCE_EXTRAPOLATION_S = 0.04


def running_direction(gait: Gait, com: np.ndarray) -> np.ndarray | None:
    """(3,) horizontal unit direction of running relative to the ground, or None when the body neither
    travels nor has feet sliding back (standing).

    The COM's mean velocity less the velocity of the feet resting on the ground: the COM's for a take with
    root travel, minus the feet's for an in-place take (treadmill-like) whose stance feet slide back.
    com: (F, 3) [m].
    """
    F = com.shape[0]
    if F < 3:
        return None
    v = (com[-1] - com[0]) / ((F - 1) * gait.frame_time)
    if gait.ball is not None:
        v = v - ground_velocity(gait.ball, gait.leg_length, gait.frame_time)
    v[UP_AXIS] = 0.0
    n = float(np.linalg.norm(v))
    return v / n if n > 0.05 * np.sqrt(GRAVITY * gait.leg_length) else None


#: A take whose COM travels in directions this far apart [rad] over its first and last quarters turns: its
#: midstances are found along each stance's own travel (``midstance_times``). Far above a straight take's
#: veer with its sway's tilt of a quarter's chord (the shared straight takes: under 10 degrees), far below a
#: turn (84-97 degrees).
TURNING_TAKE_RAD = math.radians(30.0)


def _turns(com: np.ndarray) -> bool:
    """Whether the COM (F, 3) [m] travels in directions more than TURNING_TAKE_RAD apart over the take's first
    and last quarters."""
    F = com.shape[0]
    q = F // 4
    if q < 1:
        return False
    d0, d1 = com[q] - com[0], com[-1] - com[-1 - q]
    d0[UP_AXIS] = d1[UP_AXIS] = 0.0
    n0, n1 = float(np.linalg.norm(d0)), float(np.linalg.norm(d1))
    return n0 > 0 and n1 > 0 and float(d0 @ d1) < n0 * n1 * math.cos(TURNING_TAKE_RAD)


def _stance_travel(rel: np.ndarray, fwd: np.ndarray) -> np.ndarray:
    """(3,) the horizontal direction the COM travels over a stance relative to its ball, rel (K, 3) [m] the COM
    less the ball over the stance's frames; fwd (the take's direction) where it travels too little or back."""
    moved = rel[-1] - rel[0]
    moved[UP_AXIS] = 0.0
    n = float(np.linalg.norm(moved))
    return moved / n if n > 0 and float(moved @ fwd) > 0 else fwd


def midstance_times(gait: Gait, com: np.ndarray) -> np.ndarray:
    """Sorted midstance times [frames]: where the COM passes over the stance foot's ball, one per stance.

    The forward distance ball → COM grows through zero in every stance at about the running speed (the
    ball is planted, or slides back at that speed in place), so its crossing falls between two frames
    by linear interpolation to a fraction of a millisecond whatever the frame rate: unlike touchdown
    and toe-off, whose thresholds are crossed slowly (a toe rolls off the floor over 50-80 ms) and
    read 5-20 ms apart at 30 and 120 Hz. A stance cut by the clip's edge gives its midstance when the
    crossing lies within MIDSTANCE_EXTRAPOLATION_S of the edge. com: (F, 3) [m]. Empty without a
    running direction or the balls' paths.
    """
    return np.sort(np.asarray([t for _, t in _midstances(gait, com)], float))


def _midstances(gait: Gait, com: np.ndarray) -> list[tuple[int, float]]:
    """(stance index, midstance time [frames]) of each stance whose COM passes over its ball
    (``midstance_times``); a braking plant whose COM stays behind the foot until liftoff has none."""
    ball = gait.ball
    fwd = None if ball is None else running_direction(gait, com)
    if ball is None or fwd is None:
        return []
    F = com.shape[0]
    reach = MIDSTANCE_EXTRAPOLATION_S / gait.frame_time
    turning = _turns(com)
    out = []
    for k, st in enumerate(gait.stances):
        a, b = max(st.start - 1, 0), min(st.stop + 1, F)
        along = _stance_travel(com[a:b] - ball[a:b, st.foot], fwd) if turning else fwd
        d = (com - ball[:, st.foot]) @ along  # (F,) [m]: < 0 while the ball is ahead of the COM
        seg = d[a:b]
        up = np.flatnonzero((seg[:-1] < 0) & (seg[1:] >= 0))
        if up.size:
            i = a + int(up[0])
            out.append((k, i + float(-d[i] / (d[i + 1] - d[i]))))
        elif st.stop == F and F >= 2 and d[-1] < 0 < d[-1] - d[-2]:  # the crossing just after the end
            t = (F - 1) - d[-1] / (d[-1] - d[-2])
            if t - (F - 1) <= reach:
                out.append((k, float(t)))
        elif st.start == 0 and F >= 2 and d[0] > 0 and d[1] > d[0]:  # just before the start
            t = -d[0] / (d[1] - d[0])
            if -t <= reach:
                out.append((k, float(t)))
    return out


def _whole_stride_span(t: np.ndarray) -> tuple[float, int]:
    """(span [same unit as t], steps) of sorted event times over a whole number of strides when they
    span more than one step: an odd step count leaves out one step at either end and averages the two,
    so a runner whose left and right steps differ is not biased by the odd step."""
    n = len(t) - 1
    if n > 1 and n % 2:
        n -= 1
        return 0.5 * ((t[n] - t[0]) + (t[-1] - t[-1 - n])), n
    return t[n] - t[0], n


def step_period(gait: Gait, n_frames: int, com: np.ndarray | None = None) -> float:
    """Mean step time [s] of a gait, NaN when it cannot be measured.

    From the midstance times (``midstance_times``, needs com (F, 3) [m]) when there are at least two;
    otherwise from the sub-frame touchdown and liftoff times alike (two estimates, averaged by the
    number of steps each spans; a contact cut by the clip's start gives no liftoff). Each sequence is
    used over a whole number of strides (``_whole_stride_span``).
    """
    dt = gait.frame_time
    if com is not None:
        found = _midstances(gait, com)
        # Consecutive midstances are one step apart only when no stance between them lacks one (a braking
        # plant's COM never passes its foot: CMU 16_51's first three stances, which read 2.8 Hz for 5).
        if len(found) >= 2 and all(k1 == k0 + 1 for (k0, _), (k1, _) in zip(found, found[1:])):
            span, n = _whole_stride_span(np.asarray([t for _, t in found]))
            return float(span * dt / n)
    spans, steps = [], []
    for times in ([s.t_on for s in gait.stances if s.start > 0],
                  [s.t_off for s in gait.stances if 0 < s.start and s.stop < n_frames]):
        t = np.sort(np.asarray(times, float))
        if len(t) < 2:
            continue
        span, n = _whole_stride_span(t)
        spans.append(span * dt)
        steps.append(n)
    if not steps or sum(spans) <= 0:
        return float("nan")
    return float(sum(spans) / sum(steps))


def detect_gait(motion: Motion, body: BodyModel, markers: np.ndarray | None = None,
                com: np.ndarray | None = None) -> Gait:
    """Foot contacts, stances, flight phases and ground height of a motion.

    markers: optional precomputed foot markers (F, 2, 3, 3) [m] (``body.foot_markers(motion)``); com: the
    COM path (F, 3) [m]: when given, the feet's contacts are reconciled with its eq. 1 force
    (``reconcile_contacts``: a gap in which the COM is never in flight is no flight).
    """
    if markers is None:
        markers = body.foot_markers(motion)
    dt = motion.frame_time
    L = body.leg_length
    F = motion.n_frames
    height = markers[..., UP_AXIS]  # (F, 2, 3)
    vel = np.gradient(markers[..., HORIZONTAL_AXES], dt, axis=0) if F > 1 else np.zeros(markers[..., :2].shape)
    speed = np.linalg.norm(vel, axis=-1)  # (F, 2, 3)
    h_foot = height.min(axis=2)  # (F, 2) lowest marker
    v_foot = speed.min(axis=2)  # (F, 2) slowest marker
    v_thr = 0.3 * np.sqrt(GRAVITY * L)
    h_thr = 0.05 * L
    global_ground = float(np.percentile(h_foot, 5))
    max_gap = max(1, int(round(0.05 / dt)))  # heel-to-toe roll can lift every marker briefly
    min_len = max(2, int(round(0.04 / dt)))

    contact = np.zeros((F, 2), dtype=bool)
    stance_list = []
    for foot in range(2):
        slow = _close_gaps(v_foot[:, foot] < v_thr, max_gap)
        for a, b in _runs(slow):
            local_ground = float(h_foot[a:b, foot].min())
            if local_ground > global_ground + 0.1 * L:
                continue  # slow but high: a foot held in the air (jumps, swing), not a contact
            on = _close_gaps(h_foot[a:b, foot] < local_ground + h_thr, max_gap)
            for c, d in _runs(on):
                if d - c < min_len and not (a + c == 0 or a + d == F):
                    continue
                s0, s1 = a + c, a + d
                contact[s0:s1, foot] = True
                low = np.argmin(height[s0:s1, foot], axis=1)  # lowest marker per frame
                pts = markers[np.arange(s0, s1), foot, low]
                h_lim = local_ground + h_thr
                t_on, t_off = _subframe_events(h_foot[:, foot], v_foot[:, foot], h_lim, v_thr, s0, s1)
                stance_list.append(
                    Stance(foot, int(s0), int(s1), local_ground, pts.mean(axis=0), bool(s0 == 0 or s1 == F),
                           t_on, t_off)
                )
    stance_list = _join_short_lifts(sorted(stance_list, key=lambda s: s.start), dt, contact)
    any_contact = np.asarray(contact.any(axis=1), bool)
    flights = []
    if stance_list:
        first = min(s.start for s in stance_list)
        last = max(s.stop for s in stance_list)
        for a, b in _runs(~any_contact[first:last]):
            flights.append((first + a, first + b))
    ground = float(np.median([s.ground for s in stance_list])) if stance_list else global_ground
    both = contact.all(axis=1)
    gait = Gait(contact, tuple(stance_list), tuple(flights), ground, dt, L, float(both.mean()) if F else 0.0,
                markers[:, :, 1])
    if com is not None and F >= 8:
        gait = reconcile_contacts(gait, vertical_force_bw(com, dt), h_foot)
    return gait


#: A foot that leaves the ground for less than this [s] has not stepped: the shortest swing of a human gait (a
#: sprinter's: the other foot's stance and two flights) lasts well over 0.2 s. A heel-to-toe roll at a take's
#: edge can lift every marker over the contact threshold for longer than ``detect_gait``'s gap closing (CMU
#: 16_18's left foot: 0.00-0.03 s and 0.09-0.14 s, one toe-off read as a stance of its own).
MIN_SWING_S = 0.1


def _join_short_lifts(stances: list[Stance], dt: float, contact: np.ndarray) -> list[Stance]:
    """Sorted stances with each foot's contacts less than MIN_SWING_S apart joined into one (contact (F, 2)
    bool is marked in between, in place); dt [s]."""
    out: list[Stance] = []
    for st in stances:
        prev = next((k for k in range(len(out) - 1, -1, -1) if out[k].foot == st.foot), None)
        if prev is not None and (st.start - out[prev].stop) * dt < MIN_SWING_S:
            a = out[prev]
            contact[a.stop:st.start, st.foot] = True
            out[prev] = replace(a, stop=st.stop, t_off=st.t_off, partial=a.partial or st.partial)
            continue
        out.append(st)
    return sorted(out, key=lambda s: s.start)


def reconcile_contacts(gait: Gait, fy_bw: np.ndarray, h_foot: np.ndarray) -> Gait:
    """The feet's contacts made to agree with the COM: every gap between contacts in which the vertical
    force of eq. 1 stays at or above FLIGHT_FORCE_BW is closed.

    fy_bw: (F,) COM-derived vertical ground force [body weights]; h_foot: (F, 2) each foot's lowest marker
    height [m]. In such a gap the body is borne by a foot the thresholds missed: the foot that lifted
    keeps the weight until the landing foot comes lower above its own ground than it (each foot's height
    over its stance's ground), and the two stances meet there. Gaps the COM confirms stay flights.
    """
    F = gait.contact.shape[0]
    stances: list[Stance | None] = list(gait.stances)
    changed = False
    for a, b in gait.flights:
        if float(fy_bw[a:b].min()) < FLIGHT_FORCE_BW:
            continue
        before = [i for i, st in enumerate(stances) if st is not None and st.stop == a]
        after = [i for i, st in enumerate(stances) if st is not None and st.start == b]
        if not before or not after:
            continue
        i, j = before[0], after[0]
        s_off, s_on = stances[i], stances[j]
        assert s_off is not None and s_on is not None
        if s_off.foot == s_on.foot:  # the same foot again: it never left the ground
            stances[i] = replace(s_off, stop=s_on.stop, t_off=s_on.t_off, partial=s_off.partial or s_on.partial)
            stances[j] = None
        else:
            lower = (h_foot[a:b, s_on.foot] - s_on.ground) <= (h_foot[a:b, s_off.foot] - s_off.ground)
            k = a + (int(np.argmax(lower)) if lower.any() else b - a)
            t = k - 0.5  # the handover between frames k - 1 and k
            stances[i] = replace(s_off, stop=int(k), t_off=float(t), partial=bool(s_off.start == 0 or k == F))
            stances[j] = replace(s_on, start=int(k), t_on=float(t), partial=bool(k == 0 or s_on.stop == F))
        changed = True
    if not changed:
        return gait
    kept = sorted((st for st in stances if st is not None), key=lambda st: st.start)
    contact = np.zeros_like(gait.contact)
    for st in kept:
        contact[st.start:st.stop, st.foot] = True
    flights = []
    first, last = min(st.start for st in kept), max(st.stop for st in kept)
    for a, b in _runs(~np.asarray(contact.any(axis=1), bool)[first:last]):
        flights.append((first + a, first + b))
    return replace(gait, contact=contact, stances=tuple(kept), flights=tuple(flights),
                   double_support_fraction=float(contact.all(axis=1).mean()))


@dataclass(frozen=True)
class GaitSummary:
    """Measured gait figures of a motion (SI units). NaN where a figure cannot be measured."""

    duration: float
    frame_rate: float
    mean_speed: float
    heading: np.ndarray
    froude: float
    leg_length: float
    n_contacts: int
    stance_times: np.ndarray
    flight_times: np.ndarray
    step_frequency: float
    step_length: float
    com_vertical_excursion: float
    double_support_fraction: float
    has_flight: bool
    kind: str
    reason: str
    extras: dict = field(default_factory=dict)


#: A motion runs when at least this share of its steps (stance to next stance) has a flight of at least
#: MIN_FLIGHT_S: one noisy frame that lifts both feet of a walk once does not make it a run, and a tired
#: jog with a few steps whose flight the contacts miss (6 of 10 on the Bandai jog) still runs.
RUNNING_FLIGHT_SHARE = 0.5
MIN_FLIGHT_S = 0.025


def n_flights(gait: Gait) -> int:
    """How many of a gait's flights (between consecutive contacts) last at least MIN_FLIGHT_S."""
    # a frame time written to 7 digits (.0083333 s) makes a 3-frame flight at 120 Hz 0.0249999 s: 1e-3 frame
    # of slack, as ``take.select_range`` (CMU 16_51's turn has 3-frame flights)
    return int((gait.flight_times() >= MIN_FLIGHT_S - 1e-3 * gait.frame_time).sum())


def flight_share(gait: Gait) -> float:
    """Share of the steps (consecutive contacts) of a gait that have a flight ≥ MIN_FLIGHT_S [0-1]."""
    steps = len(gait.stances) - 1
    return min(1.0, n_flights(gait) / steps) if steps >= 1 else 0.0


def summarize(motion: Motion, body: BodyModel, com: np.ndarray | None = None, gait: Gait | None = None) -> GaitSummary:
    """The gait summary behind ``froude info``: speed, Froude number U = u/√(g L), steps, phases, kind."""
    if com is None or gait is None:
        c, mk = body.com_and_markers(motion)
        com = c if com is None else com
        gait = detect_gait(motion, body, mk, com) if gait is None else gait
    disp = com[-1, HORIZONTAL_AXES] - com[0, HORIZONTAL_AXES]
    dist = float(np.linalg.norm(disp))
    duration = motion.duration
    speed = dist / duration if duration > 0 else 0.0
    heading = np.zeros(3)
    if dist > 0:
        heading[HORIZONTAL_AXES] = disp / dist
    L = body.leg_length
    period = step_period(gait, motion.n_frames, com)
    step_freq = 1.0 / period if period > 0 else np.nan
    step_len = speed / step_freq if np.isfinite(step_freq) else np.nan
    flight_times = gait.flight_times()
    has_flight = flight_share(gait) >= RUNNING_FLIGHT_SHARE
    excursion = float(com[:, UP_AXIS].max() - com[:, UP_AXIS].min())
    kind, reason = classify(gait, speed, dist, L, has_flight, single_support_vault(gait, com))
    return GaitSummary(
        duration=duration, frame_rate=motion.fps, mean_speed=speed, heading=heading,
        froude=speed / np.sqrt(GRAVITY * L), leg_length=L, n_contacts=len(gait.stances),
        stance_times=gait.stance_times(), flight_times=flight_times, step_frequency=float(step_freq),
        step_length=float(step_len), com_vertical_excursion=excursion,
        double_support_fraction=gait.double_support_fraction, has_flight=has_flight, kind=kind, reason=reason,
    )


def stride_speeds(com: np.ndarray, gait: Gait, n_frames: int) -> tuple[np.ndarray, np.ndarray]:
    """Forward speed of each whole stride of a motion (touchdown to the same foot's next touchdown).

    com: (F, 3) [m]. Returns (t_mid (S,) [s], speed (S,) [m/s]): empty when the clip holds no whole stride.
    Used to say whether a take's speed changes (a dash that speeds up) and so which part a model stands for.
    """
    dt = gait.frame_time
    t_mid, speeds = [], []
    for foot in (0, 1):
        on = sorted(s.t_on for s in gait.stances if s.foot == foot and s.start > 0)
        for a, b in zip(on[:-1], on[1:]):
            pa = np.array([np.interp(a, np.arange(n_frames), com[:, k]) for k in HORIZONTAL_AXES])
            pb = np.array([np.interp(b, np.arange(n_frames), com[:, k]) for k in HORIZONTAL_AXES])
            t_mid.append(0.5 * (a + b) * dt)
            speeds.append(float(np.linalg.norm(pb - pa) / ((b - a) * dt)))
    order = np.argsort(t_mid)
    return np.asarray(t_mid)[order], np.asarray(speeds)[order]


#: Feet sliding on the ground faster than this × √(g L) (a median over the frames they rest) are taken for
#: an in-place take's, whose speed is then measured stance by stance (``ground_velocity``).
SLIDING_FROUDE = 0.3
#: Share of each contact over which a foot is taken to be planted (the window sliding fastest): the ball
#: rolls forward after touchdown and before toe-off, and is still over about a third of the contact.
PLANTED_SHARE = 1.0 / 3.0


def ground_velocity(markers: np.ndarray, leg_length: float, frame_time: float) -> np.ndarray:
    """(3,) horizontal velocity of the balls of the feet while they are planted on the ground [m/s].

    markers: (F, 2, 3, 3) [m], or the balls' paths alone (F, 2, 3) [m]. The ball (the foot's middle marker,
    the toe joint) rests while within 0.01 L of its own low level (5th percentile). For a take with root
    travel the median velocity over those frames is returned (≈ 0). When the balls slide faster than
    SLIDING_FROUDE √(g L) (an in-place take, treadmill-like, root travel removed: the planted foot slides
    back at the running speed) the speed is measured per contact (within 0.05 L of the low level), a
    median over contacts (``_planted_speeds``): the median over the frames a ball rests reads 1-5 % low,
    because the ball rolls forward after touchdown and before toe-off.
    """
    if markers.shape[0] < 3:
        return np.zeros(3)
    ball = markers[:, :, 1] if markers.ndim == 4 else markers  # (F, 2, 3)
    vel = np.gradient(ball, frame_time, axis=0)
    h = ball[..., UP_AXIS]
    low = np.percentile(h, 5, axis=0)
    rest = h <= low + 0.01 * leg_length  # (F, 2): the ball on the floor
    v = np.median(vel[rest], axis=0) if rest.any() else np.zeros(3)
    v[UP_AXIS] = 0.0
    slide = float(np.linalg.norm(v))
    if slide < SLIDING_FROUDE * np.sqrt(GRAVITY * leg_length):
        return v
    back = v / slide  # the direction the planted feet slide (the running direction's opposite)
    contact = h <= low + 0.05 * leg_length  # the whole contact, as the gait's height test takes it
    speeds = _planted_speeds(ball @ back, contact, frame_time)
    return back * float(np.median(speeds)) if speeds.size else v


def _planted_speeds(x: np.ndarray, rest: np.ndarray, frame_time: float) -> np.ndarray:
    """Sliding speed of each contact's planted part [m/s]: per run of rest frames (≥ 0.06 s) of each foot,
    the fastest mean speed over PLANTED_SHARE of it. x: (F, 2) ball position along the sliding
    direction [m]; rest: (F, 2) bool."""
    out = []
    min_len = max(4, int(round(0.06 / frame_time)))
    for foot in range(2):
        for a, b in _runs(rest[:, foot]):
            if b - a < min_len:
                continue
            w = max(2, int(round(PLANTED_SHARE * (b - a))))
            xs = x[a:b, foot]
            out.append(float(np.max(xs[w:] - xs[:-w])) / (w * frame_time))
    return np.asarray(out)


def single_support_vault(gait: Gait, com: np.ndarray) -> float:
    """Median over the clip's single supports (one foot down, between two changes of support) of the COM's
    height at the middle less the mean of its heights at the two ends [m]: > 0 when the COM vaults over
    the stance leg (walking), < 0 when it bounces on it (running, grounded or not). NaN without a complete
    single support. com: (F, 3) [m]."""
    h = com[:, UP_AXIS]
    single = np.asarray(gait.contact.sum(axis=1) == 1, bool)
    out = []
    for a, b in _runs(single):
        if a == 0 or b >= len(h) or b - a < 3:
            continue
        out.append(h[(a + b - 1) // 2] - 0.5 * (h[a] + h[b - 1]))
    return float(np.median(out)) if out else float("nan")


#: Below this share of the time with both feet down a gait without flight has no double support.
DOUBLE_SUPPORT_MIN = 0.02


def classify(gait: Gait, speed: float, distance: float, leg_length: float, has_flight: bool,
             vault: float = float("nan")) -> tuple[str, str]:
    """('running' | 'walking' | 'grounded running' | 'in place' | 'unknown', reason): the one decision.

    has_flight: flights (confirmed by the COM force when the gait was reconciled) between at least
    RUNNING_FLIGHT_SHARE of the steps; vault: ``single_support_vault`` [m]. A take with flights runs; one
    with flights between fewer steps runs too when it has them more often than double supports (a jog
    whose short flights the COM confirms in some steps only). Without a flight, a foot is always down:
    walking when the COM vaults over the stance leg, grounded running when it bounces on it; the walking
    machine models both and needs both feet down at each handover (a double support).
    """
    if distance < 1.0 * leg_length or speed < 0.15 * np.sqrt(GRAVITY * leg_length):
        return "in place", (
            f"no forward progression (travels {distance:.2f} m at {speed:.2f} m/s): not locomotion"
        )
    if len(gait.stances) < 2:
        return "unknown", f"only {len(gait.stances)} foot contact(s) found: a gait needs at least two stances"
    ds = gait.double_support_fraction
    if has_flight:
        return "running", f"flight phases between contacts, {speed:.2f} m/s"
    flights = n_flights(gait)
    n_double = len(_runs(np.asarray(gait.contact.all(axis=1), bool)))
    if flights and flights >= n_double:
        return "running", (f"short flight phases between {flights} of the contacts, more often than both feet "
                           f"are down ({n_double}), {speed:.2f} m/s")
    if ds > DOUBLE_SUPPORT_MIN:
        both = f"both feet on the ground {100 * ds:.0f}% of the time"
        if np.isfinite(vault) and vault < 0:
            return "grounded running", (
                f"no flight phase ({both}) but the body bounces on the stance leg (COM {1000 * -vault:.0f} mm "
                "lower in mid single support): running without flight, between walking and running"
            )
        return "walking", f"no flight phase ({both}): this is walking, not running"
    return "unknown", ("no flight phase and never both feet on the ground: neither walking nor running "
                       "as the machines model them")


def require_running(summary: GaitSummary, source: str = "motion") -> None:
    """Raise NotARunningMotion with a one-line reason unless the summary describes running."""
    if summary.kind != "running":
        raise NotARunningMotion(f"{source}: {summary.kind}: {summary.reason}")


def walks(summary: GaitSummary) -> bool:
    """Whether the walking machine models this motion (walking or grounded running: a foot always down)."""
    return summary.kind in WALKING_MACHINE_KINDS
