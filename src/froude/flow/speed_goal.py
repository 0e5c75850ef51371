"""The one speed syntax of froude: ``1.2x`` (or a bare ``1.2``) is a factor, ``3.5m/s`` a speed.

Used by every command line option that takes a speed (``scale --speed``, ``accelerate --to-speed``,
``view --speed``) and meant for every other reader of speeds (batch plans, the Python API), so a bare
number means the same thing everywhere: a factor. No NumPy here: the CLI checks options before it
imports anything heavy.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass

from ..errors import FroudeError

#: Speed factors accepted at all (what a goal can reach is decided later by the planner).
FACTOR_RANGE = (0.1, 5.0)
#: Absolute speeds accepted at all [m/s] (the fastest human sprint is about 12.4 m/s).
SPEED_RANGE_M_S = (0.05, 50.0)

_NUMBER = r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?"
_GOAL = re.compile(rf"^\s*({_NUMBER}|nan|inf|infinity)\s*(x|m/s)?\s*$", re.IGNORECASE)


@dataclass(frozen=True)
class SpeedGoal:
    """Exactly one of ``factor`` (dimensionless) and ``m_s`` [m/s] is set."""

    factor: float | None = None
    m_s: float | None = None

    def __str__(self) -> str:
        return f"{self.factor:g}x" if self.factor is not None else f"{self.m_s:g} m/s"

    def factor_of(self, base_m_s: float) -> float:
        """The goal as a speed factor [-] of ``base_m_s`` [m/s], the speed at factor 1 (``mean_speed_m_s`` of
        the machine scaled to the character)."""
        return self.factor if self.factor is not None else self.m_s / base_m_s  # type: ignore[operator]


def parse_speed(text, what: str = "speed") -> SpeedGoal:
    """``'1.2x'`` or ``'1.2'`` -> factor 1.2; ``'3.5m/s'`` -> 3.5 m/s; numbers are factors.

    Raises FroudeError naming ``what`` and the accepted range for anything else (non-finite, out of
    range, unreadable, booleans).
    """
    if isinstance(text, bool):
        raise FroudeError(f"{what}: expected a factor (1.2x) or a speed (3.5m/s), got {text!r}")
    m = _GOAL.match(str(text))
    if m is None:
        raise FroudeError(f"{what}: cannot read '{text}': use a factor (1.2x, or a bare 1.2) or a speed (3.5m/s)")
    value, unit = float(m.group(1)), (m.group(2) or "x").lower()
    lo, hi = FACTOR_RANGE if unit == "x" else SPEED_RANGE_M_S
    if not (math.isfinite(value) and lo <= value <= hi):
        if unit == "x":
            hint = f" (did you mean {m.group(1)}m/s?)" if SPEED_RANGE_M_S[0] <= value <= SPEED_RANGE_M_S[1] else ""
            raise FroudeError(f"{what}: factor {m.group(1)} is outside the supported range {lo:g}x to {hi:g}x{hint}")
        raise FroudeError(f"{what}: {m.group(1)} m/s is outside the supported range {lo:g} to {hi:g} m/s")
    return SpeedGoal(factor=value) if unit == "x" else SpeedGoal(m_s=value)


def _positive(value, message: str) -> float:
    """``value`` as a float if it is finite and > 0; FroudeError(message) otherwise."""
    v = float(value)
    if not (math.isfinite(v) and v > 0):
        raise FroudeError(message)
    return v


def scale_factor(speed: float, target_speed: float | None, base_speed_m_s: float) -> float:
    """The speed factor of a ``scale``: ``target_speed`` [m/s] over the dynamically scaled speed
    ``base_speed_m_s`` when given, else ``speed``. Raises FroudeError for a non-finite or non-positive one."""
    if target_speed is not None:
        speed = _positive(target_speed, f"target speed must be > 0 m/s, got {target_speed}") / base_speed_m_s
    return _positive(speed, f"speed factor must be > 0, got {speed}")


def accelerate_goal(to_speed: float | None, to_factor: float | None, start_speed_m_s: float,
                    steps, within: float | None) -> float:
    """The goal speed [m/s] of an ``accelerate``: ``to_speed``, or ``to_factor`` × the start speed (exactly
    one), after checking it and the change's length (``steps``, whole >= 1, or ``within`` [s] > 0)."""
    if (to_speed is None) == (to_factor is None):
        raise FroudeError("give exactly one goal: a target speed [m/s] or a factor of the start speed")
    target = to_speed if to_speed is not None else float(to_factor) * start_speed_m_s  # type: ignore[arg-type]
    _positive(target, f"target speed must be > 0 m/s, got {target:g} (to stop, end the motion instead)")
    if steps is not None and within is None and not (isinstance(steps, int) and steps >= 1):
        raise FroudeError(f"steps must be a whole number >= 1, got {steps}")
    if within is not None:
        _positive(within, f"--within must be > 0 s, got {within}")
    return float(target)
