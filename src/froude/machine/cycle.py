"""§4: search for a repeatable running cycle of the simple machine, close to measured priors.

The variables z = (U, H, θ0, K, a, b, c, T_c) (dimensionless) must satisfy the periodicity
constraint r(z) = (U' − U, H' − H) = 0 of the step map. Among the solutions we want the one
nearest the priors z0 in the scaled norm ‖(z − z0)/s‖ (s = per-variable scale; s = 0 holds a
variable fixed). Each iteration linearises r, r(z + Δ) ≈ r + J Δ, and jumps to the minimum-norm
point of the linearised constraint set in scaled coordinates y = (z − z0)/s:

    y⁺ = argmin ‖y‖  s.t.  J_y y = J_y y_k − r_k,    J_y = J diag(s)       (pseudo-inverse)

with a backtracking line search on ‖r‖ (all trial step lengths evaluated in one batch call).
J comes from central finite differences, one vectorised :func:`step` call for all columns.
Rank-deficient J (e.g. energy conservation of the passive spring-mass model makes U' − U and
H' − H dependent) is fine: the least-squares solve is minimum norm.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from froude.errors import FitError
from froude.machine.dynamics import N_PER_STANCE, REASONS, Control, step

__all__ = ["PARAMETERS", "DEFAULT_SCALES", "LimitCycle", "find_limit_cycle", "step_jacobian",
           "step_map_eigenvalues"]

#: Order of the cycle variables.
PARAMETERS = ("U", "H", "theta0", "K", "a", "b", "c", "T_c")
#: Default scales: how far each variable may move per unit of cost (0 = held fixed). U, θ0 and
#: T_c are held (the measured speed, touchdown angle and stance duration are kept); H and the
#: control parameters move, K relative to its value (see find_limit_cycle).
DEFAULT_SCALES = {"U": 0.0, "H": 0.02, "theta0": 0.0, "K": 0.1, "a": 0.01, "b": 0.02,
                  "c": 0.02, "T_c": 0.0}


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
    iterations: Newton iterations used
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
        """(8,) array in PARAMETERS order."""
        return np.array([self.U, self.H, self.theta0, *map(float, self.control.as_tuple())])


def _step_rows(Z, n_per_stance):
    """step() on rows Z (M, 8) in PARAMETERS order → (residual (M, 2), StepResult)."""
    ctl = Control(K=Z[:, 3], a=Z[:, 4], b=Z[:, 5], c=Z[:, 6], T_c=Z[:, 7])
    r = step(Z[:, 0], Z[:, 1], Z[:, 2], ctl, n_per_stance=n_per_stance)
    res = np.stack([r.U_next - Z[:, 0], r.H_next - Z[:, 1]], axis=1)
    return res, r


def _fd_steps(z, free, rel_eps):
    """Central-difference steps per free variable: relative to max(|z|, 1)."""
    return rel_eps * np.maximum(np.abs(z[free]), 1.0)


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


def find_limit_cycle(U, H, theta0, control, *, scales=None, tol=1e-9, max_iter=40,
                     fd_eps=1e-6, n_per_stance=N_PER_STANCE):
    """Find a fixed point of the step map (U' = U, H' = H) close to the priors.

    U, H, theta0: prior apex state and touchdown angle (dimensionless, rad)
    control:      prior :class:`Control` (scalar fields)
    scales:       dict name → scale (PARAMETERS names). Missing names take DEFAULT_SCALES.
                  0 holds a variable fixed; a small scale holds it weakly. The scale of K is
                  *relative* (multiplied by K's prior value); all others are absolute.
    tol:          convergence bar on max(|U' − U|, |H' − H|)
    fd_eps:       relative central-difference step for the Jacobian

    Returns :class:`LimitCycle`. Raises FitError (with the reason) if the prior step is invalid,
    no variable is free, or no periodic solution is reached.
    """
    z0 = np.array([U, H, theta0, *map(float, control.as_tuple())], dtype=float)
    sc = dict(DEFAULT_SCALES)
    if scales:
        unknown = set(scales) - set(PARAMETERS)
        if unknown:
            raise FitError(f"unknown cycle variables {sorted(unknown)}; known: {PARAMETERS}")
        sc.update(scales)
    s = np.array([float(sc[p]) for p in PARAMETERS])
    s[3] *= abs(z0[3])
    free = np.flatnonzero(s > 0)
    if free.size == 0:
        raise FitError("no free variable: every scale is 0")
    D = s[free]

    z = z0.copy()
    res0, r0 = _step_rows(z[None, :], n_per_stance)
    if not r0.valid[0]:
        raise FitError(f"the prior running step is invalid: {REASONS[int(r0.reason[0])]}")
    rk = res0[0]
    nrm = float(np.max(np.abs(rk)))
    alphas = 0.5 ** np.arange(12)
    it = 0
    for it in range(1, max_iter + 1):
        h = _fd_steps(z, free, fd_eps)
        nf = free.size
        Z = np.repeat(z[None, :], 2 * nf, axis=0)
        Z[np.arange(nf), free] += h
        Z[nf + np.arange(nf), free] -= h
        resJ, rJ = _step_rows(Z, n_per_stance)
        if not np.all(rJ.valid):
            bad = [PARAMETERS[free[i % nf]] for i in np.flatnonzero(~rJ.valid)]
            raise FitError(f"step map not differentiable near the iterate (invalid step when "
                           f"perturbing {sorted(set(bad))}); the cycle search left the feasible region")
        J = ((resJ[:nf] - resJ[nf:]) / (2.0 * h)[:, None]).T  # (2, nf)
        Jy = J * D[None, :]
        y = (z[free] - z0[free]) / D
        target = Jy @ y - rk
        y_new, *_ = np.linalg.lstsq(Jy, target, rcond=1e-12)
        dz = np.zeros_like(z)
        dz[free] = D * (y_new - y)
        # Line search: every trial length in one batch call.
        Zt = z[None, :] + alphas[:, None] * dz[None, :]
        rest, rt = _step_rows(Zt, n_per_stance)
        nt = np.max(np.abs(rest), axis=1)
        acceptable = rt.valid & ((nt < nrm) | (nt <= 0.1 * tol))
        if not acceptable.any():
            if nrm <= tol:
                break
            raise FitError(f"no periodic cycle found: the search stalled at residual {nrm:.3g} "
                           f"after {it} iterations (priors may be too far from a running cycle)")
        j = int(np.argmax(acceptable))
        z = Zt[j]
        rk = rest[j]
        prev = nrm
        nrm = float(nt[j])
        step_small = float(np.max(np.abs(alphas[j] * (y_new - y)))) <= 1e-9
        if nrm <= tol and (step_small or prev <= tol and abs(prev - nrm) <= tol):
            break
    if not nrm <= tol:
        raise FitError(f"no periodic cycle found within {max_iter} iterations "
                       f"(residual {nrm:.3g} > {tol:.1g})")

    _, r = _step_rows(z[None, :], n_per_stance)
    ctl = Control(K=float(z[3]), a=float(z[4]), b=float(z[5]), c=float(z[6]), T_c=float(z[7]))
    t_fall = float(r.t_fall[0])
    t_rise = float(r.t_rise[0])
    eig = step_map_eigenvalues(float(z[0]), float(z[1]), float(z[2]), ctl, n_per_stance=n_per_stance)
    return LimitCycle(
        U=float(z[0]), H=float(z[1]), theta0=float(z[2]), control=ctl,
        t_stance=float(r.t_stance[0]), t_fall=t_fall, t_rise=t_rise, t_flight=t_rise + t_fall,
        step_length=float(r.apex_dx[0]), step_time=t_fall + float(r.t_stance[0]) + t_rise,
        peak_force=float(r.peak_force[0]), iterations=it, residual=nrm,
        prior={p: float(v) for p, v in zip(PARAMETERS, z0)},
        moved={p: float(v) for p, v in zip(PARAMETERS, z - z0)},
        moved_scaled={p: (float((z[i] - z0[i]) / s[i]) if s[i] > 0 else 0.0)
                      for i, p in enumerate(PARAMETERS)},
        eigenvalues=eig,
    )
