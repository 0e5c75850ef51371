"""The studio's model, without any UI: parameters → preview / result → drawable tracks.

Every result comes from ``pipeline.scale`` / ``pipeline.accelerate`` on one ``Prepared`` (the same calls
the CLI makes). The preview is the cheap first half of ``pipeline.scale`` (machine path + time-warped
reference poses, no IK) so that the page answers a slider within a frame or two while IK runs.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ...body.characters import apply_character, list_presets, resolve_character
from ...errors import FitError, FroudeError
from ...flow import pipeline
from ...flow.result import Output
from .tracks import Track, machine_track, motion_hash, reference_track

MODES = ("scale", "accelerate")
SAME = "same"  # the reference's own body


@dataclass(frozen=True)
class Limit:
    """A numeric control's range, as the page shows it and the server enforces it.

    lo, hi: inclusive bounds in ``unit``; step: the control's step; whole: an integer count.
    """

    label: str
    lo: float
    hi: float
    step: float
    unit: str = ""
    whole: bool = False

    def check(self, value) -> float | int:
        """The value as a float (int when whole) or a FroudeError in the user's terms with the fix."""
        try:
            v = float(value)
        except (TypeError, ValueError):
            raise FroudeError(f"{self.label} must be a number from {self.range()}, got {str(value)[:40]!r}") from None
        if not math.isfinite(v) or not (self.lo <= v <= self.hi):
            raise FroudeError(f"{self.label} {_fmt(v)}{self.unit} is outside {self.range()}: "
                              f"pick a value from {self.range()}")
        if self.whole:
            if v != int(v):
                raise FroudeError(f"{self.label} must be a whole number from {self.range()}, got {_fmt(v)}")
            return int(v)
        return v

    def range(self) -> str:
        return f"{_fmt(self.lo)}{self.unit} to {_fmt(self.hi)}{self.unit}"


def _fmt(v: float) -> str:
    return f"{v:g}"


#: Every numeric control: its range on the page and on the server (a value outside is refused, whatever
#: sent it). Strides and steps bound the work of one change (the machine path and the IK grow with them).
LIMITS = {
    "height": Limit("Height", 0.5, 4.0, 0.01, " m"),
    "mass": Limit("Mass", 5.0, 500.0, 0.5, " kg"),
    "leg_scale": Limit("Leg scale", 0.5, 2.0, 0.01, "×"),
    "speed": Limit("Speed", 0.5, 2.0, 0.05, "×"),
    "strides": Limit("Strides", 1, 12, 1, "", whole=True),
    "to_factor": Limit("Goal speed", 0.5, 2.0, 0.05, "×"),
    "steps": Limit("Steps", 1, 60, 1, "", whole=True),
}


@dataclass(frozen=True)
class Params:
    """Everything the user can change. height [m], mass [kg], leg_scale: None = the character's own."""

    mode: str = "scale"
    character: str = SAME
    height: float | None = None
    mass: float | None = None
    leg_scale: float | None = None
    speed: float = 1.0  # scale: factor on the dynamically scaled speed
    strides: int = 4  # scale: output length
    to_factor: float = 1.1  # accelerate: goal = factor × the start speed
    steps: int = 16  # accelerate: steps the change takes

    def check(self, presets=None) -> Params:
        """Every value against its control's options and limits (``LIMITS``); the checked copy, or a
        one-line FroudeError saying which control, the value and the range. presets: the Character
        control's options (default: the shipped presets and "same") -- a character is only ever one of them,
        never a path, so nothing but a preset is read from disk."""
        if self.mode not in MODES:
            raise FroudeError(f"Mode must be {' or '.join(MODES)}, got {str(self.mode)[:40]!r}")
        options = presets if presets is not None else (SAME, *list_presets())
        if self.character not in options:
            raise FroudeError(f"Character must be one of the presets ({', '.join(options)}); "
                              f"got {str(self.character)[:40]!r}")
        out: dict[str, Any] = {}
        for name, lim in LIMITS.items():
            v = getattr(self, name)
            out[name] = None if v is None else lim.check(v)
        return replace(self, **out)

    def character_args(self) -> tuple[str | None, dict]:
        """(character spec for the pipeline, the numbers that override it)."""
        nums = {k: getattr(self, k) for k in ("height", "mass", "leg_scale") if getattr(self, k) is not None}
        return (None if self.character == SAME else self.character), nums

    def label(self) -> str:
        what = f"speed ×{self.speed:g}, {self.strides} strides" if self.mode == "scale" else (
            f"to ×{self.to_factor:g} in {self.steps} steps")
        return f"{self.character}: {self.mode} {what}"


@dataclass(frozen=True, eq=False)
class Solved:
    """A result and its drawable track. preview: True when this is the IK-free preview (result is None)."""

    params: Params
    track: Track
    result: Output | None
    preview: bool
    seconds: float
    hash: str
    n_frames: int


class Session:
    """A prepared reference and the calls that turn parameters into tracks."""

    def __init__(self, prep: pipeline.Prepared):
        self.prep = prep
        self.reference = reference_track(prep)
        self.presets = [SAME, *list_presets()]
        #: speed_range.reachable_speed_range per preset on this clip, filled by the studio as presets are used
        self.speed_ranges: dict = {}

    def character_defaults(self, name: str) -> tuple[float, float, float]:
        """(height [m], mass [kg], leg scale) of a preset (or the reference itself) on this clip."""
        if name not in self.presets:
            raise FroudeError(f"Character must be one of the presets ({', '.join(self.presets)}); "
                              f"got {str(name)[:40]!r}")
        char = resolve_character(None if name == SAME else name)
        rt = apply_character(char, self.prep.body)
        return float(rt.body.stature), float(rt.body.total_mass), float(char.proportions.get("legs", 1.0))

    def preview(self, params: Params) -> Solved | None:
        """The machine path and the time-warped reference on the target skeleton, without IK.

        The front half of ``pipeline.scale`` (``pipeline.plan_scale``); accelerate has no cheap preview
        (its plan is the expensive part), so None.
        """
        if params.mode != "scale":
            return None
        t0 = time.perf_counter()
        params = params.check(self.presets)
        spec, nums = params.character_args()
        plan = pipeline.plan_scale(self.prep, spec, speed=params.speed, strides=int(params.strides), **nums)
        retarget, path = plan.retarget, plan.path
        assert path is not None  # the physical method (the studio has no naive preview)
        # along a turning take's path and on its floor, as the result
        targets, path = pipeline.targets_of(self.prep, path, retarget)
        _require_finite(targets.initial)
        track = machine_track(targets.initial, retarget.body, path)
        return Solved(params, track, None, True, time.perf_counter() - t0, motion_hash(targets.initial),
                      targets.initial.n_frames)

    def solve(self, params: Params, report: bool = True) -> Solved:
        """The full result through the pipeline (IK included) and its track. Raises FroudeError.

        report=False leaves the physics report for ``with_report`` (the motion can be shown first).
        """
        t0 = time.perf_counter()
        params = params.check(self.presets)
        spec, nums = params.character_args()
        if params.mode == "scale":
            try:
                res = pipeline.scale(self.prep, spec, speed=params.speed, strides=int(params.strides),
                                     report=report, **nums)
            except FitError as e:  # no running cycle at that speed: say it in m/s with the fix
                raise FroudeError(self._scale_message(params, e)) from None
        else:
            try:
                res = pipeline.accelerate(self.prep, spec, to_factor=params.to_factor, steps=int(params.steps),
                                          report=report, **nums)
            except FroudeError as e:
                raise FroudeError(self._accelerate_message(params, e)) from None
        _require_finite(res.motion)
        assert res.targets is not None  # a physical result
        # the corrected COM is the machine's (correct() makes it exact), so the track needs no COM pass
        track = machine_track(res.motion, res.retarget.body, res.path, body_com=res.targets.com)
        return Solved(params, track, res, False, time.perf_counter() - t0, motion_hash(res.motion),
                      res.motion.n_frames)

    def start_speed(self, params: Params) -> float:
        """The apex speed [m/s] the character runs at before an acceleration (the goal is × this)."""
        spec, nums = params.character_args()
        rt = self.prep.retarget(spec, **nums)
        m = self.prep.machine.scaled(rt.L, rt.M)
        return float(m.U * m.speed_unit)

    def _scale_message(self, params: Params, err: FroudeError) -> str:
        """The machine's refusal of a speed in the user's terms (m/s, ×) with the fix."""
        spec, nums = params.character_args()
        rt = self.prep.retarget(spec, **nums)
        m = self.prep.machine.scaled(rt.L, rt.M)
        v = params.speed * m.mean_speed_m_s
        return self.prep.kind.speed_refusal(params.character, params.speed, v, err)

    def _accelerate_message(self, params: Params, err: FroudeError) -> str:
        """The refusal's first line: the pipeline already says it in m/s, × and steps (``plan_refusal``)."""
        return str(err).splitlines()[0] if str(err) else type(err).__name__


def with_report(prep: pipeline.Prepared, solved: Solved) -> Solved:
    """The same solved result with its physics report computed (no-op if it has one)."""
    from dataclasses import replace

    if solved.result is None or solved.result.report is not None:
        return solved
    return replace(solved, result=pipeline.add_report(prep, solved.result))


def _require_finite(motion) -> None:
    if not (np.isfinite(motion.root_positions).all() and np.isfinite(motion.rotations).all()):
        raise FroudeError("the change produced non-finite poses; keeping the last good result")


def with_character(params: Params, name: str) -> Params:
    """A new character preset resets the number overrides to that character's own."""
    return replace(params, character=name, height=None, mass=None, leg_scale=None)
