"""The walking machine's periodic cycle search: the cycle variables, their scales, and the minimum-norm
Newton search for the periodic cycle that matches measured targets (``machine.orbit.solve_orbit``), used by
the walking fit (:mod:`froude.machine.walk_fit`) and the speed re-solve (:mod:`froude.machine.walk_speed`).

z = (u, v, d, s, θ0, K, a, b, c, l_td, e) and the control's two pulses (six more, held unless freed) must
make the step map periodic (4 equations) and reproduce the target step time, double-support time and mean
speed (3), and with ``hold_trough`` one more: the machine's lowest vertical force in single support equal to
``body.gait.FLIGHT_FORCE_BW`` (0.2 body weights, the force below which froude reads a body as in flight). For
a brisk walk whose vault unloads the stance leg near the clip's cycle, that keeps Newton's iterates on walking
steps; the fit and the speed re-solve take it only where the plain search fails.
"""
from __future__ import annotations

import numpy as np

from ..body.gait import FLIGHT_FORCE_BW
from ..errors import FitError
from .orbit import rowwise, solve_orbit
from .walking import PULSES_OFF, REASONS, WalkControl, WalkState, record_step, single_support_trough, walk_step

__all__ = ["CYCLE_SCALES", "PULSE_VARS", "START_SPEED_FACTORS"]

_VARS = ("u", "v", "d", "s", "theta0", "K", "a", "b", "c", "l_td", "e", "p", "tau_p", "w_p", "q", "tau_q", "w_q")
#: The two control pulses' variables (``WalkControl``): held in the cycle search; the shape fit fits
#: their amplitudes p and q.
PULSE_VARS = tuple(PULSES_OFF)
#: Scales of the cycle variables for the minimum-norm search (K relative to its prior); a pulse variable
#: is free only where a search frees it (:func:`_scales`).
CYCLE_SCALES = {"u": 0.05, "v": 0.02, "d": 0.02, "s": 0.05, "theta0": 0.03, "K": 0.1, "a": 0.01, "b": 0.02,
                "c": 0.02, "l_td": 0.01, "e": 0.02, "p": 0.01, "tau_p": 0.02, "w_p": 0.01, "q": 0.01, "tau_q": 0.02,
                "w_q": 0.01}


def _scales(z0, free=()):
    """(17,) scales of the cycle variables z0 (``_VARS``): CYCLE_SCALES, K's relative to its value, the
    pulse variables 0 (held) unless named in ``free``."""
    s = np.array([CYCLE_SCALES[v] if (v not in PULSE_VARS or v in free) else 0.0 for v in _VARS])
    s[5] *= abs(z0[5])
    return s


#: Residual [max-norm] to which a search holding the trough may end when it stalls above its tolerance: the
#: held trough is a sampled minimum refined by a parabola, smooth only between the samples it moves across, and
#: Newton stalls near 1e-7 there (walk_active_002 at x1.25: 3e-7, 0.3 µm of periodicity per metre of leg).
TROUGH_HELD_ACCEPT = 1e-6
#: Touchdown speeds (× the measured) the cycle search starts from when the measured touchdown state gives no
#: valid machine step.
START_SPEED_FACTORS = (0.95, 0.9, 0.85, 0.8, 0.7)


def _cycle_search(z0, T_c, roll, targets, n_per_stance, tol=1e-10, max_iter=40 * 32, hold_trough=False):
    """The periodic walking cycle matching targets nearest the priors (``machine.orbit.solve_orbit``, see
    the module doc): Newton with a fresh Jacobian every iteration at ``n_per_stance``, one candidate at a
    time (the walking step map has no batched path), a rejected step halved up to 30 times.

    z0: (11,) priors; T_c held; targets (t_stance, t_double, mean_speed) dimensionless. max_iter counts
    evaluations of the iterates and of their Jacobians (40 Newton iterations of a point, a Jacobian and
    up to 30 halvings). hold_trough: the single-support force trough is held too (see the module doc).
    Returns (z, WalkStep, simulator evaluations, residual max-norm).
    """
    s = _scales(z0)
    h = 1e-7 * np.maximum(np.abs(z0), 1.0)
    tgt = np.asarray(targets, float)

    def evaluate(z, n):
        args = (WalkState(*z[:4]), z[4], _control(z, T_c))
        # the trough needs the step's nodes: one recorded integration gives both the step and its force
        rec = record_step(*args, roll=roll, l_td=z[9], n_per_stance=n) if hold_trough else None
        w = rec.step if rec is not None else walk_step(*args, roll=roll, l_td=z[9], n_per_stance=n)
        if not w.valid:
            return None, w
        nx = w.next
        assert nx is not None  # a valid step has its next state
        rows = [nx.u - z[0], nx.v - z[1], nx.d - z[2], nx.s - z[3],
                (w.t_step - tgt[0]) / tgt[0], (w.t_double - tgt[1]) / tgt[1],
                (w.step_length / w.t_step - tgt[2]) / tgt[2]]
        if rec is not None:
            rows.append(single_support_trough(rec) - FLIGHT_FORCE_BW)
        return np.array(rows), w

    z0 = _valid_start(z0, T_c, roll, n_per_stance)
    # Holding the trough the search may end at TROUGH_HELD_ACCEPT; both resolutions are one here, so the switch
    # only starts the record of the best point that ``accept`` reads.
    ends = {"accept": TROUGH_HELD_ACCEPT, "switch": TROUGH_HELD_ACCEPT} if hold_trough else {}
    z, rows, calls, R = solve_orbit(rowwise(evaluate, 8 if hold_trough else 7), z0, s, h, tol=tol, max_iter=max_iter,
                                    resolutions=(n_per_stance, n_per_stance), chord=False, batched=False,
                                    max_halvings=30, what="walking cycle", reasons=REASONS, **ends)
    return z, rows.items[0], calls, float(np.max(np.abs(R)))


def _valid_start(z0, T_c, roll, n_per_stance):
    """z0 (17,), or z0 at a slower touchdown speed (``START_SPEED_FACTORS``), where the machine takes a valid
    step; FitError with the first reason when none does."""
    def step(z):
        return walk_step(WalkState(*z[:4]), z[4], _control(z, T_c), roll=roll, l_td=z[9], n_per_stance=n_per_stance)

    w0 = step(z0)
    if w0.valid:
        return z0
    for slower in START_SPEED_FACTORS:
        # A brisk walk's measured touchdown state can vault the machine off its stance leg (the clip's
        # own force nearly unloads in single support): start slower; the fit restores the speed.
        z_try = z0.copy()
        z_try[0] *= slower
        if step(z_try).valid:
            return z_try
    raise FitError(f"the walking machine has no valid step at the clip's measured step: {REASONS[w0.reason]}")


def _control(z, T_c) -> WalkControl:
    """The leg control of the cycle variables z (``_VARS``) with T_c [√(l0/g)]."""
    return WalkControl(T_c=T_c, **{k: float(v) for k, v in zip(_VARS, z) if k in WalkControl.NAMES})
