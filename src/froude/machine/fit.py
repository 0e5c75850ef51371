"""§4 end to end: fit the simple running machine to a reference motion (``froude fit``).

    motion → body COM + foot markers → gait (marker contacts) → zero-lag filtered COM → eq. 1 forces
    → force-refined touchdown / liftoff → per-stance leg geometry and eq. 2 control fits
    → stance-averaged control + measured priors → periodic cycle search → SimpleMachine

Control fit (eq. 2, per stance, dimensionless: l/l0, f/(m g)). The plain four-parameter least squares
in (k, k a, k b, k c) is ill-conditioned on capture data: the leg compression l0 − l(τ) over a
stance is itself close to a quadratic in τ, so k trades against b and c (it returns K ≈ 40-55 with
l_d dipping by 10 % of l0 on these clips). We therefore fit **spring first**: K (and an offset) by
least squares of f_leg against the compression alone — McMahon & Cheng's leg spring — then a, b, c by
least squares of the remaining force with K held (still linear). The four-parameter fit is kept in the
per-stance report as ``fit_free`` for comparison.

Cycle search: the variables z = (U, H, θ0, K, a, b, c) (T_c held at the measured mean stance time)
must make the step map periodic (U' = U, H' = H) *and* reproduce the measured stance time, flight
time and mean speed (step length / step time): five equations in seven unknowns. Newton iterations
take the minimum-norm step in coordinates scaled by ``CYCLE_SCALES`` from the measured priors z0
(so the solution is the periodic machine nearest the data), with a forward-difference Jacobian whose
seven perturbed rows are evaluated in the **same** vectorised step() call as the iterate itself:
one simulator call per iteration, an extra one only on a rejected step.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from ..body.gait import detect_gait, require_running, summarize
from ..body.model import BodyModel
from ..core.constants import GRAVITY, UP_AXIS
from ..core.motion import Motion
from ..errors import FitError, NotARunningMotion
from .control_fit import fit_leg_control
from .dynamics import N_PER_STANCE, Control, simulate, step
from .forces import (
    CUTOFF_HZ,
    EVENT_THRESHOLD_BW,
    clip_com,
    flight_residual,
    force_shares,
    refine_events,
    stance_geometry,
)
from .model import SimpleMachine
from .orbit import solve_orbit
from .units import speed_unit, time_unit

__all__ = ["StanceFit", "FitResult", "fit_stance_control", "fit_machine", "fit_machine_detailed",
           "unsprung_note", "unsprung_stances", "CYCLE_SCALES", "SWAY_SAMPLES"]

#: Scales of the cycle variables for the minimum-norm search (K relative to its prior).
CYCLE_SCALES = {"U": 0.05, "H": 0.02, "theta0": 0.03, "K": 0.1, "a": 0.01, "b": 0.02, "c": 0.02}
_VARS = ("U", "H", "theta0", "K", "a", "b", "c")
#: Frames left out at each end of a flight when measuring the flight force residual (filter edge).
RESIDUAL_GUARD_FRAMES = 2
#: Clips below ANALYSIS_MIN_FPS are analysed at ANALYSIS_FPS (see fit_machine_detailed) [Hz].
ANALYSIS_MIN_FPS = 100.0
ANALYSIS_FPS = 120.0
#: How far the force-based stance may reach beyond the foot's marker contact [s] (see fit_machine_detailed).
CONTACT_SLACK_S = 0.02
#: Only a clip whose contacts last less than this [s] (median of the complete ones) is held to them: the smear of
#: the COM filter (CUTOFF_HZ) matters
#: against a 0.13-0.17 s dash stance, not against the 0.23-0.27 s stances of the CMU runs.
SHORT_STANCE_S = 0.2
#: Fewest samples of a stance the control fit takes: K and an offset, then a, b, c (two small least
#: squares), so 4 samples determine it; a 30 Hz clip has 4-5 frames in a 0.15 s stance.
MIN_STANCE_SAMPLES = 4
#: Samples of the lateral sway profile over one stride.
SWAY_SAMPLES = 32


@dataclass(frozen=True)
class StanceFit:
    """Eq. 2 fitted to one stance (dimensionless: l0 = 1, forces in m g).

    K, a, b, c: spring-first fit; r2: coefficient of determination of f_leg; rms: RMS residual [m g];
    K_free, a_free, b_free, c_free, r2_free: the plain four-parameter least squares, for comparison.
    """

    K: float
    a: float
    b: float
    c: float
    r2: float
    rms: float
    K_free: float
    a_free: float
    b_free: float
    c_free: float
    r2_free: float

    def desired_length(self, tau):
        """l_d(τ)/l0 = 1 + a + b τ + c τ²."""
        tau = np.asarray(tau, float)
        return 1.0 + self.a + tau * (self.b + self.c * tau)

    def force(self, tau, l):
        """Model leg force K (l_d(τ) − l) [m g] for l in units of l0."""
        return self.K * (self.desired_length(tau) - np.asarray(l, float))


def fit_stance_control(tau, l, f_leg) -> StanceFit:
    """Spring-first least-squares fit of eq. 2 (see module doc), dimensionless.

    tau: (N,) stance phase [-]; l: (N,) leg length / l0 [-]; f_leg: (N,) leg force / (m g) [-].
    Several stances may be pooled (concatenate; each with its own l0 normalisation).
    """
    tau = np.asarray(tau, float)
    l = np.asarray(l, float)
    f = np.asarray(f_leg, float)
    if tau.size < MIN_STANCE_SAMPLES:
        raise FitError(f"need at least {MIN_STANCE_SAMPLES} stance samples to fit the control, got {tau.size}")
    comp = 1.0 - l
    A = np.stack([comp, np.ones_like(comp)], axis=1)
    (K, _), *_ = np.linalg.lstsq(A, f, rcond=None)
    if not K > 0:
        raise FitError(f"the leg does not act as a spring in this stance (fitted K = {K:.3g})")
    B = np.stack([np.ones_like(tau), tau, tau * tau], axis=1)
    coef, *_ = np.linalg.lstsq(B, f - K * comp, rcond=None)
    a, b, c = coef / K
    resid = f - K * comp - B @ coef
    ss_tot = float(np.sum((f - f.mean()) ** 2))
    r2 = 1.0 - float(np.sum(resid ** 2)) / ss_tot if ss_tot > 0 else float("nan")
    try:
        free = fit_leg_control(tau, l, f, 1.0)
        K_free, a_f, b_f, c_f, r2_f = free.k, free.a, free.b, free.c, free.r2
    except FitError:
        K_free = a_f = b_f = c_f = r2_f = float("nan")
    return StanceFit(float(K), float(a), float(b), float(c), float(r2), float(np.sqrt(np.mean(resid ** 2))),
                     float(K_free), float(a_f), float(b_f), float(c_f), float(r2_f))


@dataclass(frozen=True)
class FitResult:
    """Everything ``fit_machine`` computed, for reports and plots (SI unless stated).

    machine: the SimpleMachine. times (F,) [s]; p_world_com (F, 3) smoothed COM [m]; f_world (F, 3)
    eq. 1 force [N]; stances: tuple of StanceGeometry; stance_fits: tuple (StanceFit | None per stance);
    pooled: StanceFit of all full stances; stride_events (5,) reference event times [s];
    stride_kinds: 'TD'/'LO' per event; machine_event_times (5,) the matching machine times [s];
    t_ref (N,) reference frame times in the stride [s], h_ref (N,) reference COM height above the
    ground [m], h_machine (N,) machine COM height at the phase-matched times [m];
    traj: the machine's dense one-step Trajectory (dimensionless).
    """

    machine: SimpleMachine
    times: np.ndarray
    p_world_com: np.ndarray
    f_world: np.ndarray
    stances: tuple
    stance_fits: tuple
    pooled: StanceFit
    stride_events: np.ndarray
    stride_kinds: tuple
    machine_event_times: np.ndarray
    t_ref: np.ndarray
    h_ref: np.ndarray
    h_machine: np.ndarray
    traj: object


def _spring_fit(sg, mg: float) -> StanceFit | None:
    """Eq. 2 fitted to one full stance (``fit_stance_control``), or None when the leg does not act as a spring
    in it (K ≤ 0: the force does not rise as the leg shortens, as in a hard braking plant at a turn's entry:
    CMU 16_51's right foot at 0.33 s, K = −2.1 straightened, 0.3 in 3-D as taken). Such a stance is
    reported (``unsprung_stances``) and left out of the pooled fit that the machine's leg is searched from:
    one stance of a take does not refuse the take. mg [N]."""
    try:
        return fit_stance_control(sg.tau, sg.l / sg.l0, sg.f_leg / mg)
    except FitError:
        return None


def unsprung_stances(machine: SimpleMachine) -> list[dict]:
    """The full stances of a fitted running machine in which the leg did not act as a spring (left out of the
    pooled fit): their records in ``machine.stances`` (foot, touchdown time [s], duration [s])."""
    return [d for d in machine.stances if not d["partial"] and d["fit"] is None]


def unsprung_note(machine: SimpleMachine) -> str | None:
    """One line on the stances left out of the leg's fit (``unsprung_stances``), None without any."""
    left_out = unsprung_stances(machine)
    if not left_out:
        return None
    which = ", ".join(f"the {d['foot']} foot's at {d['t_touchdown_s']:.2f} s" for d in left_out)
    n_full = sum(not d["partial"] for d in machine.stances)
    return (f"{len(left_out)} of {n_full} stances ({which}) do not act as a spring (the leg's force does not rise "
            "as it shortens, as in a braking plant): the machine's leg is fitted to the others")


def fit_machine(motion: Motion, body: BodyModel | None = None, mass: float = 70.0, **kw) -> SimpleMachine:
    """Fit the simple running machine to a running motion (§4). See :func:`fit_machine_detailed`."""
    return fit_machine_detailed(motion, body, mass, **kw).machine


def _events(stances_geo, gait_stances, n_frames):
    """Valid in-clip events as (time [s], kind 'TD'/'LO', stance index), sorted."""
    ev = []
    for i, (sg, st) in enumerate(zip(stances_geo, gait_stances)):
        if st.start > 0:
            ev.append((sg.t_touchdown, "TD", i))
        if st.stop < n_frames:
            ev.append((sg.t_liftoff, "LO", i))
    ev.sort()
    return ev


def _stride_window(ev):
    """Five consecutive alternating events spanning one stride; prefer one starting at a touchdown."""
    best = None
    for j in range(len(ev) - 4):
        w = ev[j:j + 5]
        kinds = [k for _, k, _ in w]
        if kinds not in (["TD", "LO", "TD", "LO", "TD"], ["LO", "TD", "LO", "TD", "LO"]):
            continue
        # each TD→LO pair must be the same stance, consecutive stances otherwise
        idx = [i for _, _, i in w]
        ok = all((idx[q + 1] == idx[q]) if kinds[q] == "TD" else (idx[q + 1] == idx[q] + 1) for q in range(4))
        if ok and (best is None or (kinds[0] == "TD" and best[0][1] != "TD")):
            best = w
    return best


def _cycle_search(z0, T_c, targets, n_per_stance, tol=1e-10, max_iter=30, n_coarse=16):
    """The periodic cycle matching targets nearest the priors (``machine.orbit.solve_orbit``).

    z0: (7,) priors (U, H, θ0, K, a, b, c); T_c: held nominal stance time; targets: (t_stance, t_flight,
    mean_speed), all dimensionless: residual rows (U' − U, H' − H) and the three targets as relative
    errors. Coarse stance grid (``n_coarse`` RK4 steps) down to 1e-7, then full resolution
    (``n_per_stance``). Returns (z, StepResult row dict, simulator calls, residual vector).
    """
    s = np.array([CYCLE_SCALES[v] for v in _VARS])
    s[3] *= abs(z0[3])
    h = 1e-7 * np.maximum(np.abs(z0), 1.0)
    tgt = np.asarray(targets, float)
    wt = 1.0 / np.maximum(np.abs(tgt), 1e-3)  # target rows are relative errors

    def evaluate(Z, n):
        ctl = Control(K=Z[:, 3], a=Z[:, 4], b=Z[:, 5], c=Z[:, 6], T_c=T_c)
        r = step(Z[:, 0], Z[:, 1], Z[:, 2], ctl, n_per_stance=n)
        t_step = r.t_fall + r.t_stance + r.t_rise
        R = np.stack([r.U_next - Z[:, 0], r.H_next - Z[:, 1],
                      (r.t_stance - tgt[0]) * wt[0], (r.t_rise + r.t_fall - tgt[1]) * wt[1],
                      (r.apex_dx / t_step - tgt[2]) * wt[2]], axis=1)
        return R, r

    z, r, calls, R0 = solve_orbit(evaluate, z0, s, h, tol=tol, max_iter=max_iter,
                                  resolutions=(n_coarse, n_per_stance))
    row = {f: np.asarray(getattr(r, f))[0] for f in ("t_fall", "t_stance", "t_rise", "apex_dx", "peak_force",
                                                    "U_next", "H_next")}
    return z, row, calls, R0


def _upsampled(motion: Motion, body: BodyModel, fps: float) -> tuple[Motion, np.ndarray, np.ndarray]:
    """A low-rate clip at ``fps`` [Hz] for the force analysis: (motion, COM (F', 3) [m], foot markers
    (F', 2, 3, 3) [m]).

    The COM and the markers are computed at the clip's own frames and interpolated by cubic splines: the
    COM of a running body is smooth at the clip's rate, and a spline keeps its curvature (the ground force)
    between frames, where the path of a motion resampled joint by joint (slerp) is piecewise linear and
    its filtered acceleration smears each force pulse by a frame (a 30 Hz fit then read K 5 % low and θ0
    0.5° off the 120 Hz clip's).
    """
    from scipy.interpolate import CubicSpline

    com, markers = body.com_and_markers(motion)
    out = motion.resample(fps)
    t_src = np.arange(motion.n_frames) * motion.frame_time
    t = np.arange(out.n_frames) * out.frame_time
    return out, CubicSpline(t_src, com, axis=0)(t), CubicSpline(t_src, markers, axis=0)(t)


def _analysis_motion(motion: Motion, body: BodyModel, src: str):
    """(motion, com (F, 3) [m], markers (F, 2, 3, 3) [m], gait, summary) that the fit measures: the clip, or
    it upsampled to ANALYSIS_FPS when slower; the summary carries the clip's own mean speed and cadence.
    Raises NotARunningMotion for a walk, a jump in place or fewer than 2 full stances."""
    # The clip's own figures (what ``info`` prints) set the cycle's cadence and speed.
    clip_summary = summarize(motion, body)
    require_running(clip_summary, src)
    if motion.fps < ANALYSIS_MIN_FPS:
        # A 24-30 Hz clip has 4-5 frames per stance: too few for the force-refined events and the control
        # fit. The forces are measured on the motion interpolated to ANALYSIS_FPS (positions linear, rotations
        # slerped): the COM filter (CUTOFF_HZ, well below 12 Hz) sees the same band-limited signal, and the
        # events fall between the clip's frames instead of on them. Times stay in seconds.
        motion, com, markers = _upsampled(motion, body, ANALYSIS_FPS)
    else:
        com, markers = body.com_and_markers(motion)
    gait = detect_gait(motion, body, markers)
    summary = replace(summarize(motion, body, com, gait), mean_speed=clip_summary.mean_speed,
                      step_frequency=clip_summary.step_frequency)
    if sum(not st.partial for st in gait.stances) < 2:
        raise NotARunningMotion(
            f"{src}: only {sum(not st.partial for st in gait.stances)} complete stance phase(s) "
            f"(of {len(gait.stances)} contacts); "
            "the fit needs two consecutive full stances (one step) and a stride of events")
    return motion, com, markers, gait, summary


def _stance_geometries(gait, p, f, fy_bw, markers, heading, lateral, line, dt: float, src: str):
    """(geo, stances): the StanceGeometry (force-refined events) of every contact with something to measure,
    and its Stance. p, f (F, 3): filtered COM [m] and ground force [N]; fy_bw (F,) vertical force [body
    weights]; heading, lateral (3,) unit axes; line: the lateral COM line (polyfit of [m] over [s]); dt [s].
    Raises NotARunningMotion when no stance is seen whole in the force."""
    F = p.shape[0]
    geo = []
    stances = []
    contact_s = [(st.t_off - st.t_on) * dt for st in gait.stances if not st.partial]
    short = bool(contact_s) and float(np.median(contact_s)) < SHORT_STANCE_S
    for st in gait.stances:
        td, lo, td_seen, lo_seen = refine_events(fy_bw, st.start, st.stop, dt, st.partial)
        if not ((td_seen or st.start == 0) and (lo_seen or st.stop >= F)):
            # The force does not cross the event threshold near a contact's end inside the clip (near the
            # clip's edge the filter's extension holds it up): its stance time would be the marker
            # contact's, which a toe rolling off the floor leaves uncertain by a frame at 30 Hz (K 12 % off
            # on 09_07). Measured like a stance cut by the edge: not averaged, not fitted.
            st = replace(st, partial=True)
        # The force-based stance never extends past the foot's marker contact: on a short stance (4 frames of
        # a 30 Hz dash) the COM filter smears the force pulse wider than the contact, and a machine stance
        # begun before the foot is down would push a body still in the air (the output's flight gravity
        # then reads low).
        # The control is still fitted over the whole force pulse (its samples), only the events move.
        slack = CONTACT_SLACK_S / dt  # [frames]
        td_c = max(td, st.t_on - slack) if short and st.start > 0 else td
        lo_c = min(lo, st.t_off + slack) if short and st.stop < F else lo
        if st.partial and lo - td < 4:
            continue  # a sliver of a contact at the clip's edge: nothing to measure
        stances.append(st)
        t_mid = 0.5 * (td + lo) * dt
        sg = stance_geometry(st, td, lo, p, f, markers, heading, lateral, dt, float(np.polyval(line, t_mid)))
        if lo_c > td_c and (td_c, lo_c) != (td, lo):
            sg = replace(sg, t_touchdown=td_c * dt, t_liftoff=lo_c * dt)
        geo.append(sg)
    if not any(not sg.partial for sg in geo):
        # Full stances by the markers whose force events both fall near the clip's edges (where the COM
        # filter's extension holds the force up) are measured as cut: nothing is left to fit the control to.
        raise NotARunningMotion(
            f"{src}: no stance with both its touchdown and liftoff seen in the ground force inside the clip "
            f"(of {len(gait.stances)} contacts; near the clip's edges the filtered force does not show them); "
            "the fit needs two consecutive full stances")
    return geo, stances


def _step_times(geo, stances, full, summary, F: int, src: str):
    """(flights [(liftoff, touchdown) s], stance time [s], measured flight time [s], the cycle's flight time
    [s]) of the clip. Raises NotARunningMotion without a complete flight."""
    flights = [(geo[i].t_liftoff, geo[i + 1].t_touchdown) for i in range(len(geo) - 1)
               if stances[i].stop < F and stances[i + 1].start > 0]
    if not flights:
        raise NotARunningMotion(f"{src}: no complete flight phase between two contacts")
    stance_time = float(np.mean([s.duration for s in full]))
    flight_time_measured = float(np.mean([b - a for a, b in flights]))
    # The cycle's step time is the clip's own step period (the measure ``info`` prints, timed at midstance
    # over whole strides), so the output steps at the clip's cadence. Stance is the force-based
    # one (what the machine's leg does); the flight is the rest of the step. Averaging stance and flight
    # over different sets of stances would not add up to the step period (the issue that made outputs
    # step 5 % off the clip).
    step_period_s = 1.0 / summary.step_frequency if summary.step_frequency > 0 else stance_time + flight_time_measured
    flight_time = step_period_s - stance_time
    if not flight_time > 0.2 * stance_time:
        flight_time = flight_time_measured  # contacts too few to trust the period: keep the measured flight
    return flights, stance_time, flight_time_measured, flight_time


def _ground_at(geo, t):
    """Ground height [m] under the runner at times t [s] (any shape): the stance's during stance, interpolated
    in flight between the stances' mid-times."""
    tk = np.array([0.5 * (s.t_touchdown + s.t_liftoff) for s in geo])
    gk = np.array([s.ground for s in geo])
    g_t = np.interp(t, tk, gk)
    for s in geo:
        g_t = np.where((t >= s.t_touchdown) & (t <= s.t_liftoff), s.ground, g_t)
    return g_t


def _flight_apexes(flights, times, p, v, heading, geo):
    """([apex height above the ground [m]], [mean forward speed [m/s]]) of each flight with ≥ 2 frames;
    times (F,) [s], p, v (F, 3) filtered COM [m], [m/s]."""
    apex_h, apex_u = [], []
    for a, b in flights:
        m = (times >= a) & (times <= b)
        if m.sum() >= 2:
            apex_h.append(float(np.max(p[m, UP_AXIS] - _ground_at(geo, times[m]))))
            apex_u.append(float(np.mean(v[m] @ heading)))
    return apex_h, apex_u


def _residual_flight_mask(gait, geo, F: int):
    """(F,) bool: the frames of the flight residual: marker flights less a guard of RESIDUAL_GUARD_FRAMES at
    each end, where the zero-lag filter necessarily spreads the landing impact (its smoothing half-width),
    and outside every force stance."""
    in_stance = np.zeros(F, bool)
    for s in geo:
        in_stance[s.frames] = True
    marker_flight = np.zeros(F, bool)
    for a, b in gait.flights:
        marker_flight[a + RESIDUAL_GUARD_FRAMES : b - RESIDUAL_GUARD_FRAMES] = True
    return marker_flight & ~in_stance


def _machine_com_height(U, H, th, ctl, row, kinds, e, times, dt, T, l0, n_per_stance):
    """The machine's COM height over the clip's stride, phase-matched segment by segment (stance→stance,
    flight→flight): (trajectory, machine event times (5,) [√(l0/g)] since the stride's first event, the
    stride's frame times t_ref (S,) [s], h_machine (S,) [m]). e (5,) the stride's event times [s]; T [s]."""
    t_fall, t_st, t_rise = float(row["t_fall"]), float(row["t_stance"]), float(row["t_rise"])
    step_time = t_fall + t_st + t_rise
    traj = simulate(U, H, th, ctl, dt / T / 2.0, n_steps=1, n_per_stance=n_per_stance)
    m_td = t_fall  # machine touchdown time within its step (from the apex)
    seg_m = np.array([0.0, t_st, t_st + (t_rise + t_fall), 2 * t_st + (t_rise + t_fall), 2 * (step_time)])
    if kinds[0] == "LO":
        seg_m = np.array([0.0, t_rise + t_fall, step_time, step_time + t_rise + t_fall, 2 * step_time])
        m_td = t_fall + t_st
    sel = (times >= e[0]) & (times <= e[4])
    t_ref = times[sel]
    s_m = np.interp(t_ref, e, seg_m)  # machine time since the stride's first event
    t_sim = (m_td + s_m) % step_time
    h_mach = np.interp(t_sim, traj.t, traj.pos[:, 1]) * l0
    return traj, seg_m, sel, t_ref, h_mach


def _stance_dict(sg, ft, mg: float) -> dict:
    """The report's record of one stance: its geometry (SI) and, when fitted, its control fit (dimensionless);
    mg the body weight [N]."""
    d = {"foot": ("left", "right")[sg.foot], "partial": sg.partial, "t_touchdown_s": sg.t_touchdown,
         "t_liftoff_s": sg.t_liftoff, "duration_s": sg.duration, "l0_m": sg.l0,
         "theta_touchdown_rad": sg.theta_touchdown, "theta_liftoff_rad": sg.theta_liftoff,
         "com_drop_m": sg.com_drop, "peak_vertical_force_bw": sg.peak_vertical_force / mg,
         "contact_m": sg.p_world_contact, "ground_m": sg.ground, "lateral_offset_m": sg.lateral_offset,
         "fit": None, "fit_free": None}
    if ft is not None:
        d["fit"] = {"K": ft.K, "a": ft.a, "b": ft.b, "c": ft.c, "r2": ft.r2, "rms_bw": ft.rms}
        d["fit_free"] = {"K": ft.K_free, "a": ft.a_free, "b": ft.b_free, "c": ft.c_free, "r2": ft.r2_free}
    return d


def _reference_dict(stance_time, flight_time, mean_speed, stride_speed, flight_time_measured, apex_h, apex_u,
                    dt, kinds, e, stride_feet, residual_bw, shares, pooled, cutoff_hz) -> dict:
    """The report's record of the clip's measured figures (SI: s, m/s, m; forces in body weights)."""
    return {
        "stance_time_s": stance_time, "flight_time_s": flight_time, "mean_speed_m_s": mean_speed,
        "step_time_s": stance_time + flight_time, "stride_speed_m_s": stride_speed,
        "flight_time_contacts_s": flight_time_measured,
        "apex_height_m": float(np.mean(apex_h)) if apex_h else None,
        "apex_speed_m_s": float(np.mean(apex_u)) if apex_u else None,
        "frame_time_s": dt,
        "stride": {"first_event": kinds[0], "kinds": list(kinds), "t_events_s": e, "feet": stride_feet,
                   "frames": np.round(e / dt, 3)},
        "flight_residual_bw": residual_bw, "shares": shares,
        "pooled_fit": {"K": pooled.K, "a": pooled.a, "b": pooled.b, "c": pooled.c, "r2": pooled.r2,
                       "rms_bw": pooled.rms},
        "filter": {"kind": "butterworth forward-backward, quadratic edge extension", "cutoff_hz": cutoff_hz,
                   "event_threshold_bw": EVENT_THRESHOLD_BW},
    }


def _stride(ev, x_fwd, times, src: str):
    """(window [(t [s], kind, stance index)], e (5,) its event times [s], kinds (5,), the stride's mean forward
    speed [m/s]) of the clip's first whole stride; x_fwd (F,) the forward COM [m] at times (F,) [s].
    Raises NotARunningMotion without one."""
    win = _stride_window(ev)
    if win is None:
        raise NotARunningMotion(f"{src}: no complete stride (touchdown, liftoff, touchdown, liftoff, touchdown "
                                "or the same from a liftoff) inside the clip")
    e = np.array([t for t, _, _ in win])
    kinds = tuple(k for _, k, _ in win)
    stride_speed = float((np.interp(e[4], times, x_fwd) - np.interp(e[0], times, x_fwd)) / (e[4] - e[0]))
    return win, e, kinds, stride_speed


def _fit_cycle(full, pooled, apex_h, apex_u, summary, stance_time, flight_time, mean_speed, n_per_stance):
    """The periodic cycle nearest the clip's figures, searched from the measured priors (dimensionless, l0 =
    the mean touchdown leg length of the full stances): (l0 [m], T [s], V [m/s] the units, z (7,) = U, H,
    θ0, K, a, b, c, the cycle's step row, iterations). Times in [s], speeds in [m/s], apexes as measured."""
    l0 = float(np.mean([s.l0 for s in full]))
    T = time_unit(l0)
    V = speed_unit(l0)
    theta0 = float(np.mean([s.theta_touchdown for s in full]))
    U0 = (np.mean(apex_u) if apex_u else summary.mean_speed) / V
    H0 = (np.mean(apex_h) if apex_h else l0) / l0
    H0 = max(H0, math.cos(theta0) + 1e-3)
    z0 = np.array([U0, H0, theta0, pooled.K, pooled.a, pooled.b, pooled.c])
    T_c = stance_time / T
    z, row, iters, _ = _cycle_search(z0, T_c, (stance_time / T, flight_time / T, mean_speed / V), n_per_stance)
    return l0, T, V, z, row, iters


def _lateral_sway(e, times, lat, line):
    """(phase (SWAY_SAMPLES,) uniform over the stride [0, 1), sway there [m] off the lateral COM line);
    e (5,) the stride's event times [s], times (F,) [s], lat (F,) the lateral COM [m], line its polyfit."""
    phase = np.arange(SWAY_SAMPLES) / SWAY_SAMPLES
    t_sw = e[0] + phase * (e[4] - e[0])
    return phase, np.interp(t_sw, times, lat) - np.polyval(line, t_sw)


def _quality(com_rms, row, T, V, stance_time, flight_time, mean_speed) -> dict:
    """The fit's quality figures: the COM height RMS [m] and the cycle's relative errors in stance time,
    flight time and mean speed against the clip's ([s], [m/s]; T [s], V [m/s] the units)."""
    t_fall, t_st, t_rise = float(row["t_fall"]), float(row["t_stance"]), float(row["t_rise"])
    step_time = t_fall + t_st + t_rise
    return {
        "com_rms_m": com_rms,
        "stance_time_error": t_st * T / stance_time - 1.0,
        "flight_time_error": (t_rise + t_fall) * T / flight_time - 1.0,
        "mean_speed_error": float(row["apex_dx"]) / step_time * V / mean_speed - 1.0,
    }


def fit_machine_detailed(motion: Motion, body: BodyModel | None = None, mass: float = 70.0, *,
                         cutoff_hz: float = CUTOFF_HZ, n_per_stance: int = N_PER_STANCE,
                         source: str | None = None) -> FitResult:
    """Fit the simple running machine to a running motion, with everything needed to report on it.

    motion: the reference (SI); body: its BodyModel (built from the skeleton with ``mass`` if None);
    mass: body mass [kg]; cutoff_hz: COM low-pass cutoff [Hz]; n_per_stance: simulator resolution.
    Raises NotARunningMotion (walks, jumps in place, < 2 full stances) or FitError.
    """
    src = source or str(motion.meta.get("source") or "motion")
    if body is None:
        body = BodyModel.from_skeleton(motion.skeleton, mass=mass)
    mass = body.total_mass
    mg = mass * GRAVITY
    motion, com, markers, gait, summary = _analysis_motion(motion, body, src)
    dt = motion.frame_time
    F = motion.n_frames
    cc = clip_com(com, dt, mass, summary.heading, cutoff_hz)
    times, p, v, f, heading, lateral = cc.times, cc.p, cc.v, cc.f, cc.heading, cc.lateral
    # Lateral COM line (least squares over the clip): sway and foot offsets are measured from it.
    lat = p @ lateral
    line = np.polyfit(times, lat, 1)
    geo, stances = _stance_geometries(gait, p, f, f[:, UP_AXIS] / mg, markers, heading, lateral, line, dt, src)
    full = [sg for sg in geo if not sg.partial]
    # Per-stance and pooled control fits (dimensionless).
    fits = [None if sg.partial else _spring_fit(sg, mg) for sg in geo]
    springs = [sg for sg, ft in zip(geo, fits) if ft is not None] or full  # none a spring: the pooled fit says so
    pooled = fit_stance_control(np.concatenate([s.tau for s in springs]),
                                np.concatenate([s.l / s.l0 for s in springs]),
                                np.concatenate([s.f_leg / mg for s in springs]))

    # Measured figures.
    ev = _events(geo, stances, F)
    flights, stance_time, flight_time_measured, flight_time = _step_times(geo, stances, full, summary, F, src)
    win, e, kinds, stride_speed = _stride(ev, p @ heading, times, src)
    # The machine runs at the clip's mean speed (``info``'s: first to last frame), not one stride's: on a
    # take whose speed changes the two differ, and the speed factor must refer to what ``info`` printed.
    mean_speed = float(summary.mean_speed)
    apex_h, apex_u = _flight_apexes(flights, times, p, v, heading, geo)
    residual_bw = flight_residual(f, mass, _residual_flight_mask(gait, geo, F))
    shares = force_shares(full)

    l0, T, V, z, row, iters = _fit_cycle(full, pooled, apex_h, apex_u, summary, stance_time, flight_time,
                                         mean_speed, n_per_stance)
    U, H, th, K, a, b, c = map(float, z)
    T_c = stance_time / T
    ctl = Control(K=K, a=a, b=b, c=c, T_c=T_c)
    t_fall, t_st, t_rise = float(row["t_fall"]), float(row["t_stance"]), float(row["t_rise"])
    step_time = t_fall + t_st + t_rise
    periodicity = float(max(abs(row["U_next"] - U), abs(row["H_next"] - H)))

    traj, seg_m, sel, t_ref, h_mach = _machine_com_height(U, H, th, ctl, row, kinds, e, times, dt, T, l0,
                                                          n_per_stance)
    h_ref = p[sel, UP_AXIS] - _ground_at(geo, t_ref)
    com_rms = float(np.sqrt(np.mean((h_mach - h_ref) ** 2)))

    # Lateral sway over the stride (uniform phase) and lateral foot offsets.
    phase, sway = _lateral_sway(e, times, lat, line)
    foot_off = np.array([np.mean([s.lateral_offset for s in geo if s.foot == k] or [np.nan]) for k in (0, 1)])

    stride_feet = [("left", "right")[geo[i].foot] for _, _, i in win]
    reference = _reference_dict(stance_time, flight_time, mean_speed, stride_speed, flight_time_measured, apex_h,
                                apex_u, dt, kinds, e, stride_feet, residual_bw, shares, pooled, cutoff_hz)
    quality = _quality(com_rms, row, T, V, stance_time, flight_time, mean_speed)
    machine = SimpleMachine(
        U=U, H=H, theta0=th, K=K, a=a, b=b, c=c, T_c=T_c, t_stance=t_st, t_flight=t_rise + t_fall,
        t_fall=t_fall, t_rise=t_rise, step_length=float(row["apex_dx"]), step_time=step_time,
        mean_speed=float(row["apex_dx"]) / step_time, peak_force=float(row["peak_force"]),
        periodicity=periodicity, iterations=iters, mass=mass, l0=l0, g=GRAVITY, source=src,
        heading=heading, lateral=lateral, up=np.eye(3)[UP_AXIS], ground=float(gait.ground),
        lateral_foot_offset=foot_off, lateral_sway=sway, lateral_sway_phase=phase,
        reference=reference, stances=tuple(_stance_dict(sg, ft, mg) for sg, ft in zip(geo, fits)), quality=quality,
    )
    return FitResult(machine=machine, times=times, p_world_com=p, f_world=f, stances=tuple(geo),
                     stance_fits=tuple(fits), pooled=pooled, stride_events=e, stride_kinds=kinds,
                     machine_event_times=seg_m * T, t_ref=t_ref, h_ref=h_ref, h_machine=h_mach, traj=traj)

