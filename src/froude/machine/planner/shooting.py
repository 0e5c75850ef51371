"""§5.3, the problem: periodic target orbits, one-step solves and the multiple-shooting optimisation of a
speed change on the exact simulator (dimensionless). The policy that chooses what to ask is in
``planner.policy``; the whole method is described in ``froude.machine.planner``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace

import numpy as np

from froude.errors import FitError, PlanError
from froude.machine.dynamics import N_PER_STANCE, REASONS, Control, StepResult, step
from froude.machine.orbit import LimitCycle, cycle_record, solve_orbit, step_map_eigenvalues

#: Newton tolerance on the reference hit, max(|U' − U_ref|, |H' − H_ref|) ...
_TOL = 1e-11
#: ... and the largest residual still accepted when iterations stall there (the RK4 step map of
#: a passive runner conserves energy only to ~1e-9, which puts a floor under periodic orbits).
_ACCEPT = 1e-8
#: The change steps' continuity and speed constraints are met to this (or as far as Newton still lowers them):
#: the plan is re-simulated step by step, and the step maps (|λ| up to ≈ 3.5) amplify what is left over 8
#: steps (1e-11 became a 4e-8 overshoot of the last apex, a non-monotone plan).
_TOL_SHOOT = 1e-14


@dataclass(frozen=True)
class Comfort:
    """Feasibility and comfort bounds of a plan (dimensionless; relative to the start cycle).

    theta_band:  |θ0 − θ0_cycle| ≤ theta_band [rad] (default 20°)
    H_band:      apex height within H_cycle + (lo, hi) [l0]
    b_band:      |b − b_cycle| ≤ b_band [l0 per stance]; 0 forbids the energy knob
    max_stance:  t_stance ≤ max_stance × the cycle's t_stance
    max_peak_force: peak leg force ≤ max_peak_force × the cycle's peak force
    settle_H:    θ0-only plans must end within settle_H [l0] of a periodic orbit at the target
    """

    theta_band: float = math.radians(20.0)
    H_band: tuple = (-0.10, 0.15)
    b_band: float = 0.08
    max_stance: float = 2.0
    max_peak_force: float = 1.6
    settle_H: float = 0.01


#: The default bounds (a frozen value, shared).
DEFAULT_COMFORT = Comfort()




# --- the cycle, in whatever form ----------------------------------------------------------------
def _as_cycle(cycle) -> LimitCycle:
    """The start cycle as the one cycle record (``orbit.LimitCycle``), its durations, step and peak force
    re-measured by the simulator (one source of truth for the bounds): from a LimitCycle, a fitted
    SimpleMachine or anything with U, H, theta0, control (dimensionless)."""
    try:
        c = cycle.control
        ctl = Control(*(float(v) for v in c.as_tuple()))
        U, H, th = float(cycle.U), float(cycle.H), float(cycle.theta0)
    except (AttributeError, TypeError, ValueError) as e:
        raise PlanError(f"not a running cycle (needs U, H, theta0, control): {e}") from None
    if not all(math.isfinite(v) for v in (U, H, th, *ctl.as_tuple())) or U <= 0:
        raise PlanError(f"the start cycle is not a valid running cycle (U={U}, H={H})")
    r = step(U, H, th, ctl)
    if not bool(r.valid):
        raise PlanError(f"the start cycle's step is invalid: {REASONS[int(r.reason)]}")
    return LimitCycle(U=U, H=H, theta0=th, control=ctl, t_stance=float(r.t_stance), t_fall=float(r.t_fall),
                      t_rise=float(r.t_rise), t_flight=float(r.t_rise + r.t_fall), step_length=float(r.apex_dx),
                      step_time=float(r.t_fall + r.t_stance + r.t_rise), peak_force=float(r.peak_force),
                      iterations=0, residual=0.0, eigenvalues=np.full(2, np.nan + 0j))


def _bounds(cyc: LimitCycle, comfort: Comfort, energy: str):
    """((θ_lo, θ_hi), (b_lo, b_hi)) of the inputs."""
    th = (cyc.theta0 - comfort.theta_band, cyc.theta0 + comfort.theta_band)
    bb = comfort.b_band if energy == "b" else 0.0
    return th, (cyc.control.b - bb, cyc.control.b + bb)


def _step_ok(r, cyc: LimitCycle, comfort: Comfort):
    """(N,) bool: valid step inside the comfort bounds (stance length, peak force, apex height)."""
    H_lo, H_hi = cyc.H + comfort.H_band[0], cyc.H + comfort.H_band[1]
    with np.errstate(invalid="ignore"):
        return (r.valid & (r.t_stance <= comfort.max_stance * cyc.t_stance)
                & (r.peak_force <= comfort.max_peak_force * cyc.peak_force)
                & (r.H_next >= H_lo - 1e-9) & (r.H_next <= H_hi + 1e-9))


def _why_not(r, i, cyc: LimitCycle, comfort: Comfort) -> str:
    """Reason text for row i of a StepResult failing :func:`_step_ok`."""
    if not r.valid[i]:
        return REASONS[int(r.reason[i])]
    if r.t_stance[i] > comfort.max_stance * cyc.t_stance:
        return f"stance {r.t_stance[i]:.3g} > {comfort.max_stance:g}x the cycle's"
    if r.peak_force[i] > comfort.max_peak_force * cyc.peak_force:
        return f"peak force {r.peak_force[i]:.3g} m g > {comfort.max_peak_force:g}x the cycle's"
    return f"apex height H' = {r.H_next[i]:.3g} outside the band"


# --- exact evaluation and the solver ---------------------------------------------------------------------
#: Rows up to this count go one by one through the simulator's scalar path: measured ≈ 0.5 ms per
#: row against ≈ 10 ms for *any* small vectorised batch (NumPy call overhead on ~100 RK4 nodes).
_SMALL = 24
_STEP_FIELDS = tuple(f.name for f in fields(StepResult))


def _steps(U, H, theta0, b, control: Control) -> StepResult:
    """step() on rows (m,) of apex U, H, touchdown angle θ0 and control b (broadcast), the rest of
    the control fixed (or per row: its K, a, c, T_c may be (m,) arrays). Results are the simulator's own
    (scalar and batched paths agree to 1e-12)."""
    U, H, th, bb = np.broadcast_arrays(*(np.atleast_1d(np.asarray(v, float)) for v in (U, H, theta0, b)))
    if U.size > _SMALL:
        return step(U, H, th, replace(control, b=bb))  # type: ignore[arg-type]  # step() broadcasts fields
    if all(np.ndim(getattr(control, f)) == 0 for f in Control.NAMES if f != "b"):
        rows = [step(float(u), float(h), float(t), replace(control, b=float(v)))
                for u, h, t, v in zip(U, H, th, bb)]
    else:  # per-row controls (a change through several cycles): row i takes its own K, a, c, T_c
        per = {f: np.broadcast_to(np.asarray(getattr(control, f), float), U.shape) for f in ("K", "a", "c", "T_c")}
        rows = [step(float(U[i]), float(H[i]), float(th[i]),
                     Control(b=float(bb[i]), **{f: float(v[i]) for f, v in per.items()})) for i in range(U.size)]
    return StepResult(**{f: np.array([getattr(r, f) for r in rows]).reshape(U.shape)
                         for f in _STEP_FIELDS})


#: Simulator calls of one solve: 40 Newton iterations of a point, its Jacobian and up to 14 damped retries
#: (the ill-conditioned θ0-only orbits converge linearly through the retries and need most of them).
_MAX_CALLS = 40 * 16


def _solve(evaluate, z0, s, h, lo, hi, what):
    """``orbit.solve_orbit`` as the planner runs it: Newton with a fresh Jacobian every iteration at the
    simulator's full resolution (``_steps``), iterates inside the box [lo, hi], a rejected step retried
    with Levenberg–Marquardt damping (the θ0-only orbits' Jacobian is nearly singular: the fitted control
    hardly changes the apex energy), tolerance _TOL, a stall at most _ACCEPT still accepted.
    Returns (z (d,), R (r,)); raises FitError when no root is found."""
    z, _, _, R = solve_orbit(evaluate, z0, s, h, lo=lo, hi=hi, tol=_TOL, accept=_ACCEPT, max_iter=_MAX_CALLS,
                             resolutions=(N_PER_STANCE, N_PER_STANCE), chord=False, batched=False,
                             max_halvings=14, damped=True, what=what)
    return z, R


# --- target cycle ---------------------------------------------------------------------------------
def _theta_of(H, tau):
    """Touchdown angle [rad] for apex height H and apex → touchdown fall time τ: cos θ0 = H − τ²/2.
    NaN where that height is above the leg length (H − τ²/2 > 1) or not positive.

    The planner's internal input is τ, not θ0: every τ ≥ 0 is a reachable touchdown, so Newton
    iterations cannot fall off the "apex below touchdown height" cliff that the fitted cycles sit
    next to (their apex is only ≈ 0.01 l0 above the touchdown height)."""
    y = np.asarray(H, float) - 0.5 * np.asarray(tau, float) ** 2
    with np.errstate(invalid="ignore"):
        return np.where((y <= 1.0) & (y > 0.0), np.arccos(np.clip(y, -1.0, 1.0)), np.nan)


#: Scales of the orbit unknowns (τ [√(l0/g)], b [l0], H [l0]): how far each moves per unit cost.
_ORBIT_SCALES = np.array([0.05, 0.01, 0.02])


def _orbit(cyc: LimitCycle, U_t, prior, energy, comfort):
    """Periodic orbit at apex speed U_t nearest prior (τ, b, H) in the scaled norm (minimum-norm
    Newton from the prior, ``orbit.solve_orbit``; scales _ORBIT_SCALES), inside the comfort box of b and
    H (τ in 0..10). energy "b": τ, b and H free; "theta": b fixed. Returns (LimitCycle or None, problems
    list)."""
    ctl = cyc.control

    def evaluate(Z, n):  # n: _steps runs at full resolution
        r = _steps(U_t, Z[:, 2], _theta_of(Z[:, 2], Z[:, 0]), Z[:, 1], ctl)
        return np.stack([r.U_next - U_t, r.H_next - Z[:, 2]], 1), r
    _, b_b = _bounds(cyc, comfort, energy)
    lo = np.array([0.0, b_b[0], cyc.H + comfort.H_band[0]])
    hi = np.array([10.0, b_b[1], cyc.H + comfort.H_band[1]])
    s = _ORBIT_SCALES * (1.0, 1.0 if energy == "b" else 0.0, 1.0)
    try:
        z, R = _solve(evaluate, np.asarray(prior, float), s, 1e-6 * _ORBIT_SCALES, lo, hi, "orbit")
    except FitError as e:
        return None, [f"no periodic orbit within the bounds ({e})"]
    tau, b, H = z
    lc = cycle_record(float(U_t), float(H), float(_theta_of(H, tau)), replace(ctl, b=float(b)),
                      np.max(np.abs(R)), eigenvalues=False)
    return lc, _orbit_problems(lc, cyc, comfort, energy)


def _orbit_problems(lc, cyc: LimitCycle, comfort: Comfort, energy: str) -> list:
    """Comfort violations of an orbit, relative to the start cycle."""
    probs = []
    th_b, _ = _bounds(cyc, comfort, energy)
    if not th_b[0] - 1e-9 <= lc.theta0 <= th_b[1] + 1e-9:
        probs.append(f"its touchdown angle {math.degrees(lc.theta0):.1f} deg is outside "
                     f"{math.degrees(th_b[0]):.1f}..{math.degrees(th_b[1]):.1f} deg")
    if lc.t_stance > comfort.max_stance * cyc.t_stance:
        probs.append(f"its stance {lc.t_stance:.3g} is > {comfort.max_stance:g}x the cycle's")
    if lc.peak_force > comfort.max_peak_force * cyc.peak_force:
        probs.append(f"its peak force {lc.peak_force:.3g} m g is > {comfort.max_peak_force:g}x the cycle's")
    return probs


def _orbits(cyc: LimitCycle, U_nodes, energy: str, comfort: Comfort, H_prior=None):
    """Continuation of periodic orbits through U_nodes from the start cycle (apex height prior
    H_prior, default the cycle's); yields (U, LimitCycle or None, problems), stops at the first
    failure."""
    prior = (cyc.t_fall, cyc.control.b, cyc.H if H_prior is None else H_prior)
    for Un in U_nodes:
        lc, probs = _orbit(cyc, float(Un), prior, energy, comfort)
        yield float(Un), lc, probs
        if lc is None or probs:
            return
        prior = (lc.t_fall, lc.control.b, lc.H)


def target_cycle(cycle, U_target: float, *, energy: str = "b", comfort: Comfort = Comfort(),
                 H_prior: float | None = None) -> LimitCycle:
    """The periodic orbit of the machine at apex speed U_target that a plan ends on (dimensionless).

    The orbit nearest the start cycle in the scaled norm of (fall time τ, b, H) with scales
    (0.05, 0.01, 0.02): energy "b" lets θ0 (via τ), H and the control's b move (b supplies or
    removes the energy the fitted control lacks at U_target); energy "theta" keeps the fitted b.
    K, a, c and T_c always stay the fitted ones. Tried directly, then by continuation in speed
    increments of at most 10 %. H_prior (default the cycle's H) is the apex height the search
    starts from and stays near. Raises PlanError when no orbit exists within the comfort bounds.
    """
    cyc = _as_cycle(cycle)
    U_target = float(U_target)
    if not (math.isfinite(U_target) and U_target > 0):
        raise PlanError(f"target speed must be a finite U > 0, got {U_target}")
    n = max(1, int(math.ceil(abs(math.log(U_target / cyc.U)) / math.log(1.10))))
    for nodes in ([U_target], cyc.U * (U_target / cyc.U) ** (np.arange(1, n + 1) / n)):
        *_, last = _orbits(cyc, nodes, energy, comfort, H_prior)  # the continuation's last node
        if last[1] is not None and not last[2] and last[0] == U_target:
            lc = last[1]
            return replace(lc, eigenvalues=step_map_eigenvalues(lc.U, lc.H, lc.theta0, lc.control))
        if n == 1:
            break
    Un, lc, probs = last
    free = "theta0, H and b" if energy == "b" else "theta0 and H"
    raise PlanError(f"no comfortable periodic running orbit at U = {Un:.4g} ({free} free): "
                    + "; ".join(probs))


def sustainable_range(cycle, *, energy: str = "b", comfort: Comfort = Comfort(), factor: float = 1.1,
                      limits=(0.25, 3.0)) -> tuple:
    """(U_min, U_max): the speeds with a comfortable periodic orbit (see :func:`target_cycle`),
    by continuation from the cycle in factors of ``factor`` (resolution ≈ factor − 1) within
    limits × U. Dimensionless."""
    cyc = _as_cycle(cycle)
    out = []
    for lim in limits:
        m = int(math.floor(abs(math.log(lim)) / math.log(factor)))
        nodes = cyc.U * (factor if lim > 1 else 1.0 / factor) ** np.arange(1, m + 1)
        U_ok = cyc.U
        for Un, lc, probs in _orbits(cyc, nodes, energy, comfort):
            if lc is None or probs:
                break
            U_ok = Un
        out.append(U_ok)
    return out[0], out[1]


# --- one step ---------------------------------------------------------------------------------------
def one_step_range(U, H, cycle, *, energy: str = "b", comfort: Comfort = Comfort(), n_theta: int = 81):
    """(U'_min, U'_max) reachable in one comfortable step from apex (U, H), by one batched
    simulator scan over the θ0 band (× {b − band, b, b + band} when energy="b").
    (nan, nan) if no comfortable step exists."""
    cyc = _as_cycle(cycle)
    th_b, b_b = _bounds(cyc, comfort, energy)
    th = np.linspace(th_b[0], th_b[1], n_theta)
    bs = np.unique(np.array([b_b[0], cyc.control.b, b_b[1]]))
    TH, BB = np.meshgrid(th, bs, indexing="ij")
    r = step(U, H, TH, replace(cyc.control, b=BB))
    ok = _step_ok(r, cyc, comfort)
    if not ok.any():
        return math.nan, math.nan
    return float(np.min(r.U_next[ok])), float(np.max(r.U_next[ok]))


def _theta_scan(U, H, U_r, b, cyc, th_b, theta_prev):
    """θ0 in the band whose step from (U, H) gives U' = U_r, by one batched scan (41 angles, linear
    interpolation between sign changes; nearest to theta_prev), or the valid angle nearest it."""
    th = np.linspace(th_b[0], th_b[1], 41)
    r = step(U, H, th, replace(cyc.control, b=b))
    f = r.U_next - U_r
    with np.errstate(invalid="ignore"):
        good = r.valid[:-1] & r.valid[1:] & (np.sign(f[:-1]) != np.sign(f[1:]))
    if not good.any():
        if not r.valid.any():
            return theta_prev
        return float(th[int(np.argmin(np.where(r.valid, np.abs(f), np.inf)))])
    k = np.flatnonzero(good)
    roots = th[k] + f[k] / (f[k] - f[k + 1]) * (th[1] - th[0])
    return float(roots[np.argmin(np.abs(roots - theta_prev))])


def _solve_step(U, H, t0, ref, th_guess, b_guess, cyc, mode, th_b, b_b):
    """Inputs (θ0, b) for one step from apex (U, H) at time t0 meeting ref(t_next) → (U_ref, H_ref).

    mode "theta": U' = U_ref with b fixed at b_guess; "b": (U', H') = (U_ref, H_ref).
    Newton on the exact simulator (``orbit.solve_orbit`` on a square system), inside the bands th_b, b_b.
    Returns (θ0, b, converged); the guess when not converged.
    """
    ctl = cyc.control

    def evaluate(X, n):  # n: _steps runs at full resolution
        r = _steps(U, H, X[:, 0], X[:, 1], ctl)
        Ur, Hr = ref(t0 + r.t_fall + r.t_stance + r.t_rise)
        R = np.stack([r.U_next - Ur, r.H_next - Hr], 1)
        return (R[:, :1] if mode == "theta" else R), r
    s = np.array([1.0, 0.0 if mode == "theta" else 1.0])
    lo, hi = (th_b[0], b_b[0]), (th_b[1], b_b[1])
    try:
        x, _ = _solve(evaluate, (th_guess, b_guess), s, np.full(2, 1e-7), lo, hi, "step")
    except FitError:
        return float(th_guess), float(b_guess), False
    return float(x[0]), float(x[1]), True


# --- multi-step optimisation of a change (multiple shooting, finite-difference Jacobian rows) -----
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


# Long because the multiple-shooting problem's unknown layout (index offsets iT, iB, iU, iH, it_, ih_) is
# shared by its residual, Jacobian and unpacking closures; split apart they would each re-derive it.
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
    ctl = cyc.control
    tau_p, b_p, H_p = (np.asarray(v, float) for v in prior)
    use_b = mode == "b"
    th_b, b_b = _bounds(cyc, comfort, mode)
    H_lo, H_hi = cyc.H + comfort.H_band[0], cyc.H + comfort.H_band[1]
    s_tau, s_b, s_H, s_U, s_pen = 0.05, 0.01, 0.05, 2e-3, 1e-3
    s_T = _S_STEP_TIME
    sgn_dU = 1.0 if U_ref(n - 1, t0) >= U0 else -1.0
    nb = n if use_b else 0
    # z = [τ (n), b (nb), U_1..n, H_1..n, t_1..n, (θ0-only: τ_h, the fall time of the periodic
    # step that follows: the change must end on *some* orbit of the fitted control)]
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
    eye = np.eye(n)
    nrow = n if use_b else n + 1

    def parts(z):
        tau = z[iT:iT + n]
        b = z[iB:iB + n] if use_b else b_p
        U = np.r_[U0, z[iU:iU + n]]
        H = np.r_[H0, z[iH:iH + n]]
        t = np.r_[t0, z[it_:it_ + n]]
        return tau, b, U, H, t

    # Long because the constraints, soft residuals and their Jacobian columns are evaluated from one batch of
    # perturbed steps, indexed by the shared unknown layout above.
    def evaluate(z, jac=False, h=1e-6):
        """Constraints c, soft residuals r (and their Jacobians) at z; None if a step is invalid."""
        tau, b, U, H, t = parts(z)
        nr = 5 if jac else 1
        d = np.zeros((nr, 4))
        if jac:
            d[1:] = np.eye(4) * h
        base = np.stack([U[:n], H[:n], tau, b], 1)
        if not use_b:
            base = np.vstack([base, [U[n], H[n], z[ih_], b_p[-1]]])
        X = (base[:, None, :] + d[None]).reshape(-1, 4)
        th_rows = _theta_of(X[:, 1], X[:, 2])
        r = _steps(X[:, 0], X[:, 1], th_rows, X[:, 3], row_ctl[nr])
        if not np.all(r.valid & np.isfinite(th_rows)):
            return None
        Y = np.stack([r.U_next, r.H_next, r.t_fall + r.t_stance + r.t_rise], 1).reshape(nrow, nr, 3)
        th_all = th_rows.reshape(nrow, nr)[:, 0]
        th = th_all[:n]
        Ur = np.array([U_ref(k, t[k + 1]) for k in range(n)])
        cont = np.concatenate([Y[:n, 0, 0] - U[1:], Y[:n, 0, 1] - H[1:], t[:n] + Y[:n, 0, 2] - t[1:]])
        if use_b:
            c = np.r_[cont, U[1:] - Ur, H[n] - H_t]
            rr = [(tau - tau_p) / s_tau, (b - b_p) / s_b, (H[1:n] - H_p[:n - 1]) / s_H]
            if step_times is not None:
                rr.append((np.diff(t) - step_times) / s_T)
        else:
            c = np.r_[cont, U[n] - Ur[n - 1], Y[n, 0, 0] - U[n], Y[n, 0, 1] - H[n]]
            rr = [(tau - tau_p) / s_tau, (U[1:n] - Ur[:n - 1]) / s_U,
                  np.maximum(0.0, -sgn_dU * np.diff(U)) / s_pen]
        rr += [(np.maximum(0.0, H_lo - H[1:]) + np.maximum(0.0, H[1:] - H_hi)) / s_pen,
               (np.maximum(0.0, th_b[0] - th) + np.maximum(0.0, th - th_b[1])) / s_pen]
        e = dict(c=c, r=np.concatenate(rr), U=U, H=H, t=t, th=th, Ur=Ur, tau=tau, b=b,
                 tau_h=None if use_b else float(z[ih_]), th_h=None if use_b else float(th_all[n]))
        if not jac:
            return e
        D = (Y[:, 1:, :] - Y[:, :1, :]) / h  # (nrow, inputs U H τ b, outputs U' H' T)
        dUr = np.array([(U_ref(k, t[k + 1] + 1e-6) - U_ref(k, t[k + 1] - 1e-6)) / 2e-6 for k in range(n)])
        # continuity rows o·n + k: output o of step k, S_o(s_k, u_k) − s_{k+1,o}; s_0 is fixed
        Jc = np.zeros((3 * n, m))
        k1 = np.arange(1, n)  # steps whose start state is a variable (entry k − 1)
        for o, col in enumerate((iU, iH, it_)):
            rows = o * n + np.arange(n)
            Jc[rows, iT + np.arange(n)] = D[:n, 2, o]
            if use_b:
                Jc[rows, iB + np.arange(n)] = D[:n, 3, o]
            Jc[rows, col + np.arange(n)] -= 1.0
            Jc[o * n + k1, iU + k1 - 1] += D[k1, 0, o]
            Jc[o * n + k1, iH + k1 - 1] += D[k1, 1, o]
            if o == 2:
                Jc[o * n + k1, it_ + k1 - 1] += 1.0
        # profile rows: U_k − U_ref(k, t_k)
        Jp = np.zeros((n, m))
        Jp[:, iU:iU + n] = eye
        Jp[:, it_:it_ + n] = -eye * dUr
        JHn = np.zeros((1, m))
        JHn[0, iH + n - 1] = 1.0
        if use_b:
            C = np.vstack([Jc, Jp, JHn])
        else:
            # periodic end: S(s_n, τ_h) − (U_n, H_n) = 0
            Jper = np.zeros((2, m))
            for o in range(2):
                Jper[o, iU + n - 1] = D[n, 0, o] - (o == 0)
                Jper[o, iH + n - 1] = D[n, 1, o] - (o == 1)
                Jper[o, ih_] = D[n, 2, o]
            C = np.vstack([Jc, Jp[-1:], Jper])
        # soft rows (same order as rr)
        Jr = []
        Jt = np.zeros((n, m))
        Jt[:, iT:iT + n] = eye / s_tau
        Jr.append(Jt)
        if use_b:
            Jb = np.zeros((n, m))
            Jb[:, iB:iB + n] = eye / s_b
            JH = np.zeros((n - 1, m))
            JH[:, iH:iH + n - 1] = np.eye(n - 1) / s_H
            Jr += [Jb, JH]
            if step_times is not None:  # t_{k+1} − t_k, t_0 fixed
                JT = np.zeros((n, m))
                JT[:, it_:it_ + n] = (eye - np.eye(n, k=-1)) / s_T
                Jr.append(JT)
        else:
            Jr.append(Jp[:n - 1] / s_U)
            act = (-sgn_dU * np.diff(U) > 0).astype(float)
            JM = np.zeros((n, m))
            JM[:, iU:iU + n] = -sgn_dU * (eye - np.eye(n, k=-1))  # U_k − U_{k−1}, U_0 fixed
            Jr.append(act[:, None] * JM / s_pen)
        sg = (H[1:] > H_hi).astype(float) - (H[1:] < H_lo).astype(float)
        JBH = np.zeros((n, m))
        JBH[:, iH:iH + n] = eye * sg / s_pen
        Jr.append(JBH)
        # θ_k = acos(H_k − τ_k²/2): dθ = −(dH_k − τ_k dτ_k)/sin θ_k (H_0 fixed)
        sgt = (th > th_b[1]).astype(float) - (th < th_b[0]).astype(float)
        Jth = np.zeros((n, m))
        Jth[:, iT:iT + n] = eye * (tau / np.sin(th))
        Jth[1:, iH:iH + n - 1] = -np.eye(n - 1) / np.sin(th[1:])[:, None]
        Jr.append(sgt[:, None] * Jth / s_pen)
        e["C"], e["J"] = C, np.vstack(Jr)
        return e

    def merit(e):
        return 0.5 * float(e["r"] @ e["r"]) + 1e3 * float(np.sum(np.abs(e["c"])))

    # start: inputs from the prior (or the table rollout), states by simulating them (or the
    # interpolated references where the simulated run fails)
    tau0 = tau_p if tau_start is None else np.asarray(tau_start, float)
    z = None
    for tau_g, b_g in ((tau0, b_p), (tau_p, b_p), (np.full(n, cyc.t_fall), np.full(n, ctl.b))):
        U, H, t, th, res, ok = _shoot(U0, H0, t0, tau_g, b_g, ctl, bases)
        if ok:
            z = np.r_[tau_g, b_g[:nb], U[1:], H[1:], t[1:], tau_g[-1:] if not use_b else []]
            break
    if z is None:
        Ur = np.array([U_ref(k, t0 + (k + 1) * cyc.step_time) for k in range(n)])
        z = np.r_[tau_p, b_p[:nb], Ur, H_p, t0 + cyc.step_time * np.arange(1, n + 1),
                  tau_p[-1:] if not use_b else []]
    z = np.clip(z, lo, hi)
    e = evaluate(z, jac=True)
    if e is None:
        raise _StepFail(0, U0, H0, U_ref(0, t0 + cyc.step_time), "no valid first guess for the steps")
    polish = False
    history = []
    for _ in range(max_iter):
        C, J, c, r = e["C"], e["J"], e["c"], e["r"]
        q = C.shape[0]
        if polish:
            # constraints only: minimum-norm Newton correction (quadratic convergence)
            dz = np.linalg.lstsq(C, -c, rcond=1e-13)[0]
        else:
            K = np.zeros((m + q, m + q))
            K[:m, :m] = J.T @ J + 1e-9 * np.eye(m)
            K[:m, m:] = C.T
            K[m:, :m] = C
            dz = np.linalg.lstsq(K, np.r_[-J.T @ r, -c], rcond=1e-15)[0][:m]
        phi = merit(e)
        accepted = None
        for alpha in 0.5 ** np.arange(16):
            zt = np.clip(z + alpha * dz, lo, hi)
            et = evaluate(zt)
            if et is None:
                continue
            cm_t = float(np.max(np.abs(et["c"])))
            if (merit(et) < phi) if not polish else (cm_t < float(np.max(np.abs(c)))):
                accepted = (zt, et)
                break
        if accepted is None:
            if polish or float(np.max(np.abs(c))) > 1e-6:
                break
            polish = True
            continue
        z, e_new = accepted
        cmax = float(np.max(np.abs(e_new["c"])))
        history.append(merit(e_new))
        if cmax <= _TOL_SHOOT:
            e = e_new
            break
        if cmax > 1e-6 and len(history) >= 8 and history[-1] > 0.9 * history[-6]:
            e = e_new  # stalled away from feasible: the goal is out of reach
            break
        # the soft objective has stopped improving: finish the constraints by plain Newton
        if not polish and phi - merit(e_new) <= 1e-5 * phi and cmax <= 1e-5:
            polish = True
        e = evaluate(z, jac=True)
        if e is None:
            e = e_new
            break
    if e is None:
        e = evaluate(z)
    cmax = float(np.max(np.abs(e["c"])))
    pen = float(np.max(np.abs(e["r"][-2 * n:]))) * s_pen
    mono = float(np.max(np.r_[0.0, -sgn_dU * np.diff(e["U"])]))
    if cmax > _ACCEPT or pen > 1e-6 or mono > 1e-9:
        if cmax > _ACCEPT:
            k = int(np.argmax(np.abs(e["U"][1:] - e["Ur"]))) if use_b else n - 1
            why = f"the steps cannot meet the speed profile and end height (off by {cmax:.2g})"
        elif pen > 1e-6:
            k, why = 0, f"a step leaves the comfort band (apex height or touchdown angle, by {pen:.2g})"
        else:
            k, why = int(np.argmax(-sgn_dU * np.diff(e["U"]))), f"the speed reverses by {mono:.2g}"
        raise _StepFail(k, float(e["U"][k]), float(e["H"][k]), float(e["Ur"][k]), why)
    return e["tau"], e["b"], e["th_h"]




class _StepFail(Exception):
    """A step could not meet its reference within the bounds (internal; becomes PlanError)."""

    def __init__(self, i, U, H, U_ref, why):
        super().__init__(why)
        self.i, self.U, self.H, self.U_ref, self.why = i, U, H, U_ref, why

