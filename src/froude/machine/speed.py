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


def faster_machine(machine: SimpleMachine, s: float) -> SimpleMachine:
    """The machine's periodic cycle at s × its mean speed with stance time / s and the step time kept.

    Dimensionless fields change; SI fields (l0, mass, reference measurements) are those of ``machine``.
    Raises FitError if no such cycle exists (the message says why).
    """
    from .dynamics import N_PER_STANCE
    from .fit import _cycle_search

    if not s > 0:
        raise FitError(f"speed factor must be > 0, got {s}")
    t_stance = machine.t_stance / s
    t_flight = machine.step_time - t_stance
    if not t_flight > 0:
        raise FitError(f"a stance of {t_stance:.3f} leaves no flight in a step of {machine.step_time:.3f}")
    z0 = np.array([s * machine.U, machine.H, machine.theta0, machine.K, machine.a, machine.b, machine.c])
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


