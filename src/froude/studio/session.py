"""The studio's model, without any UI: parameters → preview / result → drawable tracks.

Every result comes from ``pipeline.scale`` / ``pipeline.accelerate`` on one ``Prepared`` (the same calls
the CLI makes). The preview is the cheap first half of ``pipeline.scale`` (machine path + time-warped
reference poses, no IK) so that the page answers a slider within a frame or two while IK runs.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace

import numpy as np

from .. import pipeline
from ..characters import apply_character, list_presets
from ..errors import FroudeError
from .tracks import Track, machine_track, motion_hash, reference_track

MODES = ("scale", "accelerate")
SAME = "same"  # the reference's own body


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

    def check(self) -> None:
        """The studio's own input checks (the pipeline checks again; these guard the preview)."""
        if self.mode not in MODES:
            raise FroudeError(f"unknown mode '{self.mode}' ({' or '.join(MODES)})")
        for name in ("speed", "to_factor"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise FroudeError(f"{name.replace('_', ' ')} must be > 0, got {v:g}")
        if self.mode == "scale" and self.strides < 1:
            raise FroudeError(f"strides must be >= 1, got {self.strides}")

    def character_args(self) -> tuple[str | None, dict]:
        """(character spec for the pipeline, the numbers that override it)."""
        nums = {k: getattr(self, k) for k in ("height", "mass", "leg_scale") if getattr(self, k) is not None}
        return (None if self.character == SAME else self.character), nums

    def label(self) -> str:
        what = f"speed x{self.speed:g}, {self.strides} strides" if self.mode == "scale" else (
            f"to x{self.to_factor:g} in {self.steps} steps")
        return f"{self.character}: {self.mode} {what}"


@dataclass(frozen=True, eq=False)
class Solved:
    """A result and its drawable track. preview: True when this is the IK-free preview (result is None)."""

    params: Params
    track: Track
    result: object  # pipeline.Result | None
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

    def character_defaults(self, name: str) -> tuple[float, float, float]:
        """(height [m], mass [kg], leg scale) of a preset (or the reference itself) on this clip."""
        char = pipeline.resolve_character(None if name == SAME else name)
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
        params.check()
        spec, nums = params.character_args()
        plan = pipeline.plan_scale(self.prep, spec, speed=params.speed, strides=int(params.strides), **nums)
        retarget, path = plan.retarget, plan.path
        targets = pipeline.build_targets(self.prep, path, retarget)
        _require_finite(targets.initial)
        track = machine_track(targets.initial, retarget.body, path)
        return Solved(params, track, None, True, time.perf_counter() - t0, motion_hash(targets.initial),
                      targets.initial.n_frames)

    def solve(self, params: Params, report: bool = True) -> Solved:
        """The full result through the pipeline (IK included) and its track. Raises FroudeError.

        report=False leaves the physics report for ``with_report`` (the motion can be shown first).
        """
        t0 = time.perf_counter()
        params.check()
        spec, nums = params.character_args()
        if params.mode == "scale":
            res = pipeline.scale(self.prep, spec, speed=params.speed, strides=int(params.strides), report=report,
                                 **nums)
        else:
            res = pipeline.accelerate(self.prep, spec, to_factor=params.to_factor, steps=int(params.steps),
                                      report=report, **nums)
        _require_finite(res.motion)
        # the corrected COM is the machine's (correct() makes it exact), so the track needs no COM pass
        track = machine_track(res.motion, res.retarget.body, res.path, body_com=res.targets.com)
        return Solved(params, track, res, False, time.perf_counter() - t0, motion_hash(res.motion),
                      res.motion.n_frames)


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
