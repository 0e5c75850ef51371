"""§5.3, the multiple-shooting optimisation of a speed change on the exact simulator (dimensionless): the
inputs and apex states of n change steps are unknowns tied by continuity constraints, solved by constrained
Gauss–Newton. The one-step solves and periodic orbits it starts from are in ``planner.shooting``.
"""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from froude.machine.dynamics import StepResult, step
from froude.machine.orbit import LimitCycle
from froude.machine.planner.shooting import _ACCEPT, _bounds, _StepFail, _steps, _theta_of

#: The change steps' continuity and speed constraints are met to this (or as far as Newton still lowers them):
#: the plan is re-simulated step by step, and the step maps (|λ| up to ≈ 3.5) amplify what is left over 8
#: steps (1e-11 became a 4e-8 overshoot of the last apex, a non-monotone plan).
_TOL_SHOOT = 1e-14


# --- the simulated run of given inputs (the first guess of the optimisation) ---------------------------------
def _shoot(U0, H0, t0, tau, b, ctl, bases=None):
    """Simulate steps with inputs (τ_k, b_k) from apex (U0, H0) at time t0 (scalar simulator path,
    the one ``simulate`` uses); step k's control is bases[k] (default ctl) with b_k.
    Returns (U (n+1,), H (n+1,), t (n+1,), θ0 (n,), results list, ok)."""
    n = len(tau)
    U, H, t, th = np.empty(n + 1), np.empty(n + 1), np.empty(n + 1), np.full(n, np.nan)
    U[0], H[0], t[0] = U0, H0, t0
    res: list[StepResult] = []
    for k in range(n):
        th[k] = _theta_of(H[k], tau[k])
        r = step(U[k], H[k], th[k], replace(ctl if bases is None else bases[k], b=float(b[k])))
        if not (bool(r.valid) and math.isfinite(th[k])):
            return U, H, t, th, res, False
        res.append(r)
        U[k + 1], H[k + 1] = float(r.U_next), float(r.H_next)
        t[k + 1] = t[k] + float(r.t_fall + r.t_stance + r.t_rise)
    return U, H, t, th, res, True


#: How far a step's duration may move from the one asked (``step_times``) per unit cost [√(l0/g)]: 1 % of a
#: fitted cycle's step (≈ 1.1), as firm as the touchdown fall time's prior.
_S_STEP_TIME = 0.01
#: The other soft scales of the change steps (dimensionless, per unit cost): fall time τ [√(l0/g)], energy
#: knob b [l0 per stance], apex height H [l0], apex speed U off its reference (θ0-only) [√(g l0)], and the
#: scale of the band and monotonicity penalties.
_S_TAU, _S_B, _S_H, _S_U, _S_PEN = 0.05, 0.01, 0.05, 2e-3, 1e-3


@dataclass(frozen=True)
class _ShootingProblem:
    """The multiple-shooting problem of n change steps (dimensionless): its data and its unknowns' layout.
    z (m,) = [τ (n), b (nb), U_1..n, H_1..n, t_1..n, (θ0-only: τ_h, the fall time of the periodic step after:
    the change must end on *some* orbit of the fitted control)]; i* the blocks' offsets in z, lo/hi (m,) its
    bounds; nb = n with energy "b", else 0; nrow = the simulated steps (n, or n + 1 with the periodic one)."""

    cyc: LimitCycle
    U0: float
    H0: float
    t0: float
    n: int
    U_ref: Callable[[int, float], float]  # (k, t [√(l0/g)]) -> step k's reference apex speed [√(g l0)]
    tau_p: np.ndarray  # (n,) prior fall times [√(l0/g)]
    b_p: np.ndarray  # (n,) prior energy knobs [l0 per stance]
    H_p: np.ndarray  # (n,) prior apex heights [l0]
    H_t: float
    use_b: bool
    step_times: object  # (n,) [√(l0/g)] or None
    th_b: tuple  # touchdown-angle band [rad]
    H_lo: float
    H_hi: float
    sgn_dU: float  # +1 for a speed-up, −1 for a slow-down
    row_ctl: dict  # rows per step (1 or 5) -> the Control of each simulated row
    nb: int
    iT: int
    iB: int
    iU: int
    iH: int
    it_: int
    ih_: int
    m: int
    nrow: int
    lo: np.ndarray
    hi: np.ndarray

    def parts(self, z):
        """(τ (n,), b (n,), U (n+1,), H (n+1,), t (n+1,)) of the unknowns z (m,), with the fixed start state."""
        n = self.n
        tau = z[self.iT:self.iT + n]
        b = z[self.iB:self.iB + n] if self.use_b else self.b_p
        U = np.r_[self.U0, z[self.iU:self.iU + n]]
        H = np.r_[self.H0, z[self.iH:self.iH + n]]
        t = np.r_[self.t0, z[self.it_:self.it_ + n]]
        return tau, b, U, H, t


def _shooting_problem(cyc, U0, H0, t0, n, U_ref, prior, H_t, mode, comfort, bases, step_times):
    """The :class:`_ShootingProblem` of :func:`_optimise_change`'s arguments (same meanings)."""
    ctl = cyc.control
    tau_p, b_p, H_p = (np.asarray(v, float) for v in prior)
    use_b = mode == "b"
    th_b, b_b = _bounds(cyc, comfort, mode)
    nb = n if use_b else 0
    iT, iB, iU, iH, it_ = 0, n, n + nb, 2 * n + nb, 3 * n + nb
    ih_ = 4 * n + nb
    m = 4 * n + nb + (0 if use_b else 1)
    if bases is not None and not use_b:
        raise ValueError("per-step controls need energy 'b'")
    b_lo, b_hi = (b_b[0], b_b[1]) if bases is None else (b_p - comfort.b_band, b_p + comfort.b_band)
    lo = np.r_[np.zeros(n), np.broadcast_to(b_lo, (nb,)), np.full(3 * n, -np.inf), np.zeros(m - ih_)]
    hi = np.r_[np.full(n, 10.0), np.broadcast_to(b_hi, (nb,)), np.full(3 * n, np.inf), np.full(m - ih_, 10.0)]
    # the control of each simulated row: (steps, 1 or 5 rows each) -> (K, a, c, T_c) arrays
    row_ctl = {nr: ctl if bases is None else
               replace(ctl, **{f: np.repeat([getattr(c, f) for c in bases], nr) for f in ("K", "a", "c", "T_c")})
               for nr in (1, 5)}
    return _ShootingProblem(
        cyc=cyc, U0=U0, H0=H0, t0=t0, n=n, U_ref=U_ref, tau_p=tau_p, b_p=b_p, H_p=H_p, H_t=H_t, use_b=use_b,
        step_times=step_times, th_b=th_b, H_lo=cyc.H + comfort.H_band[0], H_hi=cyc.H + comfort.H_band[1],
        sgn_dU=1.0 if U_ref(n - 1, t0) >= U0 else -1.0, row_ctl=row_ctl, nb=nb, iT=iT, iB=iB, iU=iU, iH=iH,
        it_=it_, ih_=ih_, m=m, nrow=n if use_b else n + 1, lo=lo, hi=hi)


def _simulate_rows(p: _ShootingProblem, z, jac: bool, h: float):
    """Every step of z through the simulator in one batch, with (jac) 4 forward-perturbed rows per step.

    Returns (Y (nrow, 1 or 5, 3): apex U' [√(g l0)], H' [l0] and step time [√(l0/g)] of each row;
    th_all (nrow,) the unperturbed touchdown angles [rad]), or None if a row is invalid.
    """
    n = p.n
    tau, b, U, H, t = p.parts(z)
    nr = 5 if jac else 1
    d = np.zeros((nr, 4))
    if jac:
        d[1:] = np.eye(4) * h
    base = np.stack([U[:n], H[:n], tau, b], 1)
    if not p.use_b:
        base = np.vstack([base, [U[n], H[n], z[p.ih_], p.b_p[-1]]])
    X = (base[:, None, :] + d[None]).reshape(-1, 4)
    th_rows = _theta_of(X[:, 1], X[:, 2])
    r = _steps(X[:, 0], X[:, 1], th_rows, X[:, 3], p.row_ctl[nr])
    if not np.all(r.valid & np.isfinite(th_rows)):
        return None
    Y = np.stack([r.U_next, r.H_next, r.t_fall + r.t_stance + r.t_rise], 1).reshape(p.nrow, nr, 3)
    return Y, th_rows.reshape(p.nrow, nr)[:, 0]


def _residuals(p: _ShootingProblem, z, Y, th_all) -> dict:
    """Constraints c, soft residuals r (same order as their Jacobian rows) and the state at z, as a dict."""
    n = p.n
    tau, b, U, H, t = p.parts(z)
    th = th_all[:n]
    Ur = np.array([p.U_ref(k, t[k + 1]) for k in range(n)])
    cont = np.concatenate([Y[:n, 0, 0] - U[1:], Y[:n, 0, 1] - H[1:], t[:n] + Y[:n, 0, 2] - t[1:]])
    if p.use_b:
        c = np.r_[cont, U[1:] - Ur, H[n] - p.H_t]
        rr = [(tau - p.tau_p) / _S_TAU, (b - p.b_p) / _S_B, (H[1:n] - p.H_p[:n - 1]) / _S_H]
        if p.step_times is not None:
            rr.append((np.diff(t) - p.step_times) / _S_STEP_TIME)
    else:
        c = np.r_[cont, U[n] - Ur[n - 1], Y[n, 0, 0] - U[n], Y[n, 0, 1] - H[n]]
        rr = [(tau - p.tau_p) / _S_TAU, (U[1:n] - Ur[:n - 1]) / _S_U,
              np.maximum(0.0, -p.sgn_dU * np.diff(U)) / _S_PEN]
    rr += [(np.maximum(0.0, p.H_lo - H[1:]) + np.maximum(0.0, H[1:] - p.H_hi)) / _S_PEN,
           (np.maximum(0.0, p.th_b[0] - th) + np.maximum(0.0, th - p.th_b[1])) / _S_PEN]
    return dict(c=c, r=np.concatenate(rr), U=U, H=H, t=t, th=th, Ur=Ur, tau=tau, b=b,
                tau_h=None if p.use_b else float(z[p.ih_]), th_h=None if p.use_b else float(th_all[n]))


def _continuity_jacobian(p: _ShootingProblem, D):
    """(3n, m) Jacobian of the continuity rows o·n + k: output o of step k, S_o(s_k, u_k) − s_{k+1,o}
    (s_0 is fixed); D (nrow, inputs U H τ b, outputs U' H' T) the steps' finite-difference derivatives."""
    n, m = p.n, p.m
    Jc = np.zeros((3 * n, m))
    k1 = np.arange(1, n)  # steps whose start state is a variable (entry k − 1)
    for o, col in enumerate((p.iU, p.iH, p.it_)):
        rows = o * n + np.arange(n)
        Jc[rows, p.iT + np.arange(n)] = D[:n, 2, o]
        if p.use_b:
            Jc[rows, p.iB + np.arange(n)] = D[:n, 3, o]
        Jc[rows, col + np.arange(n)] -= 1.0
        Jc[o * n + k1, p.iU + k1 - 1] += D[k1, 0, o]
        Jc[o * n + k1, p.iH + k1 - 1] += D[k1, 1, o]
        if o == 2:
            Jc[o * n + k1, p.it_ + k1 - 1] += 1.0
    return Jc


def _profile_jacobian(p: _ShootingProblem, t):
    """(n, m) Jacobian of the profile rows U_k − U_ref(k, t_k); t (n+1,) the apex times [√(l0/g)]."""
    n = p.n
    dUr = np.array([(p.U_ref(k, t[k + 1] + 1e-6) - p.U_ref(k, t[k + 1] - 1e-6)) / 2e-6 for k in range(n)])
    eye = np.eye(n)
    Jp = np.zeros((n, p.m))
    Jp[:, p.iU:p.iU + n] = eye
    Jp[:, p.it_:p.it_ + n] = -eye * dUr
    return Jp


def _constraint_jacobian(p: _ShootingProblem, D, Jp):
    """(rows of c, m) Jacobian of the hard constraints, in the order of :func:`_residuals`' c."""
    n, m = p.n, p.m
    Jc = _continuity_jacobian(p, D)
    JHn = np.zeros((1, m))
    JHn[0, p.iH + n - 1] = 1.0
    if p.use_b:
        return np.vstack([Jc, Jp, JHn])
    # periodic end: S(s_n, τ_h) − (U_n, H_n) = 0
    Jper = np.zeros((2, m))
    for o in range(2):
        Jper[o, p.iU + n - 1] = D[n, 0, o] - (o == 0)
        Jper[o, p.iH + n - 1] = D[n, 1, o] - (o == 1)
        Jper[o, p.ih_] = D[n, 2, o]
    return np.vstack([Jc, Jp[-1:], Jper])


def _soft_jacobian(p: _ShootingProblem, e: dict, Jp):
    """(rows of r, m) Jacobian of the soft residuals, in the order of :func:`_residuals`' r; e its output."""
    n, m = p.n, p.m
    U, H, th, tau = e["U"], e["H"], e["th"], e["tau"]
    eye = np.eye(n)
    Jr = []
    Jt = np.zeros((n, m))
    Jt[:, p.iT:p.iT + n] = eye / _S_TAU
    Jr.append(Jt)
    if p.use_b:
        Jb = np.zeros((n, m))
        Jb[:, p.iB:p.iB + n] = eye / _S_B
        JH = np.zeros((n - 1, m))
        JH[:, p.iH:p.iH + n - 1] = np.eye(n - 1) / _S_H
        Jr += [Jb, JH]
        if p.step_times is not None:  # t_{k+1} − t_k, t_0 fixed
            JT = np.zeros((n, m))
            JT[:, p.it_:p.it_ + n] = (eye - np.eye(n, k=-1)) / _S_STEP_TIME
            Jr.append(JT)
    else:
        Jr.append(Jp[:n - 1] / _S_U)
        act = (-p.sgn_dU * np.diff(U) > 0).astype(float)
        JM = np.zeros((n, m))
        JM[:, p.iU:p.iU + n] = -p.sgn_dU * (eye - np.eye(n, k=-1))  # U_k − U_{k−1}, U_0 fixed
        Jr.append(act[:, None] * JM / _S_PEN)
    sg = (H[1:] > p.H_hi).astype(float) - (H[1:] < p.H_lo).astype(float)
    JBH = np.zeros((n, m))
    JBH[:, p.iH:p.iH + n] = eye * sg / _S_PEN
    Jr.append(JBH)
    # θ_k = acos(H_k − τ_k²/2): dθ = −(dH_k − τ_k dτ_k)/sin θ_k (H_0 fixed)
    sgt = (th > p.th_b[1]).astype(float) - (th < p.th_b[0]).astype(float)
    Jth = np.zeros((n, m))
    Jth[:, p.iT:p.iT + n] = eye * (tau / np.sin(th))
    Jth[1:, p.iH:p.iH + n - 1] = -np.eye(n - 1) / np.sin(th[1:])[:, None]
    Jr.append(sgt[:, None] * Jth / _S_PEN)
    return np.vstack(Jr)


def _evaluate(p: _ShootingProblem, z, jac=False, h=1e-6):
    """Constraints c, soft residuals r (and with jac their Jacobians C, J by forward differences of step h)
    at the unknowns z (m,); None if a step is invalid."""
    sim = _simulate_rows(p, z, jac, h)
    if sim is None:
        return None
    Y, th_all = sim
    e = _residuals(p, z, Y, th_all)
    if not jac:
        return e
    D = (Y[:, 1:, :] - Y[:, :1, :]) / h  # (nrow, inputs U H τ b, outputs U' H' T)
    Jp = _profile_jacobian(p, e["t"])
    e["C"], e["J"] = _constraint_jacobian(p, D, Jp), _soft_jacobian(p, e, Jp)
    return e


def _merit(e) -> float:
    """The line search's merit: half the soft cost plus an exact (L1) penalty on the constraints."""
    return 0.5 * float(e["r"] @ e["r"]) + 1e3 * float(np.sum(np.abs(e["c"])))


def _first_guess(p: _ShootingProblem, tau_start, bases):
    """The unknowns (m,) to start from: inputs from the prior (or the table rollout ``tau_start``), states by
    simulating them (or the interpolated references where the simulated run fails), within the bounds."""
    n, nb, cyc, ctl = p.n, p.nb, p.cyc, p.cyc.control
    tau0 = p.tau_p if tau_start is None else np.asarray(tau_start, float)
    z = None
    for tau_g, b_g in ((tau0, p.b_p), (p.tau_p, p.b_p), (np.full(n, cyc.t_fall), np.full(n, ctl.b))):
        U, H, t, th, res, ok = _shoot(p.U0, p.H0, p.t0, tau_g, b_g, ctl, bases)
        if ok:
            z = np.r_[tau_g, b_g[:nb], U[1:], H[1:], t[1:], tau_g[-1:] if not p.use_b else []]
            break
    if z is None:
        Ur = np.array([p.U_ref(k, p.t0 + (k + 1) * cyc.step_time) for k in range(n)])
        z = np.r_[p.tau_p, p.b_p[:nb], Ur, p.H_p, p.t0 + cyc.step_time * np.arange(1, n + 1),
                  p.tau_p[-1:] if not p.use_b else []]
    return np.clip(z, p.lo, p.hi)


def _newton_direction(e, m: int, polish: bool):
    """The step (m,) in the unknowns: the equality-constrained Gauss–Newton (KKT) step, or when polishing the
    minimum-norm Newton correction of the constraints alone (quadratic convergence)."""
    C, J, c, r = e["C"], e["J"], e["c"], e["r"]
    q = C.shape[0]
    if polish:
        return np.linalg.lstsq(C, -c, rcond=1e-13)[0]
    K = np.zeros((m + q, m + q))
    K[:m, :m] = J.T @ J + 1e-9 * np.eye(m)
    K[:m, m:] = C.T
    K[m:, :m] = C
    return np.linalg.lstsq(K, np.r_[-J.T @ r, -c], rcond=1e-15)[0][:m]


def _line_search(p: _ShootingProblem, z, dz, e, polish: bool):
    """(z, e) of the first halving of dz that lowers the merit (polishing: the largest constraint), or None."""
    phi = _merit(e)
    c_max = float(np.max(np.abs(e["c"])))
    for alpha in 0.5 ** np.arange(16):
        zt = np.clip(z + alpha * dz, p.lo, p.hi)
        et = _evaluate(p, zt)
        if et is None:
            continue
        cm_t = float(np.max(np.abs(et["c"])))
        if (_merit(et) < phi) if not polish else (cm_t < c_max):
            return zt, et
    return None


def _gauss_newton(p: _ShootingProblem, z, e, max_iter: int) -> dict:
    """Iterate the constrained Gauss–Newton from z (its evaluation e, with Jacobians) until the constraints
    hold to _TOL_SHOOT, stall, or max_iter; returns the last evaluation."""
    polish = False
    history = []
    for _ in range(max_iter):
        dz = _newton_direction(e, p.m, polish)
        phi = _merit(e)
        accepted = _line_search(p, z, dz, e, polish)
        if accepted is None:
            if polish or float(np.max(np.abs(e["c"]))) > 1e-6:
                break
            polish = True
            continue
        z, e_new = accepted
        cmax = float(np.max(np.abs(e_new["c"])))
        history.append(_merit(e_new))
        if cmax <= _TOL_SHOOT:
            e = e_new
            break
        if cmax > 1e-6 and len(history) >= 8 and history[-1] > 0.9 * history[-6]:
            e = e_new  # stalled away from feasible: the goal is out of reach
            break
        # the soft objective has stopped improving: finish the constraints by plain Newton
        if not polish and phi - _merit(e_new) <= 1e-5 * phi and cmax <= 1e-5:
            polish = True
        e = _evaluate(p, z, jac=True)
        if e is None:
            e = e_new
            break
    return e


def _check_change(p: _ShootingProblem, e) -> None:
    """Raise _StepFail, saying which step and why, unless the evaluation e meets the constraints (to
    _ACCEPT), stays in the comfort band and keeps the speed monotone."""
    n = p.n
    cmax = float(np.max(np.abs(e["c"])))
    pen = float(np.max(np.abs(e["r"][-2 * n:]))) * _S_PEN
    mono = float(np.max(np.r_[0.0, -p.sgn_dU * np.diff(e["U"])]))
    if cmax > _ACCEPT or pen > 1e-6 or mono > 1e-9:
        if cmax > _ACCEPT:
            k = int(np.argmax(np.abs(e["U"][1:] - e["Ur"]))) if p.use_b else n - 1
            why = f"the steps cannot meet the speed profile and end height (off by {cmax:.2g})"
        elif pen > 1e-6:
            k, why = 0, f"a step leaves the comfort band (apex height or touchdown angle, by {pen:.2g})"
        else:
            k, why = int(np.argmax(-p.sgn_dU * np.diff(e["U"]))), f"the speed reverses by {mono:.2g}"
        raise _StepFail(k, float(e["U"][k]), float(e["H"][k]), float(e["Ur"][k]), why)


def _optimise_change(cyc, U0, H0, t0, n, U_ref, prior, H_t, mode, comfort, tau_start=None,
                     max_iter=80, bases=None, step_times=None):
    """Inputs of n change steps from apex (U0, H0) at t0, by constrained Gauss–Newton on the exact
    simulator with *multiple shooting*: the unknowns are the inputs (τ_k, b_k) and the apex states
    (U_k, H_k, t_k), k = 1..n, tied by continuity constraints s_{k+1} = S(s_k, u_k). The per-step
    maps are unstable (|λ| up to ≈ 2 on the fitted cycles), so single shooting compounds
    sensitivities (∂U_8/∂τ_0 ≈ 100); multiple shooting keeps every Jacobian block local, and all
    n steps (and their finite-difference rows) go through the simulator in one batched call.

    energy "b" (2 inputs per step) — hard (to 1e-11): U_k = U_ref(k, t_k) for k = 1..n and
    H_n = H_t; soft: τ_k, b_k near ``prior`` (start → target interpolation), H_k near the
    interpolated height. energy "theta" (θ0 only, n inputs) — hard: U_n = U_ref(n−1, t_n) and a
    periodic end, S(s_n, τ_h) = (U_n, H_n) with one more unknown τ_h (the change ends on whichever
    orbit of the fitted control it reaches); soft: U_k near U_ref (σ 0.002) and monotone
    (penalty), τ_k near the prior. Both: penalties keep H_k in the band and θ0_k in the touchdown-angle band.
    bases (energy "b" only): n Controls, step k's K, a, c, T_c (a change through several cycles, e.g. the
    speed law's; b_k then stays within b_band of the prior's b_k); default the cycle's control for every step.
    step_times (energy "b" only): (n,) [√(l0/g)] soft durations of the steps (σ ``_S_STEP_TIME``; the law's).
    Returns (τ (n,), b (n,), θ0 of the periodic step that follows (θ0-only; else None)); raises
    _StepFail when the constraints cannot be met.
    """
    p = _shooting_problem(cyc, U0, H0, t0, n, U_ref, prior, H_t, mode, comfort, bases, step_times)
    z = _first_guess(p, tau_start, bases)
    e = _evaluate(p, z, jac=True)
    if e is None:
        raise _StepFail(0, U0, H0, U_ref(0, t0 + cyc.step_time), "no valid first guess for the steps")
    e = _gauss_newton(p, z, e, max_iter)
    _check_change(p, e)
    return e["tau"], e["b"], e["th_h"]
