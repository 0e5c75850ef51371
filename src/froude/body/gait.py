"""Ground height, foot contacts (stance intervals), flight phases and the gait summary of a motion.

Thresholds scale with the leg length L so that a child and a giant are judged alike:
a foot is a contact candidate while its slowest marker moves horizontally slower than 0.3 √(g L)
(≈ 0.87 m/s for an adult) and its lowest marker is within 0.05 L (≈ 4 cm) of the ground under it.
The floor of real captures is uneven by a few centimetres, so the ground is estimated per stance.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .model import SIDES, BodyModel
from ..constants import GRAVITY, UP_AXIS
from ..errors import NotARunningMotion
from ..core.motion import Motion

_HORIZONTAL = [a for a in range(3) if a != UP_AXIS]


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
    frame_time [s]; leg_length [m].
    """

    contact: np.ndarray
    stances: tuple[Stance, ...]
    flights: tuple[tuple[int, int], ...]
    ground: float
    frame_time: float
    leg_length: float
    double_support_fraction: float

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


def step_period(gait: "Gait", n_frames: int) -> float:
    """Mean step time [s] of a gait, NaN with fewer than two touchdowns or liftoffs.

    Measured from the sub-frame touchdown and liftoff times alike (two estimates, averaged by the number of
    steps each spans; a contact cut by the clip's start gives no liftoff: its extent is uncertain). Each sequence is used over a whole number of strides when it spans more than one step
    (an even number of steps), so a runner whose left and right steps differ is not biased by an odd step.
    """
    dt = gait.frame_time
    spans, steps = [], []
    for times in ([s.t_on for s in gait.stances if s.start > 0],
                  [s.t_off for s in gait.stances if 0 < s.start and s.stop < n_frames]):
        t = np.sort(np.asarray(times, float))
        n = len(t) - 1
        if n < 1:
            continue
        if n > 1 and n % 2:
            n -= 1  # whole strides: leave out one step at either end and average the two
            span = 0.5 * ((t[n] - t[0]) + (t[-1] - t[-1 - n]))
        else:
            span = t[n] - t[0]
        spans.append(span * dt)
        steps.append(n)
    if not steps or sum(spans) <= 0:
        return float("nan")
    return float(sum(spans) / sum(steps))


def detect_gait(motion: Motion, body: BodyModel, markers: np.ndarray | None = None) -> Gait:
    """Foot contacts, stances, flight phases and ground height of a motion.

    markers: optional precomputed foot markers (F, 2, 3, 3) [m] (``body.foot_markers(motion)``).
    """
    if markers is None:
        markers = body.foot_markers(motion)
    dt = motion.frame_time
    L = body.leg_length
    F = motion.n_frames
    height = markers[..., UP_AXIS]  # (F, 2, 3)
    vel = np.gradient(markers[..., _HORIZONTAL], dt, axis=0) if F > 1 else np.zeros(markers[..., :2].shape)
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
    stance_list.sort(key=lambda s: s.start)
    any_contact = contact.any(axis=1)
    flights = []
    if stance_list:
        first = min(s.start for s in stance_list)
        last = max(s.stop for s in stance_list)
        for a, b in _runs(~any_contact[first:last]):
            flights.append((first + a, first + b))
    ground = float(np.median([s.ground for s in stance_list])) if stance_list else global_ground
    both = contact.all(axis=1)
    return Gait(contact, tuple(stance_list), tuple(flights), ground, dt, L, float(both.mean()) if F else 0.0)


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


def flight_share(gait: Gait) -> float:
    """Share of the steps (consecutive contacts) of a gait that have a flight ≥ MIN_FLIGHT_S [0-1]."""
    steps = len(gait.stances) - 1
    if steps < 1:
        return 0.0
    return min(1.0, float((gait.flight_times() >= MIN_FLIGHT_S).sum()) / steps)


def summarize(motion: Motion, body: BodyModel, com: np.ndarray | None = None, gait: Gait | None = None) -> GaitSummary:
    """The gait summary behind ``froude info``: speed, Froude number U = u/√(g L), steps, phases, kind."""
    if com is None or gait is None:
        c, mk = body.com_and_markers(motion)
        com = c if com is None else com
        gait = detect_gait(motion, body, mk) if gait is None else gait
    dt = motion.frame_time
    disp = com[-1, _HORIZONTAL] - com[0, _HORIZONTAL]
    dist = float(np.linalg.norm(disp))
    duration = motion.duration
    speed = dist / duration if duration > 0 else 0.0
    heading = np.zeros(3)
    if dist > 0:
        heading[_HORIZONTAL] = disp / dist
    L = body.leg_length
    period = step_period(gait, motion.n_frames)
    step_freq = 1.0 / period if period > 0 else np.nan
    step_len = speed / step_freq if np.isfinite(step_freq) else np.nan
    flight_times = gait.flight_times()
    has_flight = flight_share(gait) >= RUNNING_FLIGHT_SHARE
    excursion = float(com[:, UP_AXIS].max() - com[:, UP_AXIS].min())
    kind, reason = classify(gait, speed, dist, L, has_flight)
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
            pa = np.array([np.interp(a, np.arange(n_frames), com[:, k]) for k in _HORIZONTAL])
            pb = np.array([np.interp(b, np.arange(n_frames), com[:, k]) for k in _HORIZONTAL])
            t_mid.append(0.5 * (a + b) * dt)
            speeds.append(float(np.linalg.norm(pb - pa) / ((b - a) * dt)))
    order = np.argsort(t_mid)
    return np.asarray(t_mid)[order], np.asarray(speeds)[order]


def ground_velocity(markers: np.ndarray, leg_length: float, frame_time: float) -> np.ndarray:
    """(3,) horizontal velocity of the balls of the feet while they rest on the ground [m/s] (a median).

    markers: (F, 2, 3, 3) [m]. The ball (the foot's middle marker, the toe joint) counts as resting while
    within 0.01 L of its own low level (5th percentile): it is the point a runner stands on from foot-flat
    to toe-off (the ankle centre moves on as the foot rolls off the heel). For a take with root travel this
    is ≈ 0; for an in-place take (treadmill-like, root travel removed) it is minus the running velocity: the
    planted foot slides back at the running speed. Joint centres sit above the floor, so a rolling foot
    still carries the ball's centre forward a little: on the CMU runs this reads 1-5 % below the speed.
    """
    if markers.shape[0] < 3:
        return np.zeros(3)
    ball = markers[:, :, 1]  # (F, 2, 3)
    vel = np.gradient(ball, frame_time, axis=0)
    h = ball[..., UP_AXIS]
    rest = h <= np.percentile(h, 5, axis=0) + 0.01 * leg_length
    v = np.median(vel[rest], axis=0) if rest.any() else np.zeros(3)
    v[UP_AXIS] = 0.0
    return v


def classify(gait: Gait, speed: float, distance: float, leg_length: float, has_flight: bool) -> tuple[str, str]:
    """('running' | 'walking' | 'in place' | 'unknown', reason)."""
    if distance < 1.0 * leg_length or speed < 0.15 * np.sqrt(GRAVITY * leg_length):
        return "in place", (
            f"no forward progression (travels {distance:.2f} m at {speed:.2f} m/s): not locomotion"
        )
    if len(gait.stances) < 2:
        return "unknown", f"only {len(gait.stances)} foot contact(s) found: a running fit needs at least two stances"
    if not has_flight:
        if gait.double_support_fraction > 0.02:
            return "walking", (
                f"no flight phase (both feet on the ground {100 * gait.double_support_fraction:.0f}% of the time): "
                "this is walking, not running"
            )
        return "unknown", "no flight phase between foot contacts: not running"
    return "running", f"flight phases between contacts, {speed:.2f} m/s"


def require_running(summary: GaitSummary, source: str = "motion") -> None:
    """Raise NotARunningMotion with a one-line reason unless the summary describes running."""
    if summary.kind != "running":
        raise NotARunningMotion(f"{source}: {summary.reason}")
