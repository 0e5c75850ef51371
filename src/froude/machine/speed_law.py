"""How runners share a change of speed between step length and step frequency, in Froude terms
(docs/speed_law.md, with its sources: the velocity-cadence-step-length relation), and the human limits of a run.

Lengths are in units of the runner's stature S, times in √(S/g), speeds in √(g S): a step frequency
f [1/s] is f̂ = f √(S/g), a speed v [m/s] is V̂ = v / √(g S). Dynamically similar runners (a child, a
giant) share every dimensionless number, so the law and the limits below hold for every size; the
published figures, measured on adults, are turned into these units with a reference adult stature
``STATURE_REF_M``.

The law (segmented, like the published regression): ln f̂ rises with ln v with slope ``ALPHA`` below the
inflection cadence ``F_INFLECTION`` (speed gained mostly by longer steps) and with slope ``BETA`` above it
(mostly by faster steps). It is applied around the clip's own cadence: a speed factor s keeps the clip at
s = 1 and gives the cadence ratio :func:`cadence_ratio`, so a runner who steps slowly for their size
lengthens steps further before the cadence takes over. Step length = v / f.

Stance time (:func:`stance_time`): faster than the clip the contact length v t_c is kept (Weyand et al.
2000: nearly constant across speeds; the stance leg sweeps the same angle), the flight taking the rest of
the step; slower than the clip the flight time is kept (weakly speed dependent in distance running,
REFERENCE.md §2), so the slower run still leaves the ground. Both rules agree at s = 1.

Human limits (:func:`human_limits`): a step no longer than ``STEP_MAX_PER_STATURE`` × stature, a step
frequency no higher than ``F_MAX`` and a stance no shorter than ``T_STANCE_MIN`` (elite sprinters at top
speed, scaled by dynamic similarity). A clip that is itself outside a limit keeps its own value as the
limit (x1 is always the clip).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..core.constants import GRAVITY

__all__ = ["ALPHA", "BETA", "F_INFLECTION", "F_MAX", "T_STANCE_MIN", "STEP_MAX_PER_STATURE", "STATURE_REF_M",
           "HUMAN_MARGIN", "HUMAN_TOP_TOL", "LawStep", "HumanTop", "cadence_ratio", "stance_time", "law_step",
           "human_top_factor", "froude_cadence"]

#: Reference adult stature [m] that turns the published adult figures into Froude terms (≈; the sources
#: report adults, typically 1.70-1.80 m).
STATURE_REF_M = 1.75
#: d ln f / d ln v below the inflection: 3.5 -> 7.0 m/s, stride frequency +10 % then +12 % (Dorn, Schache &
#: Pandy 2012, J Exp Biol 215:1944, Fig. 2A): ln(1.10 x 1.12) / ln 2 = 0.30.
ALPHA = 0.30
#: d ln f / d ln v above the inflection: 7.0 -> 8.95 m/s, stride frequency +25 %, length +3 % (same figure):
#: ln 1.25 / ln(8.95 / 7.0) = 0.91.
BETA = 0.90
#: The inflection cadence: 3.0 ± 0.2 steps/s in sprinters, distance runners, active and sedentary adults
#: (PMC8523042), at 65-70 % of their top speed.
F_INFLECTION_HZ = 3.0
#: Highest step frequency of elite sprinters at top speed (≈ 4.5-5.0 steps/s; docs/speed_law.md).
F_MAX_HZ = 5.0
#: Shortest stance of elite sprinters at top speed [s] (≈ 0.08-0.10 s; REFERENCE.md §7).
T_STANCE_MIN_S = 0.08
#: Longest step of elite sprinters at top speed, per stature (1.3-1.4; issue 30, REFERENCE.md §7).
STEP_MAX_PER_STATURE = 1.4


def froude_cadence(f_hz, stature_m):
    """Step frequency f [1/s] in Froude terms, f √(S/g) [-], for a runner of stature S [m]."""
    return f_hz * np.sqrt(stature_m / GRAVITY)


F_INFLECTION = float(froude_cadence(F_INFLECTION_HZ, STATURE_REF_M))
F_MAX = float(froude_cadence(F_MAX_HZ, STATURE_REF_M))
T_STANCE_MIN = T_STANCE_MIN_S / math.sqrt(STATURE_REF_M / GRAVITY)


def cadence_ratio(s, f_clip: float):
    """The law's step frequency at s × the clip's speed over the clip's, for a clip stepping at f̂ = f_clip
    (Froude terms, stature units). s: speed factor(s) > 0 [-], any shape; returns the same shape [-].

    ln f̂(x) = ln F_INFLECTION + ALPHA min(x − x_i, 0) + BETA max(x − x_i, 0), x = ln s, with x_i the
    log speed factor where the clip's curve crosses the inflection cadence (so that f̂(0) = f_clip)."""
    x = np.log(np.asarray(s, float))
    gap = math.log(F_INFLECTION / f_clip)
    x_i = gap / (ALPHA if gap > 0 else BETA)
    ln_f = math.log(F_INFLECTION) + ALPHA * np.minimum(x - x_i, 0.0) + BETA * np.maximum(x - x_i, 0.0)
    return np.exp(ln_f) / f_clip


def stance_time(s, t_stance: float, t_flight: float, step_time):
    """The law's stance time at s × the clip's speed [the unit of the times given]: faster (s > 1) the
    clip's contact length kept, t_stance / s; slower the clip's flight kept, step_time − t_flight.

    s: speed factor(s) [-]; t_stance, t_flight: the clip's; step_time: the law's step time at s (same shape as s)."""
    s = np.asarray(s, float)
    return np.where(s > 1.0, t_stance / s, np.asarray(step_time, float) - t_flight)


@dataclass(frozen=True)
class LawStep:
    """One steady step of the law at a speed factor, in the units of the clip's times and lengths given.

    s: speed factor [-]; cadence_ratio: f / f_clip [-]; step_time, t_stance, t_flight: [time];
    step_length: [length]."""

    s: float
    cadence_ratio: float
    step_time: float
    t_stance: float
    t_flight: float
    step_length: float


def law_step(s: float, f_clip: float, step_time: float, t_stance: float, t_flight: float,
             mean_speed: float) -> LawStep:
    """The law's step at s × the clip's speed. f_clip: the clip's cadence in Froude terms (stature units);
    step_time, t_stance, t_flight [time], mean_speed [length/time]: the clip's, in any one unit system."""
    r = float(cadence_ratio(s, f_clip))
    t_step = step_time / r
    t_st = float(stance_time(s, t_stance, t_flight, t_step))
    return LawStep(s=float(s), cadence_ratio=r, step_time=t_step, t_stance=t_st, t_flight=t_step - t_st,
                   step_length=s * mean_speed * t_step)


@dataclass(frozen=True)
class HumanTop:
    """The fastest speed factor whose law step stays inside the human limits, and which limit ends it.

    factor: [-] (1.0 when the clip is itself at a limit); limit: "step length", "step frequency" or
    "stance time"; values: (law's value, limit) at ``factor`` in Froude terms (stature units)."""

    factor: float
    limit: str
    values: tuple

    def sentence(self, base_m_s: float, stature_m: float) -> str:
        """The limit in the user's terms: '9.45 m/s (x2.65): there a step is 1.40 x stature, the longest a
        human takes'. base_m_s: the speed at x1 [m/s]; stature_m: the character's stature [m]."""
        t_unit = math.sqrt(stature_m / GRAVITY)
        head = f"{self.factor * base_m_s:.2f} m/s (x{self.factor:.2f})"
        law = self.values[0]
        if self.limit == "step length":
            return (f"{head}: there a step is {law:.2f} x stature ({law * stature_m:.2f} m), the longest a "
                    f"human sprinter takes is {STEP_MAX_PER_STATURE:g} x stature")
        if self.limit == "step frequency":
            return (f"{head}: there the step frequency is {law / t_unit:.2f} steps/s, the highest a human "
                    f"sprinter of this size reaches is {F_MAX / t_unit:.2f}")
        return (f"{head}: there a stance lasts {law * t_unit * 1e3:.0f} ms, the shortest a human sprinter "
                f"of this size has is {T_STANCE_MIN * t_unit * 1e3:.0f} ms")


#: The precision of :func:`human_top_factor` [-]: a factor within this of the top is inside.
HUMAN_TOP_TOL = 1e-4
#: The top is this fraction slower than where the law's step reaches the first limit [-], so that an
#: output there, whose steps are measured between frames, is still inside it (measured at the exact top of
#: a Bandai dash: a step 0.1 % longer than 1.4 x stature; above the inflection a step grows only as
#: s^(1 - BETA), so 2 % of speed is 0.2 % of step).
HUMAN_MARGIN = 0.02


def human_top_factor(f_law: float, step_time: float, t_stance: float, t_flight: float, step_length: float,
                     s_max: float = 10.0, tol: float = HUMAN_TOP_TOL) -> HumanTop:
    """The largest speed factor whose law step has a step ≤ STEP_MAX_PER_STATURE, a cadence ≤ F_MAX and
    a stance ≥ T_STANCE_MIN (each widened to the runner's own value at x1 when that is past it), made
    HUMAN_MARGIN slower (never below 1).

    f_law: where the clip sits on the law (its cadence in Froude terms, the machine's ``cadence_ratio``
    argument); step_time, t_stance, t_flight [√(S/g)], step_length [S]: the runner's steady step at x1 in
    Froude terms of the runner's own stature S (a character: its own). The three law quantities are
    monotone in s above 1 (step length ∝ s / cadence ratio with ALPHA, BETA < 1; stance ∝ 1/s), so each
    limit is found by bisection on [1, s_max] to ``tol``."""
    v = step_length / step_time
    f_own = 1.0 / step_time
    limits = {"step length": max(STEP_MAX_PER_STATURE, step_length), "step frequency": max(F_MAX, f_own),
              "stance time": min(T_STANCE_MIN, t_stance)}

    def values(s: float) -> dict:
        st = law_step(s, f_law, step_time, t_stance, t_flight, v)
        return {"step length": st.step_length, "step frequency": f_own * st.cadence_ratio,
                "stance time": st.t_stance}

    def inside(s: float, name: str) -> bool:
        val = values(s)[name]
        return val >= limits[name] - 1e-12 if name == "stance time" else val <= limits[name] + 1e-12

    best = HumanTop(s_max, "none", (math.nan, math.nan))
    for name in limits:
        if inside(s_max, name):
            continue
        lo, hi = 1.0, s_max
        while hi - lo > tol:
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if inside(mid, name) else (lo, mid)
        top = max(1.0, lo * (1 - HUMAN_MARGIN)) if lo > 1.0 else 1.0
        if top < best.factor:
            best = HumanTop(top, name, (values(top)[name], limits[name]))
    return best
