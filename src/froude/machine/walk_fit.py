"""§4 for walking: fit the simple walking machine (:mod:`froude.machine.walking`) to a walking clip.

    motion → body COM + foot markers → gait (contacts) → zero-lag filtered COM → eq. 1 forces
    → per-stance geometry (touchdown point, centre-of-pressure roll) → eq. 2 control of both legs by
    linear least squares → periodic cycle (Newton) → shape fit of the force and COM height (least
    squares) → exact periodic cycle again → WalkingMachine

Events. In walking the total vertical force never falls near zero, so the running fit's force-refined
events do not exist; touchdown and liftoff are the sub-frame contact events of :mod:`froude.body.gait`
(``Stance.t_on`` / ``t_off``).

Geometry. A walking foot rolls: the centre of pressure travels from the heel to the toes. Each stance's
contact is the least-squares line x_touchdown + roll·τ through the foot's lowest marker (τ = 0 … 1 over
the stance); the machine's legs roll the same way (``roll``, the clips' mean, in l0 per unit τ).

Control fit (eq. 2). In single support the measured sagittal force belongs to one leg; in double support
it is the sum of two. The model force of the legs in contact is linear in (K, K a, K b, K c)::

    f(t) = Σ_legs [K (1 − l_i/l0_i) + K a + K b τ_i + K c τ_i²] u_i,   u_i = unit leg vector foot → COM

so one linear least-squares solve over both force components of every frame whose legs are all in
complete stances gives a control without splitting the double-support force between the legs. On the
real clips it explains little of the force (r² ≈ 0: the leg-length change of walking is mostly
geometry, not compression), so it is only a start; a plain spring leg (Geyer et al.'s) is the other.

Cycle search: z = (u, v, d, s, θ0, K, a, b, c, l_td, e) (T_c held at the measured mean stance time; the
control's two pulses, six more entries of z, held) must make the step map periodic (4 equations) and reproduce
the measured step time, double-support time and mean speed (3): seven equations in eleven unknowns, solved by
minimum-norm Newton from the priors in coordinates scaled by ``CYCLE_SCALES`` (the periodic machine nearest
them). Then the *shape fit*: least squares of the machine's total vertical force over a stance (measured
through the clip's filter) and its COM height over a step against the clip's on the periodic cycles
(periodicity and the three targets as exact constraints, a constrained Gauss-Newton run until its step is
below a tolerance, so that its end point is the minimum and not where a budget ran out: issue 26), the force
weighted up around the clip's two peaks and trough (``LANDMARK_WEIGHT``: the acceptance is on those landmarks,
and a plain least-squares fit of the CMU clips' W-shaped single support flattens them), the landing leg kept
``MIN_CLEARANCE`` above the ground where the COM dips in single support (at a graze the step map jumps, and
the exact cycle's existence would hang on the last bits); the exact cycle is then found again from its result.
Each of the two starts is tried without the control's pulses and with them (``PULSE_START``: a push-off pulse
just past the other foot's touchdown, a weight-acceptance pulse at the clip's first peak, their amplitudes
fitted by the shape fit); of the four periodic starts the shape fit runs from the two whose shape residual is
the smallest (``_shape_fit_nearest``), the others only if both fail, and ``choose_fit`` picks between the
converged ones (the nearest unless another's cost is lower by COST_MARGIN); where every start fails at the
coarse resolution they all run again at the fine one. A chosen fit whose force landmarks are further from the
clip's than LANDMARK_TIMING_TOL is refined with the weight-acceptance pulse's centre free
(``_refine_pulse_centre``). The shape fit, the choice and the refinement are :mod:`froude.machine.walk_shape`;
the solver is :mod:`froude.machine.gauss_newton`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import partial

import numpy as np

from ..body.com_force import force_landmarks
from ..body.gait import detect_gait, summarize, walks
from ..body.model import BodyModel
from ..core.constants import GRAVITY, UP_AXIS
from ..core.motion import Motion
from ..errors import FitError, NotAWalkingMotion
from .forces import CUTOFF_HZ, clip_com
from .walk_cycle import (
    _VARS,
    CYCLE_SCALES,
    PULSE_VARS,
    _control,
    _cycle_search,
)
from .walk_model import WalkingMachine
from .walk_shape import (
    SHAPE_N_PER_STANCE,
    _refine_pulse_centre,
    _shape_fit_nearest,
    _shape_problem,
    cycle_landmark_timing,
    landmark_timing,
    stance_force_profile,
    step_phase_times,
)
from .walk_stance import measure_stance
from .walking import (
    N_PER_STANCE,
    PULSES_OFF,
    WalkState,
    desired_leg_length,
    record_step,
    simulate_walk,
)

__all__ = ["WalkFitResult", "fit_walking_detailed", "CYCLE_SCALES", "force_landmarks", "PROFILE_SAMPLES"]

#: The start of the fit with pulses: amplitudes p, q [l0], the push-off pulse's centre past the other
#: foot's touchdown (dtau_p, stance phase) and both widths (half the support, stance phase).
PULSE_START = {"p": 0.03, "dtau_p": 0.007, "w_p": 0.04, "q": 0.02, "w_q": 0.075}
#: The second start of the cycle search: a plain spring leg, Geyer et al.'s K ≈ 20 (k = 20 kN/m, m = 80 kg,
#: l0 = 1 m gives 25), l_d = l0; (K, a, b, c).
GEYER_CONTROL = (20.0, 0.0, 0.0, 0.0)
#: Residual [max-norm of the cycle search's rows] to which a start of the shape fit is made periodic. The shape
#: fit meets the constraints itself (its first step is their Newton step) and ends at its minimum to STEP_TOL
#: (1e-4 scaled) whatever its start, and the exact cycle is found after it to 1e-10; the start's own search
#: converges only linearly near the end (the nearest-point Newton turns along the curved cycle set: 07_01's
#: starts with pulses at 0.2 an iteration), so its last four orders cost up to 7 Jacobians a start for nothing.
START_TOL = 1e-6
#: Samples of the stance-normalised force profiles (τ = 0 … 1).
PROFILE_SAMPLES = 51


@dataclass(frozen=True)
class LegSamples:
    """The legs in contact at each usable frame (sagittal, per stance normalisation).

    frame: (N,) frame index; for every sample the legs (1 or 2) as rows of (M,) arrays: sample (index
    into frame), stance (index), c = 1 − l/l0 [-], tau [-], ux, uy (unit leg vector foot → COM).
    """

    frame: np.ndarray
    sample: np.ndarray
    stance: np.ndarray
    comp: np.ndarray
    tau: np.ndarray
    ux: np.ndarray
    uy: np.ndarray


def _leg_samples(geo, p_sag, F, dt) -> LegSamples:
    """Frames covered by complete stances only (every leg in contact has a known touchdown and liftoff)."""
    cover: list[list[int]] = [[] for _ in range(F)]
    usable = np.zeros(F, bool)
    for i, sg in enumerate(geo):
        td, lo = sg.t_touchdown / dt, sg.t_liftoff / dt
        for k in range(int(math.ceil(td)), int(math.floor(lo)) + 1):
            if 0 <= k < F:
                cover[k].append(i)
                usable[k] = True
    for k in range(F):
        if any(geo[i].partial for i in cover[k]):
            usable[k] = False
    frames: list[int] = []
    rows: list[tuple[int, int, int]] = []
    for k in map(int, np.flatnonzero(usable)):
        for i in cover[k]:
            rows.append((len(frames), i, k))
        frames.append(k)
    sample = np.array([r[0] for r in rows], int)
    stance = np.array([r[1] for r in rows], int)
    kk = np.array([r[2] for r in rows], int)
    cx = np.array([geo[i].contact_x(k * dt) for i, k in zip(stance, kk)])
    rx = p_sag[kk, 0] - cx
    ry = p_sag[kk, 1] - np.array([geo[i].ground for i in stance])
    l = np.hypot(rx, ry)
    l0 = np.array([geo[i].l0 for i in stance])
    td = np.array([geo[i].t_touchdown for i in stance])
    dur = np.array([geo[i].duration for i in stance])
    return LegSamples(frame=np.array(frames, int), sample=sample, stance=stance, comp=1.0 - l / l0,
                      tau=(kk * dt - td) / dur, ux=rx / l, uy=ry / l)


def fit_two_leg_control(ls: LegSamples, f_sag_bw: np.ndarray, w_horizontal: float = 1.0):
    """Least squares of eq. 2 over both legs' force (see module doc).

    f_sag_bw: (F, 2) measured sagittal force (forward, up) [body weights]. Returns (K, a, b, c, r2_vertical,
    rms_bw) with r2 and rms of the vertical component.
    """
    n = ls.frame.size
    if n < 12:
        raise FitError(f"only {n} frames lie in complete stances: too few to fit the leg control")
    cols = np.stack([ls.comp, np.ones_like(ls.tau), ls.tau, ls.tau ** 2], axis=1)  # (M, 4)
    A = np.zeros((2 * n, 4))
    np.add.at(A, ls.sample, cols * ls.ux[:, None] * w_horizontal)
    np.add.at(A, n + ls.sample, cols * ls.uy[:, None])
    y = np.concatenate([f_sag_bw[ls.frame, 0] * w_horizontal, f_sag_bw[ls.frame, 1]])
    coef, *_ = np.linalg.lstsq(A, y, rcond=None)
    K, KA, KB, KC = coef
    if not K > 0:
        raise FitError(f"the legs do not act as springs in this walk (fitted K = {K:.3g})")
    pred = A[n:] @ coef
    fy = f_sag_bw[ls.frame, 1]
    ss = float(np.sum((fy - fy.mean()) ** 2))
    r2 = 1.0 - float(np.sum((fy - pred) ** 2)) / ss if ss > 0 else float("nan")
    return float(K), float(KA / K), float(KB / K), float(KC / K), r2, float(np.sqrt(np.mean((fy - pred) ** 2)))


@dataclass(frozen=True)
class WalkFitResult:
    """Everything the walking fit computed, for reports and plots (SI unless stated).

    machine: the WalkingMachine. profile_tau (N,) stance phase; profile_ref (N,) the clip's total vertical
    force over a stance (mean of its complete stances) [BW]; profile_model (N,) the machine's, measured
    through the clip's filter; profile_unfiltered (N,) the machine's exact force. t_ref (M,) times of the
    frames of the complete steps [s], h_ref (M,) their COM height above the ground [m], h_model (M,) the
    machine's at the phase-matched times [m]. stances: the walk_stance.WalkStance of each contact. t_leg (K,) time
    since touchdown [s] and l_leg (K,) leg length [m] (COM → rolling centre of pressure) over the clip's
    first complete stance. steps (S, 3): touchdown, the other foot's liftoff, next touchdown [s].
    """

    machine: WalkingMachine
    profile_tau: np.ndarray
    profile_ref: np.ndarray
    profile_model: np.ndarray
    profile_unfiltered: np.ndarray
    t_ref: np.ndarray
    h_ref: np.ndarray
    h_model: np.ndarray
    stances: tuple
    t_leg: np.ndarray
    l_leg: np.ndarray
    steps: np.ndarray


def stance_leg_length(m, tau, n_per_stance=N_PER_STANCE):
    """Leg length l and desired length l_d [l0] of one leg of the periodic machine ``m`` over its stance.

    m: a WalkingMachine; tau (N,) stance phase 0 … 1 (by T_c = the stance time). The leg is the leading
    one of a step until t_step, then the trailing one of the next (the same step, by periodicity).
    """
    tau = np.asarray(tau, float)
    t = tau * m.t_stance
    first = t <= m.t_step
    tq = np.where(first, t, t - m.t_step)
    tr = simulate_walk(m.state, m.theta0, m.control, tq, roll=m.roll, l_td=m.l_td, n_per_stance=n_per_stance)
    xc = np.where(first, tr.contact_x[1], tr.contact_x[0]) + m.roll * tau
    l = np.hypot(tr.pos[:, 0] - xc, tr.pos[:, 1])
    return l, desired_leg_length(m.control, tau)


def _start_passes(n_per_stance: int) -> tuple:
    """The passes over the starts, each (simulator resolution of the start's cycle search and shape fit,
    whether the search holds the single-support force trough: ``walk_cycle``), each only where
    every start of the passes before failed: the shape fit's resolution; the simulation's (walk_active_002:
    every start fails at 120 steps a stance); the shape fit's with the trough held (a brisk walk whose
    starts vault off the stance leg, walk_active_009: the search stalls on the unloading boundary). The
    held trough shapes the start only: the exact cycle after the shape fit is the plain one."""
    return tuple(dict.fromkeys(((SHAPE_N_PER_STANCE, False), (n_per_stance, False), (SHAPE_N_PER_STANCE, True))))


def _refusal(reason: str) -> str:
    """The walking fit's last failure said as what it means for the walk: the shape fit's own words (a
    Gauss-Newton that finds no descent or does not converge) are about the search, not the clip."""
    if reason.startswith("the walking shape fit"):
        return ("no walking cycle whose ground force over a stance comes near this walk's could be fitted "
                f"({reason.removeprefix('the walking shape fit ')})")
    return reason


def _walk_figures(step_s: float, double_s: float, speed_m_s: float, landmarks: dict) -> str:
    """The clip's figures a walking cycle must meet, in the user's terms: its step [s], double support [% of a
    step], speed [m/s] and the ground force's landmarks over a stance [body weights]."""
    return (f"its steps: {step_s:.2f} s, {100 * double_s / step_s:.0f} % of each in double support, "
            f"{speed_m_s:.2f} m/s; its vertical force over a stance: peaks {landmarks['peak1']:.2f} and "
            f"{landmarks['peak2']:.2f}, trough {landmarks['trough']:.2f} body weights")


# Long because, like fit.fit_machine_detailed, the walking fit is one sequential pass whose intermediates
# all end up in the WalkFitResult.
def fit_walking_detailed(motion: Motion, body: BodyModel | None = None, mass: float = 70.0, *,
                         cutoff_hz: float = CUTOFF_HZ, n_per_stance: int = N_PER_STANCE,
                         source: str | None = None) -> WalkFitResult:
    """Fit the simple walking machine to a walking motion (see module doc).

    Raises NotAWalkingMotion when the clip is not a walk (with the gait's reason) or has too few
    complete steps, FitError when no periodic cycle is found.
    """
    src = source or str(motion.meta.get("source") or "motion")
    if body is None:
        body = BodyModel.from_skeleton(motion.skeleton, mass=mass)
    mass = body.total_mass
    mg = mass * GRAVITY
    com, markers = body.com_and_markers(motion)
    gait = detect_gait(motion, body, markers, com)
    summary = summarize(motion, body, com, gait)
    if not walks(summary):
        raise NotAWalkingMotion(f"{src}: {summary.kind}, not a walk: {summary.reason}")
    dt = motion.frame_time
    F = motion.n_frames
    cc = clip_com(com, dt, mass, summary.heading, cutoff_hz)
    times, p, v, f, heading, lateral = cc.times, cc.p, cc.v, cc.f, cc.heading, cc.lateral

    x_fwd = p @ heading
    geo, stances = [], []
    for st in gait.stances:
        td = st.t_on if math.isfinite(st.t_on) else st.start - 0.5
        lo = st.t_off if math.isfinite(st.t_off) else st.stop - 0.5
        td, lo = max(td, 0.0), min(lo, F - 1.0)
        if lo - td < 4:
            continue
        stances.append(st)
        geo.append(measure_stance(st, td, lo, x_fwd, p[:, UP_AXIS], markers, heading, dt))
    # Complete steps: a touchdown (lead) while the other foot's stance (trail) is on, then the trail's
    # liftoff, then the next touchdown (the other foot again).
    steps = []
    for j, gl in enumerate(geo):
        if stances[j].start == 0:
            continue
        trail = [i for i in range(j) if geo[i].foot != gl.foot and geo[i].t_touchdown < gl.t_touchdown
                 < geo[i].t_liftoff and not geo[i].partial]
        nxt = [k for k in range(j + 1, len(geo)) if geo[k].foot != gl.foot and stances[k].start > 0
               and geo[k].t_touchdown > gl.t_touchdown]
        if trail and nxt:
            steps.append((trail[-1], j, nxt[0]))
    full = [sg for sg in geo if not sg.partial]
    if len(steps) < 1 or len(full) < 1:
        raise NotAWalkingMotion(f"{src}: no complete walking step (touchdown, the other foot's liftoff, "
                                "the next touchdown) inside the clip")

    t_td = np.array([geo[j].t_touchdown for _, j, _ in steps])
    t_lo = np.array([geo[i].t_liftoff for i, _, _ in steps])
    t_nx = np.array([geo[k].t_touchdown for _, _, k in steps])
    stance_time = float(np.mean([sg.duration for sg in full]))
    double_time = float(np.mean(t_lo - t_td))
    step_time = float(np.mean(t_nx - t_td))
    t_first, t_last = float(t_td.min()), float(t_nx.max())
    mean_speed = float((np.interp(t_last, times, x_fwd) - np.interp(t_first, times, x_fwd)) / (t_last - t_first))
    if motion.meta.get("straightened") is not None and summary.step_frequency > 0:
        # A turning take (straightened along its path) slows into its turn and out of it: its complete steps,
        # a few of its steps, time it off its mean step (walk-turn-right_normal_001: 0.551 s against 0.536,
        # 3 %; left_active_001 -2 %), and the machine, whose cycle every output step repeats, walked off the
        # take's cadence by as much (issue 28's cadence bar, 2 %). Its steps are timed at the take's mean
        # step (the gait's step frequency, info's), double support and stance in proportion.
        k = 1.0 / (summary.step_frequency * step_time)
        step_time, double_time, stance_time = k * step_time, k * double_time, k * stance_time

    # Priors at the touchdowns (dimensionless, l0 = mean touchdown leg length).
    l0 = float(np.mean([geo[j].l0 for _, j, _ in steps]))
    T = math.sqrt(l0 / GRAVITY)
    V = math.sqrt(GRAVITY * l0)
    u0 = float(np.mean(np.interp(t_td, times, v @ heading))) / V
    v0 = float(np.mean(np.interp(t_td, times, v[:, UP_AXIS]))) / V
    d0 = float(np.mean([np.interp(geo[j].t_touchdown, times, x_fwd) - geo[i].x_touchdown
                        for i, j, _ in steps])) / l0
    roll = float(np.mean([sg.roll for sg in full])) / l0
    th0 = float(np.mean([geo[j].theta_touchdown for _, j, _ in steps]))

    f_sag = np.stack([f @ heading, f[:, UP_AXIS]], axis=1) / mg
    p_sag = np.stack([x_fwd, p[:, UP_AXIS]], axis=1)
    ls = _leg_samples(geo, p_sag, F, dt)
    starts = [GEYER_CONTROL]
    try:
        K0, a0, b0, c0, r2, rms = fit_two_leg_control(ls, f_sag)
        starts.insert(0, (K0, a0, b0, c0))
    except FitError as e:  # the plain spring start remains; the failure is reported in the machine's fit
        K0 = a0 = b0 = c0 = r2 = rms = float("nan")
        fit_note = str(e)
    else:
        fit_note = ""
    T_c = stance_time / T  # τ runs 0 … 1 over the clip's mean stance
    targets = (step_time / T, double_time / T, mean_speed / V)
    tau = np.linspace(0.0, 1.0, PROFILE_SAMPLES)
    prof_ref = np.mean([np.interp(sg.t_touchdown + tau * sg.duration, times, f_sag[:, 1]) for sg in full], axis=0)
    # COM height above the ground (interpolated between the stances' grounds) over a step, phase-matched.
    tk = np.array([0.5 * (sg.t_touchdown + sg.t_liftoff) for sg in geo])
    gk = np.array([sg.ground for sg in geo])

    def height(t):
        return np.interp(t, times, p[:, UP_AXIS]) - np.interp(t, tk, gk)

    lm_ref = force_landmarks(tau, prof_ref, double_time / stance_time)
    tau_landmarks = [lm_ref[k] for k in ("tau_peak1", "tau_trough", "tau_peak2")]
    ph = step_phase_times(double_time, step_time)
    h_ref_step = np.mean([height(np.interp(ph, [0.0, double_time, step_time], [a, b, c]))
                          for a, b, c in zip(t_td, t_lo, t_nx)], axis=0) / l0

    # Two starts: the least-squares control, and a plain spring leg (Geyer's K ≈ 20, l_d = l0) in case
    # the force of the clip does not determine the control well; each without and with the two control
    # pulses (push-off just past the other foot's touchdown, weight acceptance at the clip's first peak).
    # Each start's periodic cycle is found (cheap), and the shape fit (the expensive part) runs from the
    # two whose shape residual there is the smallest (``_shape_fit_nearest``).
    pulses_on = (PULSE_START["p"], step_time / stance_time + PULSE_START["dtau_p"], PULSE_START["w_p"],
                 PULSE_START["q"], lm_ref["tau_peak1"], PULSE_START["w_q"])
    errors: list[str] = []
    pulses_off = tuple(PULSES_OFF[k] for k in PULSE_VARS)
    best, plain_reason = None, None
    def problem(z1, free, n_shape):  # the shape fit's problem from the periodic cycle z1
        return _shape_problem(z1, T_c, roll, targets, tau, prof_ref, h_ref_step, dt, T, tau_landmarks, free,
                              n_per_stance=n_shape)

    def refine(z2, n_shape):  # the weight-acceptance pulse placed where the landmarks miss
        return _refine_pulse_centre(z2, lambda z1, free: problem(z1, free, n_shape), lambda z: cycle_landmark_timing(
            z, T_c, roll, tau, dt, T, lm_ref, (stance_time, step_time), n_shape))

    for n_shape, held in _start_passes(n_per_stance):
        if held:
            # A refusal gives the plain passes' last reason: the held trough is a last resort, and its own
            # failure (a residual) says less about the clip and moves with the last bits of the input.
            plain_reason = errors[-1] if errors else None
        candidates = []
        for ctl0 in starts:
            for pulses, free in ((pulses_off, ()), (pulses_on, ("p", "q"))):
                z0 = np.array([u0, v0, d0, step_time / T, th0, *ctl0, 1.0, 0.0, *pulses])
                try:
                    z1, _, it1, _ = _cycle_search(z0, T_c, roll, targets, n_shape, tol=START_TOL, hold_trough=held)
                except FitError as e:
                    errors.append(str(e))
                    continue
                candidates.append((problem(z1, free, n_shape), it1, z0))
        best = _shape_fit_nearest(candidates, T_c, roll, targets, n_per_stance, errors,
                                  partial(refine, n_shape=n_shape))
        if best is not None:
            break
    if best is None:  # what the clip is (the gait's decision, as info says it), then why it is refused
        figures = _walk_figures(step_time, double_time, mean_speed, lm_ref)
        raise FitError(f"{src}: {summary.kind} that the walking machine cannot follow: "
                       f"{_refusal(plain_reason or errors[-1])} ({figures})")
    z, cost, w, iters, z0 = best
    state = WalkState(*map(float, z[:4]))
    th, ctl = float(z[4]), _control(z, T_c)
    l_td = float(z[9])
    nx = w.next
    periodicity = float(max(abs(nx.u - state.u), abs(nx.v - state.v), abs(nx.d - state.d), abs(nx.s - state.s)))
    rec = record_step(state, th, ctl, roll=roll, l_td=l_td, n_per_stance=n_per_stance)
    prof_model = stance_force_profile(rec, tau, frame_time=dt, time_unit=T)
    prof_raw = stance_force_profile(rec, tau)
    lm_mod = force_landmarks(tau, prof_model, w.t_double / w.t_stance)
    lm_raw = force_landmarks(tau, prof_raw, w.t_double / w.t_stance)

    # COM height over every complete step, phase-matched (double support → double support, single →
    # single).
    t_parts: list[np.ndarray] = []
    h_parts: list[np.ndarray] = []
    m_parts: list[np.ndarray] = []
    for a, b, c in zip(t_td, t_lo, t_nx):
        tt = times[(times >= a) & (times <= c)]
        tm = np.interp(tt, [a, b, c], [0.0, w.t_double, w.t_step])
        trj = rec.sample(tm)
        t_parts.append(tt)
        h_parts.append(height(tt))
        m_parts.append(trj.pos[:, 1] * l0)
    t_ref, h_ref, h_mod = (np.concatenate(p) for p in (t_parts, h_parts, m_parts))
    com_rms = float(np.sqrt(np.mean((h_mod - h_ref) ** 2)))

    timing = landmark_timing(lm_mod, w.t_stance * T, lm_ref, stance_time, step_time)
    reference = {"stance_time_s": stance_time, "double_support_s": double_time, "step_time_s": step_time,
                 "mean_speed_m_s": mean_speed, "theta0_rad": th0, "roll_m": roll * l0, "n_steps": len(steps),
                 "steps_s": [[float(a), float(b), float(c)] for a, b, c in zip(t_td, t_lo, t_nx)],
                 "force_bw": lm_ref, "frame_time_s": dt,
                 "filter": {"kind": "butterworth forward-backward, quadratic edge extension", "cutoff_hz": cutoff_hz}}
    quality = {
        "com_rms_m": com_rms,
        "stance_time_error": w.t_stance * T / stance_time - 1.0,
        "double_support_error": w.t_double * T / double_time - 1.0,
        "step_time_error": w.t_step * T / step_time - 1.0,
        "mean_speed_error": w.step_length / w.t_step * V / mean_speed - 1.0,
        "force_bw": lm_mod, "force_unfiltered_bw": lm_raw,
        "peak1_error_bw": lm_mod["peak1"] - lm_ref["peak1"], "trough_error_bw": lm_mod["trough"] - lm_ref["trough"],
        "peak2_error_bw": lm_mod["peak2"] - lm_ref["peak2"],
        "peak1_timing_error_step": float(timing[0]), "trough_timing_error_step": float(timing[1]),
        "peak2_timing_error_step": float(timing[2]),
        "force_profile_rms_bw": float(np.sqrt(np.mean((prof_model - prof_ref) ** 2))),
    }
    fit = {"K": K0, "a": a0, "b": b0, "c": c0, "r2_vertical": r2, "rms_bw": rms, "note": fit_note,
           "prior": dict(zip(_VARS, map(float, z0))), "shape_cost": float(cost),
           "pulses_start": dict(zip(PULSE_VARS, map(float, z0[11:])))}
    machine = WalkingMachine(
        u=state.u, v=state.v, d=state.d, s=state.s, theta0=th, l_td=l_td, roll=roll, K=ctl.K, a=ctl.a, b=ctl.b,
        c=ctl.c, e=ctl.e, **{k: getattr(ctl, k) for k in PULSE_VARS}, T_c=T_c,
        t_stance=w.t_stance, t_double=w.t_double, t_step=w.t_step, step_length=w.step_length,
        mean_speed=w.step_length / w.t_step, periodicity=periodicity, iterations=iters, mass=mass, l0=l0,
        g=GRAVITY, source=src, heading=heading, lateral=lateral, up=np.eye(3)[UP_AXIS], ground=float(gait.ground),
        reference=reference, quality=quality, fit=fit)
    # The clip's leg length over its first complete stance (COM → rolling centre of pressure).
    sg = full[0]
    t_leg = times[(times >= sg.t_touchdown) & (times <= sg.t_liftoff)]
    l_leg = np.hypot(np.interp(t_leg, times, x_fwd) - sg.contact_x(t_leg), height(t_leg))
    return WalkFitResult(machine=machine, profile_tau=tau, profile_ref=prof_ref, profile_model=prof_model,
                         profile_unfiltered=prof_raw, t_ref=t_ref, h_ref=h_ref, h_model=h_mod, stances=tuple(geo),
                         t_leg=t_leg - sg.t_touchdown, l_leg=l_leg, steps=np.array([t_td, t_lo, t_nx]).T)
