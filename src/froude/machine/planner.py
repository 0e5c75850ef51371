"""§5.3: plan acceleration and deceleration of the simple machine, step by step (dimensionless).

A *step* is one stance and the flight after it, apex → apex; a stride is two steps. The state at
each apex is (U, H) (speed [√(g l0)], height [l0]); per step the planner chooses the touchdown angle
θ0 — the paper's control input (eq. 5) — and, only where θ0 alone cannot do the job, a small change
δb of the control's linear leg-extension coefficient b ("push harder / softer"). K, a, c and T_c
always stay the fitted ones.

Why b and not a. At a running cycle the step map nearly conserves the apex energy E = ½U² + H
whatever θ0 is (measured on a K = 17 cycle: ΔE' ≈ 0.005 for 8° of θ0): a steeper or flatter leg
only trades speed for height. Halving U = 1.2 with θ0 alone would lift the apex by
½(1.2² − 0.6²) = 0.54 l0, a bound rather than a run, and U × 1.3 would need an apex below the
touchdown height. Energy must be added or removed in stance. Of the control's coefficients, a
(length offset) acts like θ0 (measured ∂U'/∂a ≈ −2.2, ∂E'/∂a ≈ 0.1-0.3), while b (desired length
growing by b l0 over the stance) changes the actuator work ∫ f dl_d almost alone (∂E'/∂b ≈ 2.5,
∂U'/∂b ≈ 0.08). δb is the runner extending the leg more (accelerating) or less (braking) during
the push; the planner keeps |δb| ≤ ``Comfort.b_band`` (0.08 l0; the real clips use ≤ 0.05).

Policy (:func:`plan_speed_change`):

* target: a periodic orbit of the machine at U_t (:func:`target_cycle`), the one nearest the start
  cycle in fall time, b and apex height (scales 0.05, 0.01, 0.02), found by continuation;
* reference speeds: U_ref(k) = U0 + (U_t − U0) s(k/n) for the n change steps, s = ``"ease"``
  (smoothstep 3x² − 2x³: gentle start and end, peak change 1.5× the mean) or ``"even"`` (equal ΔU);
  monotone, so apex speeds never overshoot;
* ``energy="b"``: θ0 and b per step; every apex speed equals U_ref exactly and the last apex is
  the target orbit's fixed point; among the solutions the planner takes the one whose inputs
  stay closest to the start → target interpolation (least squares, scaled);
* ``energy="theta"`` (the paper's): θ0 only; the last apex speed is U_t exactly and the change
  ends on a periodic orbit of the fitted control (whichever it reaches: θ0 only barely moves the
  energy), the intermediate speeds follow U_ref in the least-squares sense and monotonically;
* ``energy="auto"`` (default): θ0 only when that works within the comfort bounds, else θ0 + δb;
* lead steps (before) and hold steps (after) track the start and target fixed points exactly.

Numerics. The change steps are solved together by constrained Gauss–Newton with *multiple
shooting* (inputs and apex states are unknowns tied by continuity constraints; the per-step maps
are unstable, |λ| up to ≈ 2, so single shooting compounds sensitivities) on the exact simulator
:func:`~froude.machine.dynamics.step`, with finite-difference rows batched into one call. Inside,
the touchdown is parametrised by the apex → touchdown fall time τ (cos θ0 = H − τ²/2): every τ ≥ 0
is a reachable touchdown, so iterations cannot fall off the "apex below touchdown" cliff the fitted
cycles sit next to (their apex is only ≈ 0.01-0.05 l0 above touchdown height). With a transition
table, θ0-only plans start from a table rollout (``theta_for_speed`` + ``lookup``, the paper's
use) and lead/hold steps take their first θ0 from it; the answer never comes from the
interpolant: the final plan is re-simulated step by step with the simulator's scalar path (the
one :func:`~froude.machine.dynamics.simulate` uses), so it is exact against direct simulation.
``pipeline.accelerate`` passes no table: on the 9 CMU running clips θ0 alone reaches neither 0.9× nor
1.1× in 8 steps, so every plan there is θ0 + δb, which the table (of the fitted control) does not
cover; given a table, the 18 plans of 0.5×/1.3× are identical to the bit and no faster
(``benchmarks/bench_plan_table.py``).

Everything is dimensionless (l0 = g = m = 1); nothing depends on a character's size or mass, so one
plan serves every dynamically similar character. SI appears only in :meth:`SpeedPlan.to_si`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace
from typing import Any

import numpy as np

from froude.errors import PlanError
from froude.machine.dynamics import REASONS, Control, StepResult, Trajectory, fall_time, simulate, step
from froude.machine.orbit import LimitCycle, cycle_record, step_map_eigenvalues
from froude.machine.units import speed_unit, time_unit

__all__ = ["Comfort", "SpeedPlan", "plan_speed_change", "plan_speed_profile", "target_cycle",
           "one_step_range", "sustainable_range", "speed_fraction_at", "POLICIES", "ENERGY_MODES"]

POLICIES = ("ease", "even")
ENERGY_MODES = ("auto", "theta", "b")
LEAD, CHANGE, HOLD = 0, 1, 2
_PHASE_NAMES = {LEAD: "lead", CHANGE: "change", HOLD: "hold"}

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


@dataclass(frozen=True)
class SpeedPlan:
    """A planned sequence of n steps (dimensionless: l0, √(l0/g), √(g l0), m g; angles rad).

    Per step i (apex i → apex i+1), shape (n,):
      theta0:      touchdown angle [rad]
      b:           the control's b used [l0 per stance] (= the cycle's unless δb was needed)
      controls:    tuple of n :class:`Control` — pass to ``simulate`` as is
      t_fall, t_stance, t_rise: apex → touchdown, stance, liftoff → next apex [√(l0/g)]
      t_flight:    liftoff → next touchdown (t_rise + next step's fall; the last step assumes its own θ0)
      step_length: this contact → next contact [l0] (last step: the next contact at its own θ0)
      x_contact:   contact point x [l0] (x = 0 at apex 0)
      peak_force:  [m g]
      phase:       int8: 0 lead, 1 change, 2 hold
    Per apex, shape (n+1,):
      U, H:        apex speed [√(g l0)] and height [l0] (simulator output, exact)
      U_ref:       the speed the planner aimed at (U_ref[0] = U[0])
      t_apex, x_apex: time [√(l0/g)] and x [l0] of each apex
    Summary: U_start, U_target; target (the target cycle's LimitCycle); mode ("theta" or "b");
    policy; feasible (every bound met, final speed within 3 %, monotone); notes (tuple of str).
    """

    theta0: np.ndarray
    b: np.ndarray
    controls: tuple
    U: np.ndarray
    H: np.ndarray
    U_ref: np.ndarray
    t_apex: np.ndarray
    x_apex: np.ndarray
    x_contact: np.ndarray
    t_fall: np.ndarray
    t_stance: np.ndarray
    t_rise: np.ndarray
    t_flight: np.ndarray
    step_length: np.ndarray
    peak_force: np.ndarray
    phase: np.ndarray
    U_start: float
    U_target: float
    target: LimitCycle | None
    mode: str
    policy: str
    feasible: bool
    notes: tuple = ()

    @property
    def n_steps(self) -> int:
        return int(self.theta0.size)

    @property
    def step_time(self) -> np.ndarray:
        """(n,) apex → apex durations [√(l0/g)]."""
        return np.diff(self.t_apex)

    @property
    def change_steps(self) -> np.ndarray:
        """Indices of the change steps."""
        return np.flatnonzero(self.phase == CHANGE)

    def trajectory(self, dt: float) -> Trajectory:
        """Dense machine trajectory of the whole plan via ``simulate`` (dt in √(l0/g))."""
        return simulate(float(self.U[0]), float(self.H[0]), self.theta0, self.controls, dt)

    def speed_at(self, t) -> np.ndarray:
        """Running speed at time t [√(l0/g)]: apex speeds interpolated linearly over apex times
        (clamped at the ends). The COM's instantaneous horizontal speed also dips in each stance;
        this is the speed a viewer reads off stride by stride."""
        return np.interp(np.asarray(t, float), self.t_apex, self.U)

    def to_si(self, l0_m: float, g: float = 9.81) -> dict:
        """SI views for one character of touchdown leg length l0 [m]: apex speeds [m/s], apex
        heights and contact x [m], apex times and durations [s], touchdown angles [deg]."""
        T, V = time_unit(l0_m, g), speed_unit(l0_m, g)
        return {"U_m_s": self.U * V, "H_m": self.H * l0_m, "t_apex_s": self.t_apex * T,
                "x_contact_m": self.x_contact * l0_m, "t_stance_s": self.t_stance * T,
                "t_flight_s": self.t_flight * T, "step_length_m": self.step_length * l0_m,
                "theta0_deg": np.degrees(self.theta0)}

    def summary(self) -> str:
        """One line per step: phase, θ0 [deg], δb, U, H, times."""
        rows = [f"{'i':>3} {'phase':>6} {'theta0':>8} {'b':>8} {'U':>7} {'H':>7} {'t_st':>6} {'t_fl':>6}"]
        for i in range(self.n_steps):
            rows.append(f"{i:>3} {_PHASE_NAMES[int(self.phase[i])]:>6} {math.degrees(self.theta0[i]):8.3f} "
                        f"{self.b[i]:8.4f} {self.U[i + 1]:7.4f} {self.H[i + 1]:7.4f} "
                        f"{self.t_stance[i]:6.3f} {self.t_flight[i]:6.3f}")
        return "\n".join(rows)


def speed_fraction_at(plan: SpeedPlan, t) -> np.ndarray:
    """Running speed at time t [√(l0/g)] (see :meth:`SpeedPlan.speed_at`) as a fraction of the
    start speed. For a character of leg length l0 [m], t = t_s / √(l0/g)."""
    return plan.speed_at(t) / plan.U_start


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


# --- exact evaluation and Newton ---------------------------------------------------------------------
#: Rows up to this count go one by one through the simulator's scalar path: measured ≈ 0.5 ms per
#: row against ≈ 10 ms for *any* small vectorised batch (NumPy call overhead on ~100 RK4 nodes).
_SMALL = 24
_STEP_FIELDS = tuple(f.name for f in fields(StepResult))


def _steps(U, H, theta0, b, control: Control) -> StepResult:
    """step() on rows (m,) of apex U, H, touchdown angle θ0 and control b (broadcast), the rest of
    the control fixed. Results are the simulator's own (scalar and batched paths agree to 1e-12)."""
    U, H, th, bb = np.broadcast_arrays(*(np.atleast_1d(np.asarray(v, float)) for v in (U, H, theta0, b)))
    if U.size > _SMALL:
        return step(U, H, th, replace(control, b=bb))  # type: ignore[arg-type]  # step() broadcasts fields
    rows = [step(float(u), float(h), float(t), replace(control, b=float(v)))
            for u, h, t, v in zip(U, H, th, bb)]
    return StepResult(**{f: np.array([getattr(r, f) for r in rows]).reshape(U.shape)
                         for f in _STEP_FIELDS})


def _newton(resid, x0, lo, hi, free, *, tol=_TOL, max_iter=40, h=1e-7):
    """Drive resid(x) → 0 over the ``free`` coordinates of x, kept inside the box [lo, hi].

    resid(X (m, d)) → (R (m, r), valid (m,) bool). Forward-difference Jacobian (one extra row per free
    coordinate, stepping inward at the box's upper edge or where a row is invalid) and
    Levenberg–Marquardt steps (damping raised ×10 until max|R| decreases, lowered after success):
    plain Newton when the Jacobian is well conditioned, safe when it is (near) rank deficient —
    e.g. the passive spring-mass runner, whose energy conservation ties U' − U to H' − H.
    Returns (x (d,), R (r,) or None, converged bool).
    """
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    x = np.clip(np.asarray(x0, float), lo, hi)
    R, v = resid(x[None])
    if not v[0]:
        return x, None, False
    R = R[0]
    mu = 1e-10
    for _ in range(max_iter):
        nrm = float(np.max(np.abs(R)))
        if nrm <= tol:
            return x, R, True
        hs = np.where(x[free] + h <= hi[free], h, -h)
        X = np.repeat(x[None], len(free), axis=0)
        X[np.arange(len(free)), free] += hs
        RJ, vJ = resid(X)
        if not vJ.all():
            X[~vJ, free[~vJ]] -= 2 * hs[~vJ]
            hs = np.where(vJ, hs, -hs)
            RJ2, vJ2 = resid(X[~vJ])
            RJ[~vJ], vJ[~vJ] = RJ2, vJ2
            if not vJ.all():
                return x, R, False
        J = ((RJ - R[None]) / hs[:, None]).T  # (r, nf)
        JtJ, g = J.T @ J, J.T @ R
        scale = float(np.trace(JtJ)) / len(free) or 1.0
        for _ in range(14):
            dx = -np.linalg.solve(JtJ + mu * scale * np.eye(len(free)), g)
            xt = x.copy()
            xt[free] += dx
            xt = np.clip(xt, lo, hi)
            Rt, vt = resid(xt[None])
            if vt[0] and float(np.max(np.abs(Rt[0]))) < nrm:
                x, R = xt, Rt[0]
                mu = max(mu * 0.1, 1e-12)
                break
            mu *= 10.0
        else:
            break  # no decrease at any damping: a floor (integration error) or a dead end
    return x, R, float(np.max(np.abs(R))) <= _ACCEPT


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
    Newton from the prior; scales _ORBIT_SCALES). energy "b": τ, b and H free; "theta": b fixed.
    Returns (LimitCycle or None, problems list)."""
    ctl = cyc.control
    s = _ORBIT_SCALES

    def resid(Xs):
        X = Xs * s
        r = _steps(U_t, X[:, 2], _theta_of(X[:, 2], X[:, 0]), X[:, 1], ctl)
        return np.stack([r.U_next - U_t, r.H_next - X[:, 2]], 1), r.valid
    _, b_b = _bounds(cyc, comfort, energy)
    lo = np.array([0.0, b_b[0], cyc.H + comfort.H_band[0]]) / s
    hi = np.array([10.0, b_b[1], cyc.H + comfort.H_band[1]]) / s
    free = np.array([0, 1, 2]) if energy == "b" else np.array([0, 2])
    x, R, ok = _newton(resid, np.asarray(prior, float) / s, lo, hi, free, h=1e-6)
    if not ok:
        why = "the search left the valid region" if R is None else f"residual {np.max(np.abs(R)):.2g}"
        return None, [f"no periodic orbit within the bounds ({why})"]
    tau, b, H = x * s
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
    Newton on the exact simulator. Returns (θ0, b, converged).
    """
    ctl = cyc.control

    def resid(X):
        r = _steps(U, H, X[:, 0], X[:, 1], ctl)
        Ur, Hr = ref(t0 + r.t_fall + r.t_stance + r.t_rise)
        R = np.stack([r.U_next - Ur, r.H_next - Hr], 1)
        return (R[:, :1] if mode == "theta" else R), r.valid
    free = np.array([0]) if mode == "theta" else np.array([0, 1])
    lo, hi = (th_b[0], b_b[0]), (th_b[1], b_b[1])
    x, R, ok = _newton(resid, (th_guess, b_guess), lo, hi, free)
    return float(x[0]), float(x[1]), ok


# --- multi-step optimisation of a change (multiple shooting, finite-difference Jacobian rows) -----
def _shoot(U0, H0, t0, tau, b, ctl):
    """Simulate steps with inputs (τ_k, b_k) from apex (U0, H0) at time t0 (scalar simulator path,
    the one ``simulate`` uses). Returns (U (n+1,), H (n+1,), t (n+1,), θ0 (n,), results list, ok)."""
    n = len(tau)
    U, H, t, th = np.empty(n + 1), np.empty(n + 1), np.empty(n + 1), np.full(n, np.nan)
    U[0], H[0], t[0] = U0, H0, t0
    res: list[StepResult] = []
    for k in range(n):
        th[k] = _theta_of(H[k], tau[k])
        r = step(U[k], H[k], th[k], replace(ctl, b=float(b[k])))
        if not (bool(r.valid) and math.isfinite(th[k])):
            return U, H, t, th, res, False
        res.append(r)
        U[k + 1], H[k + 1] = float(r.U_next), float(r.H_next)
        t[k + 1] = t[k] + float(r.t_fall + r.t_stance + r.t_rise)
    return U, H, t, th, res, True


# Long because the multiple-shooting problem's unknown layout (index offsets iT, iB, iU, iH, it_, ih_) is
# shared by its residual, Jacobian and unpacking closures; split apart they would each re-derive it.
def _optimise_change(cyc, U0, H0, t0, n, U_ref, prior, H_t, mode, comfort, tau_start=None,
                     max_iter=80):
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
    Returns (τ (n,), b (n,), θ0 of the periodic step that follows (θ0-only; else None)); raises
    _StepFail when the constraints cannot be met.
    """
    ctl = cyc.control
    tau_p, b_p, H_p = (np.asarray(v, float) for v in prior)
    use_b = mode == "b"
    th_b, b_b = _bounds(cyc, comfort, mode)
    H_lo, H_hi = cyc.H + comfort.H_band[0], cyc.H + comfort.H_band[1]
    s_tau, s_b, s_H, s_U, s_pen = 0.05, 0.01, 0.05, 2e-3, 1e-3
    sgn_dU = 1.0 if U_ref(n - 1, t0) >= U0 else -1.0
    nb = n if use_b else 0
    # z = [τ (n), b (nb), U_1..n, H_1..n, t_1..n, (θ0-only: τ_h, the fall time of the periodic
    # step that follows: the change must end on *some* orbit of the fitted control)]
    iT, iB, iU, iH, it_ = 0, n, n + nb, 2 * n + nb, 3 * n + nb
    ih_ = 4 * n + nb
    m = 4 * n + nb + (0 if use_b else 1)
    lo = np.r_[np.zeros(n), np.full(nb, b_b[0]), np.full(3 * n, -np.inf), np.zeros(m - ih_)]
    hi = np.r_[np.full(n, 10.0), np.full(nb, b_b[1]), np.full(3 * n, np.inf), np.full(m - ih_, 10.0)]
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
        r = _steps(X[:, 0], X[:, 1], th_rows, X[:, 3], ctl)
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
        U, H, t, th, res, ok = _shoot(U0, H0, t0, tau_g, b_g, ctl)
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
        if cmax <= _TOL:
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


def _record(out, th, b, r, phase, U_ref_next):
    """Append one simulated step (StepResult r with scalar or (1,) fields) to the plan lists."""
    f1 = {f: float(np.ravel(getattr(r, f))[0]) for f in ("x_contact", "t_fall", "t_stance", "t_rise",
                                                          "peak_force", "U_next", "H_next", "apex_dx")}
    out["theta0"].append(th)
    out["b"].append(b)
    out["_b"] = b
    out["x_contact"].append(out["x_apex"][-1] + f1["x_contact"])
    for f in ("t_fall", "t_stance", "t_rise", "peak_force"):
        out[f].append(f1[f])
    out["t_apex"].append(out["t_apex"][-1] + f1["t_fall"] + f1["t_stance"] + f1["t_rise"])
    out["U"].append(f1["U_next"])
    out["H"].append(f1["H_next"])
    out["U_ref"].append(U_ref_next)
    out["x_apex"].append(out["x_apex"][-1] + f1["apex_dx"])
    out["phase"].append(phase)


# --- planning core ----------------------------------------------------------------------------------
def _ease(s, policy):
    s = np.clip(np.asarray(s, float), 0.0, 1.0)
    if policy == "even":
        return s
    return s * s * (3.0 - 2.0 * s)


class _StepFail(Exception):
    """A step could not meet its reference within the bounds (internal; becomes PlanError)."""

    def __init__(self, i, U, H, U_ref, why):
        super().__init__(why)
        self.i, self.U, self.H, self.U_ref, self.why = i, U, H, U_ref, why


_OUT_KEYS = ("theta0", "b", "U", "H", "U_ref", "t_apex", "x_apex", "x_contact", "t_fall", "t_stance",
             "t_rise", "peak_force", "phase")


def _new_out(U, H, b):
    out: dict[str, Any] = {k: [] for k in _OUT_KEYS}
    out.update(U=[U], H=[H], U_ref=[U], t_apex=[0.0], x_apex=[0.0])
    out["_b"] = b
    return out


def _run(cyc, out, phase, n, ref_k, done, comfort, mode, table):
    """Append steps to ``out`` (continuing from its last apex) until n steps (or done(t) is true).

    ref_k(k, t_next) → (U_ref, H_ref) for the k-th step of this segment, whose next apex is at time
    t_next. Bounds are relative to the start cycle ``cyc``. Raises _StepFail.
    """
    th_b, b_b = _bounds(cyc, comfort, mode)
    solve_mode = "b" if mode == "b" else "theta"
    k = 0
    while (k < n) if n is not None else not done(out["t_apex"][-1]):
        U, H, t = out["U"][-1], out["H"][-1], out["t_apex"][-1]
        theta_prev = out["theta0"][-1] if out["theta0"] else cyc.theta0

        def ref(t_next, k=k):
            return ref_k(k, t_next)
        U_guess = float(ref(t + cyc.step_time)[0])
        th0 = theta_prev
        if table is not None and out["_b"] == cyc.control.b:
            tt, ok = table.theta_for_speed(U, H, U_guess, theta_ref=theta_prev)
            if bool(ok) and th_b[0] <= float(tt) <= th_b[1]:
                th0 = float(tt)
        th, b, conv = _solve_step(U, H, t, ref, th0, out["_b"], cyc, solve_mode, th_b, b_b)
        if not conv:  # a poor start: scan the band once for a better one
            th0 = _theta_scan(U, H, U_guess, out["_b"], cyc, th_b, theta_prev)
            th, b, conv = _solve_step(U, H, t, ref, th0, out["_b"], cyc, solve_mode, th_b, b_b)
        r = _steps(U, H, th, b, cyc.control)
        ok = bool(_step_ok(r, cyc, comfort)[0])
        if not (conv and ok):
            why = _why_not(r, 0, cyc, comfort) if not ok else "the reference is out of reach"
            raise _StepFail(len(out["theta0"]), U, H, U_guess, why)
        t_next = t + float(r.t_fall[0] + r.t_stance[0] + r.t_rise[0])
        _record(out, th, b, r, phase, float(ref(t_next)[0]))
        k += 1
        if len(out["theta0"]) > 10000:
            raise PlanError("plan longer than 10000 steps")
    return out


def _finish(cyc, out, U_target, target, mode, policy, notes):
    """Assemble the SpeedPlan: flight times and step lengths use the next step's θ0."""
    th = np.array(out["theta0"])
    U, H = np.array(out["U"]), np.array(out["H"])
    th_next = np.append(th[1:], th[-1])
    t_rise = np.array(out["t_rise"])
    t_fall_next = fall_time(H[1:], th_next)
    t_flight = t_rise + t_fall_next
    x_apex = np.array(out["x_apex"])
    x_contact = np.array(out["x_contact"])
    step_length = x_apex[1:] + U[1:] * t_fall_next + np.sin(th_next) - x_contact
    b = np.array(out["b"])
    controls = tuple(replace(cyc.control, b=float(v)) for v in b)
    phase = np.array(out["phase"], np.int8)
    idx = np.flatnonzero(phase == CHANGE)
    notes = list(notes)
    monotone = True
    if idx.size and U_target != cyc.U:
        Uc = U[idx[0]:idx[-1] + 2]
        monotone = bool(np.all(np.diff(Uc) * np.sign(U_target - Uc[0]) >= -1e-9))
    final_ok = abs(U[-1] - U_target) <= 0.03 * U_target
    finite = all(np.all(np.isfinite(v)) for v in (th, U, H, t_flight, step_length, x_contact, b))
    if not monotone:
        notes.append("apex speeds are not monotone over the change")
    if not final_ok:
        notes.append(f"final speed {U[-1]:.4g} is not within 3 % of {U_target:.4g}")
    if not finite:
        notes.append("non-finite values in the plan (the last step cannot be followed by another)")
    return SpeedPlan(theta0=th, b=b, controls=controls, U=U, H=H, U_ref=np.array(out["U_ref"]),
                     t_apex=np.array(out["t_apex"]), x_apex=x_apex, x_contact=x_contact,
                     t_fall=np.array(out["t_fall"]), t_stance=np.array(out["t_stance"]), t_rise=t_rise,
                     t_flight=t_flight, step_length=step_length,
                     peak_force=np.array(out["peak_force"]), phase=phase, U_start=cyc.U,
                     U_target=float(U_target), target=target, mode=mode, policy=policy,
                     feasible=monotone and final_ok and finite, notes=tuple(notes))


def _check_common(policy, energy, lead_steps, hold_steps):
    if policy not in POLICIES:
        raise PlanError(f"unknown policy {policy!r}; known: {', '.join(POLICIES)}")
    if energy not in ENERGY_MODES:
        raise PlanError(f"unknown energy mode {energy!r}; known: {', '.join(ENERGY_MODES)}")
    for name, v in (("lead_steps", lead_steps), ("hold_steps", hold_steps)):
        if not isinstance(v, (int, np.integer)) or v < 0:
            raise PlanError(f"{name} must be an integer >= 0, got {v!r}")


def _table_ok(table, cyc):
    if table is None:
        return None
    if tuple(map(float, table.control.as_tuple())) != tuple(map(float, cyc.control.as_tuple())):
        raise PlanError(f"the transition table was built for {table.control}, the cycle runs "
                        f"{cyc.control}; build it with the cycle's control")
    return table


def _unreachable(cyc, U_target, n, fail, comfort, energy, what):
    """PlanError text naming what is reachable (one step from the start, the sustainable range), in the
    machine's dimensionless U, and the same facts as PlanError's keyword arguments: (text, facts)."""
    e = "theta" if energy == "theta" else "b"
    lo1, hi1 = one_step_range(cyc.U, cyc.H, cyc, energy=e, comfort=comfort)
    smin, smax = sustainable_range(cyc, energy=e, comfort=comfort)
    faster = U_target > cyc.U
    if math.isfinite(lo1):
        one = f"the {'fastest' if faster else 'slowest'} reachable in 1 step is U = {hi1 if faster else lo1:.3g}"
    else:
        one = "no comfortable step exists from the start state"
    # the continuation stops at 0.25x and 3x the start speed: a range edge there is a lower bound
    if faster:
        sus = (f"max sustainable U > {smax:.3g}" if smax >= 2.7 * cyc.U else f"max sustainable U ≈ {smax:.3g}")
    else:
        sus = (f"min sustainable U < {smin:.3g}" if smin <= 0.28 * cyc.U else f"min sustainable U ≈ {smin:.3g}")
    n_min = 0
    if not smin <= U_target <= smax:
        rng = f"; reaching U = {U_target:.3g} is outside the machine's range ({sus}, start U = {cyc.U:.3g})"
    else:
        rng = f" (sustainable U ≈ {smin:.3g}..{smax:.3g})"
        per = (hi1 - cyc.U) if faster else (cyc.U - lo1)
        if math.isfinite(per) and per > 0 and n is not None:
            n_min = int(math.ceil(1.5 * abs(U_target - cyc.U) / per))  # "ease" peaks at 1.5x the mean
            if n_min > n:
                rng += f"; try at least {n_min} steps"
    where = ""
    if fail is not None:
        where = (f" [failed at step {fail.i + 1}, from U = {fail.U:.4g}, H = {fail.H:.4g} toward "
                 f"U = {fail.U_ref:.4g}: {fail.why}]")
    facts = dict(U_goal=float(U_target), U_start=float(cyc.U),
                 U_one_step=float(hi1 if faster else lo1) if math.isfinite(lo1) else None,
                 U_sustainable=(float(smin), float(smax)), steps_needed=n_min if n_min > (n or 0) else None)
    return f"cannot reach U = {U_target:.3g} {what}: {one}{rng}{where}", facts


def _as_target(target_U):
    try:
        U_t = float(target_U)
    except (TypeError, ValueError):
        raise PlanError(f"target speed must be a number, got {target_U!r}") from None
    return U_t


def plan_speed_change(cycle, target_U: float, *, n_steps: int | None = None,
                      within_time: float | None = None, table=None, comfort: Comfort = Comfort(),
                      policy: str = "ease", energy: str = "auto", lead_steps: int = 0,
                      hold_steps: int = 0) -> SpeedPlan:
    """Plan touchdown angles (and, if needed, small δb) taking apex speed from the cycle's U to
    ``target_U`` (dimensionless, √(g l0)) and holding it.

    cycle:       the start running cycle: a :class:`LimitCycle`, or a fitted ``SimpleMachine``
                 (anything with U, H, theta0 and a ``control``)
    target_U:    target apex speed (Froude number U = u/√(g l0)); e.g. 0.5 * cycle.U
    n_steps:     the change takes exactly this many steps, or
    within_time: the change ends by this time [√(l0/g)] after its first apex: the plan uses the most
                 change steps whose duration is ≤ within_time (the gentlest change that fits)
    table:       optional :class:`~froude.machine.table.TransitionTable` of the cycle's control;
                 gives each step's initial θ0 (refined on the simulator afterwards)
    comfort:     :class:`Comfort` bounds (relative to the start cycle)
    policy:      "ease" (smoothstep: U_ref(k) = U0 + ΔU (3x² − 2x³), x = k/n) or "even" (equal ΔU)
    energy:      "auto" | "theta" (θ0 only, the paper's control) | "b" (θ0 and δb)
    lead_steps:  steady steps at the start cycle before the change
    hold_steps:  steady steps at the target cycle after the change

    The change steps' apex speeds equal U_ref exactly (monotone, no overshoot, the last one is
    target_U); with energy "b" the apex heights equal H_ref exactly and the change ends on the
    target cycle's fixed point, which the hold steps keep. Returns a :class:`SpeedPlan`. Raises
    PlanError naming what is reachable when the goal is impossible (target ≤ 0, outside the
    machine's sustainable range, a change too fast for n steps).
    """
    cyc = _as_cycle(cycle)
    _check_common(policy, energy, lead_steps, hold_steps)
    table = _table_ok(table, cyc)
    U_t = _as_target(target_U)
    if not math.isfinite(U_t) or U_t <= 0:
        raise PlanError(f"cannot plan a change to U = {U_t:g}: a running machine needs a speed > 0 "
                        f"(the start cycle runs at U = {cyc.U:.4g}; to stop, end the motion instead)")
    if (n_steps is None) == (within_time is None):
        raise PlanError("give exactly one of n_steps or within_time")
    if within_time is not None:
        if not (isinstance(within_time, (int, float)) and math.isfinite(within_time) and within_time > 0):
            raise PlanError(f"within_time must be a time > 0 [sqrt(l0/g)], got {within_time!r}")
        return _within_time(cyc, U_t, float(within_time), table=table, comfort=comfort, policy=policy,
                            energy=energy, lead_steps=lead_steps, hold_steps=hold_steps)
    if not isinstance(n_steps, (int, np.integer)) or n_steps < 1:
        raise PlanError(f"n_steps must be an integer >= 1, got {n_steps!r}")
    return _plan_n(cyc, U_t, int(n_steps), table, comfort, policy, energy, lead_steps, hold_steps)


def _first_mode(energy: str, attempt):
    """Try the energy modes in order ("auto": θ0 only, then θ0 + δb): (plan, tried notes, last _StepFail).

    plan is the first that succeeds, with the failed attempts prepended to its notes, or None.
    """
    tried: list[str] = []
    fail = None
    for mode in (("theta", "b") if energy == "auto" else (energy,)):
        try:
            plan = attempt(mode)
            return replace(plan, notes=tuple(tried) + plan.notes), tried, fail
        except _StepFail as f:
            fail = f
            tried.append(f"{mode}: step {f.i + 1} failed ({f.why})")
        except PlanError as e:
            tried.append(f"{mode}: {e}")
    return None, tried, fail


def _plan_n(cyc, U_t, n, table, comfort, policy, energy, lead_steps, hold_steps):
    plan, tried, fail = _first_mode(energy, lambda mode: _plan_change(cyc, U_t, n, table, comfort, policy, mode,
                                                                      lead_steps, hold_steps))
    if plan is not None:
        return plan
    msg, facts = _unreachable(cyc, U_t, n, fail, comfort, energy, f"in {n} step{'s' if n != 1 else ''}")
    if fail is None:
        msg += " [" + "; ".join(tried) + "]"
    raise PlanError(msg, **facts)


def _table_rollout(table, U0, H0, t0, n, U_ref, step_time, tau_fallback):
    """Initial fall times for n steps from the transition table alone (the paper's §5.3 use):
    per step θ0 = theta_for_speed(U_k, H_k, U_ref), the next apex from the interpolant. Where the
    table has no answer the fallback is kept and the rollout stops."""
    tau = np.array(tau_fallback, float)
    U, H, t = U0, H0, t0
    for k in range(n):
        th, ok = table.theta_for_speed(U, H, U_ref(k, t + step_time))
        if not bool(ok):
            break
        lk = table.lookup(U, H, float(th))
        if not bool(lk.feasible):
            break
        tau[k] = math.sqrt(max(2.0 * (H - math.cos(float(th))), 0.0))
        U, H, t = float(lk.U_next), float(lk.H_next), t + float(lk.t_fall + lk.t_stance + lk.t_rise)
    return tau


def _change_steps(cyc, out, n, U_ref, target, mode, comfort, table, policy):
    """Optimise and append n change steps from out's last apex, ending on a periodic orbit:
    ``target`` (energy "b") or, θ0-only (target None), the orbit of the fitted control the steps
    reach. Returns the orbit (LimitCycle)."""
    U0, H0, t0 = out["U"][-1], out["H"][-1], out["t_apex"][-1]
    w = _ease(np.arange(1, n + 1) / n, policy)
    end = target if target is not None else cyc
    tau_p = cyc.t_fall + (end.t_fall - cyc.t_fall) * w
    b_p = cyc.control.b + (end.control.b - cyc.control.b) * w
    H_t = end.H if target is not None else H0
    H_p = H0 + (H_t - H0) * w
    tau0 = tau_p
    if table is not None and mode == "theta":
        tau0 = _table_rollout(table, U0, H0, t0, n, U_ref, cyc.step_time, tau_p)
    tau, b, th_h = _optimise_change(cyc, U0, H0, t0, n, U_ref, (tau_p, b_p, H_p), H_t, mode, comfort,
                                    tau_start=tau0)
    start = len(out["theta0"])
    for k in range(n):
        U, H = out["U"][-1], out["H"][-1]
        th = float(_theta_of(H, tau[k]))
        r = step(U, H, th, replace(cyc.control, b=float(b[k])))
        t_next = out["t_apex"][-1] + float(r.t_fall + r.t_stance + r.t_rise)
        if not bool(_step_ok(r, cyc, comfort)):
            raise _StepFail(start + k, U, H, U_ref(k, t_next), _why_not(r, (), cyc, comfort))
        _record(out, th, float(b[k]), r, CHANGE, float(U_ref(k, t_next)))
    if target is None:
        target = cycle_record(out["U"][-1], out["H"][-1], float(th_h), cyc.control, 0.0)
        probs = _orbit_problems(target, cyc, comfort, mode)
        if probs:
            raise PlanError("the orbit the theta0-only steps end on is not comfortable: " + "; ".join(probs))
    return target


def _theta_change(cyc, out, n, U_ref, U_t, comfort, table, policy):
    """θ0-only change steps ending on a periodic orbit of the fitted control. θ0 hardly moves the
    apex energy E = ½U² + H, so a change whose energy-consistent end height E0 − ½U_t² lies far
    outside the band is refused at once. Returns the end orbit (raises PlanError / _StepFail)."""
    H_energy = cyc.H + 0.5 * (cyc.U ** 2 - U_t ** 2)
    lo, hi = cyc.H + comfort.H_band[0], cyc.H + comfort.H_band[1]
    if not lo - 0.05 <= H_energy <= hi + 0.05:
        raise PlanError(f"theta0 alone keeps the apex energy, so U = {U_t:.3g} would need an apex "
                        f"height H ≈ {H_energy:.3g} (band {lo:.3g}..{hi:.3g})")
    return _change_steps(cyc, out, n, U_ref, None, "theta", comfort, table, policy)


def _plan_change(cyc, U_t, n, table, comfort, policy, mode, lead_steps, hold_steps):
    """One planning attempt in one energy mode (raises _StepFail / PlanError)."""
    U0 = cyc.U

    def U_ref(k, t):
        return U0 + (U_t - U0) * float(_ease((k + 1) / n, policy))

    out = _new_out(cyc.U, cyc.H, cyc.control.b)
    _run(cyc, out, LEAD, int(lead_steps), lambda k, t: (cyc.U, cyc.H), None, comfort, mode, table)
    if mode == "b":
        target = target_cycle(cyc, U_t, energy=mode, comfort=comfort)
        _change_steps(cyc, out, n, U_ref, target, mode, comfort, table, policy)
    else:
        target = _theta_change(cyc, out, n, U_ref, U_t, comfort, table, policy)
    _run(cyc, out, HOLD, int(hold_steps), lambda k, t: (U_t, target.H), None, comfort, mode, table)
    if mode == "theta":
        note = ("theta0-only control (the paper's): the fitted control in every change step; apex "
                "speeds follow the profile in the least-squares sense, exactly at the end")
    else:
        db = float(np.max(np.abs(np.array(out["b"]) - cyc.control.b))) if out["b"] else 0.0
        note = (f"theta0 + delta-b control: apex speeds follow the profile exactly; "
                f"max |delta b| = {db:.4f} l0")
    return _finish(cyc, out, U_t, target, mode, policy, [note])


def _within_time(cyc, U_t, T, *, table, comfort, policy, energy, lead_steps, hold_steps):
    """The most change steps whose change duration is ≤ T."""

    def dur(p):
        idx = p.change_steps
        return float(p.t_apex[idx[-1] + 1] - p.t_apex[idx[0]])

    plans, errs = {}, {}

    def attempt(k):
        if k not in plans and k not in errs:
            try:
                plans[k] = _plan_n(cyc, U_t, k, table, comfort, policy, energy, lead_steps, hold_steps)
            except PlanError as e:
                errs[k] = e
        return plans.get(k)

    n = max(1, int(T // cyc.step_time))
    p = attempt(n)
    while p is not None and dur(p) > T and n > 1:  # too long: fewer steps
        n -= 1
        p = attempt(n)
    if p is not None and dur(p) <= T:
        while True:  # fits: try one more (gentler)
            q = attempt(n + 1)
            if q is None or dur(q) > T:
                break
            n, p = n + 1, q
    if p is None or dur(p) > T:
        why = errs.get(n)
        msg = (f"cannot reach U = {U_t:.3g} within t = {T:.4g} [sqrt(l0/g)] (one step at the start "
               f"cycle takes {cyc.step_time:.3g})")
        raise PlanError(msg + (f": {why}" if why is not None else ""))
    return replace(p, notes=p.notes + (f"within_time {T:.4g}: {n} change steps lasting {dur(p):.4g}",))


def plan_speed_profile(cycle, profile, *, duration: float | None = None, table=None,
                       comfort: Comfort = Comfort(), energy: str = "auto", lead_steps: int = 0,
                       hold_steps: int = 0) -> SpeedPlan:
    """Follow a speed profile U(t) (dimensionless) at the apexes.

    profile:   a callable t → U (t [√(l0/g)] from the first change apex; ``duration`` required) or
               a pair of arrays (t (m,), U (m,)) interpolated linearly (duration = t[-1] unless
               given). Beyond the profile's end its last value holds.
    Each step picks its inputs so that the speed at its *next apex* equals U(t_next); the apex time
    depends on the inputs and is part of the Newton solve. With energy "b" apex heights follow the
    periodic orbits' heights interpolated by speed; with "theta" they are left free. Steps
    continue until an apex reaches t ≥ duration, then ``hold_steps`` at the end speed. PlanError if
    a step cannot follow the profile, naming the one-step reachable range there.
    """
    cyc = _as_cycle(cycle)
    _check_common("even", energy, lead_steps, hold_steps)
    table = _table_ok(table, cyc)
    if callable(profile):
        fn = profile
        if duration is None:
            raise PlanError("a callable speed profile needs a duration")
    else:
        try:
            tp, Up = (np.asarray(v, float) for v in profile)
        except (TypeError, ValueError):
            raise PlanError("profile must be a callable or a pair of arrays (t, U)") from None
        if tp.ndim != 1 or tp.shape != Up.shape or tp.size < 2 or np.any(np.diff(tp) <= 0):
            raise PlanError("profile arrays must be 1-D, of equal length >= 2, with increasing t")

        def fn(t):
            return np.interp(t, tp, Up)
        duration = float(tp[-1]) if duration is None else duration
    if not (isinstance(duration, (int, float)) and math.isfinite(duration) and duration > 0):
        raise PlanError(f"duration must be > 0, got {duration!r}")
    ts = np.linspace(0.0, duration, 65)
    Us = np.asarray(fn(ts), float) * np.ones_like(ts)
    if not np.all(np.isfinite(Us)) or np.any(Us <= 0):
        raise PlanError(f"the profile must give finite speeds > 0 on [0, {duration:g}]")
    U_end = float(Us[-1])

    plan, tried, fail = _first_mode(energy, lambda mode: _plan_profile(cyc, fn, duration, U_end, Us, table, comfort,
                                                                       mode, lead_steps, hold_steps))
    if plan is not None:
        return plan
    if fail is None:
        raise PlanError("cannot follow the speed profile: " + "; ".join(tried))
    lo, hi = one_step_range(fail.U, fail.H, cyc, energy="theta" if energy == "theta" else "b",
                            comfort=comfort)
    raise PlanError(f"cannot follow the speed profile: at step {fail.i + 1} (U = {fail.U:.4g}, "
                    f"H = {fail.H:.4g}) it asks for U = {fail.U_ref:.4g} but one comfortable step "
                    f"reaches U = {lo:.4g}..{hi:.4g} ({fail.why})")


def _plan_profile(cyc, fn, duration, U_end, Us, table, comfort, mode, lead_steps, hold_steps):
    """One profile-following attempt in one energy mode (raises _StepFail / PlanError)."""
    target = target_cycle(cyc, U_end, energy="b", comfort=comfort) if mode == "b" else None
    out = _new_out(cyc.U, cyc.H, cyc.control.b)
    _run(cyc, out, LEAD, int(lead_steps), lambda k, t: (cyc.U, cyc.H), None, comfort, mode, table)
    t_start = out["t_apex"][-1]
    # as many steps as fit the duration at the mean of the start and end step times
    step_time = 0.5 * (cyc.step_time + (target.step_time if target is not None else cyc.step_time))
    n = max(1, int(round(duration / step_time)))

    def U_ref(k, t):  # the last change apex takes the profile's end value
        return float(fn(duration if k == n - 1 else min(max(t - t_start, 0.0), duration)))
    if mode == "b":
        _change_steps(cyc, out, n, U_ref, target, mode, comfort, table, "even")
    else:
        target = _theta_change(cyc, out, n, U_ref, U_end, comfort, table, "even")
    assert target is not None  # the target orbit (b) or the one the angle-only change reached
    _run(cyc, out, HOLD, int(hold_steps), lambda k, t: (U_end, target.H), None, comfort, mode, table)
    notes = [f"profile followed at the apexes over {n} steps: U(apex) = profile(t_apex - t_start), "
             f"the last apex's speed is the profile's end value"]
    if mode == "theta":
        notes.append("theta0-only control: speeds follow the profile in the least-squares sense")
    return _finish(cyc, out, U_end, target, mode, "profile", notes)
