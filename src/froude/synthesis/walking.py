"""The walking machine's path in the world and the walking time warp (issue 17).

The walking counterpart of ``pipeline.machine_path``: the (scaled) walking machine's periodic walk
(``WalkingMachine.path``) placed in the reference's heading frame, with the reference stride phase ψ of
every output time. The time warp is piecewise linear with knots at the walking events in their order
(A lands, B lifts, B lands, A lifts: ``synthesis.EVENT_ORDERS["walking"]``), so the reference's double
supports are played over the machine's double supports and its single supports over the machine's;
both feet are on the ground, and held by the IK, in every double support.

The foot anchors are the reference's contact points (``Stance.contact_point``, the foot's mean loaded
position): each contact is placed as far ahead of (or behind) the machine's COM at mid-stance as the
reference's is of its COM (× L), so the time-warped reference pose reaches its feet.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..core.constants import UP_AXIS
from ..errors import FroudeError
from ..machine.walk_fit import fit_walking_detailed
from ..machine.walk_speed import check_walking_speed, walking_machines_at_speeds
from .cycle import extract_cycle, sample_cycle
from .feet import min_jerk
from .phases import FootEvent
from .timewarp import MachinePath

__all__ = ["StepPlan", "contact_from_com", "fit_walk", "plan_walk_speed_change", "soften_swing_weights", "steps_path",
           "walk_machine_path", "walking_events"]


def walking_events(gait, frame_time: float, n_frames: int) -> list[FootEvent]:
    """Touchdowns and liftoffs of a walk at the gait's sub-frame times (the walking fit's events), in time
    order; edges of stances cut by the clip omitted. frame_time [s] is unused but kept for symmetry."""
    ev = []
    for s in gait.stances:
        if s.start > 0:
            ev.append(FootEvent(float(s.t_on) if math.isfinite(s.t_on) else float(s.start), s.foot, "td"))
        if s.stop < n_frames:
            ev.append(FootEvent(float(s.t_off) if math.isfinite(s.t_off) else float(s.stop), s.foot, "lo"))
    return sorted(ev, key=lambda e: e.frame)


def contact_from_com(gait, com: np.ndarray, heading: np.ndarray, frame_time: float) -> np.ndarray:
    """(2,) mean forward distance [m] of each foot's contact point (``Stance.contact_point``) ahead of the
    COM at mid-stance, over the clip's complete stances (left, right; a foot never seen takes the other's).
    com: (F, 3) [m]; heading: (3,) forward unit vector."""
    F = com.shape[0]
    x = com @ heading
    d: list[list[float]] = [[], []]
    for st in gait.full_stances:
        a = st.t_on if math.isfinite(st.t_on) else float(st.start)
        b = st.t_off if math.isfinite(st.t_off) else float(st.stop - 1)
        d[st.foot].append(float(st.contact_point @ heading) - float(np.interp(0.5 * (a + b), np.arange(F), x)))
    out = np.array([np.mean(v) if v else np.nan for v in d])
    return np.where(np.isnan(out), out[::-1], out)


def fit_walk(motion, body, com, markers, gait, source: str, mass: float):
    """The walking machine's fit and the walking stride cycle of a walk (``pipeline.prepare`` for walks).

    Returns (WalkFitResult, ReferenceCycle)."""
    from pathlib import Path

    fit = fit_walking_detailed(motion, body, mass=mass, source=Path(source).name)
    events = walking_events(gait, motion.frame_time, motion.n_frames)
    cycle = extract_cycle(motion, body, gait, com, markers, events=events, order="walking")
    return fit, cycle


def _knots(t_td: np.ndarray, t_double: np.ndarray, pe: np.ndarray):
    """Time warp knots (times [s], phases ψ) at every touchdown and the other foot's liftoff, two steps
    before and after the output as well (at the first and last steps' durations). Step i (foot A for even
    i) lands at t_td[i] and the other foot lifts t_double[i] later; pe: the cycle's phase_events."""
    n = len(t_td)
    first = t_td[1] - t_td[0] if n > 1 else 1.0
    last = t_td[-1] - t_td[-2] if n > 1 else first
    times, psis = [], []
    for i in range(-2, n + 2):
        j = min(max(i, 0), n - 1)
        td_t = t_td[0] + i * first if i < 0 else (t_td[-1] + (i - n + 1) * last if i >= n else t_td[i])
        k = i // 2
        if i % 2 == 0:   # A lands, then B lifts
            td, lo = k + 0.0, k + pe[3]
        else:            # B lands, then A lifts
            td, lo = k + pe[2], k + pe[1]
        times += [td_t, td_t + t_double[j]]
        psis += [td, lo]
    return np.array(times), np.array(psis)


@dataclass(frozen=True)
class StepPlan:
    """A walk step by step: step i is walked by machines[i] (scaled, SI view) stretched horizontally by
    stretch[i] (§5.2; 1 for a re-solved cycle). continuous: the stretch varies linearly in time between the
    steps' middles instead of holding over each step, so the COM's forward velocity does not jump at a
    touchdown where it changes (a walker's speed along a turn, ``TakePath.speed_factors``)."""

    machines: tuple
    stretch: np.ndarray
    continuous: bool = False


def _stitch(plan: StepPlan, fps: float):
    """Machine steps one after another (each from its own touchdown; COM forward positions continued).

    Returns t (N,) [s], p (N, 2) COM forward/up [m] (x from 0), force (N, 2) [N], lead/trail (N,) bool
    (the step's leading and trailing machine legs on the ground), step index (N,), t_td (n,), t_double
    (n,), t_stance (n,) [s], x_td (n,) COM forward position at each touchdown [m], and x_at(times) the
    COM forward position at any times ≥ 0 [m] (past the end: the last machine's periodic walk).
    """
    ms, sig = plan.machines, plan.stretch
    n = len(ms)
    dur = np.array([m.t_step * m.time_unit for m in ms])
    t_td = np.concatenate([[0.0], np.cumsum(dur)[:-1]])
    x_td = np.concatenate([[0.0], np.cumsum([s * m.step_length * m.l0 for m, s in zip(ms, sig)])[:-1]])
    N = int(math.floor(dur.sum() * fps + 1e-9)) + 1
    t = np.arange(N) / fps
    k = np.clip(np.searchsorted(t_td, t, side="right") - 1, 0, n - 1)
    p = np.empty((N, 2))
    force = np.empty((N, 2))
    lead = np.empty(N, bool)
    trail = np.empty(N, bool)
    # touchdown COM heights differ between machines of different speeds (their θ0 and l_td): each step
    # starts where the last ended and eases into its own cycle (min-jerk over the step)
    y_td = np.array([m.l_td * math.cos(m.theta0) * m.l0 for m in ms])
    dy = np.concatenate([[0.0], y_td[:-1] - y_td[1:]])
    if plan.continuous:
        t_dense, x_dense, sigma, dsigma = _continuous_stretch(ms, sig, t_td, dur)
        x_td = np.interp(t_td, t_dense, x_dense)
    for i in np.unique(k):
        sel = k == i
        local = t[sel] - t_td[i]
        mp = ms[i].path(local)  # the machine's step 0: its foot 0 leads, foot 1 trails
        if plan.continuous:  # x' = σ(t) v_machine: the force along is σ f + m σ' v
            p[sel, 0] = np.interp(t[sel], t_dense, x_dense)
            force[sel, 0] = sigma(t[sel]) * mp["force"][:, 0] + ms[i].mass * dsigma(t[sel]) * mp["v_com"][:, 0]
            force[sel, 1] = mp["force"][:, 1]
        else:
            p[sel, 0] = x_td[i] + sig[i] * mp["p_com"][:, 0]
            force[sel] = mp["force"] * np.array([sig[i], 1.0])
        p[sel, 1] = mp["p_com"][:, 1] + dy[i] * (1.0 - min_jerk(local / dur[i]))
        lead[sel], trail[sel] = mp["contact"][:, 0], mp["contact"][:, 1]

    def x_at(times):
        times = np.asarray(times, float)
        j = np.clip(np.searchsorted(t_td, times, side="right") - 1, 0, n - 1)
        out = np.empty(times.shape)
        for i in np.unique(j):
            sel = j == i
            if plan.continuous and i < n - 1:
                out[sel] = np.interp(times[sel], t_dense, x_dense)
            else:  # past the last touchdown: that machine's periodic walk
                out[sel] = x_td[i] + sig[i] * ms[i].path(times[sel] - t_td[i])["p_com"][:, 0]
        return out

    t_double = np.array([m.t_double * m.time_unit for m in ms])
    t_stance = np.array([m.t_stance * m.time_unit for m in ms])
    return t, p, force, lead, trail, k, t_td, t_double, t_stance, x_td, x_at


#: Samples of each step on which ``_continuous_stretch`` integrates the COM's forward velocity.
STRETCH_SAMPLES = 129


def _continuous_stretch(ms, sig: np.ndarray, t_td: np.ndarray, dur: np.ndarray):
    """The COM's forward path under a stretch σ(t) linear between the steps' middles (σ = sig[i] there, held
    before the first and after the last): x(t) = ∫ σ v_machine dt, each step's machine from its touchdown.

    ms: the steps' machines (scaled); sig, t_td, dur (n,): their stretch, touchdown times and durations [s].
    Returns (t (K,) [s], x (K,) [m], σ(times), σ'(times) [1/s]): x sampled STRETCH_SAMPLES times a step
    (trapezoid rule), x(0) = 0.
    """
    t_mid = t_td + 0.5 * dur

    def sigma(times):
        return np.interp(times, t_mid, sig)

    def dsigma(times):
        if len(sig) < 2:
            return np.zeros(np.shape(times))
        slope = np.diff(sig) / np.diff(t_mid)
        i = np.clip(np.searchsorted(t_mid, times, side="right") - 1, 0, len(slope) - 1)
        inside = (np.asarray(times) >= t_mid[0]) & (np.asarray(times) < t_mid[-1])
        return np.where(inside, slope[i], 0.0)

    ts, xs, x0 = [], [], 0.0
    for m, t0, d in zip(ms, t_td, dur):
        g = np.linspace(0.0, d, STRETCH_SAMPLES)
        f = sigma(t0 + g) * m.path(g)["v_com"][:, 0]
        x = x0 + np.concatenate([[0.0], np.cumsum(0.5 * (f[1:] + f[:-1]) * np.diff(g))])
        ts.append(t0 + g)
        xs.append(x)
        x0 = float(x[-1])
    return np.concatenate(ts), np.concatenate(xs), sigma, dsigma


def walk_machine_path(prep, retarget, *, n_steps: int, fps: float, machine=None, speed: float = 1.0):
    """The scaled walking machine for n_steps steps in the world (a ``pipeline.MachinePath``).

    prep: a prepared walk (``pipeline.prepare``); retarget: the character (L, M); fps: output frame rate
    [Hz]; machine: the (unscaled) WalkingMachine to walk (default: the fitted one); speed: §5.2's horizontal
    stretch factor (slower walks: the COM and the contacts × speed along the heading, timing kept; faster
    walks re-solve the cycle instead, ``machine.walk_speed``).
    """
    m = (prep.machine if machine is None else machine).scaled(retarget.L, retarget.M)
    return steps_path(prep, retarget, StepPlan((m,) * n_steps, np.full(n_steps, float(speed))), fps)


def walk_scale_path(prep, retarget, speed: float, *, n_steps: int, fps: float):
    """The machine path and method name of a walk's ``scale``: faster by the re-solved walking cycle, slower
    by §5.2's stretch (below the clip's speed the re-solved cycle does not exist: ``machine.walk_speed``);
    past Froude 0.5 refused (``check_walking_speed``). A turning take's steps are each stretched besides by
    the clip's speed along its path at their place (``TakePath.speed_factors``; docs/path.md)."""
    walk = prep.machine  # a WalkingMachine (prepare chose it for the walk)
    check_walking_speed(walk.scaled(retarget.L, retarget.M), speed)
    if speed > 1.0 + 1e-9:  # longer and quicker steps
        machine, stretch = prep.machine_at_speed(speed), 1.0
        method = "physical (walking cycle re-solved at the new speed)"
    else:
        machine, stretch, method = walk, speed, "physical"
    if prep.turn is None:
        return walk_machine_path(prep, retarget, n_steps=n_steps, fps=fps, machine=machine, speed=stretch), method
    # along a turn the walker's speed varies: each step stretched by the clip's speed at its place
    m = machine.scaled(retarget.L, retarget.M)
    factors = prep.path.speed_factors(stretch * m.step_length * m.l0 / retarget.L, n_steps,
                                      prep.machine.t_step * prep.machine.time_unit)
    check_walking_speed(walk.scaled(retarget.L, retarget.M), speed, "walk along this turn", float(factors.max()))
    method += f"; the clip's speed along its turn ({factors.min():.2f}-{factors.max():.2f} x)"
    return steps_path(prep, retarget, StepPlan((m,) * n_steps, stretch * factors, continuous=True), fps), method


def steps_path(prep, retarget, plan: StepPlan, fps: float):
    """A walk of ``plan``'s steps in the world (a ``pipeline.MachinePath``), time-warped and placed like
    ``walk_machine_path`` (which is this with one machine for every step)."""
    cyc = prep.cycle
    n_steps = len(plan.machines)
    t, p, f_sag, lead, trail, k, t_td, t_double, t_stance, x_td, x_at = _stitch(plan, fps)
    n_frames = t.size
    A = cyc.first_foot
    feet = np.where(np.arange(n_steps) % 2 == 0, A, 1 - A)
    # a foot lifts at the end of the next step's double support (the last step's: its own stance)
    t_lo = np.concatenate([t_td[1:] + t_double[1:], [t_td[-1] + t_stance[-1]]])
    kt, kp = _knots(t_td, t_double, cyc.phase_events)
    psi = np.interp(t, kt, kp)
    pe = cyc.phase_events
    # each step's foot: its touchdown and liftoff phases, then its marker contact (a little wider)
    psi_td = np.interp(t_td, kt, kp)
    td_ph = np.where(feet == A, 0.0, pe[2])
    lo_ph = np.where(feet == A, pe[1], pe[3])
    stance_ph = np.mod(lo_ph - td_ph, 1.0)
    ext_before = np.array([(0.0 if f == A else pe[2]) - cyc.contact_phase[f, 0] for f in feet])
    ext_after = np.array([cyc.contact_phase[f, 1] - cyc.contact_phase[f, 0] for f in feet]) - ext_before - stance_ph
    contact_on = np.interp(psi_td - ext_before, kp, kt)
    contact_off = np.interp(psi_td + stance_ph + ext_after, kp, kt)

    fwd, up, lat = cyc.frame
    L = retarget.L
    _, data = sample_cycle(cyc, np.mod(psi, 1.0), rotations=False)
    origin = np.array(prep.origin, dtype=float)
    origin[UP_AXIS] = 0.0
    com = origin + np.outer(p[:, 0], fwd) + np.outer(p[:, 1], up) + np.outer(L * data["com_lateral"], lat)
    # Each foot stands where the reference's stands relative to the COM at mid-stance (× L): the pose and
    # the foot then agree. The machine's own touchdown point (l_td sin θ0 ahead of the COM, the centre of
    # pressure's heel end) differs from it by the fit's geometry error; the IK follows the reference's.
    x_mid = x_at(0.5 * (t_td + t_lo))
    ahead = contact_from_com(prep.gait, prep.com, fwd, prep.motion.frame_time)
    contacts = origin + np.outer(x_mid + L * ahead[feet], fwd) + np.outer(L * cyc.contact_lateral[feet], lat)
    force = np.outer(f_sag[:, 0], fwd) + np.outer(f_sag[:, 1], up)
    # the machine's legs (leading, trailing in each step) are the reference's feet
    stance = np.zeros((n_frames, 2), bool)
    rows = np.arange(n_frames)
    stance[rows, feet[k]] = lead
    stance[rows, 1 - feet[k]] |= trail
    contact = np.zeros((n_frames, 2), bool)
    for i, f in enumerate(feet):
        contact[(t >= contact_on[i]) & (t < contact_off[i]), f] = True
    U = np.array([s * m.mean_speed for m, s in zip(plan.machines, plan.stretch)])
    v = np.array([s * m.mean_speed * m.speed_unit for m, s in zip(plan.machines, plan.stretch)])
    m0 = plan.machines[0]
    return MachinePath(
        times=t, com=com, force=force, psi=psi, stance=stance, contact=contact, foot_of_step=feet,
        t_touchdown=t_td, t_liftoff=t_lo, contact_on=contact_on, contact_off=contact_off, contacts=contacts,
        apex_speed=np.concatenate([v, v[-1:]]), U=np.concatenate([U, U[-1:]]), frame=cyc.frame, l0=m0.l0,
        mass=m0.mass,
    )


#: Swing marker weight reached at touchdown and left at liftoff by ``soften_swing_weights`` [1/m²], and the
#: share of the step time over which it ramps (geometrically, from the swing weight).
SWING_GUIDE_WEIGHT = 0.5
SWING_GUIDE_SHARE = 0.35


def soften_swing_weights(path, weight: np.ndarray, swing_weight: float) -> np.ndarray:
    """(T, 2, 3) foot marker weights with the swinging foot guided more firmly near its contacts.

    A walking foot lands and leaves with an almost straight knee; the swing weight lets the foot drift
    centimetres from its target (the posture pull wins), and the stance ramp then pulls it back within a
    frame or two, a knee jump of 10-15 degrees. Here the weight rises geometrically (min-jerk in log
    weight) from swing_weight to SWING_GUIDE_WEIGHT over SWING_GUIDE_SHARE of a step before each contact
    and falls the same way after it, so the foot is brought to its target over a tenth of a second.
    weight: (T, 2, 3) [1/m²] before the per-size factor; path: the walking MachinePath.
    """

    t = path.times
    step = float(np.median(np.diff(path.t_touchdown))) if len(path.t_touchdown) > 1 else 0.5
    Tw = SWING_GUIDE_SHARE * step
    ratio = math.log(SWING_GUIDE_WEIGHT / swing_weight)
    out = weight.copy()
    on, off, feet = path.contact_on, path.contact_off, path.foot_of_step
    # virtual contacts a stride before the first and after the last of each foot: the swing at an end of
    # the output is guided toward the contact it would make
    for f in (0, 1):
        k = np.flatnonzero(feet == f)
        if k.size:
            on = np.concatenate([on, [on[k[0]] - 2 * step, on[k[-1]] + 2 * step]])
            off = np.concatenate([off, [off[k[0]] - 2 * step, off[k[-1]] + 2 * step]])
            feet = np.concatenate([feet, [f, f]])
    for a, b, f in zip(on, off, feet):
        u = np.where((t >= a) & (t <= b), 1.0, np.minimum(np.clip((t - (a - Tw)) / Tw, 0, 1),
                                                            np.clip(((b + Tw) - t) / Tw, 0, 1)))
        g = swing_weight * np.exp(ratio * min_jerk(u))
        out[:, f] = np.maximum(out[:, f], g[:, None])
    return out


def plan_walk_speed_change(prep, retarget, *, to_speed=None, to_factor=None, steps=8, within=None, lead_steps=2,
                           hold_steps=4, fps=None):
    """The walking path of ``pipeline.accelerate``: the speed changes step by step along a min-jerk profile.

    Each step is walked by the periodic walking cycle of its speed (re-solved above the clip's speed by
    continuation, ``machine.walk_speed``; §5.2's horizontal stretch below it), the steps joined touchdown
    to touchdown (COM forward position continued, its touchdown height eased over the next step), so the
    speed profile is monotonic by construction. lead_steps at the start speed, then ``steps`` (or as many
    as fit in ``within`` seconds) changing, then hold_steps at the goal. Returns (MachinePath, plan dict for
    the report's extras).
    """
    m = prep.machine.scaled(retarget.L, retarget.M)
    start = m.mean_speed_m_s
    if (to_speed is None) == (to_factor is None):
        raise FroudeError("give exactly one goal: a target speed [m/s] or a factor of the start speed")
    target = to_speed if to_speed is not None else to_factor * start
    if not (np.isfinite(target) and target > 0):
        raise FroudeError(f"target speed must be > 0 m/s, got {target:g} (to stop, end the motion instead)")
    s_goal = target / start
    check_walking_speed(m, s_goal, "walk accelerating")
    if within is not None:
        if not (np.isfinite(within) and within > 0):
            raise FroudeError(f"--within must be > 0 s, got {within}")
        steps = max(1, int(round(within / (m.t_step * m.time_unit))))
    if not (isinstance(steps, (int, np.integer)) and steps >= 1):
        raise FroudeError(f"steps must be a whole number >= 1, got {steps}")
    change = 1.0 + (s_goal - 1.0) * min_jerk(np.arange(1, steps + 1) / steps)
    factors = np.concatenate([np.ones(lead_steps), change, np.full(hold_steps, s_goal)])
    solved = walking_machines_at_speeds(prep.machine, factors[factors > 1.0 + 1e-9], prep.memo.faster_machines)
    machines = tuple((solved[float(f)] if f > 1.0 + 1e-9 else prep.machine).scaled(retarget.L, retarget.M)
                     for f in factors)
    stretch = np.where(factors > 1.0 + 1e-9, 1.0, factors)
    fps = prep.motion.fps if fps is None else float(fps)
    path = steps_path(prep, retarget, StepPlan(machines, stretch), fps)
    speeds = [float(s * mm.mean_speed * mm.speed_unit) for mm, s in zip(machines, stretch)]
    plan = {
        "start_speed_m_s": start, "target_speed_m_s": target, "apex_speed_m_s": speeds,
        "apex_U": [float(s * mm.mean_speed) for mm, s in zip(machines, stretch)],
        "apex_time_s": path.t_touchdown.tolist(), "theta0_deg": [math.degrees(mm.theta0) for mm in machines],
        "step_time_s": [float(mm.t_step * mm.time_unit) for mm in machines],
        "phase": ["lead"] * lead_steps + ["change"] * steps + ["hold"] * hold_steps,
        "mode": "walking (a periodic cycle per step)", "policy": "ease"}
    return path, plan
