"""Constrained Gauss-Newton: the solver of the walking machine's shape fit (:mod:`froude.machine.walk_fit`).

min ½‖r(y)‖² + ½ w²‖y‖² subject to c(y) = 0, for a model whose residuals r and constraints c come from a
simulation (no analytic derivatives; some y give no valid model). Its own module so the walking fit stays
a fit (the clip's measurements and the machine's) and the solver can be tested on its own. Why it runs to
a step test and not to an evaluation budget: docs/walking.md, "Convergence" (issue 26).
"""
from __future__ import annotations

import math

import numpy as np

from ..errors import FitError

__all__ = ["constrained_gauss_newton", "still_converging", "STEP_TOL", "LOCAL_STEP", "MAX_ITERATIONS",
           "MAX_ITERATIONS_CONVERGING", "CONTRACTION_WINDOW", "FD_STEP", "MERIT_PENALTY"]

#: The shape fit's convergence test: the largest component of a full Gauss-Newton step [CYCLE_SCALES units],
#: its iteration budget, its finite-difference step [CYCLE_SCALES units] and the merit's weight of the
#: constraints' violation (``constrained_gauss_newton``).
STEP_TOL = 1e-4
LOCAL_STEP = 0.05
MAX_ITERATIONS = 50
FD_STEP = 1e-4
MERIT_PENALTY = 1e3
#: Past MAX_ITERATIONS a fit goes on while it is still converging (``still_converging``: its last
#: CONTRACTION_WINDOW full steps each shorter than the one before, at a rate that reaches STEP_TOL within
#: MAX_ITERATIONS_CONVERGING), so the end of a slow but converging fit does not hang
#: on whether its last steps fall just before or just after the budget (issue 26). Measured (28 Nov): the
#: Bandai walk_active_002's fit at 240 steps per stance contracts by 0.66 a step from iteration 45 and
#: converges at 65; 02_01's nearest start cycles (steps 0.03 → 5 → 20 → … → 0.03) and is stopped at 50.
MAX_ITERATIONS_CONVERGING = 150
CONTRACTION_WINDOW = 8


def constrained_gauss_newton(evaluate, n, w_prior, *, start=None, what="the shape fit", step_tol=STEP_TOL,
                             max_iter=MAX_ITERATIONS, fd_step=FD_STEP):
    """min ½‖r(y)‖² + ½ w_prior²‖y‖² subject to c(y) = 0 from y = 0, by Gauss-Newton (the walking shape fit).

    evaluate(y (n,)) → (r (R,), c (C,)), or None where the model is invalid; start: evaluate(0) when the
    caller has it already; what: the fit's name in the FitError messages. Each iteration linearises r and
    c by forward differences of fd_step (in y's units, the scaled variables, so one step fits all), takes
    the constraints' Newton step of least norm and, in their null space, the Gauss-Newton step of the
    cost. Far from the minimum a step must lower the merit ½‖r‖² + ½ w²‖y‖² + MERIT_PENALTY ‖c‖₁, first as
    it is, then with a second-order correction onto the constraints (which curve: a long step violates
    them by O(step²), the Maratos effect), else it is halved (up to 12 times; the largest such λ is
    searched from the last iteration's, ``_descent_step``). A step shorter than LOCAL_STEP is taken whole:
    there Gauss-Newton contracts, and a merit test would compare costs
    that differ in their last bits (where the old trust-region fit stopped). Converged when the full
    step's largest component is below step_tol: the end point is then the constrained minimum to that
    tolerance, whatever path led there.
    A fit still converging at max_iter (``still_converging``) goes on, up to MAX_ITERATIONS_CONVERGING.
    Returns (y (n,), cost ½‖r‖² + ½ w²‖y‖² at y). Raises FitError when no valid descent is found or it does
    not converge (a non-converged end point is never returned: it is not a minimum, and where it lies
    follows the last bits).
    """
    y = np.zeros(n)
    out = evaluate(y) if start is None else start
    if out is None:
        raise FitError(f"{what} starts from an invalid machine step")
    r, c = out

    def merit(y, r, c):
        return 0.5 * float(r @ r) + 0.5 * w_prior ** 2 * float(y @ y) + MERIT_PENALTY * float(np.abs(c).sum())

    full = math.inf
    lam = 1.0  # the line search's last step (its next search starts near it: ``_descent_step``)
    steps: list[float] = []
    cap = max(max_iter, MAX_ITERATIONS_CONVERGING)
    for it in range(cap):
        if it >= max_iter and not still_converging(steps, step_tol, cap - it):
            break
        Jr, Jc = _forward_differences(evaluate, y, r, c, fd_step, what)
        U, S, Vt = np.linalg.svd(Jc)
        rank = int(np.sum(S > S[0] * 1e-10))
        pinv_c = Vt[:rank].T @ (U[:, :rank].T / S[:rank, None])  # (n, C): least-norm solve of Jc dy = c
        dy_c = -pinv_c @ c
        N = Vt[rank:].T  # the constraints' null space
        A = np.vstack([Jr @ N, w_prior * N])
        b = -np.concatenate([r + Jr @ dy_c, w_prior * (y + dy_c)])
        dy = dy_c + N @ np.linalg.lstsq(A, b, rcond=None)[0]
        full = float(np.max(np.abs(dy)))
        steps.append(full)
        step = _descent_step(evaluate, merit, y, dy, merit(y, r, c), pinv_c, whole=full < LOCAL_STEP, lam_hint=lam)
        if step is None:
            raise FitError(f"{what} found no valid descent from its current point")
        y, (r, c), lam = step
        if full < step_tol:
            return y, 0.5 * float(r @ r) + 0.5 * w_prior ** 2 * float(y @ y)
    raise FitError(f"{what} did not converge in {len(steps)} iterations (last step {full:.2g} in "
                   "scaled units)")


def still_converging(steps, step_tol=STEP_TOL, remaining=MAX_ITERATIONS_CONVERGING - MAX_ITERATIONS,
                     window=CONTRACTION_WINDOW) -> bool:
    """Whether a fit whose full steps so far were ``steps`` (sizes, CYCLE_SCALES units) is converging.

    True when its last ``window`` steps each shrank and their mean contraction rate ρ (Gauss-Newton near a
    minimum contracts linearly) brings the last step below step_tol within ``remaining`` iterations
    (ρ^remaining × last < step_tol). A fit that cycles or stalls
    has a step that grows again within any window; a slow linear contraction (ρ near 1) is not counted.
    """
    if len(steps) < window or remaining <= 0:
        return False
    last = np.asarray(steps[-window:], float)
    if not (np.all(np.diff(last) < 0.0) and last[-1] > 0.0):
        return False
    rho = (last[-1] / last[0]) ** (1.0 / (window - 1))
    return bool(last[-1] * rho ** remaining < step_tol)


def _forward_differences(evaluate, y, r, c, h, what):
    """(∂r/∂y (R, n), ∂c/∂y (C, n)) at y by forward differences of h (backward where y + h is invalid)."""
    Jr = np.empty((r.size, y.size))
    Jc = np.empty((c.size, y.size))
    for j in range(y.size):
        for sign in (1.0, -1.0):
            yj = y.copy()
            yj[j] += sign * h
            out = evaluate(yj)
            if out is not None:
                Jr[:, j] = sign * (out[0] - r) / h
                Jc[:, j] = sign * (out[1] - c) / h
                break
        else:
            raise FitError(f"{what} reached the edge of the machine's valid steps")
    return Jr, Jc


#: Halvings of a step the line search tries (``_descent_step``): λ = 1, 1/2, … 2^-(HALVINGS − 1).
HALVINGS = 13


def _descent_step(evaluate, merit, y, dy, phi, pinv_c, whole, lam_hint=1.0):
    """(y, evaluate(y), λ) of the step from y along dy that ``constrained_gauss_newton`` takes, or None.

    The step is the largest λ = 2^-k (k < HALVINGS) whose point, or its second-order correction, lowers the
    merit below phi (``whole``: λ = 1 if its point is valid). lam_hint: the λ the previous iteration took; the
    search starts at twice it and goes down while rejected, else up while accepted (to 1), so where the
    accepted λ form an interval it takes the λ a search from 1 down takes, and a fit creeping at λ = 1/32
    far from its minimum (the Bandai walk) pays 3 evaluations an iteration, not 11.
    """
    def accept(lam):
        y_new = y + lam * dy
        out = evaluate(y_new)
        if out is not None and (whole or merit(y_new, *out) <= phi):
            return y_new, out
        if out is not None:  # second-order correction: one chord step back onto the constraints
            y_soc = y_new - pinv_c @ out[1]
            out = evaluate(y_soc)
            if out is not None and merit(y_soc, *out) <= phi:
                return y_soc, out
        return None

    k = 0 if whole else max(0, min(HALVINGS - 1, round(-math.log2(lam_hint)) - 1))
    found = accept(0.5 ** k)
    if found is not None:
        while k > 0:  # up while accepted
            higher = accept(0.5 ** (k - 1))
            if higher is None:
                break
            k, found = k - 1, higher
        return (*found, 0.5 ** k)
    for lower in range(k + 1, HALVINGS):  # down while rejected
        found = accept(0.5 ** lower)
        if found is not None:
            return (*found, 0.5 ** lower)
    return None
