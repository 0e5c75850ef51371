"""The top-level Python API: the CLI's commands as functions with explicit, typed, SI-unit arguments.

    import froude
    run = froude.load("run.bvh")                          # a Motion (BVH or glTF/GLB by suffix)
    fitted = froude.fit(run)                              # the simple machine fitted to the clip
    child = froude.scale(fitted, "child", speed=0.8)      # a path, a Motion or a fit result
    child.com, child.ground_force, child.contacts         # (F, 3) [m], (F, 3) [N], (F, 2) bool
    child.report.froude_U                                 # the physics report
    child.save("child.glb")                               # .bvh / .glb / .gltf (+ child.report.json)
    child.save_data("child.csv")                          # per frame: .csv / .parquet / .npz
    faster = froude.accelerate(fitted, to_factor=1.3, steps=8)
    froude.info(run)["froude_U"]                           # what ``froude info --json`` says
    f = froude.ground_reaction_force(run)                 # (F, 3) [N] from the COM, eq. 1

Every function calls the same pipeline as the CLI (``froude.flow.pipeline``). A misspelt keyword argument is a
TypeError that names the valid ones.
"""
from __future__ import annotations

import difflib
import functools
import inspect
import os
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np

from .core.motion import Motion
from .errors import FroudeError
from .io.formats import save

__all__ = ["Result", "accelerate", "fit", "ground_reaction_force", "info", "load", "save", "scale"]

def _checked_keywords(fn):
    """Unknown keyword arguments → TypeError naming the closest valid one and listing them all."""
    params = inspect.signature(fn).parameters
    valid = [n for n, p in params.items() if p.kind in (p.KEYWORD_ONLY, p.POSITIONAL_OR_KEYWORD)]

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        unknown = [k for k in kwargs if k not in params]
        if unknown:
            k = unknown[0]
            close = difflib.get_close_matches(k, valid, n=1)
            hint = f" (did you mean '{close[0]}'?)" if close else ""
            raise TypeError(f"froude.{fn.__name__}() got an unexpected keyword argument '{k}'{hint}; "
                            f"valid arguments: {', '.join(valid)}")
        return fn(*args, **kwargs)

    return wrapper


# ---- loading and saving -----------------------------------------------------------------------------------
@_checked_keywords
def load(path: str | os.PathLike, *, length_scale: float | None = None, clean: bool = True,
         fps: float | None = None) -> Motion:
    """A motion from a ``.bvh`` or ``.glb``/``.gltf`` file, in SI units (+Y up).

    length_scale: metres per file unit (BVH default: detected from the motion; glTF: 1, its metres);
    clean: drop a synthetic T-pose frame (and a BVH's invalid edge rows); fps: sampling rate [Hz] for glTF
    (default: the file's own for froude files, else the animation's key spacing when even, else 30).
    """
    suffix = Path(path).suffix.lower()
    if suffix in (".glb", ".gltf"):
        from .body.load import load_gltf  # lazy: start-up (import froude and its light verbs load no pipeline)

        return load_gltf(path, fps=fps, clean=clean, length_scale=length_scale)
    from .body.load import load_bvh  # lazy: start-up (import froude and its light verbs load no pipeline)

    return load_bvh(path, length_scale=length_scale, clean=clean)


# ---- results ------------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class Result:
    """A motion with its physics: what ``fit``, ``scale`` and ``accelerate`` return.

    motion: the Motion (the input for ``fit``); body: its BodyModel; report: the physics report
    (metrics.Report); machine_path: the simple machine's path on the same frames (synthesis.timewarp.MachinePath;
    None for ``fit``); notes: what froude noted on the way; prepared: the fitted clip (pipeline.Prepared),
    reused when this result is passed to ``scale`` or ``accelerate``.
    """

    motion: Motion
    body: Any
    report: Any
    machine_path: Any = None
    notes: tuple = ()
    prepared: Any = field(default=None, repr=False)

    @cached_property
    def table(self) -> dict:
        """The per-frame columns (``froude.io.framedata``): {name: (F,) array}."""
        from .report.frames import frame_table  # lazy: start-up (import froude and its light verbs load no pipeline)

        return frame_table(self.motion, self.body, machine_path=self.machine_path)

    def _xyz(self, name: str) -> np.ndarray:
        return np.stack([self.table[name.format(a)] for a in "xyz"], axis=1)

    @property
    def times(self) -> np.ndarray:
        """(F,) frame times [s]."""
        return self.motion.times

    @property
    def com(self) -> np.ndarray:
        """(F, 3) the body's centre of mass [m]."""
        return self._xyz("com_{}_m")

    @property
    def com_velocity(self) -> np.ndarray:
        """(F, 3) its velocity [m/s] (zero-lag low-pass, as in the fit)."""
        return self._xyz("com_v{}_m_s")

    @property
    def ground_force(self) -> np.ndarray:
        """(F, 3) ground reaction force [N]: the simple machine's for outputs, from the COM (eq. 1) for a fit."""
        return self._xyz("machine_force_{}_N" if self.machine_path is not None else "com_force_{}_N")

    @property
    def contacts(self) -> np.ndarray:
        """(F, 2) bool: (left, right) foot on the ground."""
        return np.stack([self.table["contact_left"], self.table["contact_right"]], axis=1).astype(bool)

    @property
    def machine(self):
        """The fitted SimpleMachine (its parameters: ``machine.l0``, ``machine.k`` ...)."""
        return None if self.prepared is None else self.prepared.machine

    def save(self, path: str | os.PathLike, *, mesh: bool = True, report: bool = True) -> list[Path]:
        """Write the motion (suffix decides: .bvh / .glb / .gltf) and, unless report=False, OUT.report.json
        beside it; atomically. Returns the paths written."""
        from .flow.pipeline import report_path  # lazy: start-up (import froude and its light verbs load no pipeline)
        from .io.atomic import atomic_group  # lazy: start-up (import froude and its light verbs load no pipeline)
        from .report.metrics import write_report  # lazy: start-up (import froude and its light verbs load no pipeline)

        with atomic_group():  # both files or neither
            out = [save(self.motion, path, mesh=mesh)]
            if report:
                rp = report_path(path)
                write_report(self.report, rp)
                out.append(rp)
        return out

    def save_data(self, path: str | os.PathLike) -> Path:
        """Write the per-frame table as .csv / .parquet / .npz (atomically)."""
        from .io.framedata import write_frame_data  # lazy: start-up

        return write_frame_data(self.table, path)


def _prepared(clip, reference_mass: float, length_scale: float | None):
    """A pipeline.Prepared from a path, a Motion or an earlier Result (whose fit is reused)."""
    from .flow import pipeline  # lazy: start-up (import froude and its light verbs load no pipeline)

    if isinstance(clip, Result):
        if clip.prepared is None:
            raise FroudeError("this result has no fitted clip: pass froude.fit(...)'s result, a Motion or a path")
        return clip.prepared
    if isinstance(clip, (str, os.PathLike)):
        clip = load(clip, length_scale=length_scale)
    if not isinstance(clip, Motion):
        raise TypeError(f"clip must be a path, a froude.Motion or a froude result, not {type(clip).__name__}")
    return pipeline.prepare(clip, mass=reference_mass)


def _from_pipeline(res, prep) -> Result:
    return Result(res.motion, res.retarget.body, res.report, res.path, tuple(res.notes), prep)


# ---- the commands -------------------------------------------------------------------------------------------
@_checked_keywords
def info(clip: str | os.PathLike | Motion, *, mass: float = 70.0, length_scale: float | None = None) -> dict:
    """What is in a clip: ``froude info --json`` as a function (the same dict, schema ``froude.info/1``).

    clip: a BVH/GLB path or a Motion; mass: the performer's mass [kg] for the COM model; length_scale:
    metres per BVH file unit (default: detected). Keys include kind, mean_speed_m_s, froude_U,
    step_frequency_hz, contacts (per stance: foot, start_s, stop_s), skeleton (height_m, units ...).
    """
    from .body.model import BodyModel  # lazy: start-up (import froude and its light verbs load no pipeline)
    from .flow.clipinfo import clip_info  # lazy: start-up (import froude and its light verbs load no pipeline)

    motion = clip if isinstance(clip, Motion) else load(clip, length_scale=length_scale)
    return clip_info(motion, BodyModel.from_skeleton(motion.skeleton, mass=mass))[0]


@_checked_keywords
def fit(clip: str | os.PathLike | Motion, *, reference_mass: float = 70.0, length_scale: float | None = None) -> Result:
    """Fit the simple machine to a clip (paper §4: the running machine for a run, the walking machine for a
    walk) and measure it: ``froude fit`` as a function.

    clip: a BVH/GLB path or a Motion; reference_mass: the performer's mass [kg]; length_scale: metres per
    BVH file unit (default: detected). The result's ground_force is eq. 1 from the clip's COM; its
    ``machine`` the fitted SimpleMachine; pass it to ``scale``/``accelerate`` to reuse the fit.
    Raises NotARunningMotion for a clip that neither runs nor walks (in place, too few stances),
    FroudeError for a bad file.
    """
    from .report.metrics import physics_report  # lazy: start-up (import froude and its light verbs load no pipeline)

    prep = _prepared(clip, reference_mass, length_scale)
    report = physics_report(prep.motion, prep.body, com_and_markers=(prep.com, prep.markers))
    return Result(prep.motion, prep.body, report, None, (), prep)


@_checked_keywords
def scale(
    clip: str | os.PathLike | Motion | Result,
    character: str | os.PathLike | None = None,
    *,
    height: float | None = None,
    character_mass: float | None = None,
    leg_scale: float | None = None,
    arm_scale: float | None = None,
    head_scale: float | None = None,
    trunk_scale: float | None = None,
    speed: float | str = 1.0,
    target_speed: float | None = None,
    strides: int | None = None,
    duration: float | None = None,
    fps: float | None = None,
    method: str = "physical",
    reference_mass: float = 70.0,
    length_scale: float | None = None,
    unlimited: bool = False,
) -> Result:
    """The run on another character and/or at another speed (paper §5.1, §5.2, §6): ``froude scale``.

    clip: a path, a Motion or a ``fit`` result (its fit is reused); character: a preset name ("child",
    "giant", "small", "troll"), a character YAML or a target BVH skeleton (None: the reference's body);
    height [m], character_mass [kg], leg/arm/head/trunk_scale (factors on the reference's bones) on top;
    speed: factor on the character's dynamically scaled speed, or froude's speed syntax as text ("0.8x",
    "3.5m/s", as on the command line); target_speed: an absolute speed [m/s] instead; strides (two steps each) or
    duration [s]; fps: output frame rate [Hz] (default: the clip's);
    method: "physical" or "naive" (angles copied, root × L); reference_mass: the performer's mass [kg];
    length_scale: metres per BVH file unit of the clip (default: detected); unlimited: allow a run faster
    than the human range for the character's size (default: refused, BeyondHumanRange, with the limit in m/s).
    """
    from .flow import pipeline  # lazy: start-up (import froude and its light verbs load no pipeline)

    if isinstance(speed, str):
        from .flow.speed_goal import parse_speed  # lazy: start-up (import froude and its light verbs load no pipeline)

        goal = parse_speed(speed, "speed")
        speed, target_speed = (goal.factor, target_speed) if goal.factor is not None else (1.0, goal.m_s)
    prep = _prepared(clip, reference_mass, length_scale)
    res = pipeline.scale(prep, None if character is None else str(character), speed=speed,
                         target_speed=target_speed, strides=strides, duration=duration, fps=fps, method=method,
                         unlimited=unlimited, height=height, mass=character_mass, leg_scale=leg_scale,
                         arm_scale=arm_scale, head_scale=head_scale, trunk_scale=trunk_scale)
    return _from_pipeline(res, prep)


@_checked_keywords
def accelerate(
    clip: str | os.PathLike | Motion | Result,
    character: str | os.PathLike | None = None,
    *,
    to_speed: float | None = None,
    to_factor: float | None = None,
    steps: int | None = None,
    within: float | None = None,
    lead_steps: int = 2,
    hold_steps: int = 4,
    policy: str = "ease",
    fps: float | None = None,
    height: float | None = None,
    character_mass: float | None = None,
    leg_scale: float | None = None,
    arm_scale: float | None = None,
    head_scale: float | None = None,
    trunk_scale: float | None = None,
    reference_mass: float = 70.0,
    length_scale: float | None = None,
    unlimited: bool = False,
) -> Result:
    """Speed up or slow down over some steps (paper §5.3, §6): ``froude accelerate``.

    Exactly one goal: to_speed [m/s] or to_factor (× the start speed); the change takes ``steps`` steps
    (default 8) or happens ``within`` seconds; lead_steps / hold_steps steady steps before / after; policy:
    "ease" or "even". Character arguments and ``unlimited`` as in ``scale``.
    """
    from .flow import pipeline  # lazy: start-up (import froude and its light verbs load no pipeline)

    if steps is None and within is None:
        steps = 8
    prep = _prepared(clip, reference_mass, length_scale)
    res = pipeline.accelerate(prep, None if character is None else str(character), to_speed=to_speed,
                              to_factor=to_factor, steps=steps, within=within, lead_steps=lead_steps,
                              hold_steps=hold_steps, fps=fps, policy=policy, unlimited=unlimited, height=height,
                              mass=character_mass, leg_scale=leg_scale, arm_scale=arm_scale, head_scale=head_scale,
                              trunk_scale=trunk_scale)
    return _from_pipeline(res, prep)


@_checked_keywords
def ground_reaction_force(motion: Motion, body=None, *, mass: float = 70.0) -> np.ndarray:
    """(F, 3) ground reaction force [N] of a motion from its COM: low-passed (zero lag) and eq. 1,
    f = m (a - g), as the fit and the report compute it.

    body: its BodyModel (default: built from the skeleton with ``mass`` [kg]; a given body has its own).
    """
    from .body.model import BodyModel  # lazy: start-up (import froude and its light verbs load no pipeline)
    from .machine.forces import ground_force, smooth_com  # lazy: start-up

    if body is None:
        body = BodyModel.from_skeleton(motion.skeleton, mass=mass)
    a = smooth_com(body.com(motion), motion.frame_time)[2]
    return ground_force(a, body.total_mass)
