"""The one periodic-orbit solver of the running machine, and the one record of a periodic cycle.

A periodic running cycle is a fixed point of the step map: apex (U, H) → next apex (U', H') with the
residual r(z) = (U' − U, H' − H, extra rows) = 0 over some unknowns z (apex state, touchdown angle,
control, …). Such fixed points form a family; the one wanted is the one nearest the priors z0 in the
scaled norm ‖(z − z0)/s‖ (s: per-unknown scale; s = 0 holds an unknown at its prior). Each iteration
linearises r and jumps to the minimum-norm point of the linearised constraint set in scaled coordinates
y = (z − z0)/s (pseudo-inverse, so a rank-deficient Jacobian — the passive spring-mass runner, whose
energy conservation ties U' − U to H' − H — is fine):

    y⁺ = argmin ‖y‖  s.t.  J_y y = J_y y_k − r_k,    J_y = J diag(s)

Used by the fit (§4: the cycle matching the measured timing), the speed re-solve (§5.2), the planner's
target orbits (§5.3) and ``find_limit_cycle``. Dimensionless throughout (``machine.units``).
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


def solve_orbit(evaluate, z0, s, h, *, tol=1e-10, max_iter=30, resolutions=(16, N_PER_STANCE), switch=1e-7,
                accept=None, what="running cycle"):
    """Minimum-norm Newton for a periodic orbit near the priors (see module doc).

    evaluate(Z (m, d), n) → (R (m, r), rows with a ``valid`` (m,) field): the residual rows of each
    candidate z at simulator resolution n (RK4 steps per stance). z0: (d,) priors; s: (d,) scales (0:
    held at the prior); h: (d,) forward-difference steps.
    resolutions (coarse, fine): Newton with a batched forward-difference Jacobian at the coarse
    resolution down to ``switch``, then chord iterations at the fine one that reuse the last Jacobian and
    need only one row per iteration (a fresh fine Jacobian only if the chord stalls); a rejected step is
    halved. Both equal: plain Newton at that resolution after the first converged coarse pass.
    accept: when the iterations end above ``tol`` (an integration-error floor), the best point seen is
    still returned if its residual is at most ``accept`` (None: ``tol`` is the bar).
    Returns (z (d,), rows of the last evaluation (row 0 is z), evaluations, R (r,) at z).
    Raises FitError naming ``what`` when the search leaves the valid region or does not converge.
    """
    z0 = np.asarray(z0, float)
    s, h = np.asarray(s, float), np.asarray(h, float)
    free = np.flatnonzero(s > 0)
    nf = free.size
    z = z0.copy()
    z_prev, nrm_prev, J = None, np.inf, None
    calls = 0
    fine = False
    nrm = np.inf
    R = r = None
    best: tuple = (np.inf, None, None, None)  # (residual, z, rows, R) of the best fine-resolution point
    for _ in range(max_iter):
        n = resolutions[1] if fine else resolutions[0]
        need_jac = (not fine) or J is None
        Z = np.repeat(z[None, :], nf + 1 if need_jac else 1, axis=0)
        if need_jac:
            Z[1 + np.arange(nf), free] += h[free]
        R, r = evaluate(Z, n)
        calls += 1
        nrm = float(np.max(np.abs(R[0]))) if r.valid[0] else np.inf
        if fine and nrm < best[0]:
            best = (nrm, z, r, R[0])
        if z_prev is not None and not nrm < nrm_prev:
            if fine and not need_jac:
                J = None  # the chord stalled: take a fresh full-resolution Jacobian here
                z, z_prev, nrm_prev = z_prev, None, np.inf
            else:
                z = z_prev + 0.5 * (z - z_prev)  # rejected Newton step: halve it
            continue
        if fine and nrm <= tol:
            break
        if not fine and nrm <= switch:
            fine, z_prev, nrm_prev = True, None, np.inf  # coarse fixed point found; J kept for the chord
            continue
        if need_jac:
            if not np.all(r.valid):
                raise FitError(f"no {what} found: the search left the feasible region "
                               f"({REASONS[int(r.reason[~r.valid][0])]})")
            J = ((R[1:] - R[0]) / h[free][:, None]).T  # (r, nf)
        z_prev, nrm_prev = z, nrm
        Js = J * s[free][None, :]
        y = (z[free] - z0[free]) / s[free]
        y_new, *_ = np.linalg.lstsq(Js, Js @ y - R[0], rcond=1e-12)
        z = z.copy()
        z[free] = z0[free] + s[free] * y_new
    if not (fine and nrm <= tol) and accept is not None and best[0] <= accept:
        nrm, z, r, R0 = best
        return z, r, calls, R0
    if not (fine and nrm <= tol):
        raise FitError(f"no periodic {what} found within {max_iter} simulator calls (residual {nrm:.2g})")
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
