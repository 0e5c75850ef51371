"""A change of running speed along the human speed law (issue 30): every step on its way is the law's.

The §5.3 planner (``planner.policy``) keeps the fitted control's K, a, c and T_c and ends on the periodic
orbit nearest the start cycle, so its cadence at the goal is the spring-mass machine's, not a runner's: its
steps grow with the speed where a runner's cadence would rise (09_01 to x1.5: a 2.19 m step, 1.45 x stature).

Here the change walks through the law's own cycles (``machine.speed.machine_at_speed``: the fitted machine
re-solved at s × its mean speed with the law's step frequency and stance time, all of K, a, b, c, T_c
free), at speed factors s_1 … s_n that move from 1 to the goal's s_n on the policy's profile (ease or even).
Change step k runs with the control (K, a, c, T_c) of the cycle at s_k; the touchdown angles θ0 and changes
δb of each cycle's b (≤ 0.08 l0) are solved together by the §5.3 planner's multiple shooting on the exact
simulator (``planner.change._optimise_change`` with per-step controls): apex k+1 has cycle k's apex speed
exactly and the last apex is the goal cycle's fixed point (U, H); softly, the apex heights stay near the
cycles' and each step lasts its cycle's step time. A step cannot pin its apex height too: from a slower apex
the faster cycle's height would need a touchdown above the apex (measured on 09_01 to x1.3: the nearest
reachable state 0.005 off). The hold steps keep the goal cycle, so the last steps' step frequency and length
are the law's (the ones ``scale`` writes at that speed), and on the way they move along the law with the
speed (step times within ~3 % of the law cycles' on 09_01). The goal is an apex speed (as in
``plan_speed_change``): its factor s_n is found so that the law cycle's apex speed is the goal's (the law is
stated in mean speed; the two differ by ~1 %).

Everything is dimensionless (l0 = g = m = 1) and the same for every dynamically similar character.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np

from froude.errors import FitError, PlanError
from froude.machine.dynamics import step
from froude.machine.planner.change import _optimise_change
from froude.machine.planner.policy import CHANGE, HOLD, LEAD, SpeedPlan, _ease, _finish, _new_out, _record, _run
from froude.machine.planner.shooting import (
    DEFAULT_COMFORT,
    Comfort,
    _as_cycle,
    _step_ok,
    _StepFail,
    _theta_of,
    _why_not,
)

__all__ = ["law_goal_factor", "law_factors", "law_cycles", "plan_law_change"]

#: The goal's law cycle has the goal's apex speed to this relative tolerance [-] ...
_GOAL_RTOL = 1e-6
#: ... found in at most this many fixed-point updates s <- s U_goal / U(s) (each one cycle search).
_GOAL_ITER = 8


def law_goal_factor(cycle_at: Callable, U_start: float, U_goal: float) -> tuple:
    """(s, cycle): the law's speed factor whose cycle runs at apex speed U_goal, and that cycle.

    cycle_at(s): the law's cycle (a SimpleMachine: U, H, theta0, control) at s × the clip's mean speed;
    U_start, U_goal: apex speeds [√(g l0)]. The apex-to-mean speed ratio of the law's cycles changes slowly
    with s (by ~1 % from x1 to x1.5), so s <- s U_goal / U(s) converges in two or three updates."""
    s = U_goal / U_start
    for _ in range(_GOAL_ITER):
        cyc = cycle_at(s)
        if abs(cyc.U / U_goal - 1.0) <= _GOAL_RTOL:
            break
        s *= U_goal / cyc.U
    return s, cycle_at(s)


def law_factors(s_goal: float, n_steps: int, policy: str = "ease") -> np.ndarray:
    """(n,) the law's speed factors that the n change steps end at: 1 → s_goal on the policy's profile
    (``ease``: smoothstep, ``even``: equal steps), the last one s_goal. [-]"""
    return 1.0 + (s_goal - 1.0) * _ease(np.arange(1, n_steps + 1) / n_steps, policy)


def plan_law_change(start, cycles, *, policy: str = "ease", lead_steps: int = 0, hold_steps: int = 0,
                    comfort: Comfort = DEFAULT_COMFORT) -> SpeedPlan:
    """Plan a change of speed through a sequence of periodic cycles (dimensionless).

    start: the start cycle (the fitted machine: U, H, theta0, control); cycles: the n cycles the n change
    steps run with, in order (the law's at ``law_factors``; the last one is the goal and the hold steps keep
    it). Change step k uses cycle k's control (K, a, c, T_c) with its own touchdown angle and b (within
    b_band of cycle k's), solved together by the planner's multiple shooting (``change._optimise_change``)
    so that apex k+1 has cycle k's speed U exactly, the last apex is the goal's fixed point (U, H) and the
    apex heights on the way stay near the cycles' (a step cannot also pin its height: from a slower apex the
    touchdown would have to be above it). Returns a SpeedPlan (mode "law"; ``controls`` per step carry each
    step's K, a, b, c, T_c). Raises PlanError naming the step that cannot follow.
    """
    if not cycles:
        raise PlanError("a change along the law needs at least one step")
    cyc0 = _as_cycle(start)
    targets = [_as_cycle(c) for c in cycles]
    goal = targets[-1]
    n = len(targets)
    out = _new_out(cyc0.U, cyc0.H, cyc0.control.b)
    bases = [cyc0.control] * int(lead_steps) + [c.control for c in targets] + [goal.control] * int(hold_steps)
    U_law = np.array([c.U for c in targets])
    try:
        _run(cyc0, out, LEAD, int(lead_steps), lambda k, t: (cyc0.U, cyc0.H), None, comfort, "b", None)
        U0, H0, t0 = out["U"][-1], out["H"][-1], out["t_apex"][-1]
        prior = (np.array([c.t_fall for c in targets]), np.array([c.control.b for c in targets]),
                 np.array([c.H for c in targets]))
        tau, b, _ = _optimise_change(cyc0, U0, H0, t0, n, lambda k, t: float(U_law[k]), prior, goal.H, "b", comfort,
                                     bases=[c.control for c in targets],
                                     step_times=np.array([c.step_time for c in targets]))
        for k, tgt in enumerate(targets):  # re-simulated step by step: the plan is the simulator's
            U, H = out["U"][-1], out["H"][-1]
            th = float(_theta_of(H, tau[k]))
            r = step(U, H, th, replace(tgt.control, b=float(b[k])))
            if not bool(_step_ok(r, tgt, comfort)):
                raise _StepFail(len(out["theta0"]), U, H, tgt.U, _why_not(r, (), tgt, comfort))
            _record(out, th, float(b[k]), r, CHANGE, tgt.U)
        out["_b"] = goal.control.b
        _run(goal, out, HOLD, int(hold_steps), lambda k, t: (goal.U, goal.H), None, comfort, "b", None)
    except _StepFail as f:
        raise PlanError(f"step {f.i + 1} cannot follow the speed law's cycles (at U = {f.U:.4g}, H = {f.H:.4g}, "
                        f"toward U = {f.U_ref:.4g}): {f.why}", U_goal=goal.U) from None
    db = max(abs(v - c.b) for v, c in zip(out["b"], bases))
    note = (f"speed law: {n} change steps through the law's cycles (each step's K, a, c, T_c; its b within "
            f"{db:.4f} l0 of the cycle's)")
    plan = _finish(cyc0, out, goal.U, goal, "law", policy, [note])
    return replace(plan, controls=tuple(replace(c, b=float(v)) for c, v in zip(bases, plan.b)))


def law_cycles(cycle_at: Callable, factors) -> list:
    """The law's cycles at ``factors`` (cycle_at(s) for each), with the failing factor said as a PlanError."""
    cycles = []
    for s in factors:
        try:
            cycles.append(cycle_at(float(s)))
        except FitError as e:
            raise PlanError(f"the speed law's running cycle at x{float(s):.2f} of the clip's speed does not exist "
                            f"({e})") from None
    return cycles
