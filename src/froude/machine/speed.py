"""Steady running at another speed by re-solving the machine's cycle with the human speed law (beyond §5.2).

The paper changes steady speed by stretching the COM and foot paths horizontally with the timing kept
(§5.2, vertical forces only), and notes the cure of what that misses as future work: "the stance time does
vary somewhat with velocity. Adapting the control law to achieve this effect is a topic of future work."
Keeping the step time makes every step s times longer: past about x2 longer than any human's (a 4 m leap
at x3 of a CMU jog), and faster, a stretched stance asks the leg to reach beyond its length at toe-off.

Here the simple machine (along-leg forces) is re-solved for a periodic cycle at s × the speed with the
step time and stance time of the human speed law (``machine.speed_law``: step frequency and step length
share the change as runners share it; contact length kept when faster, flight kept when slower), for
speed-ups and slow-downs alike. The search is the fit's own minimum-norm cycle search, started from the
fitted cycle and, where that start is too far, continued from the cycles solved on the way.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..errors import FitError
from .dynamics import N_PER_STANCE
from .fit import _cycle_search
from .model import SimpleMachine
from .speed_law import law_step

#: When the cycle search from the fitted cycle fails at a far factor, it is continued from the cycle
#: solved at a nearer one, in steps of this much [-].
CONTINUATION_STEP = 0.1


def machine_at_speed(machine: SimpleMachine, s: float, f_clip: float) -> SimpleMachine:
    """The machine's periodic cycle at s × its mean speed with the speed law's step and stance times.

    f_clip: the clip's step frequency in Froude terms with the stature as the length, f √(S/g) [-] (where
    the clip sits on the law: ``speed_law.cadence_ratio``). The search starts from the fitted cycle; far
    from x1 that start can be too far (the search leaves the feasible region: the leg lifts off still
    falling), so it is continued from the cycles solved at x1 ± 0.1, ± 0.2, ... up to s (each the start of
    the next). Dimensionless fields change; SI fields (l0, mass, reference measurements) are those of
    ``machine``. Raises FitError if no cycle exists (why).
    """
    if not s > 0:
        raise FitError(f"speed factor must be > 0, got {s}")
    try:
        return _solve_at(machine, s, f_clip, machine)
    except FitError as first:
        if abs(s - 1.0) <= CONTINUATION_STEP:
            raise
        start, last = machine, 1.0
        direction = 1.0 if s > 1.0 else -1.0
        for f in np.arange(1.0 + direction * CONTINUATION_STEP, s, direction * CONTINUATION_STEP):
            try:
                start, last = _solve_at(machine, float(f), f_clip, start, last), float(f)
            except FitError:
                raise first from None
        try:
            return _solve_at(machine, s, f_clip, start, last)
        except FitError:
            raise first from None


def _solve_at(machine: SimpleMachine, s: float, f_clip: float, start: SimpleMachine,
              s_start: float = 1.0) -> SimpleMachine:
    """The cycle search at s × the speed of ``machine`` (the law's step and stance times), started from
    the cycle ``start`` solved at s_start × the speed."""
    law = law_step(s, f_clip, machine.step_time, machine.t_stance, machine.t_flight, machine.mean_speed)
    if not law.t_flight > 0:
        raise FitError(f"a stance of {law.t_stance:.3f} leaves no flight in a step of {law.step_time:.3f}")
    z0 = np.array([s / s_start * start.U, start.H, start.theta0, start.K, start.a, start.b, start.c])
    T_c = machine.T_c * law.t_stance / machine.t_stance
    z, row, calls, res = _cycle_search(z0, T_c, (law.t_stance, law.t_flight, s * machine.mean_speed),
                                       N_PER_STANCE)
    U, H, th, K, a, b, c = (float(v) for v in z)
    t_step = float(row["t_fall"] + row["t_stance"] + row["t_rise"])
    return replace(
        machine, U=U, H=H, theta0=th, K=K, a=a, b=b, c=c, T_c=T_c, t_stance=float(row["t_stance"]),
        t_flight=float(row["t_rise"] + row["t_fall"]), t_fall=float(row["t_fall"]), t_rise=float(row["t_rise"]),
        step_length=float(row["apex_dx"]), step_time=t_step, mean_speed=float(row["apex_dx"]) / t_step,
        peak_force=float(row["peak_force"]), periodicity=float(np.max(np.abs(res[:2]))), iterations=int(calls),
        source=machine.source + f" (re-solved at x{s:g} speed, human speed law)",
    )
