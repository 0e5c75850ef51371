"""A run's change of speed as a runner makes it: the human range for the character's size, and the plan of
an acceleration (the human speed law's cycles, ``machine.planner.law``, or the paper's §5.3 planner).

``pipeline.plan_scale`` asks ``check_human_speed``; ``pipeline.accelerate`` asks ``plan_run_speed_change``
(walks keep their own planner, ``synthesis.walking``: the law's sources are runners). Kept apart from the
pipeline so that it stays orchestration only.
"""
from __future__ import annotations

import math

import numpy as np

from ..body.characters import Retarget
from ..errors import BeyondHumanRange, FitError, FroudeError, PlanError
from ..machine.speed_law import HUMAN_TOP_TOL, STEP_MAX_PER_STATURE
from ..synthesis.timewarp import MachinePath, machine_path
from .prepared import Prepared
from .speed_goal import accelerate_goal

__all__ = ["LAW_MAX_STEPS", "SUPPORTED_SPEED_RANGE", "check_human_speed", "check_step_lengths", "output_steps",
           "plan_refusal", "plan_report", "plan_run_speed_change", "speed_range_notes"]

#: Speed factors outside this range leave what a reference clip supports: a warning, not an error.
SUPPORTED_SPEED_RANGE = (0.6, 1.6)


def speed_range_notes(speed: float) -> list[str]:
    """A note when the speed factor [-] leaves ``SUPPORTED_SPEED_RANGE`` (the poses come from one clip)."""
    lo, hi = SUPPORTED_SPEED_RANGE
    if lo <= speed <= hi:
        return []
    return [f"speed factor {speed:.2f} is outside {lo}-{hi}, the range a single reference clip supports well "
            "(the poses come from one clip at one speed)"]


def output_steps(strides: int | None, duration: float | None, step_time_s: float) -> int:
    """Steps of an output asked as ``duration`` [s] (at least 2 steps of step_time_s [s]) or ``strides``."""
    if duration is not None:
        if not (np.isfinite(duration) and duration > 0):
            raise FroudeError(f"duration must be > 0 s, got {duration}")
        return max(2, int(math.ceil(duration / step_time_s)))
    if strides is None or strides < 1:
        raise FroudeError(f"strides must be >= 1, got {strides}")
    return 2 * int(strides)


def check_human_speed(prep: Prepared, retarget: Retarget, factor: float, base_m_s: float) -> None:
    """Refuse (BeyondHumanRange) a run's speed factor past the human range for the character's size
    (``Prepared.human_top``), saying the human limit in m/s. base_m_s: the character's speed at x1 [m/s]."""
    top = prep.human_top(retarget)
    if factor > top.factor + HUMAN_TOP_TOL:
        raise BeyondHumanRange(
            f"{factor * base_m_s:.2f} m/s (x{factor:.2f}) is beyond the human range for this character "
            f"({retarget.body.stature:.2f} m tall): the human limit is {top.sentence(base_m_s, retarget.body.stature)}"
            "; --unlimited (unlimited=True) lifts it")


def check_step_lengths(path: MachinePath, stature_m: float, start_m_s: float, goal_m_s: float) -> None:
    """Refuse (BeyondHumanRange) a speed change whose machine path has a step longer than a human's
    (``machine.speed_law.STEP_MAX_PER_STATURE`` × the character's stature ``stature_m`` [m]): the §5.3 planner
    keeps the fitted control's stance, so its steps grow with the speed where a runner's cadence would (the
    law's steps stay inside below the human top; this guards the path whichever planned it)."""
    steps_m = np.linalg.norm(np.diff(path.contacts, axis=0), axis=1)
    if steps_m.size and steps_m.max() > STEP_MAX_PER_STATURE * stature_m:
        k = int(np.argmax(steps_m))
        raise BeyondHumanRange(
            f"the change from {start_m_s:.2f} to {goal_m_s:.2f} m/s (x{goal_m_s / start_m_s:.2f}) takes a step of "
            f"{steps_m[k]:.2f} m (step {k + 1}), {steps_m[k] / stature_m:.2f} x stature: longer than the "
            f"{STEP_MAX_PER_STATURE:g} x stature a human sprinter takes; choose a goal nearer x1, or --unlimited "
            "(unlimited=True)")


def plan_run_speed_change(prep: Prepared, retarget: Retarget, *, to_speed, to_factor, steps, within,
                          lead_steps: int, hold_steps: int, fps, energy: str, policy: str, unlimited: bool,
                          speed_model: str) -> tuple[MachinePath, object, list, dict]:
    """The machine path of a run changing speed (``pipeline.accelerate``'s arguments): (path, plan, notes,
    extras). to_speed [m/s] or to_factor [-]: the goal apex speed; within [s]; fps [Hz] (None: the clip's).
    Raises BeyondHumanRange past the human range (unless unlimited), PlanError when no plan is found."""
    from ..machine.planner import plan_speed_change  # lazy: start-up (scale loads no planner)

    m = prep.machine.scaled(retarget.L, retarget.M)
    v_unit = m.speed_unit
    start_speed = m.U * v_unit  # apex speed of the cycle [m/s]
    target = accelerate_goal(to_speed, to_factor, start_speed, steps, within)
    if speed_model not in ("law", "planner"):
        raise FroudeError(f"unknown speed model '{speed_model}' (law or planner)")
    if not unlimited:
        check_human_speed(prep, retarget, target / start_speed, start_speed)
    try:
        if speed_model == "law":
            plan = _law_plan(prep, m, target / v_unit, steps, within, policy, lead_steps, hold_steps)
        else:
            plan = plan_speed_change(
                m, target / v_unit, n_steps=None if within is not None else steps,
                within_time=None if within is None else within / m.time_unit, energy=energy, policy=policy,
                lead_steps=lead_steps, hold_steps=hold_steps,
            )
    except PlanError as e:
        raise PlanError(plan_refusal(e, start_speed, target, v_unit, steps, within)) from e
    fps = prep.motion.fps if fps is None else float(fps)
    path = machine_path(prep.cycle, m, retarget.L, prep.origin, n_steps=plan.n_steps, fps=fps,
                        theta0=plan.theta0, controls=plan.controls, start_state=(float(plan.U[0]), float(plan.H[0])))
    if not unlimited:
        check_step_lengths(path, retarget.body.stature, start_speed, target)
    notes = list(prep.notes) + list(plan.notes)
    return path, plan, notes, {"plan": plan_report(plan, m, start_speed, target)}


#: A change along the law refused in n steps is tried in 2n and 4n steps (at most this many), to say how
#: many are enough (each try costs a plan, 1.5-3 s for 16-32 steps: no search for the fewest).
LAW_MAX_STEPS = 32


def _law_steps_enough(plan_of, n: int) -> int | None:
    """2n or 4n (≤ LAW_MAX_STEPS): the first in which plan_of succeeds, or None."""
    for k in (2 * n, 4 * n):
        if k > LAW_MAX_STEPS:
            break
        try:
            plan_of(k)
            return k
        except PlanError:
            continue
    return None


def _law_plan(prep: Prepared, m, U_goal: float, steps, within, policy: str, lead_steps: int, hold_steps: int):
    """``machine.planner.law.plan_law_change`` for a run: the change through the law's cycles at the policy's
    factors to the goal apex speed U_goal [√(g l0)] (m: the character's machine, the start). within [s]: the
    most change steps whose change lasts no longer (the gentlest that fits). Raises PlanError."""
    from ..machine.planner import POLICIES  # lazy: start-up (scale loads no planner)
    from ..machine.planner.law import law_cycles, law_factors, law_goal_factor, plan_law_change  # lazy: start-up

    if policy not in POLICIES:
        raise PlanError(f"unknown policy '{policy}' ({' or '.join(POLICIES)})")
    try:
        s_goal, goal = law_goal_factor(prep.machine_at_speed, m.U, U_goal)
    except FitError as e:
        raise PlanError(f"the speed law has no running cycle at the goal ({e})", U_goal=U_goal) from None

    def plan_of(n: int):
        cycles = law_cycles(prep.machine_at_speed, law_factors(s_goal, n, policy))
        return plan_law_change(m, cycles, policy=policy, lead_steps=lead_steps, hold_steps=hold_steps)

    if within is None:
        try:
            return plan_of(int(steps))
        except PlanError as e:  # say how many steps are enough, if more would do
            raise PlanError(str(e), U_goal=U_goal, steps_enough=_law_steps_enough(plan_of, int(steps))) from None
    limit = within / m.time_unit

    def lasts(p) -> float:
        idx = p.change_steps
        return float(p.t_apex[idx[-1] + 1] - p.t_apex[idx[0]])

    n = max(1, int(limit // min(m.step_time, goal.step_time)))
    while n >= 1:
        p = plan_of(n)
        if lasts(p) <= limit:
            return p
        n -= 1
    raise PlanError(f"the change takes more than {within:g} s even in one step", U_goal=U_goal)


def plan_refusal(err, start_m_s: float, goal_m_s: float, v_unit: float, steps, within) -> str:
    """The planner's refusal (``PlanError`` with its U facts) said in the user's terms: m/s, ×, steps, s.

    start_m_s / goal_m_s: the apex speeds [m/s] the change goes between; v_unit: √(g l0) of the
    character [m/s], which turns the planner's dimensionless U into m/s. The planner's own words (in U)
    stay on the exception's ``__cause__`` for debugging.
    """
    head = f"cannot change speed from {start_m_s:.2f} to {goal_m_s:.2f} m/s (x{goal_m_s / start_m_s:.2f})"
    sus = getattr(err, "U_sustainable", None)
    if sus is not None and not sus[0] <= err.U_goal <= sus[1]:
        lo, hi = sus[0] * v_unit, sus[1] * v_unit
        return (f"{head}: the simple machine runs steadily only between {lo:.2f} and {hi:.2f} m/s "
                f"(x{lo / start_m_s:.2f}-{hi / start_m_s:.2f}); choose a goal in that range")
    in_steps = f"in {steps} step{'' if steps == 1 else 's'}"
    if getattr(err, "steps_needed", None):
        return f"{head} {in_steps}: too abrupt; give at least {err.steps_needed} steps"
    if getattr(err, "steps_enough", None):
        return f"{head} {in_steps}: too abrupt; {err.steps_enough} steps are enough"
    if within is not None:
        return f"{head} within {within:g} s: too abrupt; allow more time"
    one = getattr(err, "U_one_step", None)
    reach = "" if one is None else f" (one step from the start reaches {one * v_unit:.2f} m/s)"
    return f"{head} {in_steps}{reach}: try more steps or a goal nearer x1"


def plan_report(plan, m, start_speed: float, target: float) -> dict:
    """A speed-change plan as the report's ``extras["plan"]``: per apex speed [m/s] and U, time [s],
    touchdown angle [deg], control b and phase. m: the character's scaled SimpleMachine (its units);
    start_speed / target: the change's apex speeds [m/s]."""
    return {
        "start_speed_m_s": start_speed, "target_speed_m_s": target,
        "apex_speed_m_s": (plan.U * m.speed_unit).tolist(), "apex_U": plan.U.tolist(),
        "apex_time_s": (plan.t_apex * m.time_unit).tolist(),
        "theta0_deg": np.degrees(plan.theta0).tolist(), "b": plan.b.tolist(),
        "phase": ["lead" if p == 0 else "change" if p == 1 else "hold" for p in plan.phase],
        "mode": plan.mode, "policy": plan.policy,
    }
