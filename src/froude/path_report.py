"""The physics report's path figures (issue 28): the output's path against the clip's, and the bars it
must meet ("never silently straight"). Both paths are measured from motions alone (``body.path``): the
output's from the output motion, never from the synthesis' machine path or targets.
"""
from __future__ import annotations

import math

import numpy as np

from .body.path import STRAIGHT_TAKE_RAD, TakePath, is_straight, wrap_angle

__all__ = ["FACING_TOL_RAD", "HEADING_TOL_RAD", "intended_heading_change", "path_comparison", "path_rows"]

#: The quality bar (docs/architecture.md): the output's total heading change within 3 degrees of the intended.
HEADING_TOL_RAD = math.radians(3.0)
#: The output faces its travel as the clip does within 5 degrees (issue 28 acceptance 1).
FACING_TOL_RAD = math.radians(5.0)
#: A step turning more than this [rad] is a turning step: its radius and lean are compared (2 degrees).
TURNING_STEP_RAD = math.radians(2.0)


def intended_heading_change(clip: TakePath, n_steps_out: float) -> float:
    """The heading change [rad] an output of n_steps_out steps is asked for: none for a straight take
    (``is_straight``); otherwise the clip's turn per step kept, and the clip's whole turn at most (an output
    as long as the clip or longer turns as the clip does; a shorter one turns in proportion to its steps)."""
    if is_straight(clip):
        return 0.0
    share = min(1.0, n_steps_out / clip.n_steps) if clip.n_steps > 0 else 1.0
    return clip.heading_change_rad * share


def _deg(x: float) -> float | None:
    return round(math.degrees(x), 2) if math.isfinite(x) else None


def _turning(path: TakePath) -> list:
    return [s for s in path.steps if abs(s.heading_change_rad) > TURNING_STEP_RAD]


def _radius_L(path: TakePath, leg_length: float) -> float:
    """Median |radius| of the turning steps in leg lengths (NaN without a turning step)."""
    r = [abs(s.radius_m) / leg_length for s in _turning(path) if math.isfinite(s.radius_m)]
    return float(np.median(r)) if r else float("nan")


def _stride_lean(path: TakePath) -> float:
    """Mean lean [rad] over the turning steps, signed by the turn (+ = into the curve); NaN without one.

    A straight walk's lean alternates with the stance foot; over a turn's steps the mean is the lean into
    the curve (tan phi = v^2/(g r) for a body in a steady turn)."""
    leans = [s.lean_rad * math.copysign(1.0, s.heading_change_rad) for s in _turning(path)]
    return float(np.mean(leans)) if leans else float("nan")


def path_comparison(clip: TakePath, out: TakePath, clip_leg_length: float, out_leg_length: float) -> dict:
    """The output's path against the clip's (``Report.extras["path"]``): figures and the bars missed.

    Returns a JSON-able dict (degrees, metres, leg lengths): the clip's and the output's total heading
    change, the intended one (``intended_heading_change``), turn per step, radius per turning step in leg
    lengths, the lean into the curve, facing vs travel, and ``misses``: one sentence per bar missed, in the
    user's terms ("the output turns +2 deg where the clip turns +91 deg ...").
    """
    want = intended_heading_change(clip, out.n_steps)
    misses = []
    got = out.heading_change_rad
    if math.isfinite(want) and not abs(got - want) <= HEADING_TOL_RAD:  # NaN misses too
        how = "turns" if math.isfinite(got) else "has no measurable heading"
        shown = f" {math.degrees(got):+.0f} deg" if math.isfinite(got) else ""
        part = "" if abs(want - clip.heading_change_rad) < 1e-9 else \
            f" ({math.degrees(want):+.0f} deg for its {out.n_steps:.0f} steps of the clip's {clip.n_steps:.0f})"
        misses.append(f"the output {how}{shown} where the clip turns {math.degrees(clip.heading_change_rad):+.0f} "
                      f"deg{part} (within 3 deg)")
    f_clip, f_out = clip.mean_facing_vs_travel_rad, out.mean_facing_vs_travel_rad
    if math.isfinite(f_clip) and not abs(wrap_angle(f_out - f_clip)) <= FACING_TOL_RAD:
        misses.append(f"the output faces {math.degrees(f_out):+.0f} deg off its travel where the clip faces "
                      f"{math.degrees(f_clip):+.0f} deg (within 5 deg)")
    notes = []
    if is_straight(clip) and math.isfinite(clip.heading_change_rad) and clip.heading_change_rad != 0.0:
        notes.append(f"the clip veers {math.degrees(clip.heading_change_rad):+.1f} deg over its "
                     f"{clip.n_steps:.0f} steps; under {math.degrees(STRAIGHT_TAKE_RAD):.0f} deg a take is "
                     "modelled straight and the output runs straight")
    return {
        "notes": notes,
        "heading_change_deg": {"clip": _deg(clip.heading_change_rad), "output": _deg(got), "intended": _deg(want)},
        "steps": {"clip": round(clip.n_steps, 2), "output": round(out.n_steps, 2)},
        "turn_per_step_deg": {"clip": [_deg(s.heading_change_rad) for s in clip.steps],
                              "output": [_deg(s.heading_change_rad) for s in out.steps]},
        "radius_per_turning_step_L": {"clip": _finite(_radius_L(clip, clip_leg_length)),
                                      "output": _finite(_radius_L(out, out_leg_length))},
        "lean_into_turn_deg": {"clip": _deg(_stride_lean(clip)), "output": _deg(_stride_lean(out))},
        "facing_vs_travel_deg": {"clip": _deg(f_clip), "output": _deg(f_out)},
        "path_speed_m_s": {"clip": _finite(clip.path_speed_m_s), "output": _finite(out.path_speed_m_s)},
        "misses": misses,
    }


def _finite(v: float, digits: int = 4) -> float | None:
    return round(float(v), digits) if math.isfinite(v) else None


def path_rows(cmp: dict) -> list[tuple[str, str]]:
    """The result table's path rows from ``path_comparison``'s dict: heading change against the clip's and
    the intended, facing vs travel."""
    h, f = cmp["heading_change_deg"], cmp["facing_vs_travel_deg"]

    def deg(v):
        return "n/a" if v is None else f"{v:+.1f}"

    return [("heading change", f"{deg(h['output'])} deg (clip {deg(h['clip'])}, intended {deg(h['intended'])})"),
            ("facing vs travel", f"{deg(f['output'])} deg (clip {deg(f['clip'])})")]
