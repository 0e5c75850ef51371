"""§5.3, the problem: periodic target orbits and one-step solves on the exact simulator (dimensionless); the
multiple-shooting optimisation of a speed change is in ``planner.change``. The policy that chooses what to ask is in
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


class _StepFail(Exception):
    """A step could not meet its reference within the bounds (internal; becomes PlanError)."""

    def __init__(self, i, U, H, U_ref, why):
        super().__init__(why)
        self.i, self.U, self.H, self.U_ref, self.why = i, U, H, U_ref, why

