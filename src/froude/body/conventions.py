"""A rig's conventions read from its motion, not from its zero pose: up axis, length unit, a standing
reference pose, and per-joint translation channels folded into offsets and the root.

The zero-rotation pose of many rigs is not an upright human (bind orientations fold it: the
Maya/MotionBuilder habit), so everything here is measured on the animated frames, in file units.
The length unit is chosen among the usual ones by the physics of the motion where it can be
(a body in flight falls at 9.81 m/s² whatever its size), else by the most human stature, and the
choice is said aloud. All functions are pure.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..core import quat
from ..core.constants import GRAVITY, HORIZONTAL_AXES, UP_AXIS
from ..core.kinematics import forward_kinematics
from ..core.motion import Motion
from ..core.rig import Z_UP_TO_Y_UP, change_basis
from ..core.skeleton import Skeleton
from .com_force import flight_gravity
from .gait import _close_gaps, _runs
from .model import BodyModel, JointMapError, find_roles

#: Length units a BVH file may be in: (name, metres per file unit). CMU's ASF->BVH conversions use
#: 1/0.45 inch.
UNITS = (
    ("metres", 1.0),
    ("centimetres", 0.01),
    ("millimetres", 0.001),
    ("inches", 0.0254),
    ("CMU units", 0.056444),
)
UNIT_ALIASES = {"m": "metres", "cm": "centimetres", "mm": "millimetres", "in": "inches", "inch": "inches",
                "cmu": "CMU units"}
#: Statures [m] a unit may imply and still be considered (children to giants).
STATURE_RANGE_M = (0.35, 6.5)
#: The stature [m] preferred when the motion cannot decide (no flight phase).
TYPICAL_STATURE_M = 1.70
#: A flight gravity this close (ratio) to 9.81 m/s² decides the unit; the units differ by >= 1.77x.
GRAVITY_DECIDES = 1.33
#: Without a flight, the walking step frequency made dimensionless, f·√(L/g) with L the leg length, weighs
#: the units (dynamic similarity: a child's and a giant's walks share it). Measured human walking spans
#: about 0.4-0.7 (1.3-2.3 steps/s at L = 0.9 m; REFERENCE.md): centre and spread in log terms.
WALK_STEP_FREQ_HAT = 0.55
WALK_STEP_FREQ_LOG_SD = 0.2
#: The same for a run without a usable flight (too short to fit a parabola, a small character at 30 Hz):
#: joggers and distance runners step at 2.6-3.0 Hz at L ≈ 0.9 m (0.85-0.9), children at 4 Hz at L ≈ 0.45 m
#: (0.86), sprinters at 4.5-5 Hz (1.4-1.5) (REFERENCE.md): a wider spread around 0.95.
RUN_STEP_FREQ_HAT = 0.95
RUN_STEP_FREQ_LOG_SD = 0.3
#: Spread (log) of statures around TYPICAL_STATURE_M when weighed with the cadence: wide (0.5 m children to
#: 5 m giants are ordinary outputs), so that a cadence far from human walking's decides (0.5 read a 0.5 m
#: walker's output as a 1.27 m one); narrow enough that a human stature wins where the cadence fits a
#: human's run about as well as a giant's walk (0.8 read a 1.49 m tired jogger as a 3.3 m one).
STATURE_LOG_SD = 0.65
#: A unit whose score (squared log distances) is within this of the best one is a plausible alternative.
UNIT_SCORE_MARGIN = 2.0
#: At most this many frames (from the middle of the clip) are analysed: long clips load fast.
MAX_FRAMES = 2400




def unit_scale(name: str) -> tuple[float, str]:
    """(metres per unit, unit name) of a unit name or abbreviation (m, cm, mm, in, cmu)."""
    full = UNIT_ALIASES.get(name.strip().lower(), name.strip())
    for n, s in UNITS:
        if n.lower() == full.lower():
            return s, n
    raise ValueError(f"unknown length unit '{name}'; use one of: {', '.join(UNIT_ALIASES)}")


def fold_translations(motion: Motion) -> tuple[Motion, list[str]]:
    """Translation channels below the root made offsets where they are constant (the six-channel habit:
    position channels equal to the OFFSET), and the moving translation of a joint directly below a
    static or moving root folded into the root's position (a static reference root above the hips).

    The world motion is unchanged (FK of the result equals FK of the input to rounding); returns the
    motion and notes saying what was folded.
    """
    if motion.translations is None:
        return motion, []
    sk = motion.skeleton
    tr = motion.translations.copy()
    offsets = sk.offsets.copy()
    size = max(float(np.abs(sk.offsets).max()), 1e-9)
    root = motion.root_positions.copy()
    notes = []
    moving = []
    for j in range(1, sk.n_joints):
        if not sk.has_translation_channels(j):
            continue
        if np.ptp(tr[:, j], axis=0).max() <= 1e-6 * size:
            offsets[j] = tr[0, j]
        else:
            moving.append(j)
    folded = [j for j in moving if sk.parents[j] == 0]
    if len(folded) == 1 and len(moving) == 1:
        j = folded[0]
        # p_j = p_root + R_root t_j(t) = (p_root + R_root (t_j(t) - offset_j)) + R_root offset_j
        root = root + quat.rotate(motion.rotations[:, 0], tr[:, j] - offsets[j])
        notes.append(f"the translation of '{sk.names[j]}' is carried by the root '{sk.names[0]}' "
                     "(the world motion is unchanged)")
        moving = []
    if moving:
        return motion, [f"joints with moving translation channels: {', '.join(sk.names[j] for j in moving)}"]
    skel = sk.with_offsets(offsets)
    return replace(motion, skeleton=skel, root_positions=root, translations=None), notes


def _analysed(motion: Motion) -> Motion:
    """At most MAX_FRAMES frames from the middle of the clip."""
    F = motion.n_frames
    if F <= MAX_FRAMES:
        return motion
    a = (F - MAX_FRAMES) // 2
    return motion.cut(a, a + MAX_FRAMES)


def role_positions(motion: Motion, joints) -> np.ndarray:
    """(F, len(joints), 3) world positions (file units) of some joints over the analysed frames."""
    m = _analysed(motion)
    p, _ = forward_kinematics(m.skeleton, m.root_positions, m.rotations, m.translations)
    return p[:, list(joints)]


def detect_up(motion: Motion, roles) -> tuple[str, float]:
    """("Y" or "Z" or "-Y" ..., agreement 0..1): the axis from the feet to the head over the motion."""
    p = role_positions(motion, [roles["head"], roles["left_ankle"], roles["right_ankle"]])
    d = (p[:, 0] - 0.5 * (p[:, 1] + p[:, 2])).mean(axis=0)
    a = int(np.argmax(np.abs(d)))
    sign = "" if d[a] > 0 else "-"
    return sign + "XYZ"[a], float(abs(d[a]) / max(np.linalg.norm(d), 1e-12))


def rest_is_upright(skeleton: Skeleton, roles) -> bool:
    """Whether the zero-rotation pose stands (+Y up): legs hanging straight down, head over pelvis."""
    rest = skeleton.rest_positions()
    for side in ("left", "right"):
        h, k, a = (rest[roles[f"{side}_{r}"]] for r in ("hip", "knee", "ankle"))
        length = np.linalg.norm(k - h) + np.linalg.norm(a - k)
        if not (h - a)[UP_AXIS] >= 0.9 * length > 0:
            return False
    up = rest[roles["head"]] - rest[roles["pelvis"]]
    return bool(up[UP_AXIS] >= 0.8 * np.linalg.norm(up) > 0)


def reference_pose(motion: Motion, roles) -> tuple[np.ndarray, int]:
    """(J, 4) local rotations of a standing frame of the motion and its index: mid-stance, where the
    lower ankle is lowest (the stance foot flat, the trunk near upright). The motion must be +Y up."""
    m = _analysed(motion)
    p = role_positions(m, [roles["left_ankle"], roles["right_ankle"]])
    f = int(np.argmin(p[..., UP_AXIS].min(axis=1)))
    return m.rotations[f].copy(), f + (motion.n_frames - m.n_frames) // 2


def flight_gravity_units(com: np.ndarray, foot_low: np.ndarray, leg_length: float, frame_time: float,
                         planted: np.ndarray | None = None):
    """(gravity seen in the flight phases [file units/s²] or None when the motion has no flight of three
    frames or more, the number of those flights).

    com: (F, 3) COM; foot_low: (F, 2) lowest foot marker height per foot; leg_length in the same
    units. A frame is in flight when both feet are above the ground (5th percentile of the lower foot)
    by 3 % of the leg and neither is planted (``planted_feet``, when given), a scale-free test. The
    curvature is fitted by ``com_force.flight_gravity`` (one gravity shared by every flight, each its own
    height and vertical speed). Flights cut by the clip's edges are left out (a jump off or a stumble).
    """
    ground = np.percentile(foot_low.min(axis=1), 5)
    air = (foot_low > ground + 0.03 * leg_length).all(axis=1)
    if planted is not None:  # a foot resting on a floor that rises by a few centimetres is not in the air
        air &= ~planted.any(axis=1)
    flights = [(a, b) for a, b in _runs(air) if a > 0 and b < len(air)]
    g, per_phase, _ = flight_gravity(com, frame_time, flights, min_frames=3)
    if not per_phase or not np.isfinite(g):
        return None, 0
    return float(g), len(per_phase)


#: The flight gravity weighs the unit only when the feet show flights between at least this share of the
#: steps (the share ``gait.RUNNING_FLIGHT_SHARE`` that makes a run): a few isolated windows where both feet
#: read high are no flight phase, and their COM curvature is not gravity.
FLIGHT_STEP_SHARE = 0.5


def flights_between_steps(n_flights: int, step_hz: float | None, duration: float) -> bool:
    """Whether n_flights flight phases in a take of ``duration`` [s] stepping at ``step_hz`` [1/s] are a
    running gait's (one flight in at least FLIGHT_STEP_SHARE of the steps). A take whose steps cannot be
    counted (fewer than three plants: a short run) keeps its flights."""
    if step_hz is None or not step_hz > 0:
        return True
    return n_flights >= FLIGHT_STEP_SHARE * step_hz * duration


#: A take whose feet are planted more than this share of the time (duty factor, both feet averaged) has a
#: foot on the ground at every instant: a walk (or the in-between grounded run), whose cadence weighs the
#: unit; a run's feet are planted 30-45 % of the time (measured on the shared clips with ``planted_feet``:
#: runs 0.32-0.51, walks 0.51-0.66).
WALKING_DUTY = 0.5
#: Within this of WALKING_DUTY the feet do not tell the gait (a light walk, a tired jog: 0.51 both).
DUTY_MARGIN = 0.03


def planted_feet(markers: np.ndarray, com: np.ndarray, frame_time: float) -> np.ndarray:
    """(F, 2) bool: each foot planted, measured without knowing the unit: its slowest marker moves
    horizontally slower than a third of the COM's mean horizontal speed (all False for a take with no
    travel). markers: (F, 2, M, 3) foot markers; com: (F, 3) [file units, +Y up]."""
    F = com.shape[0]
    if F < 3:
        return np.zeros((F, 2), bool)
    v_com = np.linalg.norm((com[-1] - com[0])[HORIZONTAL_AXES]) / (frame_time * (F - 1))
    if not v_com > 0:
        return np.zeros((F, 2), bool)
    v = np.linalg.norm(np.gradient(markers[..., HORIZONTAL_AXES], frame_time, axis=0), axis=-1).min(axis=2)
    return np.asarray(v < v_com / 3.0)


def step_frequency_hz(foot_xyz: np.ndarray, com: np.ndarray, frame_time: float) -> float | None:
    """Steps per second from foot plants, measured without knowing the unit, or None (fewer than 3 plants,
    or a take with no travel).

    foot_xyz: (F, 2, 3) a point of each foot; com: (F, 3) [file units, +Y up]. A foot is planted while its
    horizontal speed stays below a third of the COM's mean horizontal speed for at least 0.1 s: a
    scale-free test (heights are not used: floors in captures tilt and drift by a few centimetres). A
    plant interrupted for less than 0.05 s (a marker's jitter at a high frame rate) is one plant.
    """
    dt = frame_time
    v_com = np.linalg.norm((com[-1] - com[0])[HORIZONTAL_AXES]) / (dt * (len(com) - 1))
    if not v_com > 0:
        return None
    v_foot = np.linalg.norm(np.gradient(foot_xyz[..., HORIZONTAL_AXES], dt, axis=0), axis=-1)  # (F, 2)
    min_frames = max(2, int(round(0.1 / dt)))
    touchdowns = []
    for k in range(foot_xyz.shape[1]):
        slow = _close_gaps(v_foot[:, k] < v_com / 3, max(1, int(round(0.05 / dt))))
        touchdowns += [a for a, b in _runs(slow) if b - a >= min_frames and a > 0]
    if len(touchdowns) < 3:
        return None
    t = np.sort(np.asarray(touchdowns)) * dt
    return float((len(t) - 1) / (t[-1] - t[0])) if t[-1] > t[0] else None


def choose_unit(stature_units: float, gravity_units: float | None, *, step_hz: float | None = None,
                leg_units: float | None = None, walking: bool | None = True) -> tuple[float, str, str, bool]:
    """(metres per unit, unit name, a sentence saying why, ambiguous?) from the stature and the flight
    gravity measured in file units.

    Among the units giving a stature in STATURE_RANGE_M, the flight gravity (when the motion flies)
    picks the one making it 9.81 m/s²: this does not depend on the character's size. Without a flight
    the unit wins whose stature is most human and, when the step frequency ``step_hz`` [1/s] and leg
    length ``leg_units`` [file units] are given, whose dimensionless cadence f·√(L/g) is most like human
    walking's (``walking`` True: the feet are planted most of the time) or running's (False: a run whose
    flights are too short to weigh; None: the feet cannot tell, the likelier of the two); the choice is
    flagged ambiguous when another unit scores nearly as well.
    """
    lo, hi = STATURE_RANGE_M
    plausible = [(n, s) for n, s in UNITS if lo <= stature_units * s <= hi]
    if not plausible:
        raise ValueError(
            f"cannot tell the length unit: a stature of {stature_units:g} file units is no human size in "
            f"{', '.join(n for n, _ in UNITS)}; pass length_scale (--length-scale, metres per file unit)"
        )

    def desc(n, s):
        g = f", flight gravity {gravity_units * s:.2f} m/s²" if gravity_units else ""
        return f"{n} (stature {stature_units * s:.2f} m{g})"

    if gravity_units is not None and gravity_units > 0:
        err = [abs(np.log(gravity_units * s / GRAVITY)) for _, s in plausible]
        i = int(np.argmin(err))
        if err[i] <= np.log(GRAVITY_DECIDES):
            n, s = plausible[i]
            others = [desc(*c) for k, c in enumerate(plausible) if k != i]
            why = f"{desc(n, s)}, detected by the flight gravity" + (f"; not {', '.join(others)}" if others else "")
            return s, n, why, False
    # no flight, or "flights" so flat in every plausible unit (under g/3) that they are noise: the cadence weighs
    no_flight = gravity_units is None or max(gravity_units * s for _, s in plausible) < GRAVITY / 3
    by_cadence = no_flight and step_hz is not None and leg_units is not None and leg_units > 0
    priors = {"walking": (WALK_STEP_FREQ_HAT, WALK_STEP_FREQ_LOG_SD), "running": (RUN_STEP_FREQ_HAT,
                                                                             RUN_STEP_FREQ_LOG_SD)}
    if walking is not None:  # the feet tell the gait; None: either (the cadence most like one of them)
        priors = {k: v for k, v in priors.items() if (k == "walking") == walking}
    score = [(np.log(stature_units * s / TYPICAL_STATURE_M) / STATURE_LOG_SD) ** 2 for _, s in plausible]
    if by_cadence:
        assert step_hz is not None and leg_units is not None
        f_hat = [step_hz * np.sqrt(leg_units * s / GRAVITY) for _, s in plausible]
        terms = [{g: (np.log(f / c) / sd) ** 2 for g, (c, sd) in priors.items()} for f in f_hat]
        score = [a + min(t.values()) for a, t in zip(score, terms)]
    i = int(np.argmin(score))
    n, s = plausible[i]
    # stature alone cannot tell a 1.5 m actor from a 3.8 m giant: every human size is an alternative;
    # with the cadence, only a unit that scores nearly as well is
    close = [k for k in range(len(plausible)) if k != i and (not by_cadence or score[k] - score[i] < UNIT_SCORE_MARGIN)]
    others = [desc(*plausible[k]) for k in close if 0.5 <= stature_units * plausible[k][1] <= 5.0]
    if by_cadence:
        gait = min(terms[i], key=terms[i].__getitem__)
        reason = (f"no flight phase to weigh; {step_hz:.2f} steps/s, a {gait} cadence of "
                  f"{f_hat[i]:.2f} in dynamically similar terms")
        why = f"{desc(n, s)}, detected by the stature and the {gait} cadence ({reason})"
    else:
        reason = "no flight phase to weigh" if gravity_units is None else \
            f"the flight gravity ({gravity_units:g} units/s²) fits no unit"
        why = f"{desc(n, s)}, detected as the most human stature ({reason})"
    if others:
        why += f"; AMBIGUOUS, also possible: {', '.join(others)}: pass --length-scale if it is wrong"
    return s, n, why, bool(others)


def understand(motion: Motion, *, joint_map=None, length_scale: float | None = None,
               up: str | None = None) -> tuple[Motion, dict]:
    """A motion in file units and file axes, made SI and +Y up, with its conventions.

    motion: as read (lengths in file units). joint_map: role -> joint name for unusual names.
    length_scale: metres per file unit (None: detected, see ``choose_unit``). up: "Y" or "Z" (None:
    detected from the motion). Returns the motion (metres, +Y up, translations folded, a reference
    pose set when the rest pose is folded) and meta entries: length_scale, units (a sentence),
    units_ambiguous, up_axis, notes (list of sentences).
    Raises ValueError when the unit cannot be told; JointMapError for a bad joint map.
    """
    motion, notes = fold_translations(motion)
    if joint_map:
        motion = replace(motion, skeleton=replace(motion.skeleton, joint_map=tuple(sorted(joint_map.items()))))
    sk = motion.skeleton
    try:
        roles = find_roles(sk, joint_map)
    except JointMapError as e:
        if joint_map and "role(s)" not in str(e):
            raise  # the user's map itself is wrong
        roles = None  # the body model raises the same error, naming the roles, when it is needed
    up_axis = "Y" if up is None else up.upper()
    if roles is not None and up is None:
        up_axis, agree = detect_up(motion, roles)
        if up_axis not in ("Y", "Z"):
            notes.append(f"the body's up is {up_axis} in the file; read as +Y up")
            up_axis = "Y"
    if up_axis not in ("Y", "Z"):
        raise ValueError(f"up axis must be Y or Z, got '{up}'")
    if up_axis == "Z":
        motion = change_basis(motion, Z_UP_TO_Y_UP)
        motion = replace(motion, skeleton=replace(motion.skeleton, file_up="Z"))
        notes.append("Z-up file: read as +Y up (x, z, -y); outputs are written Z-up again")
    if roles is not None and not rest_is_upright(motion.skeleton, roles):
        pose, f = reference_pose(motion, roles)
        motion = replace(motion, skeleton=replace(motion.skeleton, reference_pose=pose))
        notes.append(f"the zero-rotation pose is not upright (bind orientations): the body is measured "
                     f"in frame {f} of the motion (mid-stance)")
    ambiguous = False
    if length_scale is None:
        if roles is not None:
            body = BodyModel.from_skeleton(motion.skeleton, joint_map=joint_map)
            m = _analysed(motion)
            com, mk = body.com_and_markers(m)
            foot_low = mk[..., UP_AXIS].min(axis=2)
            planted = planted_feet(mk, com, m.frame_time)
            g_u, n_flights = flight_gravity_units(com, foot_low, body.leg_length, m.frame_time, planted)
            hz = step_frequency_hz(mk.mean(axis=2), com, m.frame_time)
            flight_note = ""
            if g_u is not None and not flights_between_steps(n_flights, hz, m.duration):
                # a few windows where both feet read high (a tilted floor, a foot's marker placement) are
                # no flight: the gravity they give weighs nothing (a brisk walk read as a 3.8 m performer)
                flight_note = (f"; {n_flights} brief 'flight(s)' in about {(hz or 0.0) * m.duration:.0f} steps are "
                               "no flight phase")
                g_u = None
            duty = float(planted.mean()) if planted.size else 0.0
            walking = True if duty > WALKING_DUTY + DUTY_MARGIN else False if duty < WALKING_DUTY - DUTY_MARGIN \
                else None
            length_scale, name, units, ambiguous = choose_unit(body.stature, g_u, step_hz=hz,
                                                               leg_units=body.leg_length, walking=walking)
            units += flight_note
        else:
            stature = motion.skeleton.standing_height()
            length_scale, name, units, ambiguous = choose_unit(stature, None)
            units += " (joint roles unknown: stature from the zero pose)"
    else:
        if not (np.isfinite(length_scale) and length_scale > 0):
            raise ValueError(f"length_scale must be > 0, got {length_scale}")
        units = f"length scale {length_scale:g} m per file unit (given)"
    s = float(length_scale)
    out = replace(
        motion,
        skeleton=motion.skeleton.scaled(s),
        root_positions=motion.root_positions * s,
        translations=None if motion.translations is None else motion.translations * s,
    )
    return out, {"length_scale": s, "units": units, "units_ambiguous": ambiguous, "up_axis": up_axis,
                 "notes": tuple(notes)}
