"""§5.3, the policy: reference speeds (ease / even), lead / change / hold steps, θ0-only first or θ0 + δb,
the plan record (``SpeedPlan``) and the public planners ``plan_speed_change`` and ``plan_speed_profile``.
The problem they pose is solved in ``planner.shooting``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from froude.errors import PlanError
from froude.machine.dynamics import Trajectory, fall_time, simulate, step
from froude.machine.orbit import LimitCycle, cycle_record
from froude.machine.planner.change import _optimise_change
from froude.machine.planner.shooting import (
    DEFAULT_COMFORT,
    Comfort,
    _as_cycle,
    _bounds,
    _orbit_problems,
    _solve_step,
    _step_ok,
    _StepFail,
    _steps,
    _theta_of,
    _theta_scan,
    _why_not,
    one_step_range,
    sustainable_range,
    target_cycle,
)
from froude.machine.units import speed_unit, time_unit

POLICIES = ("ease", "even")
ENERGY_MODES = ("auto", "theta", "b")
LEAD, CHANGE, HOLD = 0, 1, 2
_PHASE_NAMES = {LEAD: "lead", CHANGE: "change", HOLD: "hold"}


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
                      within_time: float | None = None, table=None, comfort: Comfort = DEFAULT_COMFORT,
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
                       comfort: Comfort = DEFAULT_COMFORT, energy: str = "auto", lead_steps: int = 0,
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

