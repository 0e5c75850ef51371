"""The physics report: what any motion does physically, and for outputs how well it tracks its machine.

Every figure is measured from the motion itself (its COM from the body model and its foot markers), so
the same report judges a mocap clip, froude's output and a naive retarget alike. Written next to every
output as ``*.report.json``.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np

from ..body.com_force import FLIGHT_MIN_FRAMES, flight_gravity, vertical_force_bw
from ..body.footing import (
    SKATE_BAND_L,
    SKATE_MARKERS,
    SKATE_REACH_L,
    floor_height,
    skate_windows,
    stance_rest_heights,
)
from ..body.gait import Gait, detect_gait, summarize
from ..body.model import SIDES, BodyModel
from ..body.path import TakePath, is_straight, take_path
from ..core import quat
from ..core.constants import GRAVITY, HORIZONTAL_AXES, UP_AXIS
from ..core.motion import Motion, max_joint_jump_deg
from ..io.atomic import atomic_write_text
from ..io.jsonable import dumps, jsonable
from ..machine.speed_law import STEP_MAX_PER_STATURE
from .path_report import path_comparison

#: The project's physics bars (docs/architecture.md, "Quality bars").
BARS = {
    "flight_gravity_rel_tol": 0.03,
    "com_tracking_rms_mm": 5.0,
    "com_tracking_max_mm": 10.0,
    "foot_skate_mm": 5.0,
    "foot_skate_floor_mm": 5.0,
    "penetration_mm": 5.0,
    "joint_jump_ratio": 1.5,
    "rest_height_L": 0.003,
    "step_length_stature": STEP_MAX_PER_STATURE,
}


#: Why a report figure is ``null`` (written beside it as ``unmeasured``).
UNMEASURED = {
    "flight_gravity_m_s2": "no flight phase of at least 3 frames (a parabola needs 3 samples)",
    "flight_horizontal_accel_m_s2": "no flight phase of at least 3 frames",
    "step_frequency_hz": "fewer than two touchdowns or two liftoffs inside the motion",
    "step_length_m": "fewer than two touchdowns or two liftoffs inside the motion",
    "peak_vertical_force_bw": "motion too short (at most 8 frames) to differentiate the COM",
    "leg_stiffness_n_m": "no complete stance with a measurable leg compression",
    "leg_stiffness_K": "no complete stance with a measurable leg compression",
    "com_tracking_rms_mm": "no machine COM to track (not a physical output)",
    "com_tracking_max_mm": "no machine COM to track (not a physical output)",
    "foot_marker_rms_mm": "no foot targets (not a physical output)",
    "foot_marker_max_mm": "no foot targets (not a physical output)",
    "pose_deviation_mean_deg": "no reference pose given",
    "pose_deviation_max_deg": "no reference pose given",
    "reference_max_joint_jump_deg": "no reference given",
    "froude_U": "no leg length",
    "rest_height_error_mm": "no source rest heights given, or no whole stance of a foot in one of the motions",
    "max_step_length_m": "fewer than two whole foot contacts inside the motion",
    "floor_m": "no foot contact",
}

#: Foot marker names in the report, in the body model's order.
MARKER_NAMES = ("ankle", "ball", "tip")


@dataclass
class Report:
    """Physics report of a motion (SI units unless the name says otherwise). NaN: not measurable."""

    duration_s: float
    n_frames: int
    frame_rate_hz: float
    mean_speed_m_s: float
    froude_U: float
    leg_length_m: float
    mass_kg: float
    step_frequency_hz: float
    step_length_m: float
    stance_times_s: list
    flight_times_s: list
    com_vertical_excursion_m: float
    flight_gravity_m_s2: float
    flight_gravity_per_phase: list
    flight_horizontal_accel_m_s2: float
    foot_skate_mm: float
    #: the stricter skate measure (issue 13, docs/architecture.md quality bars): ball and tip, whole stance
    #: including touchdown and lift-off, while within 2 % of L of the floor: one of the bars (check_bars).
    foot_skate_floor_mm: float
    penetration_mm: float
    float_mm: float
    peak_vertical_force_bw: float
    leg_stiffness_n_m: float
    leg_stiffness_K: float
    max_joint_jump_deg: float
    # outputs only
    com_tracking_rms_mm: float = float("nan")
    com_tracking_max_mm: float = float("nan")
    foot_marker_rms_mm: float = float("nan")
    foot_marker_max_mm: float = float("nan")
    pose_deviation_mean_deg: float = float("nan")
    pose_deviation_max_deg: float = float("nan")
    reference_max_joint_jump_deg: float = float("nan")
    #: the floor the rest heights are measured from [m] and how it was found (``floor_height``)
    floor_m: float = float("nan")
    floor_found: str = ""
    #: per foot (left, right) and marker (ankle, ball, tip): the median over the foot's whole stances of the
    #: marker's lowest height in the stance above the floor [mm] (``stance_rest_heights``); None if no stance
    rest_height_mm: dict = field(default_factory=dict)
    #: the same of the source, scaled by L [mm] (what the output should rest at), when given
    source_rest_height_mm: dict = field(default_factory=dict)
    #: the largest |foot rest height - source's| over both feet [mm] (a foot's: its lowest marker's;
    #: ``rest_height_error``), and its foot, the marker it rests on and the frames of that foot's stances
    rest_height_error_mm: float = float("nan")
    rest_height_worst: dict = field(default_factory=dict)
    #: the longest step (horizontal distance between consecutive contacts of the two feet) [m], and the
    #: stature it is held against [m], with the frames of the two contacts
    max_step_length_m: float = float("nan")
    stature_m: float = float("nan")
    longest_step: dict = field(default_factory=dict)
    #: where the stricter skate is largest: foot, marker and frames
    skate_worst: dict = field(default_factory=dict)
    extras: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        """Plain JSON-able dict: NaN/Infinity become ``null`` and ``unmeasured`` says why for each such field."""
        d = asdict(self)
        out = {"schema": "froude.report/1", **{k: jsonable(v) for k, v in d.items()}}
        out["unmeasured"] = {k: UNMEASURED.get(k, "not measurable on this motion")
                             for k, v in out.items() if v is None}
        return out

    def to_json(self) -> str:
        """Strict JSON (no NaN/Infinity tokens: any parser reads it)."""
        return dumps(self.to_dict(), indent=2)

    def check_bars(self) -> list[str]:
        """Which of the project's physics bars this report fails (empty list: all pass)."""
        fails = []
        # the output's path against the clip's (``path_report``): a turn lost is a bar missed
        fails += list(self.extras.get("path_vs_clip", {}).get("misses", []))
        g_err = abs(self.flight_gravity_m_s2 - GRAVITY) / GRAVITY
        # an output of a kind without flight (a walk: ``kinds.MotionKind.has_flight``) has none to measure
        if self.extras.get("flights", True) and not g_err <= BARS["flight_gravity_rel_tol"]:
            fails.append(f"flight gravity {self.flight_gravity_m_s2:.2f} m/s^2 (9.81 +- 3%)")
        if not np.isnan(self.com_tracking_rms_mm):
            if not self.com_tracking_rms_mm <= BARS["com_tracking_rms_mm"]:
                fails.append(f"COM tracking RMS {self.com_tracking_rms_mm:.2f} mm (<= 5)")
            if not self.com_tracking_max_mm <= BARS["com_tracking_max_mm"]:
                fails.append(f"COM tracking max {self.com_tracking_max_mm:.2f} mm (<= 10)")
        if not self.foot_skate_mm <= BARS["foot_skate_mm"]:
            fails.append(f"foot skate {self.foot_skate_mm:.2f} mm (<= 5)")
        if not self.foot_skate_floor_mm <= BARS["foot_skate_floor_mm"]:
            fails.append(f"foot skate (ball and tip near the floor) {self.foot_skate_floor_mm:.2f} mm (<= 5)"
                         + _where(self.skate_worst))
        if not self.penetration_mm <= BARS["penetration_mm"]:
            fails.append(f"ground penetration {self.penetration_mm:.2f} mm (<= 5)")
        if not np.isnan(self.rest_height_error_mm):
            tol = 1000.0 * BARS["rest_height_L"] * self.leg_length_m
            if not self.rest_height_error_mm <= tol:
                w = self.rest_height_worst
                fails.append(
                    f"{w['foot']} foot rests {abs(w['error_mm']):.1f} mm {'above' if w['error_mm'] > 0 else 'below'} "
                    f"the source's stance height (on its {w['marker']}, {w['height_mm']:.1f} mm over the floor; "
                    f"the source's foot {w['expected_mm']:.1f} mm, scaled; within {tol:.1f} mm = 0.3 % of L)"
                    + _where(w, foot=False))
        if np.isfinite(self.max_step_length_m) and np.isfinite(self.stature_m):
            lim = BARS["step_length_stature"] * self.stature_m
            if not self.max_step_length_m <= lim:
                fails.append(f"step of {self.max_step_length_m:.2f} m, longer than "
                             f"{BARS['step_length_stature']:g} x stature ({lim:.2f} m)"
                             + _where(self.longest_step))
        if not np.isnan(self.reference_max_joint_jump_deg):
            lim = BARS["joint_jump_ratio"] * self.reference_max_joint_jump_deg
            if not self.max_joint_jump_deg <= lim:
                fails.append(
                    f"joint jump {self.max_joint_jump_deg:.2f} deg "
                    f"(<= 1.5 x reference {self.reference_max_joint_jump_deg:.2f})"
                )
        return fails


def _where(w: dict, foot: bool = True) -> str:
    """": left foot, frames 12-20, 38-46" for a report's worst-case dict (foot and frames [start, stop)), ""
    if it has no frames; without the foot when foot=False or it names none."""
    if not w or not w.get("frames"):
        return ""
    spans = ", ".join(f"{a}-{b - 1}" if b - 1 > a else f"{a}" for a, b in w["frames"])
    return f": {w['foot']} foot, frames {spans}" if foot and "foot" in w else f": frames {spans}"


#: For flight gravity a body is airborne while each foot's lowest point is more than this fraction of L
#: above its own low level: tighter than the contact test (0.05 L), so a 30 Hz flight keeps its 3-4 frames.
AIRBORNE_BAND_L = 0.02


def airborne_phases(markers: np.ndarray, gait: Gait, leg_length: float) -> list[tuple[int, int]]:
    """The gait's flights [start, stop), those shorter than FLIGHT_MIN_FRAMES widened (up to that length)
    over neighbouring frames in which both feet are still more than AIRBORNE_BAND_L × L above their low
    level (5th percentile of each foot's lowest marker): a 30 Hz flight the contact test sees as 2 frames
    is 3-4 frames in the air. markers: (F, 2, 3, 3) [m]."""
    h = markers[..., UP_AXIS].min(axis=2)  # (F, 2)
    air = np.all(h > np.percentile(h, 5, axis=0) + AIRBORNE_BAND_L * leg_length, axis=1)
    out: list[tuple[int, int]] = []
    for a, b in gait.flights:
        while b - a < FLIGHT_MIN_FRAMES:  # only as far as a parabola needs: contact frames bias it
            if b < len(air) and air[b] and (b - a) % 2 == 0 or not (a > 0 and air[a - 1]):
                if not (b < len(air) and air[b]):
                    break
                b += 1
            else:
                a -= 1
        if not out or a >= out[-1][1]:
            out.append((int(a), int(b)))
    return out


def foot_skate_mm(markers: np.ndarray, gait: Gait, leg_length: float) -> float:
    """Largest sliding of a foot marker while it is on the ground [mm].

    markers: (F, 2, 3, 3) [m] (ankle, toe, toe end per foot: joint centres, which sit a sole's thickness
    above the floor when the foot is down). For each stance and each marker of the stance foot that
    reaches the floor (its lowest point in the stance within 0.03 L of that stance's ground), the marker
    is on the ground while it is within a contact band of that lowest point: max(5 mm, 0.006 L). A contact
    lasts until the marker clearly lifts (above 1.5 bands: hysteresis, so noise does not split it); skate
    is the largest horizontal distance of the marker from where its contact began. Rolling from heel to
    toe, or a toe tip that lifts and touches down again, is not sliding.
    """
    worst = 0.0
    band = max(0.005, 0.006 * leg_length)
    for s in gait.stances:
        seg = markers[s.start : s.stop, s.foot]  # (n, 3 markers, 3)
        height = seg[..., UP_AXIS] - s.ground
        for k in range(seg.shape[1]):
            h_min = height[:, k].min()
            if h_min > 0.03 * leg_length:
                continue
            on = height[:, k] <= h_min + band
            idx = np.flatnonzero(on)
            if idx.size < 2:
                continue
            lifted = np.array([height[a + 1 : b, k].max(initial=-np.inf) > h_min + 1.5 * band
                               for a, b in zip(idx[:-1], idx[1:])])
            starts = np.concatenate([[0], np.flatnonzero(lifted) + 1])
            stops = np.concatenate([np.flatnonzero(lifted) + 1, [idx.size]])
            for a, b in zip(starts, stops):
                p = seg[idx[a:b], k][:, HORIZONTAL_AXES]
                worst = max(worst, float(np.max(np.linalg.norm(p - p[0], axis=1))))
    return 1000.0 * worst


def foot_skate_floor_mm(markers: np.ndarray, gait: Gait, leg_length: float) -> float:
    """foot_skate_floor (below) without where."""
    return foot_skate_floor(markers, gait, leg_length)[0]


def foot_skate_floor(markers: np.ndarray, gait: Gait, leg_length: float) -> tuple[float, dict]:
    """Largest sliding of the ball or the tip of a foot while it is on or just above the floor [mm].

    markers: (F, 2, 3, 3) [m] (ankle, toe, toe end per foot: joint centres, which sit a sole's thickness
    above the floor when the foot is down). For each stance of a foot, widened by SKATE_MARGIN_S on each
    side (not past the middle of the swings around it) so that touchdown and lift-off are included, each of
    the ball and the tip (SKATE_MARKERS) rests at its lowest height in that window; it is on or just above
    the floor while within SKATE_BAND_L × L of that height. Over each such run of frames, sliding is the
    largest horizontal distance of the marker from where it was at its lowest point in the run. Rolling from
    heel to toe does not slide the ball or the tip; a toe that scuffs sideways at lift-off does. A stance cut
    by the clip's edge whose marker is lowest outside the stance (a landing foot's ball still in its swing
    at the last frame, heel first) never has that marker on the floor within the clip: it is not counted.
    Nor is the part of a cut stance above where the marker rests on the floor (_floor_rest_heights).
    Returns the skate [mm] and where it is largest: {"foot", "marker", "frames": [(start, stop)]} ({} if 0).
    """
    worst, where = 0.0, dict[str, object]()
    band = SKATE_BAND_L * leg_length
    rest = _floor_rest_heights(markers, gait)
    for foot, s, a, b in skate_windows(gait, markers.shape[0]):
        for k in SKATE_MARKERS:
            seg = markers[a:b, foot, k]  # (n, 3)
            h = seg[:, UP_AXIS]
            if h.min() > s.ground + SKATE_REACH_L * leg_length:
                continue  # this point never comes down to the floor around this contact
            base = h.min()
            if s.partial:
                if not s.start <= a + int(np.argmin(h)) < s.stop:
                    # cut by the clip's edge before the point came down (or after it rose): its lowest
                    # point is in the swing, whose forward travel is not a slide (02_01 x0.8: a ball
                    # 32 mm up, 166 mm of swing, in the last 20 frames)
                    continue
                # cut where the point is still coming down or already rising, its contact's lowest height
                # lies outside the clip: the floor is where the marker rests in the foot's whole stances
                # (run_tired's troll: its first frame 6 ms after the right foot's contact ends, the tip 0.03 L
                # up and swinging forward 13-18 mm a frame, as at every lift-off inside the clip; its rest
                # in the whole stances is 0.0004 L)
                base = min(base, rest[foot, k])
            low = h <= base + band
            for r0, r1 in _true_runs(low):
                if a + r1 <= s.start or a + r0 >= s.stop:
                    # a run wholly in the swing, apart from the contact, is a foot swinging low past the
                    # floor, not one on it: the Bandai elderly walks' toes clear the floor by 2-10 mm in
                    # mid-swing, within the band, travelling 80-100 mm a frame (the clip
                    # dataset-2_walk_elderly_001 itself "skated" 77 mm, left tip, frames 376-378)
                    continue
                p = seg[r0:r1][:, HORIZONTAL_AXES]
                p_rest = p[int(np.argmin(h[r0:r1]))]
                slide = float(np.max(np.linalg.norm(p - p_rest, axis=1)))
                if slide > worst:
                    worst = slide
                    where = {"foot": SIDES[foot], "marker": MARKER_NAMES[k], "frames": [(int(a + r0), int(a + r1))]}
    return 1000.0 * worst, where


def source_rest_heights(markers: np.ndarray, gait: Gait, leg_length: float) -> np.ndarray:
    """(2, 3) [m] how high a clip's foot markers (F, 2, 3, 3) [m] rest in stance above its floor, both found
    from the clip by the report's own measures (``floor_height``, ``stance_rest_heights``): × L, what an
    output's feet must rest at (``physics_report``'s source_rest_heights)."""
    floor, _ = floor_height(markers, gait, leg_length)
    return stance_rest_heights(markers, gait, floor)[0]


def rest_height_error(rest: np.ndarray, expected: np.ndarray, per_stance: list) -> tuple[float, dict]:
    """How far a foot rests above or below the source's: the largest |foot rest - expected| [mm] over the two
    feet, where a foot's rest is its lowest marker's rest height (rest, expected (2, 3) [m] per marker), and
    where: {"foot", "marker" (the one it rests on), "height_mm", "expected_mm", "error_mm", "frames"}; frames:
    every whole stance of that foot (the figure is their median: which of them alone was off by more than the
    bar hung on the last bit, CMU 16_18's child listing other stances under 1e-9 m noise, issue 26). NaN, {}
    when neither foot has both.

    The foot, not each marker: a foot floats or sinks when the point it rests on does. The other markers'
    heights are its posture over that point (a heel that stays up at a higher speed, a troll's short-legged
    ankle dropped with the toes on the floor) and are reported (``rest_height_mm``), not held to the clip's:
    each marker against the clip's refused 09_01 at x1.6, whose toes rest where the clip's do but whose
    ankle, heel up as a faster runner's, rests 8 mm (0.9 % of L) higher."""
    low = np.where(np.isfinite(rest).all(axis=1), np.nanmin(np.where(np.isfinite(rest), rest, np.inf), axis=1), np.nan)
    exp = np.where(np.isfinite(expected).all(axis=1),
                   np.nanmin(np.where(np.isfinite(expected), expected, np.inf), axis=1), np.nan)
    err = low - exp
    if not np.isfinite(err).any():
        return float("nan"), {}
    f = int(np.nanargmax(np.abs(err)))
    k = int(np.argmin(rest[f]))
    st = [(a, b) for foot, a, b, h in per_stance if foot == f]
    return 1000.0 * abs(float(err[f])), {
        "foot": SIDES[f], "marker": MARKER_NAMES[k], "height_mm": 1000.0 * float(low[f]),
        "expected_mm": 1000.0 * float(exp[f]), "error_mm": 1000.0 * float(err[f]),
        "frames": [(int(a), int(b)) for a, b in st]}


def longest_step(gait: Gait) -> tuple[float, dict]:
    """The longest step [m] (horizontal distance between the contact points of consecutive whole stances of
    the two feet) and where: {"frames": [(start, stop) of the two stances]}; NaN, {} with fewer than two."""
    st = sorted(gait.full_stances, key=lambda s: s.start)
    best, where = float("nan"), dict[str, object]()
    for a, b in zip(st[:-1], st[1:]):
        if a.foot == b.foot:
            continue
        d = float(np.linalg.norm((b.contact_point - a.contact_point)[list(HORIZONTAL_AXES)]))
        if not d <= best:
            best, where = d, {"frames": [(int(a.start), int(a.stop)), (int(b.start), int(b.stop))]}
    return best, where


def _floor_rest_heights(markers: np.ndarray, gait: Gait) -> np.ndarray:
    """(2, 3) [m] the height at which each foot marker rests on the floor: the highest of its lowest heights
    over the foot's whole (uncut) stance windows (the highest: a cut stance's band then reaches as high as
    any whole stance's), the other foot's where a foot has none; +inf where no stance is whole."""
    lows = np.full((2, 3), np.inf)
    for foot, s, a, b in skate_windows(gait, markers.shape[0]):
        if not s.partial:
            low = markers[a:b, foot, :, UP_AXIS].min(axis=0)  # (3,)
            lows[foot] = np.where(np.isinf(lows[foot]), low, np.maximum(lows[foot], low))
    for foot in (0, 1):
        if np.isinf(lows[foot]).all():
            lows[foot] = lows[1 - foot]
    return lows


def _true_runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """[start, stop) intervals where a 1-D bool array is True."""
    d = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return list(zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1)))


# Long because every figure of the report is measured here from the motion alone, one call each, in the order
# the report lists them: splitting it would pass the contacts, floor and COM through several signatures.
def physics_report(
    motion: Motion,
    body: BodyModel | None = None,
    *,
    ground_height: float | None = None,
    machine_com: np.ndarray | None = None,
    marker_targets: np.ndarray | None = None,
    reference_pose: Motion | None = None,
    reference_max_joint_jump_deg: float | None = None,
    com_and_markers: tuple[np.ndarray, np.ndarray] | None = None,
    reference_path: TakePath | None = None,
    reference_leg_length: float | None = None,
    source_rest_heights: np.ndarray | None = None,
) -> Report:
    """The physics report (docs/architecture.md) for any motion; tracking figures when targets are given.

    ground_height: the floor's height [m] (outputs know it); None estimates it per stance.
    machine_com: (F, 3) the simple machine's COM path [m]; marker_targets: (F, 2, 3, 3) [m], NaN where
    a marker had no target; reference_pose: the time-warped reference on the same frames (pose deviation);
    reference_max_joint_jump_deg: the reference's own largest frame-to-frame joint change.
    reference_path: the clip's path (``body.path.take_path``) and reference_leg_length [m] its leg length:
    the output's path, measured here from the motion, is compared with it (``path_report``; a turn lost is
    a bar missed). Every report carries the motion's own path in ``extras["path"]``.
    source_rest_heights: (2, 3) [m] how high the source's foot markers rest in stance (its
    ``stance_rest_heights``, scaled by L): each foot's lowest is then a bar (within BARS["rest_height_L"] × L;
    ``rest_height_error``).
    Contacts are always found from the motion; the floor too unless ground_height is given (an output
    written on y = 0). The rest heights are measured from ``ground_height`` when given, else from the
    floor found (``floor_height``).
    """
    if body is None:
        body = BodyModel.from_skeleton(motion.skeleton)
    com, markers = com_and_markers if com_and_markers is not None else body.com_and_markers(motion)
    gait = detect_gait(motion, body, markers)
    if ground_height is not None:
        gait = _with_ground(gait, ground_height)
    summ = summarize(motion, body, com, gait)
    dt = motion.frame_time
    L = body.leg_length
    g_fl, g_list, acc_h = flight_gravity(com, dt, airborne_phases(markers, gait, L))

    h_low = markers[..., UP_AXIS].min(axis=2)  # (F, 2) lowest marker per foot
    ground_f = np.full(motion.n_frames, gait.ground)
    if ground_height is None:
        for s in gait.stances:  # per-stance ground for an uneven real floor
            ground_f[s.start : s.stop] = s.ground
    penetration = float(max(0.0, np.max(ground_f[:, None] - h_low))) * 1000.0
    floats = [float(np.min(h_low[s.start : s.stop, s.foot]) - ground_f[s.start]) for s in gait.stances]
    float_mm = 1000.0 * max([0.0] + floats)
    skate = foot_skate_mm(markers, gait, L)
    skate_floor, skate_where = foot_skate_floor(markers, gait, L)
    floor, how = floor_height(markers, gait, L)
    if ground_height is not None:
        how = f"given ({1000 * ground_height:.1f} mm); found from the motion: {how}"
        floor = float(ground_height)
    rest, per_stance = stance_rest_heights(markers, gait, floor)
    step_max, step_where = longest_step(gait)

    fz = vertical_force_bw(com, dt) if motion.n_frames >= 8 else np.full(motion.n_frames, np.nan)
    inner = slice(3, max(3, motion.n_frames - 3))  # filter edges are least trustworthy
    peak_bw = float(np.nanmax(fz[inner])) if motion.n_frames > 8 else float("nan")
    k_leg, K = _stiffness(com, gait, fz, body)

    rep = Report(
        duration_s=motion.duration, n_frames=motion.n_frames, frame_rate_hz=motion.fps,
        mean_speed_m_s=summ.mean_speed, froude_U=summ.froude, leg_length_m=L, mass_kg=body.total_mass,
        step_frequency_hz=summ.step_frequency, step_length_m=summ.step_length,
        stance_times_s=summ.stance_times.tolist(), flight_times_s=summ.flight_times.tolist(),
        com_vertical_excursion_m=summ.com_vertical_excursion, flight_gravity_m_s2=g_fl,
        flight_gravity_per_phase=g_list, flight_horizontal_accel_m_s2=acc_h, foot_skate_mm=skate,
        foot_skate_floor_mm=skate_floor,
        penetration_mm=penetration, float_mm=float_mm, peak_vertical_force_bw=peak_bw,
        leg_stiffness_n_m=k_leg, leg_stiffness_K=K, max_joint_jump_deg=max_joint_jump_deg(motion),
        floor_m=floor, floor_found=how, rest_height_mm=_by_foot(rest), max_step_length_m=step_max,
        stature_m=body.stature, longest_step=step_where, skate_worst=skate_where,
    )
    if motion.n_frames >= 3:
        # compared with a turning clip, the output's heading is measured over the clip's share of a stride
        # (take_path); against a straight one over its own window (at least a stride: its sway cancels)
        window_strides = None
        if reference_path is not None and not is_straight(reference_path):
            window_strides = reference_path.window_s / reference_path.stride_s
        path = take_path(motion, body, com, gait, window_strides=window_strides)
        rep.extras["path"] = path.to_dict()
        if reference_path is not None:
            ref_L = L if reference_leg_length is None else float(reference_leg_length)
            rep.extras["path_vs_clip"] = path_comparison(reference_path, path, ref_L, L)
    if source_rest_heights is not None:
        expected = np.asarray(source_rest_heights, float)
        rep.source_rest_height_mm = _by_foot(expected)
        rep.rest_height_error_mm, rep.rest_height_worst = rest_height_error(rest, expected, per_stance)
    if machine_com is not None:
        err = np.linalg.norm(com - machine_com, axis=1)
        rep.com_tracking_rms_mm = 1000.0 * float(np.sqrt(np.mean(err**2)))
        rep.com_tracking_max_mm = 1000.0 * float(err.max())
    if marker_targets is not None:
        err = np.linalg.norm(markers - marker_targets, axis=-1)
        err = err[np.isfinite(err)]
        if err.size:
            rep.foot_marker_rms_mm = 1000.0 * float(np.sqrt(np.mean(err**2)))
            rep.foot_marker_max_mm = 1000.0 * float(err.max())
    if reference_pose is not None:
        dev = np.degrees(quat.angle_between(motion.rotations[:, 1:], reference_pose.rotations[:, 1:]))
        rep.pose_deviation_mean_deg = float(dev.mean())
        rep.pose_deviation_max_deg = float(dev.max())
    if reference_max_joint_jump_deg is not None:
        rep.reference_max_joint_jump_deg = float(reference_max_joint_jump_deg)
    return rep


def _by_foot(h: np.ndarray) -> dict:
    """{"left": {"ankle": mm, "ball": mm, "tip": mm}, "right": ...} from (2, 3) [m] (None where NaN)."""
    return {SIDES[f]: {MARKER_NAMES[k]: (round(1000.0 * float(h[f, k]), 2) if np.isfinite(h[f, k]) else None)
                       for k in range(3)} for f in (0, 1)}


def _with_ground(gait: Gait, ground: float) -> Gait:
    from dataclasses import replace

    return replace(gait, ground=float(ground), stances=tuple(replace(s, ground=float(ground)) for s in gait.stances))


def _stiffness(com: np.ndarray, gait: Gait, fz_bw: np.ndarray, body: BodyModel) -> tuple[float, float]:
    """Leg stiffness k = F_peak / ΔL over full stances (McMahon & Cheng): [N/m] and K = k l0/(m g)."""
    ks, Ks = [], []
    m = body.total_mass
    for s in gait.full_stances:
        leg = com[s.start : s.stop] - s.contact_point
        leg[:, UP_AXIS] = com[s.start : s.stop, UP_AXIS] - s.ground
        length = np.linalg.norm(leg, axis=1)
        l0 = length[0]
        dL = l0 - length.min()
        f_peak = np.nanmax(fz_bw[s.start : s.stop]) * m * GRAVITY
        if dL > 1e-3 and np.isfinite(f_peak):
            ks.append(f_peak / dL)
            Ks.append(f_peak / dL * l0 / (m * GRAVITY))
    if not ks:
        return float("nan"), float("nan")
    return float(np.mean(ks)), float(np.mean(Ks))


def write_report(report: Report, path) -> None:
    """Write a report as JSON, atomically."""
    atomic_write_text(path, report.to_json() + "\n")
