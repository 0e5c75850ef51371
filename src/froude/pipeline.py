"""fit → modify → synthesise → correct, as plain functions: the one place the CLI, studio and batch call.

    prep = prepare("run.bvh")                                   # load, body model, gait, §4 fit, cycle
    out = scale(prep, character="child", speed=0.7, strides=4)  # §5.1 + §5.2 + §6
    out = accelerate(prep, to_speed=0.5, steps=8)               # §5.3 + §6
    write_result(out, "child.bvh")                              # BVH + child.report.json, atomically

The output stands on the floor y = 0, starts where the reference's COM starts (horizontally) and runs in
the reference's direction of travel.
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .body import BodyModel
from .characters import Character, Retarget, apply_character, character_from_numbers, load_character
from .constants import GRAVITY, UP_AXIS
from .errors import FroudeError, PlanError
from .gait import Gait, GaitSummary, detect_gait, require_running, summarize
from .metrics import Report, physics_report, write_report
from .motion import Motion
from .synthesis import ReferenceCycle, extract_cycle, min_jerk, sample_cycle

#: Speed factors outside this range leave what a reference clip supports: a warning, not an error.
SUPPORTED_SPEED_RANGE = (0.6, 1.6)
#: IK weights [1/m²] for a reference-sized body (scaled by (reference leg / target leg)² for others);
#: posture pulls at 1e-4 per rad² (the solver's default). The COM is held hardest: it carries the physics
#: (flight gravity needs it to well under a millimetre); loaded foot markers next; swing feet only guide.
COM_WEIGHT = 1e4
STANCE_MARKER_WEIGHT = 1e3
SWING_MARKER_WEIGHT = 1e-2
#: IK stops a frame when every weighted error is below this [m], after at most IK_ITERS steps; the COM is
#: then made exact by shifting the root (a root translation moves the COM one to one).
IK_TOL = 1e-3
IK_ITERS = 4
#: Gauss-Newton steps (fresh Jacobian each) of the repair pass. Frames that missed their targets need few:
#: on the 108 scale outputs of the 9 clips, 2 meet every bar as 6 do (same worst skate 4.5 mm, penetration
#: 2.8 mm and joint jump 1.37x the reference's; 0 steps leave 5.9 mm penetration and 5.1 mm skate). A
#: frame that flipped to another branch needs more to come back (accelerating 09_04 to 1.3x keeps a 20 deg
#: knee jump with 3).
IK_REPAIR_ITERS = 2
IK_UNFLIP_ITERS = IK_ITERS + 2
#: Posture weight [1/rad²] of the trunk, arms and head (the legs take the solver's default, 1e-4).
UPPER_BODY_POSTURE_WEIGHT = 1e-2
#: Joints IK leaves alone: hands, fingers, mass-less joints and the head and neck (kept from the reference).
IK_FREEZE = "auto+head"
#: A joint changing this much more between two frames than in the reference pose there is a branch flip.
BRANCH_JUMP_DEG = 10.0
#: Frames whose COM error, or the error of a foot marker the IK is asked to hold, exceeds this [m] after
#: the fast pass are solved again, harder.
RETRY_COM_ERROR = 3e-3
RETRY_MARKER_ERROR = 3e-3
#: A foot marker the IK is asked to hold has at least this weight (before the per-size factor); lighter
#: ones only guide a swinging foot and may stay centimetres off (their floor is SWING_MARKER_WEIGHT): that
#: is neither a reason to solve again nor a failure.
HELD_MARKER_WEIGHT = 1.0
#: Time [s] over which a foot's marker weight ramps between swing and stance around its events.
WEIGHT_RAMP_S = 0.04
#: Fraction of the stance marker weight every marker of a foot keeps around its contact (see _marker_weights).
LANDING_WEIGHT = 0.1


# ---- 1. prepare: load, body model, gait, fit, cycle --------------------------------------------------
@dataclass(frozen=True, eq=False)
class Prepared:
    """A reference clip made ready for any number of changes (fit once, reuse for every variation)."""

    motion: Motion
    body: BodyModel
    com: np.ndarray
    markers: np.ndarray
    gait: Gait
    summary: GaitSummary
    machine: object  # froude.machine.model.SimpleMachine
    cycle: ReferenceCycle
    source: str = ""
    fit: object = None  # froude.machine.fit.FitResult: everything the fit measured (plots, tables)
    #: What the machine stands for ("0.00-2.40 s of the take: 3.150 m/s, 2.930 steps/s") and notes about
    #: the take (its speed changes: which part is modelled, how to choose another).
    modelled: str = ""
    notes: tuple = ()
    #: Retargets already built for this clip, by (preset name or None, character numbers): an editor asks
    #: for the same character again and again (every speed change) and building one costs milliseconds.
    retargets: dict = field(default_factory=dict, repr=False)
    #: Machines re-solved for a faster speed, by speed factor (the studio's speed slider revisits values).
    faster_machines: dict = field(default_factory=dict, repr=False)

    def faster_machine(self, speed: float):
        """``machine.speed.faster_machine(self.machine, speed)``, remembered per speed factor."""
        from .machine.speed import faster_machine

        key = float(speed)
        hit = self.faster_machines.get(key)
        if hit is None:
            hit = self.faster_machines[key] = faster_machine(self.machine, key)
        return hit

    def retarget(self, character=None, **character_numbers) -> Retarget:
        """``apply_character(resolve_character(character, **numbers), self.body)``, remembered for the
        built-in presets and the reference's own body (files and Character objects are built each time)."""
        key = None
        if character is None or (isinstance(character, str) and character in _preset_names()):
            key = (character, tuple(sorted((k, v) for k, v in character_numbers.items() if v is not None)))
            hit = self.retargets.get(key)
            if hit is not None:
                return hit
        rt = apply_character(resolve_character(character, **character_numbers), self.body)
        if key is not None:
            self.retargets[key] = rt
        return rt


@functools.cache
def _preset_names() -> frozenset:
    from .characters import list_presets

    return frozenset(list_presets())


#: A take whose stride speeds spread more than this (fastest / slowest − 1) is said to change speed: the
#: output then says which part the machine models and how to choose another (``time_range``).
SPEED_CHANGE_NOTE = 0.10  # a steady CMU run's strides spread 2-5 %


def parse_time_range(text: str) -> tuple[float | None, float | None]:
    """'T0:T1' [s] -> (T0, T1); either side may be empty ('1.5:' from 1.5 s to the end)."""
    a, sep, b = str(text).partition(":")
    try:
        if not sep:
            raise ValueError
        return (float(a) if a.strip() else None), (float(b) if b.strip() else None)
    except ValueError:
        raise FroudeError(f"cannot read time range '{text}': use T0:T1 in seconds (e.g. 1.2:3.0, or 1.2: to the end)") from None


def select_range(motion: Motion, time_range, source: str = "motion") -> Motion:
    """The frames of ``motion`` whose times [s] lie in time_range = (T0, T1) (None: the clip's start / end)."""
    t0, t1 = time_range
    t0 = 0.0 if t0 is None else float(t0)
    t1 = motion.duration if t1 is None else float(t1)
    if not (np.isfinite(t0) and np.isfinite(t1) and 0.0 <= t0 < t1):
        raise FroudeError(f"{source}: time range {t0:g}:{t1:g} s is empty or negative")
    if t0 >= motion.duration:
        raise FroudeError(f"{source}: time range starts at {t0:g} s, after the clip's end ({motion.duration:.3f} s)")
    i0 = int(math.ceil(t0 / motion.frame_time - 1e-3))  # a frame time written to 7 digits: 1e-3 frame slack
    i1 = min(motion.n_frames, int(math.floor(t1 / motion.frame_time + 1e-3)) + 1)
    out = motion.cut(i0, i1)
    meta = dict(out.meta)
    meta["time_range_s"] = (i0 * motion.frame_time, (i1 - 1) * motion.frame_time)
    from dataclasses import replace as _replace

    return _replace(out, meta=meta)


def modelled_part(motion: Motion, summary: GaitSummary, com: np.ndarray, gait: Gait) -> tuple[str, str | None]:
    """What the machine of a clip stands for, in one line, and a note when the take's speed changes.

    Returns (description, note or None): "0.00-2.40 s of the take: 3.150 m/s, 2.930 steps/s".
    """
    from .gait import stride_speeds

    t0, t1 = motion.meta.get("time_range_s", (0.0, motion.duration))
    loop = motion.meta.get("loop")
    part = (f"a {loop['frames'] * motion.frame_time:.2f} s loop ({loop['frames']} frames, unrolled x{loop['copies']})"
            if loop else f"{t0:.2f}-{t1:.2f} s of the take")
    if motion.meta.get("in_place"):
        part += ", in place (speed from the feet)"
    text = f"{part}: {summary.mean_speed:.3f} m/s, {summary.step_frequency:.3f} steps/s"
    _, v = stride_speeds(com, gait, motion.n_frames)
    note = None
    if v.size >= 2 and v.max() / v.min() - 1.0 > SPEED_CHANGE_NOTE:
        note = (f"the speed changes within the take (first stride {v[0]:.2f} m/s, last {v[-1]:.2f}, strides "
                f"{v.min():.2f}-{v.max():.2f}): the machine runs its mean over {t0:.2f}-{t1:.2f} s, "
                f"{summary.mean_speed:.2f} m/s, and speed factors refer to that; choose a part with "
                "--range T0:T1 (time_range=)")
    return text, note


#: A clip is a loop when its last pose is this close to its first (mean joint angle), relative to the
#: median change between neighbouring frames: below LOOP_DUPLICATE the last frame repeats the first, below LOOP_CONTINUES the first
#: frame follows the last.
LOOP_DUPLICATE = 0.25
LOOP_CONTINUES = 1.5
#: A looping take is unrolled into at least this many copies and at least LOOP_MIN_S seconds.
LOOP_MIN_COPIES = 3
LOOP_MIN_S = 1.5
#: An in-place take travels less than this × L, while its feet slide back faster than IN_PLACE_MIN_FROUDE
#: √(g L) on the ground.
IN_PLACE_MAX_TRAVEL_L = 0.5
IN_PLACE_MIN_FROUDE = 0.3


def unroll_loop(motion: Motion, body: BodyModel) -> tuple[Motion, str] | None:
    """A looping take (one stride or a few that repeat) as several copies in a row, with its travel.

    The take loops when its last pose returns to its first: either repeating it (the last frame is dropped
    when tiling) or one frame before it (the first frame follows the last). Each copy is moved on by the
    loop's horizontal COM travel, so a root-motion loop runs on and an in-place loop stays in place.
    Returns (motion, note) or None when the take does not loop.
    """
    from . import quat

    F = motion.n_frames
    if F < 4:
        return None
    rot = quat.make_continuous(motion.rotations)
    # mean over joints: one joint landing fast at the seam (or a glitch at a clip's edge) does not decide
    step = quat.angle_between(rot[1:], rot[:-1]).mean(axis=1)
    close = float(quat.angle_between(rot[-1], rot[0]).mean())
    typical = float(np.median(step))
    if not typical > 0:
        return None
    com = body.com(motion)
    travel = com[-1] - com[0]
    if close <= LOOP_DUPLICATE * typical:
        n, per_loop = F - 1, travel
    elif close <= LOOP_CONTINUES * typical:
        n, per_loop = F, travel * F / (F - 1)
    else:
        return None
    per_loop = per_loop.copy()
    per_loop[UP_AXIS] = 0.0
    copies = max(LOOP_MIN_COPIES, int(math.ceil(LOOP_MIN_S / (n * motion.frame_time))))
    k = np.repeat(np.arange(copies), n)
    idx = np.tile(np.arange(n), copies)
    root = motion.root_positions[idx] + k[:, None] * per_loop[None, :]
    tr = None if motion.translations is None else motion.translations[idx]
    from dataclasses import replace as _replace

    meta = dict(motion.meta)
    meta["loop"] = {"frames": n, "copies": copies}
    out = _replace(motion, root_positions=root, rotations=rot[idx], translations=tr, meta=meta)
    note = (f"a looping take ({n} frames, {n * motion.frame_time:.2f} s, "
            f"{'last frame repeats the first' if n == F - 1 else 'first frame follows the last'}): "
            f"unrolled {copies} times")
    return out, note


def add_travel(motion: Motion, body: BodyModel, markers: np.ndarray | None = None) -> tuple[Motion, str] | None:
    """An in-place take (root travel removed, the stance foot sliding back) with its travel put back.

    The running velocity is minus the feet's velocity on the ground (``gait.ground_velocity``); the root
    then moves at it. Returns (motion, note), or None when the take travels or its feet do not slide.
    """
    from .gait import ground_velocity

    com = body.com(motion)
    L = body.leg_length
    travel = com[-1] - com[0]
    travel[UP_AXIS] = 0.0
    if np.linalg.norm(travel) >= IN_PLACE_MAX_TRAVEL_L * L:
        return None
    if markers is None:
        markers = body.foot_markers(motion)
    v = -ground_velocity(markers, L, motion.frame_time)
    u = float(np.linalg.norm(v))
    if u < IN_PLACE_MIN_FROUDE * math.sqrt(GRAVITY * L):
        return None
    t = np.arange(motion.n_frames) * motion.frame_time
    from dataclasses import replace as _replace

    meta = dict(motion.meta)
    meta["in_place"] = {"speed_m_s": u, "velocity_m_s": v.tolist()}
    out = _replace(motion, root_positions=motion.root_positions + t[:, None] * v[None, :], meta=meta)
    return out, (f"an in-place take: running at {u:.2f} m/s, found from the feet sliding back on the ground; "
                 "its travel is put back for the fit (outputs are written in place too unless --travel)")


def running_take(motion: Motion, body: BodyModel) -> tuple[Motion, list[str]]:
    """The take as froude analyses it: a loop unrolled, an in-place take given its travel back (notes say
    what was done). Other takes are returned as they are."""
    notes = []
    moving = add_travel(motion, body)  # first: an in-place take's contacts are found once it travels
    if moving is not None:
        motion, note = moving
        notes.append(note)
    # only a take too short to fit is unrolled (fewer than two complete stances): a longer one that happens
    # to end near its first pose is analysed as it is
    loop = unroll_loop(motion, body) if _full_stances(motion, body) < 2 else None
    if loop is not None and _full_stances(loop[0], body) >= 2:
        motion, note = loop
        notes.append(note)
    return motion, notes


def _full_stances(motion: Motion, body: BodyModel) -> int:
    return len(detect_gait(motion, body).full_stances)


def prepare(clip, *, mass: float = 70.0, sex: str = "male", joint_map=None, length_scale=None,
            time_range=None) -> Prepared:
    """Load (if given a path), model, check it is running, fit the simple machine and build the cycle.

    time_range: (T0, T1) [s] (either None): model only that part of the take (its speed, cadence and
    strides); the whole take by default.
    """
    from .io.bvh import load_bvh
    from .machine.fit import fit_machine_detailed

    if isinstance(clip, Motion):
        motion, source = clip, str(clip.meta.get("source", "motion"))
    else:
        motion, source = load_bvh(clip, length_scale=length_scale), str(clip)
    if time_range is not None:
        motion = select_range(motion, time_range, Path(source).name)
    body = BodyModel.from_skeleton(motion.skeleton, mass=mass, sex=sex, joint_map=joint_map)
    motion, take_notes = running_take(motion, body)
    com, markers = body.com_and_markers(motion)
    gait = detect_gait(motion, body, markers)
    summary = summarize(motion, body, com, gait)
    require_running(summary, source)
    fit = fit_machine_detailed(motion, body, mass=mass, source=Path(source).name)
    machine = fit.machine
    cycle = extract_cycle(motion, body, gait, com, markers, events=_fit_events(machine, motion))
    modelled, note = modelled_part(motion, summary, com, gait)
    return Prepared(motion, body, com, markers, gait, summary, machine, cycle, source, fit,
                    modelled=modelled, notes=tuple(take_notes) + ((note,) if note else ()))


def _fit_events(machine, motion: Motion):
    """The fit's force-refined touchdown/liftoff times as foot events (None: use the gait's)."""
    from .synthesis import FootEvent

    ev = []
    for s in getattr(machine, "stances", ()):
        foot = 0 if s.get("foot") in (0, "left") else 1
        for key, kind in (("t_touchdown_s", "td"), ("t_liftoff_s", "lo")):
            t = s.get(key)
            if t is not None and np.isfinite(t) and 0 < t < motion.duration:
                ev.append(FootEvent(t / motion.frame_time, foot, kind))
    ev.sort(key=lambda e: e.frame)
    # events must alternate td/lo per foot and the feet alternate; otherwise trust the gait
    for a, b in zip(ev[:-1], ev[1:]):
        if a.kind == b.kind:
            return None
    return ev or None


# ---- 2. the machine's trajectory in the world ----------------------------------------------------------
@dataclass(frozen=True, eq=False)
class MachinePath:
    """The simple machine's motion in world coordinates at the output frame rate (SI).

    times: (T,) [s]; com: (T, 3) [m]; force: (T, 3) ground force on the COM [N]; psi: (T,) unwrapped stride
    phase (0 at the first touchdown of foot A); stance: (T, 2) bool (the machine's force-based stance);
    contact: (T, 2) bool, the foot on the ground (the reference's marker contact through the time warp,
    a little wider than the stance); foot_of_step: (n,) 0/1; t_touchdown, t_liftoff: (n,) [s];
    contact_on, contact_off: (n,) [s]; contacts: (n, 3) contact points [m]; apex_speed: (n+1,) [m/s];
    U: (n+1,) dimensionless apex speeds; frame: (3, 3) heading frame rows; l0 [m]; mass [kg].
    """

    times: np.ndarray
    com: np.ndarray
    force: np.ndarray
    psi: np.ndarray
    stance: np.ndarray
    contact: np.ndarray
    foot_of_step: np.ndarray
    t_touchdown: np.ndarray
    t_liftoff: np.ndarray
    contact_on: np.ndarray
    contact_off: np.ndarray
    contacts: np.ndarray
    apex_speed: np.ndarray
    U: np.ndarray
    frame: np.ndarray
    l0: float
    mass: float

    @property
    def frame_time(self) -> float:
        return float(self.times[1] - self.times[0]) if len(self.times) > 1 else 0.0


def machine_path(
    prep: Prepared,
    retarget: Retarget,
    *,
    speed: float = 1.0,
    n_steps: int,
    fps: float,
    theta0=None,
    controls=None,
    start_state: tuple[float, float] | None = None,
    machine=None,
) -> MachinePath:
    """Simulate the (scaled) machine for n_steps steps and place it in the world.

    speed: §5.2 horizontal stretch factor s (vertical motion and timing unchanged).
    theta0: per-step touchdown angles (n_steps,) [rad] (default: the cycle's); controls: per-step Controls;
    start_state: apex (U, H) to start from (default: the periodic cycle's).
    machine: the (unscaled) SimpleMachine to run (default: the fitted one).
    """
    m = (prep.machine if machine is None else machine).scaled(retarget.L, retarget.M)
    T_unit = m.time_unit
    dt = 1.0 / fps / T_unit
    if theta0 is None and controls is None and start_state is None:
        tr = _periodic_trajectory(m, n_steps, dt)
    else:
        from .machine.dynamics import simulate

        th = np.full(n_steps, m.theta0) if theta0 is None else np.asarray(theta0, float)
        U0, H0 = (m.U, m.H) if start_state is None else start_state
        tr = simulate(U0, H0, th, m.control if controls is None else controls, dt)
    cyc = prep.cycle
    Rh = cyc.frame
    fwd, up, lat = Rh
    L = retarget.L
    l0 = m.l0
    t = tr.t * T_unit
    A = cyc.first_foot
    feet = np.where(np.arange(n_steps) % 2 == 0, A, 1 - A)
    t_td = tr.t_touchdown * T_unit
    t_lo = tr.t_liftoff * T_unit
    psi, _, _, contact_on, contact_off = _stride_phase(t, t_td, t_lo, feet, A, cyc.phase_events,
                                                       cyc.contact_phase, tr, T_unit)
    phi = np.mod(psi, 1.0)
    _, data = sample_cycle(cyc, phi, rotations=False)
    origin = prep.com[0].copy()
    origin[UP_AXIS] = 0.0
    com = (origin + np.outer(speed * tr.pos[:, 0] * l0, fwd) + np.outer(tr.pos[:, 1] * l0, up)
           + np.outer(L * data["com_lateral"], lat))
    contacts = (origin + np.outer(speed * tr.contact_x * l0, fwd)
                + np.outer(L * cyc.contact_lateral[feet], lat))
    force = (np.outer(speed * tr.force[:, 0], fwd) + np.outer(tr.force[:, 1], up)) * m.mass * GRAVITY
    stance = np.zeros((len(t), 2), bool)
    contact = np.zeros((len(t), 2), bool)
    for i, f in enumerate(feet):
        stance[(t >= t_td[i]) & (t < t_lo[i]), f] = True
        contact[(t >= contact_on[i]) & (t < contact_off[i]), f] = True
    return MachinePath(
        times=t, com=com, force=force, psi=psi, stance=stance, contact=contact, foot_of_step=feet,
        t_touchdown=t_td, t_liftoff=t_lo, contact_on=contact_on, contact_off=contact_off, contacts=contacts, apex_speed=speed * tr.U_apex * m.speed_unit, U=tr.U_apex,
        frame=Rh, l0=l0, mass=m.mass,
    )


@dataclass(frozen=True)
class _Tiled:
    """The fields of machine.dynamics.Trajectory that machine_path uses (dimensionless)."""

    t: np.ndarray
    pos: np.ndarray
    force: np.ndarray
    t_touchdown: np.ndarray
    t_liftoff: np.ndarray
    contact_x: np.ndarray
    U_apex: np.ndarray
    t_apex: np.ndarray


def _periodic_trajectory(m, n_steps: int, dt: float) -> _Tiled:
    """n_steps of the periodic cycle: one stride simulated at the output times modulo the stride, tiled.

    The cycle is periodic to 1e-9, so this equals simulating every step while costing one stride.
    """
    from .machine.dynamics import simulate

    T2, dx = 2.0 * m.step_time, 2.0 * m.step_length
    n_frames = int(math.floor(n_steps * m.step_time / dt + 1e-9)) + 1
    t = np.arange(n_frames) * dt
    k = np.floor(t / T2 + 1e-12)
    tau = t - k * T2
    one = simulate(m.U, m.H, np.full(2, m.theta0), m.control, dt, times=tau)
    pos = one.pos.copy()
    pos[:, 0] += k * dx
    i = np.arange(n_steps)
    shift = (i // 2) * T2
    return _Tiled(
        t=t, pos=pos, force=one.force, t_touchdown=one.t_touchdown[i % 2] + shift,
        t_liftoff=one.t_liftoff[i % 2] + shift, contact_x=one.contact_x[i % 2] + (i // 2) * dx,
        U_apex=np.full(n_steps + 1, m.U), t_apex=np.arange(n_steps + 1) * m.step_time,
    )


def _stride_phase(t, t_td, t_lo, feet, A, phase_events, contact_phase, tr, T_unit):
    """Unwrapped reference stride phase of each output time, and each step's ground contact [s].

    The time warp is piecewise linear with knots at every touchdown and liftoff (stance→stance,
    flight→flight, paper §6), plus knots where the foot reaches and leaves the ground as the reference's
    markers see it (contact_phase, a little outside the force-based stance): those stretches are played at
    the stance's rate, so the body travels as far over the planted foot as in the reference whatever the
    flight time is. Returns (psi (T,), knot times, knot phases, contact_on (n,), contact_off (n,)).
    """
    p = {(A, "td"): 0.0, (A, "lo"): phase_events[1], (1 - A, "td"): phase_events[2], (1 - A, "lo"): phase_events[3]}
    n = len(feet)
    k = np.arange(n) // 2
    psi_td = k + np.array([p[(f, "td")] for f in feet])
    psi_lo = k + np.array([p[(f, "lo")] for f in feet])
    ext_before = np.array([p[(f, "td")] - contact_phase[f, 0] for f in feet])  # [phase] before touchdown
    ext_after = np.array([contact_phase[f, 1] - p[(f, "lo")] for f in feet])  # [phase] after liftoff
    rate = (t_lo - t_td) / (psi_lo - psi_td)  # [s per phase] in each stance
    # the flights around each step, in time (the first and last from the machine's own flight time)
    flight_time = (t_td[1:] - t_lo[:-1]) if n > 1 else np.array([(tr.t_apex[-1] * T_unit - t_lo[-1]) * 2])
    fl_before = np.concatenate([[flight_time[0]], flight_time])[:n]
    fl_after = np.concatenate([flight_time, [flight_time[-1]]])[:n]
    on_t = t_td - ext_before * rate
    off_t = t_lo + ext_after * rate
    # never let the extensions eat a flight: keep at least 20 % of each flight as true flight
    room_before = 0.4 * fl_before
    room_after = 0.4 * fl_after
    on_t = np.maximum(on_t, t_td - room_before)
    off_t = np.minimum(off_t, t_lo + room_after)
    times, psis = [], []
    for i in range(n):
        times += [on_t[i], t_td[i], t_lo[i], off_t[i]]
        psis += [psi_td[i] - ext_before[i], psi_td[i], psi_lo[i], psi_lo[i] + ext_after[i]]
    last_f = feet[-1]
    next_td_psi = k[-1] + (1.0 if last_f == 1 - A else phase_events[2])
    times = np.array([t_td[0] - fl_before[0]] + times + [t_lo[-1] + fl_after[-1]])
    psis = np.array([p[(1 - A, "lo")] - 1.0] + psis + [next_td_psi])
    return np.interp(t, times, psis), times, psis, on_t, off_t


# ---- 3. synthesise: time-warped reference on the target skeleton, IK targets ------------------------------
@dataclass(frozen=True, eq=False)
class Targets:
    """Initial motion (reference angles, root from the machine COM) and the IK targets and weights."""

    initial: Motion
    com: np.ndarray  # (T, 3) [m]
    markers: np.ndarray  # (T, 2, 3, 3) [m]
    marker_weight: np.ndarray  # (T, 2, 3)
    com_weight: np.ndarray  # (T,)


def build_targets(prep: Prepared, path: MachinePath, retarget: Retarget) -> Targets:
    """Time-warp the reference cycle onto the machine's steps and set the COM and foot targets."""
    cyc = prep.cycle
    L = retarget.L
    Rh = path.frame
    phi = np.mod(path.psi, 1.0)
    rot, data = sample_cycle(cyc, phi)
    T = len(path.times)
    anchors, w_ground = _foot_anchors(path)
    rel_world = np.einsum("fpki,ij->fpkj", L * data["marker_rel"], Rh)  # heading frame -> world
    on_ground = anchors[:, :, None, :] + rel_world
    # In mid-swing the foot moves with the body (its offset from the COM, scaled), not along a stretched
    # ground path: a stretched path would leave the trailing foot out of the leg's reach after toe-off
    # when running faster. Near toe-off and touchdown the ground-anchored path takes over.
    com_rel = L * data["marker_from_com"]
    com_rel[..., 1] = L * data["marker_rel"][..., 1]  # heights above the ground as in the anchored path
    with_body = path.com[:, None, None, :] + np.einsum("fpki,ij->fpkj", com_rel, Rh)
    # In mid-swing the foot keeps at least its reference height below the COM: a machine whose COM flies
    # higher than the reference's at that phase (a faster cycle: shorter stance, longer flight) would
    # otherwise leave the swinging foot at the reference's height above the ground, out of the leg's reach,
    # and the IK straightens the knee and flips it (a 60-70 deg pop at x1.5).
    below_com = path.com[:, None, None, UP_AXIS] + L * (data["marker_from_com"][..., 1]
                                                        - data["com_height"][:, None, None])
    with_body[..., UP_AXIS] = np.maximum(on_ground[..., UP_AXIS], below_com)
    w = w_ground[:, :, None, None]
    markers = w * on_ground + (1.0 - w) * with_body
    root = path.com + (L * data["root_from_com"]) @ Rh
    meta = {"source": prep.source, "length_scale": float(prep.motion.meta.get("length_scale", 1.0))}
    initial = Motion(retarget.skeleton, root, rot, float(path.frame_time), None, meta)
    # The reference's root-to-COM offset × L is where the root goes for a body of the reference's
    # proportions. A character with other proportions (a troll's trunk) carries its COM elsewhere relative
    # to the root, and when the root is a static reference joint far from the pelvis (the Bandai rig's
    # joint_Root, metres from the body through the pelvis offset) the error is metres: the IK would start
    # with the feet out of reach. So the initial pose is translated to put its own COM on the machine's.
    initial = initial.with_(root_positions=root + (path.com - retarget.body.com(initial)))
    markers = _lift_out_of_reach(initial, retarget.body, markers)
    weight = _marker_weights(path, markers, retarget.body.leg_length) * _reach_factor(initial, retarget.body, markers)
    weight = np.maximum(weight, SWING_MARKER_WEIGHT)
    # Weights are per (leg length)^2, so the trade-off between a position error and a joint angle is the
    # same for a child and a giant (errors in metres grow with size, joint angles do not).
    per_size = (prep.body.leg_length / retarget.body.leg_length) ** 2
    return Targets(initial, path.com, markers, weight * per_size, np.full(T, COM_WEIGHT * per_size))


def _leg_reach(body: BodyModel, side: str) -> np.ndarray:
    """(3,) straight-leg distances [m] from the hip to the ankle, the ball and the tip of one foot."""
    r, rest = body.roles, body.skeleton.rest_positions()
    leg = np.linalg.norm(rest[r[f"{side}_knee"]] - rest[r[f"{side}_hip"]]) + np.linalg.norm(
        rest[r[f"{side}_ankle"]] - rest[r[f"{side}_knee"]])
    ankle_toe = np.linalg.norm(rest[r[f"{side}_toe"]] - rest[r[f"{side}_ankle"]])
    toe_end = np.linalg.norm(body.marker_local[0 if side == "left" else 1, 2])
    return np.array([leg, leg + ankle_toe, leg + ankle_toe + toe_end])


#: A foot marker target farther from the hip than its straight-leg reach less this many REACH_MARGIN_L is
#: raised until it is not (see _lift_out_of_reach).
LIFT_AT_MARGINS = 2.0
REACH_MARGIN_L = 0.03
#: ... by at most about this fraction of L (a soft cap: the rise needed grows without bound as the
#: horizontal distance nears the reach; beyond the cap the target stays out of reach and _reach_factor lets
#: it go, by then above the floor band in which the physics report watches it slide).
LIFT_MAX_L = 0.05


def _lift_out_of_reach(initial: Motion, body: BodyModel, markers: np.ndarray) -> np.ndarray:
    """markers (T, 2, 3, 3) [m] with every target beyond the leg's reach raised straight up until it is
    within it (hip from the initial pose; reach from _leg_reach less LIFT_AT_MARGINS margins).

    When the body has travelled farther over a planted foot than the leg allows (an acceleration's longer
    stance, a faster run), holding the foot's points where they are ends with the knee locked and the IK
    failing, and releasing them lets the posture swing the toe sideways while it is still on the floor (a
    10-15 mm scuff at lift-off). Raising them instead is what a foot does at toe-off: the heel, then the
    ball and the tip rise where they stand, so they leave the floor without sliding. A target whose
    horizontal distance alone is out of reach is raised by the cap and released by _reach_factor.
    """
    hips = body.joint_positions(initial, [body.roles["left_hip"], body.roles["right_hip"]])  # (T, 2, 3)
    out = markers.copy()
    margin = REACH_MARGIN_L * body.leg_length
    cap = LIFT_MAX_L * body.leg_length
    horizontal = [a for a in range(3) if a != UP_AXIS]
    for i, side in enumerate(("left", "right")):
        reach = _leg_reach(body, side) - LIFT_AT_MARGINS * margin  # (3,)
        rel = markers[:, i] - hips[:, i, None, :]  # (T, 3, 3)
        flat = np.linalg.norm(rel[..., horizontal], axis=-1)  # (T, 3)
        lowest = -np.sqrt(np.maximum(reach[None, :] ** 2 - flat**2, 0.0))  # lowest reachable height below the hip
        need = np.where(flat < reach[None, :], lowest - rel[..., UP_AXIS], np.inf)  # (T, 3) rise needed [m]
        out[:, i, :, UP_AXIS] += cap * np.tanh(np.maximum(need, 0.0) / cap)
    return out


def _reach_factor(initial: Motion, body: BodyModel, markers: np.ndarray) -> np.ndarray:
    """(T, 2, 3) in [0, 1]: 1 where a marker target is within the leg's reach from the hip, fading to 0 as
    it approaches the straight-leg limit (thigh + shank + the foot's bones to that marker), so an
    unreachable target is released instead of wrenching the body (the foot simply leaves a little early).
    """
    skel = body.skeleton
    hips = body.joint_positions(initial, [body.roles["left_hip"], body.roles["right_hip"]])  # (T, 2, 3)
    out = np.ones(markers.shape[:3])
    margin = 0.03 * body.leg_length
    for i, side in enumerate(("left", "right")):
        r = body.roles
        hip = hips[:, i]  # (T, 3)
        rest = skel.rest_positions()
        leg = np.linalg.norm(rest[r[f"{side}_knee"]] - rest[r[f"{side}_hip"]]) + np.linalg.norm(
            rest[r[f"{side}_ankle"]] - rest[r[f"{side}_knee"]])
        ankle_toe = np.linalg.norm(rest[r[f"{side}_toe"]] - rest[r[f"{side}_ankle"]])
        toe_end = np.linalg.norm(body.marker_local[i, 2])
        reach = np.array([leg, leg + ankle_toe, leg + ankle_toe + toe_end]) - 0.5 * margin
        d = np.linalg.norm(markers[:, i] - hip[:, None, :], axis=-1)  # (T, 3)
        out[:, i] = min_jerk((reach[None, :] - d) / margin)
    return out


#: Fractions of a swing over which the foot target blends from the ground-anchored path to the
#: body-relative one after toe-off (quickly: the leg is nearly straight at toe-off and cannot trail a
#: ground path that a faster body leaves behind) and back before touchdown (slowly, to land on the contact).
SWING_RELEASE = 0.05
SWING_LANDING = 0.35


def _foot_anchors(path: MachinePath) -> tuple[np.ndarray, np.ndarray]:
    """Each foot's anchor (T, 2, 3): its contact point on the ground, a min-jerk blend between contacts in
    swing; and the weight (T, 2) of the ground-anchored foot path (1 on the ground and at the ends of a
    swing, 0 in mid-swing, min-jerk in between)."""
    T = len(path.times)
    t = path.times
    out = np.zeros((T, 2, 3))
    w_ground = np.ones((T, 2))
    n = len(path.foot_of_step)
    for foot in range(2):
        idx = np.flatnonzero(path.foot_of_step == foot)
        if idx.size == 0:
            continue
        c = path.contacts[idx]
        td = path.contact_on[idx]
        lo = path.contact_off[idx]
        # virtual contacts one stride before the first and after the last (periodic extension); with a single
        # contact of this foot, the stride comes from both feet's steps (along the heading only: the feet's
        # lateral offsets differ)
        # (the first stride extends backwards, the last one forwards: speeds change in an acceleration)
        if len(c) > 1:
            stride_a, swing_a = c[1] - c[0], td[1] - lo[0]
            stride_b, swing_b = c[-1] - c[-2], td[-1] - lo[-2]
        else:
            fwd = path.frame[0]
            step = (path.contacts[-1] - path.contacts[0]) @ fwd / max(n - 1, 1)
            stride_a = stride_b = 2.0 * step * fwd
            t_stride = 2.0 * (path.t_touchdown[-1] - path.t_touchdown[0]) / max(n - 1, 1)
            swing_a = swing_b = t_stride - (lo[0] - td[0])
        c_ext = np.concatenate([c[:1] - stride_a, c, c[-1:] + stride_b])
        lo_ext = np.concatenate([[td[0] - swing_a], lo, [np.inf]])
        td_ext = np.concatenate([[-np.inf], td, [lo[-1] + swing_b]])
        # for each frame: the last touchdown at or before it (index into *_ext)
        k = np.searchsorted(td_ext, t, side="right") - 1
        in_stance = t < lo_ext[k]
        out[in_stance, foot] = c_ext[k[in_stance]]
        sw = ~in_stance
        k_sw = k[sw]
        t0, t1 = lo_ext[k_sw], td_ext[k_sw + 1]
        # progress in stride phase between liftoff and next touchdown (same measure as the reference)
        p = np.interp(t[sw], t, path.psi)
        p0 = _psi_at(path, t0)
        p1 = _psi_at(path, t1)
        u = (p - p0) / np.maximum(p1 - p0, 1e-9)
        w = min_jerk(u)[:, None]
        out[sw, foot] = c_ext[k_sw] * (1 - w) + c_ext[k_sw + 1] * w
        w_ground[sw, foot] = 1.0 - min_jerk(u / SWING_RELEASE) * min_jerk((1.0 - u) / SWING_LANDING)
    return out, w_ground


def _psi_at(path: MachinePath, times: np.ndarray) -> np.ndarray:
    """Stride phase at arbitrary times, extrapolated linearly beyond the path."""
    t, psi = path.times, path.psi
    rate = (psi[-1] - psi[0]) / max(t[-1] - t[0], 1e-9)
    out = np.interp(times, t, psi)
    out = np.where(times < t[0], psi[0] + (times - t[0]) * rate, out)
    return np.where(times > t[-1], psi[-1] + (times - t[-1]) * rate, out)


def _marker_weights(path: MachinePath, markers: np.ndarray, leg_length: float) -> np.ndarray:
    """(T, 2, 3) foot marker weights: high for markers that bear load, low for the rest.

    A foot on the ground is weighted by STANCE_MARKER_WEIGHT, ramped (min-jerk over WEIGHT_RAMP_S) around
    each contact; within it each marker's weight falls smoothly from full at ≤ 0.02 L above the ground to
    the swing weight at ≥ 0.05 L. So the loaded point is held still while the rest of the foot may pivot
    about it (push-off on the toes when a faster or longer-legged run needs more reach than the
    reference's foot pose gives). markers: (T, 2, 3, 3) targets [m]; leg_length [m].
    """
    t = path.times
    ramp = np.zeros((len(t), 2))
    landing = np.zeros((len(t), 2))  # the ramp on the touchdown side of each contact only
    for foot in range(2):
        cols = np.flatnonzero(path.foot_of_step == foot)
        if cols.size == 0:
            continue
        a = path.contact_on[cols]
        b = path.contact_off[cols]
        # the contacts that can touch a frame: the last one starting before t + ramp, and the one before it
        k = np.searchsorted(a - WEIGHT_RAMP_S, t, side="right") - 1
        for kk in (k, k - 1):
            ok = kk >= 0
            kc = np.clip(kk, 0, cols.size - 1)
            u = np.clip(np.minimum(t - (a[kc] - WEIGHT_RAMP_S), (b[kc] + WEIGHT_RAMP_S) - t) / WEIGHT_RAMP_S, 0.0, 1.0)
            ramp[:, foot] = np.maximum(ramp[:, foot], np.where(ok, u, 0.0))
            landing[:, foot] = np.maximum(landing[:, foot], np.where(ok & (t <= a[kc] + WEIGHT_RAMP_S), u, 0.0))
    height = markers[..., UP_AXIS]  # ground at 0
    lo, hi = 0.02 * leg_length, 0.05 * leg_length
    loaded = min_jerk((hi - height) / (hi - lo))  # 1 at or below lo, 0 at or above hi
    # Around a touchdown every marker of the foot keeps at least LANDING_WEIGHT of the stance weight: a
    # landing foot follows its targets down to the contact point instead of being left by the posture pull
    # a centimetre lower and still sweeping forward (a scuff the report sees at touchdown). Not at lift-off:
    # there the leg is nearly straight and a pulled toe can flip the knee.
    loaded = np.maximum(loaded, LANDING_WEIGHT * min_jerk(landing)[..., None])
    return SWING_MARKER_WEIGHT + (STANCE_MARKER_WEIGHT - SWING_MARKER_WEIGHT) * min_jerk(ramp)[..., None] * loaded


# ---- 4. correct (IK) and report ----------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class Result:
    """An output motion with its machine path, targets and physics report."""

    motion: Motion
    report: Report
    path: MachinePath | None
    targets: Targets | None
    retarget: Retarget
    method: str
    speed_factor: float
    notes: tuple[str, ...] = field(default=())
    plan: object = None
    extras: dict = field(default_factory=dict)  # merged into report.extras (e.g. the speed plan)

    def summary_rows(self) -> list[tuple[str, str]]:
        """(label, text) rows of the CLI's result table; a figure that cannot be measured reads "n/a"."""
        r = self.report
        f = _shown
        rows = [
            ("character", f"{self.retarget.character.name} (L = {self.retarget.L:.3f}, M = {self.retarget.M:.3f})"),
            ("method", self.method),
        ]
        if r.extras.get("modelled"):
            rows.append(("modelled", r.extras["modelled"]))
        rows += [
            ("speed", f"{f(r.mean_speed_m_s, '.3f')} m/s (x{self.speed_factor:g})"),
            ("Froude number U", f"{f(r.froude_U, '.3f')}"),
            ("step frequency", f"{f(r.step_frequency_hz, '.3f')} Hz"),
            ("stance / flight", f"{f(_mean(r.stance_times_s), '.3f')} s / {f(_mean(r.flight_times_s), '.3f')} s"),
            ("flight gravity", f"{f(r.flight_gravity_m_s2, '.2f')} m/s^2"),
            ("COM tracking", f"RMS {f(r.com_tracking_rms_mm, '.2f')} mm, max {f(r.com_tracking_max_mm, '.2f')} mm"),
            ("foot skate / penetration", f"{f(r.foot_skate_mm, '.2f')} mm / {f(r.penetration_mm, '.2f')} mm "
             f"(ball and tip near the floor: {f(r.foot_skate_floor_mm, '.2f')} mm)"),
            ("joint jump", f"{f(r.max_joint_jump_deg, '.1f')} deg (reference {f(r.reference_max_joint_jump_deg, '.1f')})"),
        ]
        return rows


def _shown(v, spec: str) -> str:
    """A figure for a table: formatted, or "n/a" when it could not be measured (None, NaN, infinite)."""
    return "n/a" if v is None or not math.isfinite(v) else format(v, spec)


def _mean(x) -> float:
    return float(np.mean(x)) if len(x) else float("nan")


def correct(targets: Targets, body: BodyModel, on_failure: str = "flag"):
    """§6: whole-body IK toward the machine COM and the foot targets, pulled toward the reference pose.

    All frames are solved together with the solver's fast chord iterations. Then one repair pass solves
    again, with a fresh Jacobian every iteration, the few frames whose COM or held foot markers stayed
    above RETRY_COM_ERROR / RETRY_MARKER_ERROR or that jumped to another branch (a knee flipping near full
    extension), warm-started from the neighbouring frame's solution where they jumped; frames are
    independent problems, so this is the same problem solved harder where needed. Finally the COM is made
    exact by a root translation.
    """
    from dataclasses import replace as _replace

    from .ik import DEFAULT_MAX_ERROR, ComTask, MarkerTask, PostureTask, solve_ik

    tasks = [ComTask(body, targets.com, targets.com_weight),
             MarkerTask.feet(body, targets.markers, targets.marker_weight), PostureTask(weight=posture_weights(body))]
    res = solve_ik(targets.initial, tasks, body=body, freeze=IK_FREEZE, on_failure="flag", tol=IK_TOL,
                   max_iters=IK_ITERS)
    held = _held_markers(targets)
    res = _replace(res, failed=_missed(res, held, DEFAULT_MAX_ERROR))
    rot = res.motion.rotations
    init_jump = _largest_joint_angle_deg(targets.initial.rotations[1:], targets.initial.rotations[:-1])
    jump = _largest_joint_angle_deg(rot[1:], rot[:-1])
    flip = np.zeros(len(rot), bool)
    flip[1:] = jump > init_jump + BRANCH_JUMP_DEG
    bad = np.flatnonzero(flip | (res.com_error > RETRY_COM_ERROR) | _missed(res, held, RETRY_MARKER_ERROR))
    if bad.size:
        src = np.where(flip[bad], bad - 1, bad)  # a jumped frame starts from its neighbour's solution
        start = res.motion.with_(root_positions=res.motion.root_positions[src], rotations=rot[src])
        sub = Targets(targets.initial.with_(root_positions=targets.initial.root_positions[bad],
                                            rotations=targets.initial.rotations[bad]),
                      targets.com[bad], targets.markers[bad], targets.marker_weight[bad], targets.com_weight[bad])
        again = _solve_from(sub, start, body, IK_UNFLIP_ITERS if flip[bad].any() else IK_REPAIR_ITERS)
        again = _replace(again, failed=_missed(again, held[bad], DEFAULT_MAX_ERROR))
        prev = rot[np.maximum(bad - 1, 0)]
        old_jump = _largest_joint_angle_deg(rot[bad], prev)
        new_jump = _largest_joint_angle_deg(again.motion.rotations, prev)
        better = np.where(flip[bad], new_jump < old_jump,
                          _worst_held(again, held[bad]) < _worst_held(res, held)[bad])
        better &= again.com_error <= np.maximum(res.com_error[bad], RETRY_COM_ERROR)
        root = res.motion.root_positions.copy()
        rot = rot.copy()
        root[bad[better]] = again.motion.root_positions[better]
        rot[bad[better]] = again.motion.rotations[better]
        com_err = res.com_error.copy()
        com_err[bad[better]] = again.com_error[better]
        com = res.com.copy()
        com[bad[better]] = again.com[better]
        failed = res.failed.copy()
        failed[bad[better]] = again.failed[better]
        res = _replace(res, motion=res.motion.with_(root_positions=root, rotations=rot), com_error=com_err,
                       failed=failed, com=com)
    # Make the COM exact: the remaining sub-millimetre error is removed by a root translation (the COM
    # moves one to one with it), which moves the feet by as little, so the flight parabola is exact.
    shift = targets.com - res.com  # the solver's COM of the solved poses (no second FK)
    res = _replace(res, motion=res.motion.with_(root_positions=res.motion.root_positions + shift),
                   com_error=np.zeros(len(shift)), com=targets.com.copy())
    if on_failure == "raise" and not res.ok:
        from .errors import IkError

        f = int(np.flatnonzero(res.failed)[0])
        raise IkError(f"IK cannot reach its targets at frame {f} (COM error {1000 * res.com_error[f]:.1f} mm)")
    return res


def _held_markers(targets: Targets) -> np.ndarray:
    """(F, 6) the foot markers the IK is asked to hold (weight >= HELD_MARKER_WEIGHT, per size)."""
    per_size = targets.com_weight / COM_WEIGHT  # (F,): the weights' (reference / target leg)² factor
    return targets.marker_weight.reshape(len(per_size), -1) >= HELD_MARKER_WEIGHT * per_size[:, None]


def _largest_joint_angle_deg(q0: np.ndarray, q1: np.ndarray) -> np.ndarray:
    """(F,) the largest rotation of any joint between two poses per frame [deg], rotations (F, J, 4) each:
    2 acos of the smallest |q0 · q1| (acos falls, so one acos per frame instead of one per joint)."""
    dot = np.abs(np.einsum("fjc,fjc->fj", q0, q1)).min(axis=1)
    return np.degrees(2.0 * np.arccos(np.minimum(dot, 1.0)))


def _worst_held(res, held: np.ndarray) -> np.ndarray:
    """(F,) the largest of the COM error and the held foot markers' errors [m]."""
    return np.maximum(res.com_error, np.where(held, res.marker_error, 0.0).max(axis=1))


def _missed(res, held: np.ndarray, limit: float) -> np.ndarray:
    """(F,) frames whose COM or a held foot marker (held (F, 6)) is more than ``limit`` [m] off its target
    (NaN-safe: a non-finite error misses)."""
    return ~(res.com_error <= limit) | np.any(held & ~(res.marker_error <= limit), axis=1)


def posture_weights(body: BodyModel) -> np.ndarray:
    """(J,) posture weights [1/rad²]: the legs free to meet the feet, the upper body held to the reference.

    The COM is finally placed by the root (see ``correct``), so the trunk, arms and head need not bend to
    move it: they keep the reference's motion (UPPER_BODY_POSTURE_WEIGHT), the legs take the solver's
    default.
    """
    from .ik import DEFAULT_JOINT_WEIGHT

    skel = body.skeleton
    w = np.full(skel.n_joints, DEFAULT_JOINT_WEIGHT)
    legs = set()
    for side in ("left", "right"):
        stack = [body.roles[f"{side}_hip"]]
        while stack:
            j = stack.pop()
            legs.add(j)
            stack.extend(skel.children(j))
    for j in range(1, skel.n_joints):
        if j not in legs:
            w[j] = UPPER_BODY_POSTURE_WEIGHT
    return w


def _solve_from(t: Targets, start: Motion, body: BodyModel, max_iters: int):
    """IK of some frames warm-started from ``start`` while still pulled toward the targets' reference pose,
    re-linearised at every one of at most ``max_iters`` steps."""
    from .ik import ComTask, MarkerTask, PostureTask, RootTask, solve_ik

    tasks = [ComTask(body, t.com, t.com_weight), MarkerTask.feet(body, t.markers, t.marker_weight),
             PostureTask(weight=posture_weights(body), reference=t.initial), RootTask(reference=t.initial)]
    return solve_ik(start, tasks, body=body, freeze=IK_FREEZE, on_failure="flag", tol=IK_TOL,
                    max_iters=max_iters, refresh_jacobian=True)


def resolve_character(character=None, *, height=None, mass=None, leg_scale=None, arm_scale=None,
                      head_scale=None, trunk_scale=None) -> Character:
    """A Character from a preset name / file / Character plus optional numbers (numbers win)."""
    base = character if isinstance(character, Character) else (load_character(character) if character else None)
    if base is None and all(v is None for v in (height, mass, leg_scale, arm_scale, head_scale, trunk_scale)):
        return Character(name="same")
    return character_from_numbers(base, height, mass, leg_scale, arm_scale, head_scale, trunk_scale)


@dataclass(frozen=True, eq=False)
class ScalePlan:
    """The first half of ``scale``: the character applied, the machine chosen and its path simulated.

    ``finish(*plan.finish_args())`` completes it (targets, IK, report); the studio shows ``path`` and
    ``build_targets(prep, plan.path, plan.retarget).initial`` as an instant preview.
    """

    prep: Prepared
    path: MachinePath
    retarget: Retarget
    speed: float
    notes: tuple
    method: str
    periodic: tuple | None
    naive: Result | None = None

    def finish(self, report: bool = True) -> Result:
        if self.naive is not None:
            return self.naive
        return finish(self.prep, self.path, self.retarget, self.speed, list(self.notes), self.method,
                      periodic=self.periodic, report=report)


def scale(prep: Prepared, character=None, *, report: bool = True, **options) -> Result:
    """§5.1, §5.2, §6: the reference run on another character, at another speed, for any number of strides.

    character: preset name, YAML/BVH path or Character (None: the reference's own body);
    speed: factor s on the dynamically scaled speed; target_speed: absolute speed [m/s] (overrides speed);
    strides / duration [s]: output length; fps: output frame rate (default: the input's);
    method: "physical" (froude) or "naive" (engines: angles copied, root × L, timing unchanged).
    speed_model: "stretch" (paper §5.2: horizontal stretch, timing kept), "resolve" (the machine's cycle
        re-solved at the new speed with stance time / s and the step time kept, see machine.speed), or
        "auto": stretch when slowing down, resolve when speeding up (a stretched stance would need the leg
        to reach beyond its length at toe-off).
    report: compute the physics report (False: result.report is None; for benchmarks of the synthesis).
    The other options are ``plan_scale``'s (this is ``plan_scale(...).finish(report)``).
    """
    return plan_scale(prep, character, **options).finish(report=report)


@dataclass(frozen=True)
class SpeedRange:
    """The speeds a prepared clip reaches for one character with every physics bar met.

    lo, hi: speed factors on the character's dynamically scaled speed [-]; lo_m_s, hi_m_s: the same in
    m/s; base_m_s: the character's speed at factor 1 [m/s] (the clip's mean speed for its own body).
    probes: ((factor, met: bool, reason), ...) every output tried, in order.
    """

    lo: float
    hi: float
    lo_m_s: float
    hi_m_s: float
    base_m_s: float
    probes: tuple = ()
    empty: bool = False  # True when not even x1 meets every bar

    def describe(self) -> str:
        if self.empty:
            return f"none (x1 = {self.base_m_s:.2f} m/s already misses a bar)"
        return (f"x{self.lo:.2f}-{self.hi:.2f} ({self.lo_m_s:.2f}-{self.hi_m_s:.2f} m/s; "
                f"x1 = {self.base_m_s:.2f} m/s)")


#: The factors reachable_speed_range searches between, and how finely [-].
SPEED_SEARCH_RANGE = (0.3, 3.0)
SPEED_SEARCH_TOL = 0.03


def _speed_ok(prep: Prepared, character, s: float, numbers: dict) -> tuple[bool, str]:
    """Whether a 4-stride output (scale's default) at speed factor s meets every physics bar, and why not."""
    from .errors import FitError

    try:
        rep = plan_scale(prep, character, speed=s, strides=4, **numbers).finish().report
    except FitError as e:
        return False, str(e)
    fails = rep.check_bars()
    return not fails, "; ".join(fails)


def reachable_speed_range(prep: Prepared, character=None, **character_numbers) -> SpeedRange:
    """The range of ``scale`` speed factors whose outputs meet every physics bar, for one character.

    Bisection on real outputs (4 strides each, the same synthesis and IK as ``scale``) between 1 and the
    ends of SPEED_SEARCH_RANGE, to SPEED_SEARCH_TOL; the ends returned were themselves produced and
    checked. About a dozen short outputs (a few seconds); remembered per character on ``prep``. Assumes the
    reachable speeds form one interval around x1 (true on the shared clips: faster outputs fail by a knee
    that pops or a cycle that does not exist, slower ones by nothing down to x0.3).
    For the studio's speed slider and for ``scale``'s refusals.
    """
    key = ("speed_range", character if isinstance(character, (str, type(None))) else id(character),
           tuple(sorted((k, v) for k, v in character_numbers.items() if v is not None)))
    hit = prep.retargets.get(key)
    if hit is not None:
        return hit
    rt = prep.retarget(character, **character_numbers)
    m = prep.machine.scaled(rt.L, rt.M)
    base = m.mean_speed * m.speed_unit
    probes = []

    def ok(s):
        good, why = _speed_ok(prep, character, s, character_numbers)
        probes.append((float(s), good, why))
        return good

    if not ok(1.0):
        lo = hi = 1.0  # not even the clip's own speed meets the bars: nothing is reachable (empty range)
    else:
        ends = []
        for far in SPEED_SEARCH_RANGE:
            good, bad = 1.0, far
            if ok(far):
                ends.append(far)
                continue
            while abs(bad - good) > SPEED_SEARCH_TOL:
                mid = 0.5 * (good + bad)
                if ok(mid):
                    good = mid
                else:
                    bad = mid
            ends.append(good)
        lo, hi = ends
    out = SpeedRange(lo=lo, hi=hi, lo_m_s=lo * base, hi_m_s=hi * base, base_m_s=base, probes=tuple(probes),
                     empty=not probes[0][1])
    prep.retargets[key] = out
    return out


def plan_scale(
    prep: Prepared,
    character=None,
    *,
    speed: float = 1.0,
    target_speed: float | None = None,
    strides: int | None = 4,
    duration: float | None = None,
    fps: float | None = None,
    method: str = "physical",
    speed_model: str = "auto",
    **character_numbers,
) -> ScalePlan:
    """The first half of ``scale`` (same arguments): character, machine, path. Cheap: no IK."""
    retarget = prep.retarget(character, **character_numbers)
    fps = prep.motion.fps if fps is None else float(fps)
    if not (np.isfinite(fps) and fps > 0):
        raise FroudeError(f"fps must be > 0, got {fps}")
    notes = list(prep.notes)
    m_scaled = prep.machine.scaled(retarget.L, retarget.M)
    base_speed = m_scaled.mean_speed * m_scaled.speed_unit
    if target_speed is not None:
        if not (np.isfinite(target_speed) and target_speed > 0):
            raise FroudeError(f"target speed must be > 0 m/s, got {target_speed}")
        speed = target_speed / base_speed
    if not (np.isfinite(speed) and speed > 0):
        raise FroudeError(f"speed factor must be > 0, got {speed}")
    lo, hi = SUPPORTED_SPEED_RANGE
    if not lo <= speed <= hi:
        notes.append(
            f"speed factor {speed:.2f} is outside {lo}-{hi}, the range a single reference clip supports well "
            "(stance time does not change with speed in the vertical-force model, paper §5.2)"
        )
    step_time = m_scaled.step_time * m_scaled.time_unit
    if duration is not None:
        if not (np.isfinite(duration) and duration > 0):
            raise FroudeError(f"duration must be > 0 s, got {duration}")
        n_steps = max(2, int(math.ceil(duration / step_time)))
    else:
        if strides is None or strides < 1:
            raise FroudeError(f"strides must be >= 1, got {strides}")
        n_steps = 2 * int(strides)
    if method == "naive":
        res = _naive(prep, retarget, speed, n_steps, fps, notes)
        return ScalePlan(prep, None, retarget, speed, tuple(notes), "naive", None, naive=res)
    if method != "physical":
        raise FroudeError(f"unknown method '{method}' (physical or naive)")
    if speed_model not in ("auto", "stretch", "resolve"):
        raise FroudeError(f"unknown speed model '{speed_model}' (auto, stretch or resolve)")
    if speed_model == "resolve" or (speed_model == "auto" and speed > 1.0 + 1e-9):
        machine = prep.faster_machine(speed)
        stretch = 1.0
        method = "physical (cycle re-solved at the new speed)"
    else:
        machine, stretch = prep.machine, speed
        method = "physical"
    path = machine_path(prep, retarget, speed=stretch, n_steps=n_steps, fps=fps, machine=machine)
    return ScalePlan(prep, path, retarget, speed, tuple(notes), method, (machine, stretch, fps))


def accelerate(
    prep: Prepared,
    character=None,
    *,
    to_speed: float | None = None,
    to_factor: float | None = None,
    steps: int | None = 8,
    within: float | None = None,
    lead_steps: int = 2,
    hold_steps: int = 4,
    fps: float | None = None,
    energy: str = "auto",
    policy: str = "ease",
    report: bool = True,
    **character_numbers,
) -> Result:
    """§5.3 + §6: speed up or slow down to ``to_speed`` [m/s] or ``to_factor`` × the start speed.

    steps: the change takes this many steps (a step = one stance and the flight after it), or
    within: ... this many seconds; lead_steps / hold_steps: steady steps before / after the change.
    The plan is dimensionless, so it is the same for every dynamically similar character.
    """
    from .machine.planner import plan_speed_change

    retarget = prep.retarget(character, **character_numbers)
    m = prep.machine.scaled(retarget.L, retarget.M)
    v_unit = m.speed_unit
    start_speed = m.U * v_unit  # apex speed of the cycle [m/s]
    if (to_speed is None) == (to_factor is None):
        raise FroudeError("give exactly one goal: a target speed [m/s] or a factor of the start speed")
    target = to_speed if to_speed is not None else to_factor * start_speed
    if not (np.isfinite(target) and target > 0):
        raise FroudeError(f"target speed must be > 0 m/s, got {target:g} (to stop, end the motion instead)")
    if steps is not None and within is None and not (isinstance(steps, int) and steps >= 1):
        raise FroudeError(f"steps must be a whole number >= 1, got {steps}")
    if within is not None and not (np.isfinite(within) and within > 0):
        raise FroudeError(f"--within must be > 0 s, got {within}")
    try:
        plan = plan_speed_change(
            m, target / v_unit, n_steps=None if within is not None else steps,
            within_time=None if within is None else within / m.time_unit, energy=energy, policy=policy,
            lead_steps=lead_steps, hold_steps=hold_steps,
        )
    except PlanError as e:
        raise PlanError(plan_refusal(e, start_speed, target, v_unit, steps, within)) from e
    fps = prep.motion.fps if fps is None else float(fps)
    path = machine_path(prep, retarget, n_steps=plan.n_steps, fps=fps, theta0=plan.theta0,
                        controls=plan.controls, start_state=(float(plan.U[0]), float(plan.H[0])))
    notes = list(prep.notes) + list(plan.notes)
    extras = {
        "plan": {
            "start_speed_m_s": start_speed, "target_speed_m_s": target,
            "apex_speed_m_s": (plan.U * v_unit).tolist(), "apex_U": plan.U.tolist(),
            "apex_time_s": (plan.t_apex * m.time_unit).tolist(),
            "theta0_deg": np.degrees(plan.theta0).tolist(), "b": plan.b.tolist(),
            "phase": ["lead" if p == 0 else "change" if p == 1 else "hold" for p in plan.phase],
            "mode": plan.mode, "policy": plan.policy,
        }
    }
    return finish(prep, path, retarget, 1.0, notes, "physical", plan=plan, report=report, extras=extras)


def plan_refusal(err, start_m_s: float, goal_m_s: float, v_unit: float, steps, within) -> str:
    """The planner's refusal (``PlanError`` with its U facts) said in the user's terms: m/s, ×, steps, s.

    start_m_s / goal_m_s: the apex speeds [m/s] the change goes between; v_unit: √(g l0) of the
    character [m/s], which turns the planner's dimensionless U into m/s. The planner's own words (in U)
    stay on the exception's ``__cause__`` for debugging.
    """
    head = f"cannot change speed from {start_m_s:.2f} to {goal_m_s:.2f} m/s (x{goal_m_s / start_m_s:.2f})"
    sus = getattr(err, "U_sustainable", None)
    if sus is not None and not sus[0] <= err.U_goal <= sus[1]:
        lo, hi = sus[0] * v_unit, sus[1] * v_unit
        return (f"{head}: the simple machine runs steadily only between {lo:.2f} and {hi:.2f} m/s "
                f"(x{lo / start_m_s:.2f}-{hi / start_m_s:.2f}); choose a goal in that range")
    in_steps = f"in {steps} step{'' if steps == 1 else 's'}"
    if getattr(err, "steps_needed", None):
        return f"{head} {in_steps}: too abrupt; give at least {err.steps_needed} steps"
    if within is not None:
        return f"{head} within {within:g} s: too abrupt; allow more time"
    one = getattr(err, "U_one_step", None)
    reach = "" if one is None else f" (one step from the start reaches {one * v_unit:.2f} m/s)"
    return f"{head} {in_steps}{reach}: try more steps or a goal nearer x1"


#: A steady (periodic) output longer than this many strides is corrected by solving the IK of one stride
#: sampled PERIODIC_OVERSAMPLE times finer and tiling it (see _periodic_correct).
PERIODIC_MIN_STRIDES = 6
PERIODIC_OVERSAMPLE = 4


def finish(prep: Prepared, path: MachinePath, retarget: Retarget, speed: float, notes, method: str, plan=None,
           periodic=None, report: bool = True, extras: dict | None = None) -> Result:
    """Targets → IK → report: the common tail of scale and accelerate.

    periodic: (machine, stretch, fps) when the path is the steady cycle repeated: long outputs then solve
    the IK of one stride only (the result is periodic too) and tile it.
    """
    targets = build_targets(prep, path, retarget)
    n_strides = len(path.foot_of_step) / 2
    if periodic is not None and n_strides > PERIODIC_MIN_STRIDES:
        motion = _periodic_correct(prep, retarget, targets, path, *periodic)
    else:
        ik = correct(targets, retarget.body)
        if not ik.ok:
            bad = np.flatnonzero(ik.failed)
            notes = list(notes) + [f"IK best effort: {bad.size} frame(s) above tolerance (first frame {bad[0]})"]
        motion = ik.motion
    res = Result(motion, None, path, targets, retarget, method, speed, tuple(notes), plan, dict(extras or {}))
    return add_report(prep, res) if report else res


def add_report(prep: Prepared, res: Result) -> Result:
    """The result with its physics report (DESIGN.md) computed: tracking against the machine, the loaded
    foot targets and the time-warped reference pose. (Separate so that a viewer can show the motion first.)
    """
    from dataclasses import replace as _replace

    report = physics_report(
        res.motion, res.retarget.body, ground_height=0.0, machine_com=res.path.com,
        marker_targets=_stance_only(res.targets), reference_pose=res.targets.initial,
        reference_max_joint_jump_deg=prep.cycle.max_joint_jump_deg,
    )
    report.extras.update({"character": res.retarget.character.name, "L": res.retarget.L, "M": res.retarget.M,
                          "speed_factor": res.speed_factor, "method": res.method, "notes": list(res.notes),
                          "machine_apex_speed_m_s": res.path.apex_speed.tolist(), "modelled": prep.modelled,
                          "input_in_place": bool(prep.motion.meta.get("in_place")),
                          **res.extras})
    return _replace(res, report=report)


def _periodic_correct(prep: Prepared, retarget: Retarget, targets: Targets, path: MachinePath, machine,
                      stretch: float, fps: float) -> Motion:
    """IK of a steady output by solving one stride and tiling it.

    The steady cycle is periodic: stride n of the output is stride 0 translated by n stride lengths (COM,
    contacts, foot targets and the time-warped reference pose all repeat). So the IK is solved once, for one
    stride sampled PERIODIC_OVERSAMPLE times finer than the output, and each output frame takes the pose at
    its time modulo the stride (root interpolated linearly, rotations by nlerp between samples a few
    milliseconds apart) plus its stride's translation; finally the COM is made exact by a root translation,
    as in ``correct``. The work is then that of one stride whatever the length, which is what makes long
    outputs (an hour of running) cheap in time and memory.
    """
    from .synthesis import nlerp_rows

    m = machine.scaled(retarget.L, retarget.M)
    k = PERIODIC_OVERSAMPLE
    one = machine_path(prep, retarget, speed=stretch, n_steps=2, fps=k * fps, machine=machine)
    ik = correct(build_targets(prep, one, retarget), retarget.body)
    T2 = 2.0 * m.step_time * m.time_unit  # stride period [s]
    stride = path.contacts[2] - path.contacts[0] if len(path.contacts) > 2 else np.zeros(3)
    stride[UP_AXIS] = 0.0
    t = path.times
    n = np.floor(t / T2 + 1e-9)
    x = (t - n * T2) * (k * fps)  # fractional dense sample
    i0 = np.clip(np.floor(x).astype(int), 0, ik.motion.n_frames - 2)
    w = (x - i0)[:, None]
    root = ik.motion.root_positions[i0] * (1 - w) + ik.motion.root_positions[i0 + 1] * w + n[:, None] * stride
    rot = nlerp_rows(ik.motion.rotations, i0, i0 + 1, w[:, 0])
    motion = targets.initial.with_(root_positions=root, rotations=rot)
    return motion.with_(root_positions=root + (targets.com - retarget.body.com(motion)))


def _stance_only(targets: Targets) -> np.ndarray:
    """Foot marker targets that must be met (loaded markers of feet on the ground), NaN elsewhere."""
    out = targets.markers.copy()
    w = targets.marker_weight
    out[w < 0.5 * w.max()] = np.nan
    return out


def _naive(prep: Prepared, retarget: Retarget, speed: float, n_steps: int, fps: float, notes) -> Result:
    """What engines do: joint angles copied, root translation × L, timing unchanged (× 1/s for speed)."""
    cyc = prep.cycle
    L = retarget.L
    T_stride = cyc.stride_time / speed
    duration = n_steps / 2 * T_stride
    t = np.arange(int(math.floor(duration * fps + 1e-9)) + 1) / fps
    psi = t / T_stride
    rot, data = sample_cycle(cyc, np.mod(psi, 1.0))
    fwd, up, lat = cyc.frame
    origin = prep.com[0].copy()
    origin[UP_AXIS] = 0.0
    # the reference COM path (uniform speed + oscillation) and root offset, all lengths × L
    com = (origin + np.outer(L * (cyc.speed * psi * cyc.stride_time + data["com_forward"]), fwd)
           + np.outer(L * data["com_height"], up) + np.outer(L * data["com_lateral"], lat))
    root = com + (L * data["root_from_com"]) @ cyc.frame
    meta = {"source": prep.source, "length_scale": float(prep.motion.meta.get("length_scale", 1.0))}
    motion = Motion(retarget.skeleton, root, rot, 1.0 / fps, None, meta)
    report = physics_report(motion, retarget.body, reference_max_joint_jump_deg=prep.cycle.max_joint_jump_deg)
    report.extras.update({"character": retarget.character.name, "L": L, "M": retarget.M, "speed_factor": speed,
                          "method": "naive", "notes": list(notes), "modelled": prep.modelled,
                          "input_in_place": bool(prep.motion.meta.get("in_place"))})
    return Result(motion, report, None, None, retarget, "naive", speed, tuple(notes))


def naive_clip(motion: Motion, character=None, *, speed: float = 1.0, target_speed: float | None = None,
               fps: float | None = None, performer_mass: float = 70.0, **character_numbers) -> Result:
    """The naive baseline for any clip that loads, running or not (no fit, no cycle): what engines do with
    a clip as it is: joint angles copied, the root's motion × L about the first frame's point on the floor,
    played s times faster (and as long as the clip). ``scale(..., method="naive")`` repeats a stride cycle
    instead when the clip is a run; this is its fallback for walks, jumps and clips the fit refuses.
    target_speed [m/s] is turned into a factor of the clip's own scaled mean speed; performer_mass [kg]:
    the reference performer's (the character's own mass is a character number, ``mass=``).
    """
    from .metrics import max_joint_jump_deg

    body = BodyModel.from_skeleton(motion.skeleton, mass=performer_mass)
    retarget = apply_character(resolve_character(character, **character_numbers), body)
    L = retarget.L
    summary = summarize(motion, body)
    if target_speed is not None:
        base = summary.mean_speed * math.sqrt(L)
        if not (base > 0 and np.isfinite(target_speed) and target_speed > 0):
            raise FroudeError(f"cannot run this clip at {target_speed:g} m/s: it does not travel (give a factor)")
        speed = target_speed / base
    if not (np.isfinite(speed) and speed > 0):
        raise FroudeError(f"speed factor must be > 0, got {speed}")
    fps = motion.fps if fps is None else float(fps)
    n = int(math.floor(motion.duration / speed * fps + 1e-9)) + 1
    played = motion.sample(np.arange(n) / fps * speed)
    origin = body.com(motion)[0].copy()
    origin[UP_AXIS] = detect_gait(motion, body).ground
    root = origin + L * (played.root_positions - origin)
    meta = {"source": str(motion.meta.get("source", "motion")),
            "length_scale": float(motion.meta.get("length_scale", 1.0))}
    out = Motion(retarget.skeleton, root, played.rotations, 1.0 / fps, None, meta)
    notes = [f"naive baseline of the clip as it is ({summary.kind}): the fit was not needed"]
    report = physics_report(out, retarget.body, reference_max_joint_jump_deg=max_joint_jump_deg(motion))
    report.extras.update({"character": retarget.character.name, "L": L, "M": retarget.M, "speed_factor": speed,
                          "method": "naive", "notes": notes, "modelled": f"the whole clip ({summary.kind})",
                          "input_in_place": False})
    return Result(out, report, None, None, retarget, "naive", speed, tuple(notes))


# ---- 5. write ----------------------------------------------------------------------------------------
def report_path(out_path) -> Path:
    p = Path(out_path)
    return p.with_name(p.stem + ".report.json")


def in_place_motion(result: Result) -> Motion:
    """The output with its root travel removed (a treadmill-like loop for engines that move the character
    themselves): the root is moved back by the COM's forward progression, taken straight between the
    machine's touchdowns (constant for a steady output, step by step for an acceleration), so the body
    keeps its bob and sway within each step and the stance foot slides back at the running speed."""
    motion = result.motion
    t = np.arange(motion.n_frames) * motion.frame_time
    fwd = result.path.frame[0] if result.path is not None else _travel_direction(motion, result)
    x = result.path.com @ fwd if result.path is not None else result.retarget.body.com(motion) @ fwd
    knots = t[[0, -1]] if result.path is None else np.concatenate(
        [[t[0]], result.path.t_touchdown[(result.path.t_touchdown > t[0]) & (result.path.t_touchdown < t[-1])], [t[-1]]])
    travel = np.interp(t, knots, np.interp(knots, t, x))
    from dataclasses import replace as _replace

    return _replace(motion, root_positions=motion.root_positions - np.outer(travel - travel[0], fwd))


def _travel_direction(motion: Motion, result: Result) -> np.ndarray:
    com = result.retarget.body.com(motion)
    d = com[-1] - com[0]
    d[UP_AXIS] = 0.0
    n = np.linalg.norm(d)
    return d / n if n > 0 else np.eye(3)[0]


def write_result(result: Result, out_path, data=None, in_place: bool | None = None,
                 **bvh_options) -> tuple[Path, ...]:
    """Write OUT (.bvh, .glb or .gltf: ``froude.api.save`` decides by suffix) and OUT.report.json, and
    the per-frame table to ``data`` (.csv/.parquet/.npz) when given: all or none. Returns the paths.
    bvh_options: ``save_bvh``'s (length_scale, up, rotations_only; default: the input's conventions).

    in_place: write the motion without root travel (``in_place_motion``); None: as the input was (an
    in-place take gives in-place outputs). The report is always that of the travelling motion (its speed,
    skate and gravity are physical there) and says which was written.
    """
    from .api import save
    from .io.atomic import atomic_group

    out_path = Path(out_path)
    rp = report_path(out_path)
    if in_place is None:
        in_place = bool(result.report.extras.get("input_in_place")) if result.report is not None else False
    if result.report is not None:
        result.report.extras["written"] = "in place (root travel removed)" if in_place else "with root travel"
    with atomic_group():  # every file of the result or none
        save(in_place_motion(result) if in_place else result.motion, out_path, **bvh_options)
        write_report(result.report, rp)
        if data is None:
            return out_path, rp
        from .io.framedata import frame_table, write_frame_data

        table = frame_table(result.motion, result.retarget.body, machine_path=result.path)
        return out_path, rp, write_frame_data(table, data)


