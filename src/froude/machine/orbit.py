"""The one orbit solver of the machines, and the one record of a periodic running cycle.

A periodic running cycle is a fixed point of the step map: apex (U, H) → next apex (U', H') with the
residual r(z) = (U' − U, H' − H, extra rows) = 0 over some unknowns z (apex state, touchdown angle,
control, …). Such fixed points form a family; the one wanted is the one nearest the priors z0 in the
scaled norm ‖(z − z0)/s‖ (s: per-unknown scale; s = 0 holds an unknown at its prior). Each iteration
linearises r and jumps to the minimum-norm point of the linearised constraint set in scaled coordinates
y = (z − z0)/s (pseudo-inverse, so a rank-deficient Jacobian — the passive spring-mass runner, whose
energy conservation ties U' − U to H' − H — is fine):

    y⁺ = argmin ‖y‖  s.t.  J_y y = J_y y_k − r_k,    J_y = J diag(s)

Used by the running fit (§4: the cycle matching the measured timing), the speed re-solve (§5.2), the
planner's target orbits (§5.3, inside the comfort box) and ``find_limit_cycle``; by the walking fit and
its speed re-solve (one candidate at a time through :func:`rowwise`); and by the planner's one-step
solves (inputs of one step that hit a reference apex: the same Newton on a square system, whose
minimum-norm step is the plain Newton step). Dimensionless throughout (``machine.units``).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import FitError
from .dynamics import N_PER_STANCE, REASONS, Control, step

__all__ = ["LimitCycle", "solve_orbit", "cycle_record", "step_jacobian", "step_map_eigenvalues"]


@dataclass(frozen=True)
class LimitCycle:
    """A periodic running cycle of the machine (dimensionless; see froude.machine.dynamics).

    U, H:       periodic apex state [√(g l0)], [l0]
    theta0:     touchdown angle [rad]
    control:    adjusted :class:`Control`
    t_stance, t_fall, t_rise: phase durations [√(l0/g)]; t_flight = t_rise + t_fall
    step_length: contact-to-contact distance [l0] (= apex_dx for a periodic step)
    step_time:  apex-to-apex time [√(l0/g)]
    peak_force: [m g]
    iterations: solver iterations used
    residual:   max(|U' − U|, |H' − H|) at the solution
    prior:      dict name → prior value
    moved:      dict name → final − prior
    moved_scaled: dict name → (final − prior)/scale (0 for held variables)
    eigenvalues: (2,) complex eigenvalues of ∂(U', H')/∂(U, H) at fixed θ0 and control
    """

    U: float
    H: float
    theta0: float
    control: Control
    t_stance: float
    t_fall: float
    t_rise: float
    t_flight: float
    step_length: float
    step_time: float
    peak_force: float
    iterations: int
    residual: float
    prior: dict = field(default_factory=dict)
    moved: dict = field(default_factory=dict)
    moved_scaled: dict = field(default_factory=dict)
    eigenvalues: np.ndarray = field(default_factory=lambda: np.zeros(2, complex))

    def as_vector(self):
        """(8,) array (U, H, θ0, K, a, b, c, T_c)."""
        return np.array([self.U, self.H, self.theta0, *map(float, self.control.as_tuple())])


def cycle_record(U, H, th, ctl, residual, iterations=0, eigenvalues=True, **extra) -> LimitCycle:
    """The LimitCycle of a periodic orbit (U, H, θ0, control): durations, step and peak force from one
    simulator step (the one source of truth), eigenvalues of the step map unless ``eigenvalues`` is False."""
    r = step(U, H, th, ctl)
    t_fall, t_rise, t_st = float(r.t_fall), float(r.t_rise), float(r.t_stance)
    eig = step_map_eigenvalues(U, H, th, ctl) if eigenvalues else np.full(2, np.nan + 0j)
    return LimitCycle(U=U, H=H, theta0=th, control=ctl, t_stance=t_st, t_fall=t_fall, t_rise=t_rise,
                      t_flight=t_fall + t_rise, step_length=float(r.apex_dx),
                      step_time=t_fall + t_st + t_rise, peak_force=float(r.peak_force),
                      iterations=iterations, residual=float(residual), eigenvalues=eig, **extra)


@dataclass(frozen=True)
class Rows:
    """Rows of a one-candidate-at-a-time evaluation (:func:`rowwise`): valid (m,) bool, reason (m,) int
    (``REASONS``-style codes of the evaluator), items: the evaluator's own record of each row."""

    valid: np.ndarray
    reason: np.ndarray
    items: tuple


def rowwise(evaluate_one, n_rows: int):
    """A batched ``evaluate`` for :func:`solve_orbit` from one that takes one candidate at a time.

    evaluate_one(z (d,), n) → (R (n_rows,), record with ``valid`` (bool) and ``reason`` (int)); R is
    ignored where the record is invalid. Returns evaluate(Z (m, d), n) → (R (m, n_rows), :class:`Rows`).
    For simulators without a batched path (the walking step map).
    """
    def evaluate(Z, n):
        R = np.full((len(Z), n_rows), np.nan)
        items = []
        for i, z in enumerate(Z):
            Ri, rec = evaluate_one(z, n)
            if rec.valid:
                R[i] = Ri
            items.append(rec)
        return R, Rows(valid=np.array([bool(w.valid) for w in items]),
                       reason=np.array([int(w.reason) for w in items]), items=tuple(items))
    return evaluate


def _fd_steps(z, h, free, hi):
    """(nf,) forward-difference steps of the free unknowns: +h, or −h where z + h would pass ``hi``."""
    return h[free] if hi is None else np.where(z[free] + h[free] <= hi[free], h[free], -h[free])


def _jacobian(evaluate, z, R0, given, free, h, hi, n, what, reasons):
    """Forward-difference Jacobian (r, nf) of the residual at z over the ``free`` unknowns, and the number
    of evaluate calls it took (0 when the perturbed rows came with z's: ``given`` = (R (nf, r), valid
    (nf,)); None evaluates them here).

    Each unknown steps by :func:`_fd_steps`; a perturbed row that is invalid (z sits at the edge of the
    feasible region) is taken again on the other side of z. Raises FitError when both sides are invalid."""
    hs = _fd_steps(z, h, free, hi)
    Z = np.repeat(z[None, :], free.size, axis=0)
    Z[np.arange(free.size), free] += hs
    calls = 0
    if given is None:
        RJ, rJ = evaluate(Z, n)
        given, calls = (RJ, rJ.valid), 1
    RJ, bad = given[0], ~np.asarray(given[1], bool)
    if bad.any():
        Z[bad, free[bad]] -= 2 * hs[bad]  # the other side of z
        hs = np.where(bad, -hs, hs)
        RB, rB = evaluate(Z[bad], n)
        calls += 1
        ok = np.asarray(rB.valid, bool)
        if not ok.all():
            raise FitError(f"no {what} found: the search left the feasible region "
                           f"({reasons[int(np.asarray(rB.reason)[~ok][0])]})")
        RJ = np.array(RJ, float)
        RJ[bad] = RB
    return ((RJ - R0) / hs[:, None]).T, calls


def _min_norm_point(Js, rhs, y_box):
    """The minimum-norm y (nf,) with Js y = rhs (least squares where it has no solution), inside the box
    y_box = (y_lo, y_hi) (nf,) each, or None.

    In the box: unknowns that would leave it are held at the bound they cross and the rest solve again
    (an active set that only grows: at most nf solves). Clipping the free point instead would step off
    the linearised constraint set, and Newton then stalls against the bound."""
    y, *_ = np.linalg.lstsq(Js, rhs, rcond=1e-12)
    if y_box is None:
        return y
    held = np.zeros(y.size, bool)
    for _ in range(y.size):
        out = ~held & ((y < y_box[0]) | (y > y_box[1]))
        if not out.any():
            break
        held |= out
        y = np.clip(y, *y_box)
        if held.all():
            break
        y_free, *_ = np.linalg.lstsq(Js[:, ~held], rhs - Js[:, held] @ y[held], rcond=1e-12)
        y[~held] = y_free
    return np.clip(y, *y_box)


def _damped_point(z_prev, R_prev, J, s, free, k, lo, hi):
    """z_prev moved by the Levenberg–Marquardt increment −(JᵀJ + μ I)⁻¹ Jᵀ R in the scaled coordinates, μ =
    10^(k−7) × the mean of diag(JᵀJ) (k: the rejections so far), clipped into the box."""
    Js = J * s[free][None, :]
    A = Js.T @ Js
    mu = 10.0 ** (k - 7) * (float(np.trace(A)) / A.shape[0] or 1.0)
    z = z_prev.copy()
    z[free] -= s[free] * np.linalg.solve(A + mu * np.eye(A.shape[0]), Js.T @ R_prev)
    return z if lo is None and hi is None else np.clip(z, lo, hi)


def _scaled_box(z0, s, free, lo, hi):
    """The box (lo, hi) in the scaled coordinates y = (z − z0)/s of the free unknowns: two (nf,) arrays (±inf
    where a side is None), or None without bounds. z0, s (d,); free (nf,) indices; lo, hi (d,) or None."""
    if lo is None and hi is None:
        return None
    return tuple((np.full(free.size, sign * np.inf) if b is None else (b[free] - z0[free]) / s[free])
                 for b, sign in ((lo, -1.0), (hi, 1.0)))


def _candidates(z, with_jac: bool, h, free, hi):
    """The candidates of one evaluate call, (1, d): z alone, or (nf + 1, d): z and its forward-difference
    points (one free unknown each, steps by :func:`_fd_steps`)."""
    Z = np.repeat(z[None, :], free.size + 1 if with_jac else 1, axis=0)
    if with_jac:
        Z[1 + np.arange(free.size), free] += _fd_steps(z, h, free, hi)
    return Z


def _newton_point(z, z0, s, free, J, R0, y_box, lo, hi):
    """The next iterate (d,): the minimum-norm Newton point of the linearised residual R0 + J Δz (within the
    scaled box y_box), in the scaled coordinates y = (z − z0)/s of the free unknowns; J (r, nf)."""
    Js = J * s[free][None, :]
    y = (z[free] - z0[free]) / s[free]
    y_new = _min_norm_point(Js, Js @ y - R0, y_box)
    z = z.copy()
    z[free] = z0[free] + s[free] * y_new
    if y_box is not None:
        z = np.clip(z, lo, hi)  # (the point is in the box; this only removes rounding)
    return z


def _best_or_raise(best, accept, stalled: bool, nrm: float, nrm_prev: float, max_iter: int, what: str):
    """The best fine-resolution point (residual, z, rows, R) when the search ended above its tolerance but
    within ``accept``; else FitError saying whether it stalled (after its halvings) or ran out of calls."""
    if accept is not None and best[0] <= accept:
        return best
    if stalled:
        raise FitError(f"no periodic {what} found: the search stalled at residual {nrm_prev:.2g}")
    raise FitError(f"no periodic {what} found within {max_iter} simulator calls (residual {nrm:.2g})")


def solve_orbit(evaluate, z0, s, h, *, lo=None, hi=None, tol=1e-10, max_iter=30,
                resolutions=(16, N_PER_STANCE), switch=1e-7, chord=True, batched=True, max_halvings=None,
                damped=False, accept=None, what="running cycle", reasons=REASONS):
    """Minimum-norm Newton for a periodic orbit near the priors (see module doc).

    evaluate(Z (m, d), n) → (R (m, r), rows with ``valid`` (m,) and ``reason`` (m,) fields): the residual
    rows of each candidate z at simulator resolution n (RK4 steps per stance; :func:`rowwise` builds one
    from a one-candidate evaluator). z0: (d,) priors; s: (d,) scales (0: held at the prior); h: (d,)
    forward-difference steps (see :func:`_jacobian` for their side). lo, hi: (d,) box bounds or None:
    every iterate is clipped into the box (the priors may lie outside it; the start is clipped).
    resolutions (coarse, fine): Newton with a forward-difference Jacobian at the coarse resolution down to
    ``switch``, then at the fine one either chord iterations that reuse the last Jacobian and need only
    one row per iteration (``chord``; a fresh fine Jacobian only if the chord stalls) or Newton with a
    fresh Jacobian each iteration. A step that does not lower max|R| is halved, or with ``damped`` replaced
    by a Levenberg–Marquardt increment from the last point, damped 10× more at each rejection (for
    ill-conditioned Jacobians, where the Newton direction itself is poor); after ``max_halvings`` such
    retries in a row the search ends. Undamped steps end the search, so the point found is still the
    minimum-norm one. batched: evaluate the Jacobian rows in the same call as their
    point (one call per iteration for a vectorised simulator; False evaluates the point first, for
    :func:`rowwise` evaluators, where a rejected point would waste them). max_iter counts those calls.
    accept: when the iterations end above ``tol`` (an integration-error floor), the best point seen at
    the fine resolution is still returned if its residual is at most ``accept`` (None: ``tol`` is the bar).
    Returns (z (d,), rows of z's evaluation (row 0 is z), evaluate calls, R (r,) at z).
    Raises FitError naming ``what`` (and the reason, by ``reasons`` of the evaluator's codes) when the
    search leaves the valid region or does not converge.
    """
    z0 = np.asarray(z0, float)
    s, h = np.asarray(s, float), np.asarray(h, float)
    lo = None if lo is None else np.asarray(lo, float)
    hi = None if hi is None else np.asarray(hi, float)
    free = np.flatnonzero(s > 0)
    z = z0.copy() if lo is None and hi is None else np.clip(z0, lo, hi)
    y_box = _scaled_box(z0, s, free, lo, hi)
    z_prev, nrm_prev, J, R_prev = None, np.inf, None, None
    calls = halvings = 0
    fine = False
    nrm = np.inf
    R = r = None
    best: tuple = (np.inf, None, None, None)  # (residual, z, rows, R) of the best fine-resolution point
    while calls < max_iter:
        n = resolutions[1] if fine else resolutions[0]
        need_jac = not (fine and chord) or J is None
        with_jac = need_jac and batched
        R, r = evaluate(_candidates(z, with_jac, h, free, hi), n)
        calls += 1
        nrm = float(np.max(np.abs(R[0]))) if r.valid[0] else np.inf
        if fine and nrm < best[0]:
            best = (nrm, z, r, R[0])
        if z_prev is not None and not nrm < nrm_prev:
            if fine and not need_jac:
                J = None  # the chord stalled: take a fresh full-resolution Jacobian here
                z, z_prev, nrm_prev = z_prev, None, np.inf
            elif max_halvings is not None and halvings >= max_halvings:
                break
            else:
                halvings += 1
                z = (_damped_point(z_prev, R_prev, J, s, free, halvings, lo, hi) if damped
                     else z_prev + 0.5 * (z - z_prev))  # rejected Newton step: halve it
            continue
        halvings = 0
        if fine and nrm <= tol:
            break
        if not fine and nrm <= switch:
            fine, z_prev, nrm_prev = True, None, np.inf  # coarse fixed point found; J kept for the chord
            continue
        if need_jac:
            if not r.valid[0]:
                raise FitError(f"no {what} found: the search left the feasible region "
                               f"({reasons[int(np.asarray(r.reason)[0])]})")
            given = (R[1:], r.valid[1:]) if with_jac else None
            J, c = _jacobian(evaluate, z, R[0], given, free, h, hi, n, what, reasons)
            calls += c
        z_prev, nrm_prev, R_prev = z, nrm, R[0]
        z = _newton_point(z, z0, s, free, J, R[0], y_box, lo, hi)
    if not (fine and nrm <= tol):
        stalled = max_halvings is not None and halvings >= max_halvings
        _, z, r, R0 = _best_or_raise(best, accept, stalled, nrm, nrm_prev, max_iter, what)
        return z, r, calls, R0
    assert R is not None  # converged, so evaluated at least once
    return z, r, calls, R[0]


def step_jacobian(U, H, theta0, control, *, eps=1e-6, n_per_stance=N_PER_STANCE):
    """∂(U', H')/∂(U, H) at fixed θ0 and control, by central differences (one batch call).

    Scalars in, (2, 2) array out (rows U', H'; columns U, H). NaN if any perturbed step is invalid.
    """
    dU = eps * max(abs(U), 1.0)
    dH = eps * max(abs(H), 1.0)
    Us = np.array([U + dU, U - dU, U, U])
    Hs = np.array([H, H, H + dH, H - dH])
    r = step(Us, Hs, theta0, control, n_per_stance=n_per_stance)
    out = np.empty((2, 2))
    out[0, 0] = (r.U_next[0] - r.U_next[1]) / (2 * dU)
    out[1, 0] = (r.H_next[0] - r.H_next[1]) / (2 * dU)
    out[0, 1] = (r.U_next[2] - r.U_next[3]) / (2 * dH)
    out[1, 1] = (r.H_next[2] - r.H_next[3]) / (2 * dH)
    return out


def step_map_eigenvalues(U, H, theta0, control, **kw):
    """Eigenvalues (2,) of the apex return map Jacobian; |λ| < 1 for both ⇒ locally stable.

    For the passive spring-mass model (a = b = c = 0) energy is conserved and one eigenvalue
    is 1; the other decides self-stability at fixed touchdown angle.
    """
    J = step_jacobian(U, H, theta0, control, **kw)
    if not np.all(np.isfinite(J)):
        return np.full(2, np.nan + 0j)
    return np.linalg.eigvals(J)
