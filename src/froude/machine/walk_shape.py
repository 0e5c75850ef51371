"""The walking fit's shape fit (:mod:`froude.machine.walk_fit`): the machine's force and COM height against the clip's.

    periodic starts → least squares of the stance force profile (through the clip's filter) and COM height,
    on periodic cycles (``_shape_problem``, solved by :mod:`froude.machine.gauss_newton`) → the nearest
    starts' fits and the choice between them (``_shape_fit_nearest``, ``choose_fit``) → where the chosen
    fit's force landmarks miss the acceptance's tolerance, the weight-acceptance pulse's centre fitted too
    (``_refine_pulse_centre``)

Its own module so the fit (walk_fit: the clip's measurements, the starts, the result) reads apart from
what is fitted and how the end is chosen. docs/walking.md, "The fit".
"""
from __future__ import annotations

import math

import numpy as np

from ..body.com_force import acceleration_response, force_landmarks
from ..errors import FitError
from .forces import CUTOFF_HZ
from .gauss_newton import constrained_gauss_newton
from .walk_cycle import _control, _cycle_search, _scales
from .walking import WalkState, record_step

__all__ = ["stance_force_profile", "step_phase_times", "landmark_timing", "cycle_landmark_timing", "choose_fit",
           "LANDMARK_TIMING_TOL", "REFINEMENTS", "SHAPE_WEIGHTS", "SHAPE_N_PER_STANCE"]


#: The walking acceptance's tolerance (issue 17) on the timing of the machine's force landmarks against the
#: clip's [fraction of the clip's step]: a shape fit further off is refined (``_refine_pulse_centre``).
LANDMARK_TIMING_TOL = 0.05


#: The refinements tried, in order, on a shape fit whose landmarks miss LANDMARK_TIMING_TOL: the pulse
#: variables freed besides the cycle's, warm from the fit's end. The weight-acceptance pulse is centred at the
#: clip's first force peak, but the machine's peak follows its pulse (the spring leg answers an extension with a
#: lag): freed, the centre lies 0.03-0.07 of a stance before the clip's peak on 11 of 15 Bandai walks. The
#: centre with its amplitude first, then with the push-off's amplitude too. The push-off pulse's centre stays
#: held: freed, the fit mostly cycles without converging (its forward-difference Jacobians at steps of 1e-6,
#: 1e-4 and 1e-3 disagree: the cost has kinks there). docs/walking.md, "The weight-acceptance pulse placed".
REFINEMENTS = (("q", "tau_q"), ("p", "q", "tau_q"))


def stance_force_profile(rec, tau, *, frame_time=None, cutoff_hz=CUTOFF_HZ, time_unit=1.0):
    """Total vertical force [m g] of the periodic machine over one leg's stance at phases tau (N,).

    rec: the RecordedStep (:func:`froude.machine.walking.record_step`) of the periodic cycle. The leg
    lands at the start of a step and lifts off t_stance later; the total force of both legs repeats every
    step, so the stance profile is the step's force at (τ t_stance) mod t_step. With ``frame_time`` [s]
    (and ``time_unit`` √(l0/g) [s]) the force is *measured like the clip's*: the machine's COM height, a
    periodic signal, goes through the clip's zero-lag filter and double differentiation (eq. 1,
    :func:`froude.machine.forces.smooth_com`) as their frequency response
    (:func:`froude.body.com_force.acceleration_response`) on its harmonics up to the clip's Nyquist
    frequency, so both forces are seen through the same instrument. In the frequency domain the result is
    smooth in the machine's parameters; sampling it at the frame rate and interpolating (as before) put
    kinks into the shape fit's residual wherever a sample crossed a phase, and its minimum sat on them.
    """
    w = rec.step
    t_m = (np.asarray(tau, float) * w.t_stance) % w.t_step
    if frame_time is None:
        return rec.sample(t_m).total_force[:, 1]
    n_fft = PROFILE_FFT_SAMPLES
    y = rec.positions(np.arange(n_fft) * (w.t_step / n_fft))[0][:, 1]  # COM height over one step [l0]
    coef = np.fft.rfft(y) / n_fft
    harmonic = np.arange(coef.size)
    freq_hz = harmonic / (w.t_step * time_unit)
    gain = np.where(freq_hz < 0.5 / frame_time, acceleration_response(freq_hz, frame_time, cutoff_hz), 0.0)
    gain[1:] *= 2.0  # the negative frequencies' half (no harmonic at the Nyquist index survives: see above)
    # The sum over harmonics is elementwise on purpose: as a (N, H) complex matrix product it went to a
    # multithreaded BLAS, whose start-up cost 20 times the sum itself on a loaded machine.
    # Only the harmonics below the clip's Nyquist frequency count (gain 0 above: 8 of 129 at 30 Hz frames).
    kept = gain != 0.0
    phase = np.exp(2j * np.pi * np.outer(t_m / w.t_step, harmonic[kept]))
    acc = np.einsum("ij,j->i", phase, (gain * coef)[kept]).real  # [l0 / s²]
    return 1.0 + acc * time_unit ** 2  # l0 = g T²: the acceleration in g


#: Samples of one machine step for the harmonics of its COM height (``stance_force_profile``): harmonics up
#: to 64 of the step frequency (about 120 Hz), above every clip's Nyquist frequency up to 240 Hz frames.
PROFILE_FFT_SAMPLES = 256


#: Weights of the shape fit: periodicity and measured times are (nearly) hard, the force profile soft.
SHAPE_WEIGHTS = {"periodic": 100.0, "targets": 30.0, "prior": 0.05, "com": 10.0}


#: Extra weight of the force residual around each of the clip's landmarks (two peaks, trough), a Gaussian
#: of LANDMARK_WIDTH in stance phase: 1 + 6 at a landmark. Without it the CMU clips' W-shaped single
#: support pulled the machine's trough to its mean (02_01: +0.14 BW, +10.5 % of a step late); 3-10 and
#: widths 0.04-0.06 all put 02_01 and the Bandai walk within the acceptance, 6 and 0.06 with most margin.
LANDMARK_WEIGHT = 6.0


LANDMARK_WIDTH = 0.06


#: Least clearance of the landing leg in single support [l0] that the shape fit keeps, and the weight of a
#: shortfall (``_clearance_shortfall``). The machine's landing leg, held at θ0 with length l_td, touches the
#: ground when the COM falls to l_td cos θ0; a COM that dips towards that height in late single support and
#: rises again (the W-shaped single support of the CMU walks) has a second, earlier touchdown within reach:
#: at the graze the step map jumps (02_01's step time by 14 %), and a shape fit that ends 0.0004 l0 above it
#: (0.4 mm) left the exact cycle search's success to the BLAS kernel (issue 26). 1 % of l0 (about 9 mm, below
#: a walker's least toe clearance of 1-2 cm) is 25 times that and 20-100 times how far the fit's end point
#: moves between kernels.
MIN_CLEARANCE = 0.01


CLEARANCE_WEIGHT = 100.0


#: Simulator resolution of the shape fit (the exact cycle is found after it at N_PER_STANCE).
#: The starts' cycle searches and shape fits run at SHAPE_N_PER_STANCE, a speed choice (half the
#: simulator's work); where every start fails there (a cycle whose leg nearly unloads in single support, or a
#: pulse of 0.04 of a stance over 5 steps, is resolved only finer) they run again at the exact cycle's own
#: resolution (``fit_walking_detailed``'s n_per_stance, N_PER_STANCE). A reason of resolution, not of a clip:
#: the Bandai walk_active_002 (a brisk walk, 1.43 m/s) found no start at 120 and fits at 240 (docs/walking.md).
SHAPE_N_PER_STANCE = 120


#: Samples of the step-phase COM height profile (double support, then single support).
COM_SAMPLES = (8, 24)


def step_phase_times(t_double, t_step):
    """(N,) times of the step-phase grid: COM_SAMPLES[0] in double support, COM_SAMPLES[1] in single."""
    n1, n2 = COM_SAMPLES
    return np.concatenate([np.linspace(0.0, t_double, n1, endpoint=False), np.linspace(t_double, t_step, n2)])


def _clearance_shortfall(rec, theta0: float, l_td: float, n_samples: int = 200) -> float:
    """max(0, MIN_CLEARANCE − c) / MIN_CLEARANCE [-] of one machine step (``record_step``'s RecordedStep).

    c [l0]: the lowest dip of the COM below which the step would end early, the least height above the
    landing height l_td cos θ0 at which the COM, in single support and past the stance foot, stops
    descending and rises again (the landing leg's least clearance before its touchdown); no such dip: 0.
    """
    w = rec.step
    t = np.linspace(w.t_double, w.t_step, n_samples)
    pos, vel = rec.positions(t)
    past = pos[:-1, 0] > l_td * math.sin(theta0)
    turn = past & (vel[:-1, 1] < 0.0) & (vel[1:, 1] >= 0.0)  # a local minimum of the COM height
    if not turn.any():
        return 0.0
    c = float(np.min(pos[:-1, 1][turn])) - l_td * math.cos(theta0)
    return max(0.0, MIN_CLEARANCE - c) / MIN_CLEARANCE


def landmark_timing(lm_model: dict, t_stance_model_s: float, lm_ref: dict, stance_s: float,
                    step_s: float) -> np.ndarray:
    """(3,) timing errors [fraction of the clip's step] of the machine's force landmarks (``force_landmarks``
    over its stance of t_stance_model_s [s]) against the clip's (over its mean stance stance_s [s]; step_s its
    mean step [s]): peak 1, trough, peak 2, each as a time since the touchdown."""
    return np.array([(lm_model[k] * t_stance_model_s - lm_ref[k] * stance_s) / step_s
                     for k in ("tau_peak1", "tau_trough", "tau_peak2")])


def cycle_landmark_timing(z, T_c, roll, tau, frame_time, time_unit, lm_ref, clip_times, n_per_stance) -> float:
    """The largest |landmark timing error| [fraction of the clip's step] of the cycle z (17,) (``landmark_timing``;
    clip_times: the clip's (stance, step) [s]; the other arguments as ``_shape_problem``'s)."""
    rec = record_step(WalkState(*z[:4]), z[4], _control(z, T_c), roll=roll, l_td=z[9], n_per_stance=n_per_stance)
    w = rec.step
    lm = force_landmarks(tau, stance_force_profile(rec, tau, frame_time=frame_time, time_unit=time_unit),
                         w.t_double / w.t_stance)
    return float(np.max(np.abs(landmark_timing(lm, w.t_stance * time_unit, lm_ref, *clip_times))))


def _refine_pulse_centre(z2, problem, worst) -> np.ndarray:
    """The shape fit's end z2 (17,), or a refinement of it whose force landmarks are nearer the clip's.

    Where z2's pulses are on and its landmarks miss LANDMARK_TIMING_TOL (worst(z): the largest |timing error|
    of cycle z, ``cycle_landmark_timing``), the shape fit runs again from z2 with each of REFINEMENTS' pulse
    variables free, in order, until one ends inside the tolerance (problem(z1, free): ``_shape_problem`` from
    z1 with those free); the end whose worst error is the smallest is kept (by more than 0.1 % of a step: not
    on the last bits). A refinement that does not converge is passed over.
    """
    if z2[11] == 0.0 and z2[14] == 0.0:  # no pulses: nothing to place
        return z2
    best, err = z2, worst(z2)
    for free in REFINEMENTS:
        if err <= LANDMARK_TIMING_TOL:
            break
        evaluate, to_z, n = problem(z2, free)
        try:
            y, _ = constrained_gauss_newton(evaluate, n, SHAPE_WEIGHTS["prior"], what="the walking shape fit")
        except FitError:
            continue
        z3 = to_z(y)
        e3 = worst(z3)
        if e3 < err - 1e-3:
            best, err = z3, e3
    return best


def _shape_problem(z1, T_c, roll, targets, tau, prof_ref, h_ref, frame_time, time_unit, tau_landmarks, free=(),
                   n_per_stance=SHAPE_N_PER_STANCE):
    """The shape fit's problem from the periodic cycle z1 (17,): (evaluate, to_z, n) for
    ``gauss_newton.constrained_gauss_newton``: to_z(y) the cycle variables (17,) of the n scaled free ones y.

    The fit is the least squares of the machine's stance force profile against the clip's, on the periodic
    cycles.

    Minimises ½‖r‖² + ½ w²‖y‖² subject to c = 0, y = (z − z1)/s the free variables in CYCLE_SCALES units:
    r the vertical force over a stance at tau [BW], weighted up around the clip's landmarks at phases
    tau_landmarks (``LANDMARK_WEIGHT``), the COM height over a step and the landing leg's clearance
    shortfall (``_clearance_shortfall``, so that the exact cycle found after it is not at a graze); c the
    periodicity and the relative errors of step time, double-support time and speed (7 equations, exact);
    w = SHAPE_WEIGHTS["prior"] the pull to the periodic start z1. Solved by constrained Gauss-Newton
    (:func:`froude.machine.gauss_newton.constrained_gauss_newton`) to a step below its ``STEP_TOL``: the end
    point is the minimum, not where a budget ran out, so it does not follow the last bits of the clip
    (issue 26); the exact cycle is found from it after at full resolution.
    """
    s_all = _scales(z1, free)
    fr = s_all > 0
    s = s_all[fr]
    tgt = np.asarray(targets, float)
    wc = SHAPE_WEIGHTS["com"]
    wf = 1.0 + LANDMARK_WEIGHT * sum(np.exp(-0.5 * ((tau - tk) / LANDMARK_WIDTH) ** 2) for tk in tau_landmarks)

    def evaluate(y):
        z = to_z(y)
        rec = record_step(WalkState(*z[:4]), z[4], _control(z, T_c), roll=roll, l_td=z[9], n_per_stance=n_per_stance)
        w = rec.step
        if not w.valid:
            return None
        prof = stance_force_profile(rec, tau, frame_time=frame_time, time_unit=time_unit)
        h = rec.positions(step_phase_times(w.t_double, w.t_step))[0][:, 1]
        nx = w.next
        c = np.array([nx.u - z[0], nx.v - z[1], nx.d - z[2], nx.s - z[3], (w.t_step - tgt[0]) / tgt[0],
                      (w.t_double - tgt[1]) / tgt[1], (w.step_length / w.t_step - tgt[2]) / tgt[2]])
        graze = CLEARANCE_WEIGHT * _clearance_shortfall(rec, z[4], z[9])
        return np.concatenate([wf * (prof - prof_ref), wc * (h - h_ref), [graze]]), c

    def to_z(y):
        z = z1.copy()
        z[fr] = z1[fr] + s * y
        return z

    return evaluate, to_z, s.size


#: How many of the periodic starts, nearest the clip's shape first, the walking fit runs the shape fit from
#: (``_shape_fit_nearest``); further ones only while none has succeeded.
NEAREST_STARTS = 2


#: How much lower [relative] a farther start's converged shape cost must be than the nearest's to be chosen
#: (``choose_fit``). A converged cost is the minimum's to within ½ H STEP_TOL² (about 1e-8 of it; rounding
#: moves it by 1e-12): 1 % is a million times that, so the choice does not hang on the last bits, and far
#: below the differences between distinct minima seen (a Bandai turn: 0.162 against 0.205, 21 %).
COST_MARGIN = 0.01


def choose_fit(costs) -> list[int]:
    """The order in which the walking fit tries its shape fits' ends (the first whose exact cycle is found wins).

    costs: the shape costs of the fits in the order of their starts' nearness to the clip (nearest first),
    only converged fits (``constrained_gauss_newton`` returns no other). The nearest is chosen, and a farther
    one replaces the choice only where its cost is lower than the chosen one's by more than COST_MARGIN
    (relative), in order of nearness. Two starts that reach the same minimum (parameters within the solver's
    tolerance) have the same cost to 1e-8 and the nearest is kept; distinct minima are told apart only by a
    margin far above what rounding moves a cost. The rest follow by nearness (the fallbacks when an exact
    cycle search fails).
    """
    order = list(range(len(costs)))
    if not order:
        return order
    first = 0
    for k in order[1:]:
        if costs[k] < (1.0 - COST_MARGIN) * costs[first]:
            first = k
    return [first] + [k for k in order if k != first]


def _shape_fit_nearest(candidates, T_c, roll, targets, n_per_stance, errors, refine=None):
    """The shape fits from the NEAREST_STARTS candidate starts nearest the clip, then the exact periodic cycle
    from the end that ``choose_fit`` puts first.

    candidates: [((evaluate, to_z, n) of ``_shape_problem``, cycle-search evaluations, prior z0 (17,))], one per
    start. Every start is a periodic cycle meeting the same targets; Gauss-Newton goes downhill from where
    it starts, so the starts whose shape residual ½‖r‖² is the smallest are the ones nearest the clip's
    shape, and their fits run (the next ones only while none has succeeded: a fit or the exact cycle after
    it can fail; the reasons are appended to ``errors``); refine(z) → z: applied to the chosen end before its
    exact cycle (``_refine_pulse_centre``). Not only the nearest: the cost has several local
    minima, and the nearest start need not lead to the lowest (a Bandai turn, 27 Nov: start residuals 5.6
    and 16.7 ended at costs 0.205 and 0.162, and the output of the first missed the skate bar where the
    second's met it). A fit that does not converge is discarded (its end is not a minimum). Returns (z (17,),
    shape cost, WalkStep, evaluations, z0) or None.
    """
    ranked: list[tuple] = []
    for (evaluate, to_z, n), it1, z0 in candidates:
        start = evaluate(np.zeros(n))
        if start is None:
            errors.append("the walking shape fit starts from an invalid machine step")
            continue
        ranked.append((0.5 * float(start[0] @ start[0]), len(ranked), evaluate, to_z, n, start, it1, z0))
    fits: list[tuple] = []
    for k, (_, _, evaluate, to_z, n, start, it1, z0) in enumerate(sorted(ranked, key=lambda c: c[:2])):
        if fits and k >= NEAREST_STARTS:
            break
        try:
            y, cost = constrained_gauss_newton(evaluate, n, SHAPE_WEIGHTS["prior"], start=start,
                                               what="the walking shape fit")
        except FitError as e:
            errors.append(str(e))
            continue
        fits.append((cost, to_z(y), it1, z0))
    for i in choose_fit([f[0] for f in fits]):
        cost, z2, it1, z0 = fits[i]
        if refine is not None:
            z2 = refine(z2)
        try:
            z, w, it2, _ = _cycle_search(z2, T_c, roll, targets, n_per_stance)
        except FitError as e:
            errors.append(str(e))
            continue
        return z, cost, w, it1 + it2, z0
    return None
