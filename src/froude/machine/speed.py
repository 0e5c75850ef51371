"""Faster running by re-solving the machine's cycle (beyond §5.2).

The paper changes steady speed by stretching the COM and foot paths horizontally with the timing kept
(§5.2, vertical forces only). Slower than the reference that is always possible. Faster it is not: the
COM then travels s times further while a foot is on the ground, and real runners already leave the
ground with a nearly straight leg, so a stretched stance asks the leg to reach beyond its length at
toe-off (measured on the CMU clips: the hip-to-ankle distance of the reference reaches the full leg
length at liftoff). The paper notes the cure as future work: "the stance time does vary somewhat with
velocity. Adapting the control law to achieve this effect is a topic of future work."

Here the simple machine (along-leg forces) is re-solved for a periodic cycle at s × the speed with the
stance time divided by s (so the COM travels the same distance over the planted foot as in the
reference) and the step time kept (so the cadence and the acceptance-relevant step duration are those of
§5.2), the flight taking up the difference, as runners do (contact time falls with speed, flight time
rises). The search is the fit's own minimum-norm cycle search, started from the fitted cycle.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..errors import FitError
from .model import SimpleMachine

#: When the cycle search from the fitted cycle fails at a high factor, it is continued from the cycle
#: solved at a lower one, in steps of this much [-].
CONTINUATION_STEP = 0.1


def faster_machine(machine: SimpleMachine, s: float) -> SimpleMachine:
    """The machine's periodic cycle at s × its mean speed with stance time / s and the step time kept.

    The search starts from the fitted cycle; beyond about x1.6 that start is too far (the search leaves the
    feasible region: the leg lifts off still falling), so it is continued from the cycles solved at
    x1.1, x1.2, ... up to s (each the start of the next). Dimensionless fields change; SI fields (l0, mass,
    reference measurements) are those of ``machine``. Raises FitError if no cycle exists (why).
    """
    if not s > 0:
        raise FitError(f"speed factor must be > 0, got {s}")
    try:
        return _solve_faster(machine, s, machine)
    except FitError as first:
        if s <= 1.0 + CONTINUATION_STEP:
            raise
        start, last = machine, 1.0
        for f in np.arange(1.0 + CONTINUATION_STEP, s, CONTINUATION_STEP):
            try:
                start, last = _solve_faster(machine, float(f), start, last), float(f)
            except FitError:
                raise first from None
        try:
            return _solve_faster(machine, s, start, last)
        except FitError:
            raise first from None


def _solve_faster(machine: SimpleMachine, s: float, start: SimpleMachine, s_start: float = 1.0) -> SimpleMachine:
    """The cycle search at s × the speed of ``machine`` (stance / s, step time kept), started from the cycle
    ``start`` solved at s_start × the speed."""
    from .dynamics import N_PER_STANCE
    from .fit import _cycle_search

    t_stance = machine.t_stance / s
    t_flight = machine.step_time - t_stance
    if not t_flight > 0:
        raise FitError(f"a stance of {t_stance:.3f} leaves no flight in a step of {machine.step_time:.3f}")
    z0 = np.array([s / s_start * start.U, start.H, start.theta0, start.K, start.a, start.b, start.c])
    T_c = machine.T_c / s
    z, row, calls, res = _cycle_search(z0, T_c, (t_stance, t_flight, s * machine.mean_speed), N_PER_STANCE)
    U, H, th, K, a, b, c = (float(v) for v in z)
    t_step = float(row["t_fall"] + row["t_stance"] + row["t_rise"])
    return replace(
        machine, U=U, H=H, theta0=th, K=K, a=a, b=b, c=c, T_c=T_c, t_stance=float(row["t_stance"]),
        t_flight=float(row["t_rise"] + row["t_fall"]), t_fall=float(row["t_fall"]), t_rise=float(row["t_rise"]),
        step_length=float(row["apex_dx"]), step_time=t_step, mean_speed=float(row["apex_dx"]) / t_step,
        peak_force=float(row["peak_force"]), periodicity=float(np.max(np.abs(res[:2]))), iterations=int(calls),
        source=machine.source + f" (re-solved at x{s:g} speed)",
    )


