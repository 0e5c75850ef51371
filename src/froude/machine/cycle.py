"""§4: a repeatable running cycle of the simple machine near given priors (``find_limit_cycle``).

The variables z = (U, H, θ0, K, a, b, c, T_c) (dimensionless) must satisfy the periodicity
constraint r(z) = (U' − U, H' − H) = 0 of the step map; the solution nearest the priors in the
scaled norm is found by the one orbit solver (``machine.orbit.solve_orbit``, minimum-norm Newton).
"""
from __future__ import annotations

import numpy as np

from froude.errors import FitError
from froude.machine.dynamics import N_PER_STANCE, REASONS, Control, step
from froude.machine.orbit import LimitCycle, solve_orbit, step_jacobian, step_map_eigenvalues

__all__ = ["PARAMETERS", "DEFAULT_SCALES", "LimitCycle", "find_limit_cycle", "step_jacobian",
           "step_map_eigenvalues"]

#: Order of the cycle variables.
PARAMETERS = ("U", "H", "theta0", "K", "a", "b", "c", "T_c")
#: Default scales: how far each variable may move per unit of cost (0 = held fixed). U, θ0 and
#: T_c are held (the measured speed, touchdown angle and stance duration are kept); H and the
#: control parameters move, K relative to its value (see find_limit_cycle).
DEFAULT_SCALES = {"U": 0.0, "H": 0.02, "theta0": 0.0, "K": 0.1, "a": 0.01, "b": 0.02,
                  "c": 0.02, "T_c": 0.0}


def _step_rows(Z, n_per_stance):
    """step() on rows Z (M, 8) in PARAMETERS order → (residual (M, 2), StepResult)."""
    ctl = Control(K=Z[:, 3], a=Z[:, 4], b=Z[:, 5], c=Z[:, 6], T_c=Z[:, 7])
    r = step(Z[:, 0], Z[:, 1], Z[:, 2], ctl, n_per_stance=n_per_stance)
    res = np.stack([r.U_next - Z[:, 0], r.H_next - Z[:, 1]], axis=1)
    return res, r


def find_limit_cycle(U, H, theta0, control, *, scales=None, tol=1e-9, max_iter=40,
                     fd_eps=1e-6, n_per_stance=N_PER_STANCE):
    """Find a fixed point of the step map (U' = U, H' = H) close to the priors.

    U, H, theta0: prior apex state and touchdown angle (dimensionless, rad)
    control:      prior :class:`Control` (scalar fields)
    scales:       dict name → scale (PARAMETERS names). Missing names take DEFAULT_SCALES.
                  0 holds a variable fixed; a small scale holds it weakly. The scale of K is
                  *relative* (multiplied by K's prior value); all others are absolute.
    tol:          convergence bar on max(|U' − U|, |H' − H|)
    fd_eps:       relative forward-difference step for the Jacobian

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

    res0, r0 = _step_rows(z0[None, :], n_per_stance)
    if not r0.valid[0]:
        raise FitError(f"the prior running step is invalid: {REASONS[int(r0.reason[0])]}")
    h = fd_eps * np.maximum(np.abs(z0), 1.0)
    z, _, it, res = solve_orbit(lambda Z, n: _step_rows(Z, n), z0, s, h, tol=tol, max_iter=max_iter,
                                resolutions=(n_per_stance, n_per_stance))
    nrm = float(np.max(np.abs(res)))
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
