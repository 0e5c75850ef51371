"""The path of a take: where the body travels, how it turns, how it faces and leans (issue 28).

A take is a gait travelling along a path. The path is the whole-body COM's horizontal track smoothed over
one stride (a box average one stride long removes the step-by-step sway exactly and keeps the turn); along
it, per frame: arc length, travel heading, curvature, speed along the path, the facing of the pelvis against
the direction of travel; per step (touchdown to the next touchdown): heading change, radius, speed and the
lean (frontal-plane angle of the COM over the stance foot). The take's total heading change is the
direction of the COM's horizontal travel over the last W seconds minus that over the first W seconds, W =
0.6 s or one stride, whichever is longer, or a quarter of the take if that is shorter (``heading_change``).

Angles are about the up axis, + = to the left seen from above (a left turn is positive), in radians inside;
the ``*_deg`` figures are for reports. Everything here is measured from a motion alone, so the same code
describes a clip and an output made from it.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..core import quat
from ..core.constants import HORIZONTAL_AXES, UP, UP_AXIS
from ..core.motion import Motion
from .gait import Gait, step_period
from .model import BodyModel

#: Window over which the travel direction at each end of a take is taken for its total heading change [s]
#: (the SOURCES.md of ../shared/data/cmu-turns), or a quarter of the take if that is shorter.
HEADING_WINDOW_S = 0.6
#: Stride time [s] used to smooth the path when the take has too few contacts to measure its own: an adult's
#: walking stride (about 1.1 s) and running stride (0.7 s) lie about it.
FALLBACK_STRIDE_S = 1.0
#: A step whose heading changes less than this [rad] has no finite radius worth reporting (0.5 degree).
STRAIGHT_STEP_RAD = math.radians(0.5)
#: A clip whose total heading change is smaller than this [rad] is a straight take that veers: its outputs
#: are meant to run straight (the machines model it as it is, not straightened), and the report says how
#: much the clip veers. The straight takes of the shared data veer by up to 6.4 degrees (Bandai
#: dataset-2_walk_exhausted_001, whose SOURCES.md also says +6; CMU 02_01 +6.4); its turns turn 84-97 degrees.
STRAIGHT_TAKE_RAD = math.radians(10.0)
#: The reference horizontal direction from which headings are measured (the first horizontal axis, +X).
_E_REF = np.eye(3)[HORIZONTAL_AXES[0]]


@dataclass(frozen=True)
class PathStep:
    """One step of a take along its path: touchdown of ``foot`` to the next touchdown (either foot).

    t0_s, t1_s: its start and end [s]; heading_change_rad: travel heading at its end minus at its start
    (+ = left); radius_m: arc length / heading change (signed like the turn; inf when straight);
    speed_m_s: arc length / duration; lean_rad: mean frontal-plane angle of the COM over the stance foot's
    contact point while that foot is on the ground (+ = the COM left of the foot); facing_vs_travel_rad:
    mean facing minus travel heading; com_velocity_t0_m_s, com_velocity_t1_m_s: (3,) the COM's own horizontal
    velocity [m/s] at the step's start and end (from one touchdown of a foot to its next, the same phase of the
    gait, their difference over the time is the mean horizontal force per mass: the mean of the COM's
    acceleration telescopes).
    """

    foot: int
    t0_s: float
    t1_s: float
    arc_length_m: float
    heading_change_rad: float
    radius_m: float
    speed_m_s: float
    lean_rad: float
    facing_vs_travel_rad: float
    com_velocity_t0_m_s: tuple = (math.nan, math.nan, math.nan)
    com_velocity_t1_m_s: tuple = (math.nan, math.nan, math.nan)


@dataclass(frozen=True)
class TakePath:
    """The path of a take (SI units; angles [rad] about the up axis, + = left seen from above).

    p_world_path: (F, 3) the COM smoothed over a stride, on the COM's mean height [m]; arc_length_m: (F,)
    distance travelled along it from the first frame [m]; heading_rad: (F,) travel direction (unwrapped);
    curvature_1_m: (F,) dheading/ds [1/m]; speed_m_s: (F,) speed along the path; facing_rad: (F,) the
    pelvis' facing (unwrapped; NaN without hip joints); facing_vs_travel_rad: (F,) facing minus travel,
    wrapped to (-pi, pi]: 0 forwards, +-pi/2 side steps, pi backwards. heading_change_rad: the take's
    total (windowed, see the module); window_s: the window used; stride_s: the smoothing length;
    com_world: (F, 3) the COM the path was measured from [m] (None: not kept).
    """

    frame_time: float
    p_world_path: np.ndarray
    arc_length_m: np.ndarray
    heading_rad: np.ndarray
    curvature_1_m: np.ndarray
    speed_m_s: np.ndarray
    facing_rad: np.ndarray
    facing_vs_travel_rad: np.ndarray
    heading_change_rad: float
    window_s: float
    stride_s: float
    steps: tuple[PathStep, ...]
    com_world: np.ndarray | None = None

    @property
    def length_m(self) -> float:
        """Arc length of the whole path [m]."""
        return float(self.arc_length_m[-1]) if self.arc_length_m.size else 0.0

    @property
    def path_speed_m_s(self) -> float:
        """Mean speed along the path [m/s]: its arc length over the take's duration."""
        n = self.arc_length_m.size
        return self.length_m / ((n - 1) * self.frame_time) if n > 1 else float("nan")

    def speed_around(self, place_m: np.ndarray | float, window_s: float) -> np.ndarray:
        """(...) the mean speed along the path [m/s] over window_s [s] of the take centred where it passes the
        places place_m (...) [m of arc length]; the window kept inside the take (the mean speed where the
        take is shorter than it)."""
        arc = np.maximum.accumulate(self.arc_length_m)
        t = np.arange(arc.size) * self.frame_time
        if arc.size < 2 or not t[-1] > window_s:
            return np.full(np.shape(place_m), self.path_speed_m_s)
        half = 0.5 * window_s
        mid = np.clip(np.interp(place_m, arc, t), half, t[-1] - half)
        return (np.interp(mid + half, t, arc) - np.interp(mid - half, t, arc)) / window_s

    def speed_factors(self, step_length_m: float, n_steps: int, window_s: float) -> np.ndarray:
        """(n_steps,) the take's speed along its path where each of n_steps output steps goes, over its mean [-].

        A walker slows into a turn and speeds up out of it (the shared walk-turns: 0.64 m/s where they turn most
        against 0.88-1.01 on the straights), a runner brakes into it (CMU 16_51: 3.1 m/s before, 2.3 in it); an
        output at one speed shows a blunter turn than the take's path and leans as a faster or slower body
        would. step_length_m: an output step on this path at factor 1 (its length / L) [m]; each step's factor
        is the take's speed over window_s [s] (one of its steps) around the step's middle, the steps laid one
        after another by their factors; past the take's end, 1 (the machine's speed).
        """
        end, v_mean = float(np.max(self.arc_length_m)), self.path_speed_m_s
        out, x = np.ones(n_steps), 0.0
        for i in range(n_steps):
            f = float(self.speed_around(x + 0.5 * step_length_m, window_s)) / v_mean
            f = float(self.speed_around(x + 0.5 * f * step_length_m, window_s)) / v_mean  # at its own middle
            if x + 0.5 * f * step_length_m > end:
                break
            out[i] = f
            x += f * step_length_m
        return out

    @property
    def travel_heading_change_rad(self) -> float:
        """The heading change from the travel over the take's first stride to that over its last [rad]: the
        path's heading at its end minus at its start (``smooth_path`` continues the track by its end strides,
        so these are the directions of the COM's chords over them; NaN without frames).

        Over a whole stride the sway cancels; over the shorter windows of a short take's
        ``heading_change_rad`` (a quarter of it) the sway tilts each chord by its phase there: 7.8 degrees
        between the two on walk-turn-left_normal_001 (3.4 s: +96.4 against +88.6 here). An output is
        compared with its clip on this (``report.path_report``): its steps need not fall at the clip's phases
        of the sway. Where the window is a stride the two agree (within 0.4 degrees on the shared turns:
        the window's frames are rounded differently)."""
        h = self.heading_rad
        return float(h[-1] - h[0]) if h.size else float("nan")

    @property
    def n_steps(self) -> float:
        """How many steps the take spans: its duration over the step time (half the stride) [-]."""
        return (self.arc_length_m.size - 1) * self.frame_time / (0.5 * self.stride_s)

    def travel_line(self) -> tuple[np.ndarray, np.ndarray]:
        """The line the body travels along, without the stride average's blur: (heading (F,) [rad], arc length
        (F,) [m]) per frame of the COM's track without its periodic sway (``unswayed_track``; without
        alternating steps to give the sway's phase, or without the COM, the track whose stride average is this
        path, ``unsmooth_path``).

        The path is the COM averaged over a stride, so it cuts a turn's corner (on two walk-turns of the shared
        data 1.3 and 1.9 % shorter than the path averaged again). An output made to travel along the path itself
        and measured the same way was averaged twice: up to 2.9 % slower along its path than the clip x sqrt(L)
        and turning up to 6 degrees less over its end chords (benchmarks/turns_matrix.py, docs/path.md).
        """
        track = None
        if self.com_world is not None:
            track = unswayed_track(self.com_world, self.p_world_path, self.heading_rad, self.steps,
                                   self.frame_time, self.stride_s)
        if track is None:
            track = unsmooth_path(self.p_world_path, _stride_frames(self.stride_s, self.frame_time))
        arc, heading, _ = _track_geometry(track, self.frame_time)
        # the same branch of the angle as the path's (the bend turns by heading differences from its start)
        if heading.size:
            heading += 2 * np.pi * np.round((self.heading_rad[0] - heading[0]) / (2 * np.pi))
        return heading, arc

    @property
    def mean_facing_vs_travel_rad(self) -> float:
        """Circular mean of the facing-vs-travel angle [rad] (NaN without a facing)."""
        a = self.facing_vs_travel_rad[np.isfinite(self.facing_vs_travel_rad)]
        return float(np.angle(np.mean(np.exp(1j * a)))) if a.size else float("nan")

    def to_dict(self) -> dict:
        """The figures ``info`` and the report print, in degrees and SI units (JSON-able, no NaN)."""
        def deg(v):
            return _finite(math.degrees(v), 2)

        return {
            "heading_change_deg": deg(self.heading_change_rad),
            "heading_window_s": round(self.window_s, 3),
            "path_length_m": round(self.length_m, 4),
            "path_speed_m_s": _finite(self.path_speed_m_s, 4),
            "facing_vs_travel_deg": deg(self.mean_facing_vs_travel_rad),
            "steps": [{"foot": "left" if s.foot == 0 else "right", "start_s": round(s.t0_s, 4),
                       "stop_s": round(s.t1_s, 4), "heading_change_deg": deg(s.heading_change_rad),
                       "radius_m": _finite(s.radius_m, 3), "speed_m_s": _finite(s.speed_m_s, 4),
                       "lean_deg": deg(s.lean_rad), "facing_vs_travel_deg": deg(s.facing_vs_travel_rad)}
                      for s in self.steps],
        }


def _finite(v: float, digits: int):
    return round(float(v), digits) if math.isfinite(v) else None


def yaw_of(v_world: np.ndarray) -> np.ndarray:
    """(...,) heading angle [rad] of horizontal directions (..., 3) about the up axis from +X, + = left.

    The angle turning _E_REF into v about UP (right-handed): with Y up, a direction rotated towards -Z.
    """
    v = np.asarray(v_world, float)
    return np.arctan2(np.cross(_E_REF, v) @ UP, v @ _E_REF)


def direction_of(yaw_rad: np.ndarray) -> np.ndarray:
    """(..., 3) horizontal unit directions of heading angles (...,) [rad]: the inverse of ``yaw_of``."""
    a = np.asarray(yaw_rad, float)[..., None]
    return np.cos(a) * _E_REF + np.sin(a) * np.cross(UP, _E_REF)


def wrap_angle(a):
    """Angles [rad] wrapped to (-pi, pi]."""
    return np.pi - np.mod(np.pi - np.asarray(a, float), 2.0 * np.pi)


def heading_window_s(duration_s: float, stride_s: float) -> float:
    """W [s] of the total heading change: the longer of HEADING_WINDOW_S and one stride (stride_s [s]), or a
    quarter of the take if that is shorter."""
    return min(max(HEADING_WINDOW_S, stride_s), 0.25 * duration_s)


def heading_change(com: np.ndarray, frame_time: float, stride_s: float,
                   window_s: float | None = None) -> tuple[float, float]:
    """Total heading change of a take [rad] and the window W [s] it was measured over.

    com: (F, 3) [m]; stride_s: the take's stride time [s]. The direction of the horizontal COM travel over
    the last W s (the chord from the frame W before the end to the end) minus that over the first W s,
    wrapped to (-pi, pi]; + = left. W (``heading_window_s``) is 0.6 s as in the shared data's SOURCES.md,
    but at least one stride: over a whole stride the COM's side-to-side sway from one foot to the other
    cancels, while over half a stride it tilts a walk's chord by up to 7 degrees either way (Bandai
    straight walks, measured). window_s: that window given instead. NaN when the take has fewer than 3
    frames or does not travel in a window.
    """
    F = com.shape[0]
    w = heading_window_s((F - 1) * frame_time, stride_s) if window_s is None else float(window_s)
    n = max(1, int(round(w / frame_time)))
    if F < 3 or n >= F:
        return float("nan"), w
    first, last = com[n] - com[0], com[-1] - com[-1 - n]
    first[UP_AXIS] = last[UP_AXIS] = 0.0
    if not (np.linalg.norm(first) > 0 and np.linalg.norm(last) > 0):
        return float("nan"), w
    return float(wrap_angle(yaw_of(last) - yaw_of(first))), n * frame_time


def smooth_path(com: np.ndarray, n_box: int) -> np.ndarray:
    """(F, 3) the COM's horizontal track averaged over n_box frames (its height: the mean) [m].

    A centred box average one stride (n_box frames) long. Beyond the ends the track is continued by its
    first (last) stride repeated, moved on by that stride's travel: the sway then cancels at the ends
    too, and the path's heading there is the travel direction over the first (last) stride. A take of
    one stride or less is continued by point reflection about its end frames (2 p_0 − p_k).
    """
    F = com.shape[0]
    out = np.empty_like(com, dtype=float)
    out[:, UP_AXIS] = com[:, UP_AXIS].mean() if F else 0.0
    h = min(n_box // 2, F - 1)
    if h < 1:
        out[:, HORIZONTAL_AXES] = com[:, HORIZONTAL_AXES]
        return out
    x = com[:, HORIZONTAL_AXES]
    n = 2 * h + 1
    if F > n:
        head = x[n - h : n] - (x[n] - x[0])  # x[-j] = x[n - j] - (x[n] - x[0]), j = h..1
        tail = x[F - 1 - n + 1 : F - n + h] + (x[-1] - x[F - 1 - n])
    else:
        head, tail = 2 * x[0] - x[h:0:-1], 2 * x[-1] - x[-2 : -2 - h : -1]
    padded = np.concatenate([head, x, tail])
    c = np.cumsum(np.concatenate([np.zeros((1, x.shape[1])), padded]), axis=0)
    out[:, HORIZONTAL_AXES] = (c[2 * h + 1 :] - c[: -2 * h - 1]) / (2 * h + 1)
    return out


def unsmooth_path(p_path: np.ndarray, n_box: int) -> np.ndarray:
    """(F, 3) a track whose stride average (``smooth_path`` over n_box frames) is p_path (F, 3) [m], nearly: the
    travel line of a take whose steps give no phase for its sway (``unswayed_track``, ``TakePath.travel_line``).

    x = p + S(1 − S) p + S(1 − S)² p, S the stride average: the inverse's series S⁻¹ = Σ (1 − S)^k to its
    third term, the two after the first filtered by S. Of a turn's component over two strides (where S =
    sinc(π/2) ≈ 0.64) the average of x keeps 84 % (the path itself 64 %, with the first correction alone
    78 %). Like the path it has nothing at the sway's frequencies (multiples of the
    stride frequency, where S is zero), and it amplifies nothing by more than 1.39 (at S = 0.42): the plain
    deconvolution x <- x + (p − S x), tried, doubled what the path keeps of a sway whose period drifts from
    the stride's, and the outputs made along it skated. The second term (29 Nov): the shared walk-turns'
    outputs met the heading per step on 39 of 47 (35 with the first term alone) and the radius per step on
    14 of 30 (7) (``benchmarks/turns_matrix.py``; docs/path.md).
    """
    p = np.asarray(p_path, dtype=float)
    x = p.copy()
    rest = p - smooth_path(p, n_box)  # (1 − S) p
    x[:, HORIZONTAL_AXES] += smooth_path(rest, n_box)[:, HORIZONTAL_AXES]
    rest = rest - smooth_path(rest, n_box)  # (1 − S)² p
    x[:, HORIZONTAL_AXES] += smooth_path(rest, n_box)[:, HORIZONTAL_AXES]
    return x


#: Harmonics of the stride in a take's periodic sway (``periodic_sway``): the COM sways sideways once a stride and
#: surges along the travel once a step; 2 and 6 harmonics made the same outputs of the shared walk-turns within
#: one of 47 (``benchmarks/turns_matrix.py``).
SWAY_HARMONICS = 4


def stride_phase(steps: tuple[PathStep, ...], n_frames: int, frame_time: float) -> np.ndarray | None:
    """(F,) the stride phase per frame [strides]: foot 0 touches down at whole numbers, foot 1 at halves;
    linear between the steps' touchdowns, on at their mean step time before the first and past the last.
    None with fewer than 3 steps or steps whose feet do not alternate (no phase to hang a sway on)."""
    if len(steps) < 3 or any(a.foot == b.foot for a, b in zip(steps[:-1], steps[1:])):
        return None
    t_on = np.array([st.t0_s for st in steps] + [steps[-1].t1_s])  # (n + 1,) [s]
    u = np.arange(t_on.size, dtype=float) + (steps[0].foot % 2)  # steps since a touchdown of foot 0
    step_s = (t_on[-1] - t_on[0]) / (t_on.size - 1)
    t = np.arange(n_frames) * frame_time
    out = np.interp(t, t_on, u)
    out = np.where(t < t_on[0], u[0] + (t - t_on[0]) / step_s, out)
    out = np.where(t > t_on[-1], u[-1] + (t - t_on[-1]) / step_s, out)
    return 0.5 * out


def periodic_sway(com: np.ndarray, p_path: np.ndarray, heading_rad: np.ndarray, phase: np.ndarray,
                  harmonics: int = SWAY_HARMONICS) -> np.ndarray:
    """(F, 3) the part of the COM's horizontal offset from its path [m] that repeats every stride: the offset
    along and across the travel (heading_rad (F,)) fitted over the whole take by a Fourier series of the stride
    phase (F,) [strides] without its constant (least squares). com, p_path: (F, 3) [m]. This is what the
    machines make of a take: one stride, repeated; the rest of the offset (the corner a turn cuts, a stride
    unlike the others) is the take's own path."""
    d = com - p_path
    d[:, UP_AXIS] = 0.0
    fwd, left = direction_of(heading_rad), direction_of(heading_rad + 0.5 * np.pi)
    offset = np.stack([np.einsum("ij,ij->i", d, fwd), np.einsum("ij,ij->i", d, left)], axis=1)  # (F, 2)
    angle = 2.0 * np.pi * phase[:, None] * np.arange(1, harmonics + 1)
    basis = np.concatenate([np.cos(angle), np.sin(angle)], axis=1)  # (F, 2 harmonics)
    coef, *_ = np.linalg.lstsq(basis, offset, rcond=None)
    fit = basis @ coef  # (F, 2) along, across
    return fit[:, :1] * fwd + fit[:, 1:] * left


def unswayed_track(com: np.ndarray, p_path: np.ndarray, heading_rad: np.ndarray, steps: tuple[PathStep, ...],
                   frame_time: float, stride_s: float) -> np.ndarray | None:
    """(F, 3) the COM's track without its periodic sway (``periodic_sway``) [m], on the path's height; None
    when the steps give no stride phase (``stride_phase``).

    An output is the machines' stride, sway included, carried along a line; measured as the clip was (its COM
    averaged over a stride), it has the clip's path when that line is the clip's COM less the sway the
    machines put back, whatever the stride average blurs: the stride average's inverse (``unsmooth_path``)
    gave back 84 % of a turn over two strides, and the shared walk-turns' outputs missed the radius per step
    by 4-19 % (14 of 24; 7 with this line, ``benchmarks/turns_matrix.py``). Over the first and the last
    stride the track goes over to the path (a smoothstep of the distance from the end): past the clip's ends
    an output runs straight on in the line's end direction, which a few frames' velocity of the track would
    set up to 10 degrees off the travel over the end stride (the sway's phase is extrapolated there).
    com, p_path: (F, 3) [m]; heading_rad: (F,) the path's; stride_s [s].
    """
    F = com.shape[0]
    phase = stride_phase(steps, F, frame_time)
    if phase is None:
        return None
    rest = com - periodic_sway(com, p_path, heading_rad, phase) - p_path
    rest[:, UP_AXIS] = 0.0
    i = np.arange(F)
    u = np.clip(np.minimum(i, F - 1 - i) / max(stride_s / frame_time, 1.0), 0.0, 1.0)
    return p_path + (u * u * (3.0 - 2.0 * u))[:, None] * rest


def facing_yaw(motion: Motion, body: BodyModel) -> np.ndarray:
    """(F,) the pelvis' facing [rad] (unwrapped): forward = UP × (right hip − left hip). NaN without hips."""
    roles = body.roles
    if "left_hip" not in roles or "right_hip" not in roles:
        return np.full(motion.n_frames, np.nan)
    hips = body.joint_positions(motion, [roles["left_hip"], roles["right_hip"]])  # (F, 2, 3)
    fwd = np.cross(UP, hips[:, 1] - hips[:, 0])
    return np.unwrap(yaw_of(fwd))


def _stride_frames(stride_s: float, frame_time: float) -> int:
    """The stride average's window [frames] (``smooth_path``'s n_box): one stride, at least one frame."""
    return max(1, int(round(stride_s / frame_time)))


def _track_geometry(p_world: np.ndarray, frame_time: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(arc length (F,) [m], heading (F,) [rad, unwrapped], horizontal velocity (F, 3) [m/s]) of a track
    p_world (F, 3) [m] sampled every frame_time [s]: its horizontal distance travelled and direction."""
    F = p_world.shape[0]
    d = np.diff(p_world[:, HORIZONTAL_AXES], axis=0) if F > 1 else np.zeros((0, 2))
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(d, axis=1))])
    vel = np.gradient(p_world, frame_time, axis=0) if F > 1 else np.zeros_like(p_world)
    vel[:, UP_AXIS] = 0.0
    heading = np.unwrap(yaw_of(vel)) if F else np.zeros(0)
    return s, heading, vel


def take_path(motion: Motion, body: BodyModel, com: np.ndarray, gait: Gait,
              window_strides: float | None = None) -> TakePath:
    """The path of a take (``TakePath``) from its COM (F, 3) [m] and gait (for the stride and the steps).

    window_strides: measure the total heading change over this many of the take's strides at each end
    instead of ``heading_window_s``'s window: an output is measured over the same share of its stride as
    the clip it is compared with (the COM's sway then tilts both chords alike; a short clip's window is a
    quarter of it, less than a stride).
    """
    F, dt = motion.n_frames, motion.frame_time
    period = step_period(gait, F, com)
    stride_s = 2.0 * period if np.isfinite(period) and period > 0 else FALLBACK_STRIDE_S
    p = smooth_path(com, _stride_frames(stride_s, dt))
    s, heading, vel = _track_geometry(p, dt)
    speed = np.linalg.norm(vel, axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        curvature = np.gradient(heading, dt) / speed if F > 1 else np.zeros(F)
    curvature = np.where(speed > 0, curvature, np.nan)
    facing = facing_yaw(motion, body)
    fvt = wrap_angle(facing - heading)
    total, w = heading_change(com, dt, stride_s, None if window_strides is None else window_strides * stride_s)
    steps = _steps(gait, com, s, heading, fvt, F, dt)
    return TakePath(dt, p, s, heading, curvature, speed, facing, fvt, total, w, stride_s, steps, com)


def _steps(gait: Gait, com: np.ndarray, s: np.ndarray, heading: np.ndarray, fvt: np.ndarray, F: int,
           dt: float) -> tuple[PathStep, ...]:
    """Per step, touchdown to the next touchdown (stances that begin inside the take)."""
    on = sorted((st for st in gait.stances if st.start > 0), key=lambda st: st.start)
    frames = np.arange(F)
    u = np.gradient(com, dt, axis=0) if F > 1 else np.zeros_like(com)
    u[:, UP_AXIS] = 0.0

    def u_at(t):
        return tuple(float(np.interp(t, frames, u[:, k])) for k in range(3))
    out = []
    for a, b in zip(on[:-1], on[1:]):
        t0 = a.t_on if math.isfinite(a.t_on) else float(a.start)
        t1 = b.t_on if math.isfinite(b.t_on) else float(b.start)
        if not t1 > t0:
            continue
        arc = float(np.interp(t1, frames, s) - np.interp(t0, frames, s))
        dpsi = float(np.interp(t1, frames, heading) - np.interp(t0, frames, heading))
        radius = arc / dpsi if abs(dpsi) >= STRAIGHT_STEP_RAD else math.copysign(math.inf, dpsi or 1.0)
        # lean: the COM over the stance foot's contact point, in the frontal plane of the travel direction
        i0, i1 = a.start, min(a.stop, F)
        dcom = com[i0:i1] - a.contact_point
        psi = heading[i0:i1]
        # left of travel: the travel direction turned a quarter turn to the left about UP
        left = direction_of(psi + 0.5 * np.pi)
        lean = float(np.mean(np.arctan2(np.einsum("ij,ij->i", dcom, left), dcom[:, UP_AXIS])))
        seg = fvt[int(t0) : int(math.ceil(t1)) + 1]
        seg = seg[np.isfinite(seg)]
        f_t = float(np.angle(np.mean(np.exp(1j * seg)))) if seg.size else float("nan")
        out.append(PathStep(a.foot, t0 * dt, t1 * dt, arc, dpsi, radius, arc / ((t1 - t0) * dt), lean, f_t,
                            u_at(t0), u_at(t1)))
    return tuple(out)


def is_straight(path: TakePath) -> bool:
    """A take that veers by less than STRAIGHT_TAKE_RAD (or whose heading change is not measurable)."""
    return not abs(path.heading_change_rad) >= STRAIGHT_TAKE_RAD


def turn_note(path: TakePath) -> str:
    """What a turning take's output does, in the user's terms (a note of ``pipeline.prepare``)."""
    return (f"a turning take ({math.degrees(path.heading_change_rad):+.0f} deg over {path.length_m:.2f} m): the "
            f"machine runs along its path, {path.path_speed_m_s:.2f} m/s, and the output follows the path (scaled "
            "with the character)")


def yaw_quat(angle_rad: np.ndarray) -> np.ndarray:
    """(..., 4) rotations (w, x, y, z) by angle_rad (...,) about the up axis (+ = to the left)."""
    a = np.asarray(angle_rad, float)
    return quat.from_axis_angle(np.broadcast_to(UP, a.shape + (3,)), a)


def yaw_carrier(motion: Motion) -> int:
    """The joint that a turn about the up axis is given to when a take is straightened or put back: the root,
    or, on a rig whose root does not turn over the take and holds one child (Bandai's joint_Root over its
    Hips), that child. Turned at a static root, the body's heading was split between the root (the path's turn) and
    its child (the body's own): averaged over a stride's occurrences at different places of the turn, the
    reference stride's two rotations jumped at its loop by the turn of a stride, which the pose keeps where
    their sum does not (walk-turn-right_normal_001's outputs: the root 29 degrees in one frame)."""
    sk = motion.skeleton
    kids = np.flatnonzero(np.asarray(sk.parents) == 0)
    if kids.size != 1 or motion.n_frames < 2:
        return 0
    still = np.ptp(motion.rotations[:, 0], axis=0).max() <= 1e-9
    return int(kids[0]) if still else 0


def turn_about_up(motion: Motion, q: np.ndarray, root_world: np.ndarray, carrier: int) -> Motion:
    """The motion with each frame turned by q (F, 4) about the up axis, its root at root_world (F, 3) [m] as a
    point of the body moved rigidly: the root turned (carrier 0), or its one child turned within it and the
    root moved so that the child lands where the rigid move puts it."""
    from dataclasses import replace

    rot = motion.rotations.copy()
    root = root_world
    if carrier == 0:
        rot[:, 0] = quat.mul(q, rot[:, 0])
    else:
        r0 = rot[:, 0]
        rot[:, carrier] = quat.mul(quat.mul(quat.conj(r0), quat.mul(q, r0)), rot[:, carrier])
        off = quat.rotate(r0, motion.local_translations()[:, carrier])  # (F, 3) the child from the root
        root = root_world + quat.rotate(q, off) - off
        root[:, UP_AXIS] = root_world[:, UP_AXIS]
    return replace(motion, root_positions=root, rotations=rot)


def straighten(motion: Motion, path: TakePath) -> Motion:
    """The take unrolled onto a straight line: each frame moved rigidly so that its point of the path
    lands at its arc length along the path's first direction, turned by the heading it has gained.

    Frame i is turned about the up axis by −(heading_i − heading_0) about the path point P_i and carried to
    P_0 + s_i · direction(heading_0): the COM keeps its offset from the path (its sway and lean) in the
    path's own frame, the travel becomes straight at the speed along the path. A foot planted while the
    path turns moves a little in the straightened take (rigid per frame: about a δ²/2 sideways and a δ
    along for a foot n from the path and an angle δ = Δs/r of turn between it and the COM). In a gentle
    walk-turn that is centimetres; in CMU 16_51's sharp running turn a planted foot moves 0.3-0.4 m over
    a stance (measured in the turns3 work, issue 28), which is why that clip's fit refuses it. The turn is
    given to ``yaw_carrier``'s joint. The inverse, point by point, is ``synthesis.bend``. Returns a new
    Motion (meta "straightened": the heading change undone [rad]).
    """
    from dataclasses import replace

    dpsi = path.heading_rad - path.heading_rad[0]  # (F,)
    q = yaw_quat(-dpsi)  # (F, 4)
    p0 = path.p_world_path[0]
    fwd0 = direction_of(path.heading_rad[0])
    rel = motion.root_positions - path.p_world_path
    rel[:, UP_AXIS] = motion.root_positions[:, UP_AXIS]
    root = p0 * (1 - UP) + path.arc_length_m[:, None] * fwd0 + quat.rotate(q, rel)
    out = turn_about_up(motion, q, root, yaw_carrier(motion))
    meta = dict(motion.meta)
    meta["straightened"] = float(dpsi[-1]) if dpsi.size else 0.0
    return replace(out, meta=meta)


def unstraighten_points(x_straight: np.ndarray, path: TakePath) -> np.ndarray:
    """Points of a take straightened by ``straighten`` put back where the take was: (F, ..., 3) [m], frame i's
    points moved by the inverse of frame i's rigid move (turned back by its heading gain about the path point,
    up kept). Exact per frame: a point planted in the take comes back planted."""
    x = np.asarray(x_straight, float)
    F = path.heading_rad.shape[0]
    if x.shape[0] != F:
        raise ValueError(f"{x.shape[0]} frames of points for a path of {F} frames")
    dpsi = path.heading_rad - path.heading_rad[0]  # (F,)
    extra = (1,) * (x.ndim - 2)
    q = yaw_quat(dpsi).reshape((F, *extra, 4))
    p_to = (path.p_world_path[0] * (1 - UP) + path.arc_length_m[:, None] * direction_of(path.heading_rad[0]))
    p_from = path.p_world_path * (1 - UP)
    rel = x - p_to.reshape((F, *extra, 3))
    rel[..., UP_AXIS] = x[..., UP_AXIS]
    out = p_from.reshape((F, *extra, 3)) + quat.rotate(np.broadcast_to(q, rel.shape[:-1] + (4,)), rel)
    out[..., UP_AXIS] = x[..., UP_AXIS]
    return out


def unstraighten(motion: Motion, path: TakePath) -> Motion:
    """The inverse of ``straighten``: a straightened take (or anything on its frames) back on the path as
    taken. Returns a new Motion without the "straightened" meta."""
    from dataclasses import replace

    dpsi = path.heading_rad - path.heading_rad[0]
    root = unstraighten_points(motion.root_positions, path)
    out = turn_about_up(motion, yaw_quat(dpsi), root, yaw_carrier(motion))
    meta = {k: v for k, v in motion.meta.items() if k != "straightened"}
    return replace(out, meta=meta)
