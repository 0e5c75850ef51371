"""A reference clip made ready for any number of changes (``pipeline.prepare`` builds it), and what it
builds on demand and remembers (``Memo``)."""
from __future__ import annotations

import functools
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from ..body.characters import Retarget, apply_character, list_presets, resolve_character
from ..body.gait import Gait, GaitSummary
from ..body.model import BodyModel
from ..body.path import TakePath
from ..core.constants import GRAVITY
from ..core.motion import Motion
from ..machine.speed_law import froude_cadence, human_top_factor
from ..synthesis.cycle import ReferenceCycle

if TYPE_CHECKING:
    from ..machine.fit import FitResult
    from ..machine.model import SimpleMachine


@dataclass(eq=False)
class Memo:
    """What a prepared clip builds on demand and remembers: an editor asks for the same character again
    and again (every speed change), and the studio's speed slider revisits values.

    retargets: (preset name or None, character numbers) -> Retarget (built-in presets and the reference's
    own body only; files and Character objects are built each time); faster_machines: speed factor ->
    the machine re-solved for it (slower or faster); speed_ranges: character key -> speed_range.SpeedRange;
    speed_probes:
    character key -> {speed factor: (meets the bars, why not)}, the outputs a range search checked (kept
    when the search is stopped, so that its next run repeats none).
    """

    retargets: dict = field(default_factory=dict)
    faster_machines: dict = field(default_factory=dict)
    speed_ranges: dict = field(default_factory=dict)
    speed_probes: dict = field(default_factory=dict)


@dataclass(frozen=True, eq=False)
class Prepared:
    """A reference clip made ready for any number of changes (fit once, reuse for every variation)."""

    motion: Motion
    body: BodyModel
    com: np.ndarray
    markers: np.ndarray
    gait: Gait
    summary: GaitSummary
    machine: SimpleMachine
    cycle: ReferenceCycle
    source: str = ""
    fit: FitResult | None = None  # everything the fit measured (plots, tables)
    #: What the machine stands for ("0.00-2.40 s of the take: 3.150 m/s, 2.930 steps/s") and notes about
    #: the take (its speed changes: which part is modelled, how to choose another).
    modelled: str = ""
    notes: tuple = ()
    #: The take's path as it was taken (``body.path.take_path``); turn: the same when the take turns
    #: (``body.path.is_straight`` is False), in which case ``motion`` (and com, markers, gait, the machine,
    #: the cycle) is the take straightened along it (``body.path.straighten``) and outputs are bent back
    #: onto it (``synthesis.bend``); None for a straight take, modelled as it is.
    clip_path: TakePath | None = None
    turn: TakePath | None = None
    #: The kind of locomotion and its machine (``kinds.MotionKind``): every verb asks it, not the machine's
    #: type. ``pipeline.prepare`` sets it (``kinds.choose_kind``).
    kind: Any = None
    #: What is built on demand for this clip and remembered (see Memo).
    memo: Memo = field(default_factory=lambda: Memo(), repr=False)

    @property
    def path(self) -> TakePath:
        """The clip's path (``body.path.take_path``) as taken, before any straightening: what an output's
        path is compared with."""
        assert self.clip_path is not None, "pipeline.prepare measures the clip's path"
        return self.clip_path

    @property
    def origin(self) -> np.ndarray:
        """(3,) [m] where outputs start: the reference COM's first position (placed on the floor there)."""
        return self.com[0]

    @property
    def output_meta(self) -> dict:
        """Provenance every output motion of this clip carries (source file, the input's length scale)."""
        return {"source": self.source, "length_scale": float(self.motion.meta.get("length_scale", 1.0))}

    @property
    def law_cadence(self) -> float:
        """Where a run sits on the human speed law: the fitted cycle's step frequency in Froude terms of the
        runner's stature, f √(S/g) [-] (``machine.speed_law``)."""
        m = self.machine
        return float(froude_cadence(1.0 / (m.step_time * m.time_unit), self.body.stature))

    def machine_at_speed(self, speed: float):
        """The machine re-solved at ``speed`` × the clip's speed by its kind (a run by the human speed law,
        ``machine.speed.machine_at_speed``; a walk by its walking cycle, ``machine.walk_speed``);
        remembered per speed factor."""
        return self.kind.machine_at_speed(self, float(speed), self.memo.faster_machines)

    def human_top(self, retarget: Retarget):
        """``machine.speed_law.human_top_factor`` of a run for one character: the fastest speed factor whose
        steady step stays inside the human limits for the character's stature (the clip's cycle scaled to
        it by dynamic similarity, the law placed by the clip's own cadence)."""
        m = self.machine.scaled(retarget.L, retarget.M)
        stature = retarget.body.stature
        t_unit = m.time_unit / float(np.sqrt(stature / GRAVITY))  # the machine's time unit in √(S/g)
        return human_top_factor(self.law_cadence, m.step_time * t_unit, m.t_stance * t_unit, m.t_flight * t_unit,
                                m.step_length * m.l0 / stature)

    def retarget(self, character=None, **character_numbers) -> Retarget:
        """``apply_character(resolve_character(character, **numbers), self.body)``, remembered for the
        built-in presets and the reference's own body (files and Character objects are built each time)."""
        key = None
        if character is None or (isinstance(character, str) and character in _preset_names()):
            key = (character, tuple(sorted((k, v) for k, v in character_numbers.items() if v is not None)))
            hit = self.memo.retargets.get(key)
            if hit is not None:
                return hit
        rt = apply_character(resolve_character(character, **character_numbers), self.body)
        if key is not None:
            self.memo.retargets[key] = rt
        return rt


@functools.cache
def _preset_names() -> frozenset:
    return frozenset(list_presets())
