"""Walking faster: the walking machine's periodic cycle re-solved (issue 17, acceptance 3).

Slower walks use §5.2's horizontal stretch (``pipeline.plan_scale``): below the clip's speed the cycle
search finds no periodic cycle with the step time law below (measured on CMU 02_01: it stalls at ×0.85
with the double-support share kept, held constant in seconds, or growing).

§5.2's horizontal stretch keeps the timing, which is right for running's flight but wrong for walking:
people walk faster with longer *and* quicker steps. Here the fitted walking machine's cycle is re-solved
(the fit's own minimum-norm cycle search, started from the fitted cycle) for s × its speed with

* the step time × s^(−1/2), so the step length grows × s^(1/2) (the usual empirical shape of human
  walking, step length rising about with the square root of speed, cadence the other half: Grieve &
  Gear 1966, an approximation over 0.8-1.6 m/s);
  where that law finds no cycle, the continuation goes on with × s^(−0.7) (FAST_STEP_TIME_EXPONENT;
  the Bandai walk by ×1.5, whose stance leg otherwise unloads);
* the share of the step spent in double support kept (the reference's own; it shrinks a little with
  speed in people, which the machine may then show through its own dynamics);
* the leg control's stance time T_c scaled like the step time, the touchdown geometry, control and roll
  free to move as the search needs;
* where neither law finds a cycle because the stance leg unloads (a brisk walk's single-support force
  already near zero at the clip's speed: Bandai walk_active_002 by ×1.13), the continuation goes on with
  one more equation: the lowest vertical force in single support held at ``body.gait.FLIGHT_FORCE_BW`` (0.2
  body weights), the force below which froude reads the body as in flight (``walk_cycle``).
  Walking faster, people flatten the COM's vault rather than leave the ground; the machine's control is
  free to do the same, and the minimum-norm search then finds the cycle nearest the last one whose vault
  keeps the foot loaded.

Past a Froude number U ≈ 0.7 (Fr = U² ≈ 0.5) people break into a run (Alexander & Jayes 1983): a walk
is not asked to go there; the message says the fastest walking speed in m/s.
"""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from ..errors import FitError, PastWalkRunTransition
from .walk_cycle import _VARS, _cycle_search
from .walk_model import WalkingMachine
from .walking import N_PER_STANCE

__all__ = ["WALK_RUN_U", "STEP_TIME_EXPONENT", "walking_machine_at_speed",
           "walking_machines_at_speeds",
           "check_walking_speed"]

#: The dimensionless speed U = u/√(g l0) at which people change from walking to running (Fr = U² ≈ 0.5).
WALK_RUN_U = 0.7
#: Step time ∝ speed^STEP_TIME_EXPONENT at a speed change (step length ∝ speed^(1 + exponent)).
STEP_TIME_EXPONENT = -0.5
#: The step time law used where STEP_TIME_EXPONENT finds no cycle: cadence rising faster, the step length
#: slower (× s^0.3), as in people near their fastest walks, whose step length levels off while cadence keeps
#: rising. Measured on CMU 07_01 (1.39 m/s) before the control's pulses: with s^-0.5 the cycle existed up to
#: x1.275 and its stance leg unloaded at x1.2875 (a flight phase); with s^-0.7 the search found the cycle at
#: x1.30 (U = 0.60). With the pulses 07_01 has s^-0.5 cycles to x1.30; the Bandai walk has taken this law by
#: x1.5 (docs/walking.md).
FAST_STEP_TIME_EXPONENT = -0.7


def check_walking_speed(machine: WalkingMachine, s: float, what: str = "walk", peak: float = 1.0) -> None:
    """Raise PastWalkRunTransition (one line, in m/s) when s × the machine's speed is past the walk-run
    transition; FitError for a speed factor that is not a positive number.

    machine: the (scaled) walking machine whose speed unit √(g l0) gives m/s; s: speed factor [-]; peak: the
    fastest stretch of the output over its mean speed (a turn's, ``TakePath.speed_factors``):
    s × peak × the machine's speed is checked, and the refusal says so.
    """
    if not (math.isfinite(s) and s > 0):
        raise FitError(f"speed factor must be > 0, got {s}")
    U = s * peak * machine.mean_speed
    if U > WALK_RUN_U and peak != 1.0:
        raise PastWalkRunTransition(
            f"a {what} at x{s:g} is past the walk-run transition where it is fastest ({U * machine.speed_unit:.2f} "
            f"m/s, {peak:.2f} x its mean; Froude number U = {U:.2f} > {WALK_RUN_U}): people run there; ask at most "
            f"x{WALK_RUN_U / (peak * machine.mean_speed):.2f}")
    if U > WALK_RUN_U:
        v = U * machine.speed_unit
        v_max = WALK_RUN_U * machine.speed_unit
        raise PastWalkRunTransition(
            f"a {what} at {v:.2f} m/s (x{s:g}) is past the walk-run transition for this character "
            f"(Froude number U = {U:.2f} > {WALK_RUN_U}, Fr = U^2 = {U * U:.2f} > 0.5, leg {machine.l0:.2f} m): "
            f"people run there; ask at most {v_max:.2f} m/s (x{WALK_RUN_U / machine.mean_speed:.2f}) "
            "or use a running clip")


#: Largest change of the speed factor per cycle search: farther targets are reached by continuation.
CONTINUATION_STEP = 0.05
#: The laws tried in turn as the continuation climbs, (step time exponent, single-support force trough held
#: at FLIGHT_FORCE_BW): once a law finds no cycle, the next one carries on (the profile's cadence keeps
#: rising with speed, and a vault that unloads the leg stays unloaded faster).
LAWS = ((STEP_TIME_EXPONENT, False), (FAST_STEP_TIME_EXPONENT, False), (FAST_STEP_TIME_EXPONENT, True))


def walking_machine_at_speed(machine: WalkingMachine, s: float) -> WalkingMachine:
    """The walking machine's periodic cycle at s × its mean speed (see module doc).

    Solved by continuation from the fitted cycle (speed factors CONTINUATION_STEP apart, each search
    started from the previous cycle), so the search stays in the basin of the fitted gait.
    Dimensionless fields change; SI fields (l0, mass, reference measurements) are those of ``machine``.
    Raises FitError past the walk-run transition or when no such cycle exists (the message says why).
    """
    check_walking_speed(machine, s)
    if s <= 1.0:
        if s < 1.0:
            raise FitError(f"no walking cycle is re-solved below the clip's speed (x{s:g}): slower walks are "
                           "stretched (paper §5.2)")
        return machine
    return walking_machines_at_speeds(machine, [s])[float(s)]


def _resolve(base: WalkingMachine, start: WalkingMachine, s: float,
             law: tuple = LAWS[0]) -> WalkingMachine:
    """The cycle at s × base's speed (targets from ``base``, step time × s^exponent, the force trough held
    or not: ``law`` is one of LAWS), searched from ``start``'s cycle."""
    exponent, trough_held = law
    k = s ** exponent
    t_step, t_double = base.t_step * k, base.t_double * k
    T_c = base.T_c * k
    targets = (t_step, t_double, s * base.mean_speed)
    r = t_step / start.t_step  # time stretch from the start cycle to the target one
    # the start cycle's variables (the control's pulses held: in stance phase, they keep their share of the
    # stance), its forward speed and trailing time stretched to the target's
    z0 = np.array([float(getattr(start, k)) for k in _VARS])
    z0[_VARS.index("u")] *= s * base.mean_speed / start.mean_speed
    z0[_VARS.index("s")] *= r
    try:
        z, w, it, _ = _cycle_search(z0, T_c, base.roll, targets, N_PER_STANCE, hold_trough=trough_held)
    except FitError as e:
        raise FitError(f"no walking cycle at x{s:.2f} the clip's speed: {e}") from None
    nx = w.next
    per = float(max(abs(nx.u - z[0]), abs(nx.v - z[1]), abs(nx.d - z[2]), abs(nx.s - z[3])))
    return replace(
        base, u=float(z[0]), v=float(z[1]), d=float(z[2]), s=float(z[3]), theta0=float(z[4]), K=float(z[5]),
        a=float(z[6]), b=float(z[7]), c=float(z[8]), l_td=float(z[9]), e=float(z[10]), T_c=T_c, t_stance=w.t_stance,
        t_double=w.t_double, t_step=w.t_step, step_length=w.step_length, mean_speed=w.step_length / w.t_step,
        periodicity=per, iterations=int(it),
    )


def walking_machines_at_speeds(machine: WalkingMachine, speeds, cache: dict | None = None) -> dict:
    """{s: the cycle at s × the machine's speed} for speed factors s > 1, solved by one continuation in
    increasing order of speed (each from the previous cycle). cache: a dict by speed factor, read and
    filled (``Prepared.faster_machines``)."""
    cache = {} if cache is None else cache
    out = {}
    cur, f_cur = machine, 1.0
    law = 0  # index into LAWS
    for s in sorted({float(v) for v in speeds}):
        check_walking_speed(machine, s)
        if s in cache:
            out[s] = cur = cache[s]
            f_cur = s
            continue
        n = max(1, int(math.ceil((s - f_cur) / CONTINUATION_STEP - 1e-9)))
        for f in np.linspace(f_cur, s, n + 1)[1:]:
            cur, law = _next_cycle(machine, cur, float(f), law)
        cur = replace(cur, source=machine.source + f" (re-solved at x{s:g} speed)")
        out[s] = cache[s] = cur
        f_cur = s
    return out


def _next_cycle(machine: WalkingMachine, cur: WalkingMachine, f: float, law: int) -> tuple[WalkingMachine, int]:
    """(the cycle at f × the machine's speed searched from ``cur``, the index of the law in LAWS that found
    it): LAWS[law] first, then each later one; the last one's FitError when none does."""
    for k in range(law, len(LAWS) - 1):
        try:
            return _resolve(machine, cur, f, LAWS[k]), k
        except FitError:
            continue
    return _resolve(machine, cur, f, LAWS[-1]), len(LAWS) - 1
