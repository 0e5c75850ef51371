"""The kinds of locomotion froude models, as one type (issue 27): what a verb asks of a motion's kind.

A kind is the machine that models a motion and everything that depends on it: its fit, the machine path of
``scale`` and of ``accelerate``, the machine re-solved at another speed, the human speed limit, the IK's
repair passes, its part of the physics report and its rows in the summary, and how a refused speed is said.
The pipeline, the report, the studio and batch ask the kind (``Prepared.kind``); they never test which one
it is. ``KINDS`` lists them in the order ``choose_kind`` tries them; ``register`` adds one (a new gait is
a new ``MotionKind``, nothing else changes).

The running machine (paper §4-5) models runs; the walking machine (docs/walking.md) walks and grounded
running (a foot always down). ``body.gait`` decides what a clip is, once, for ``info`` and every verb.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any, Protocol

from ..body.gait import GaitSummary, require_running, walks
from ..machine.fit import fit_machine_detailed, unsprung_note
from ..machine.speed import machine_at_speed
from ..synthesis.cycle import extract_cycle
from ..synthesis.phases import fit_events
from ..synthesis.timewarp import machine_path
from .speed_change import check_human_speed, plan_run_speed_change

__all__ = ["KINDS", "RUNNING", "WALKING", "MotionKind", "choose_kind", "kind_named", "register"]


class MotionKind(Protocol):
    """One kind of locomotion and its machine. ``prep`` is a ``prepared.Prepared``; ``retarget`` a
    ``body.characters.Retarget``; ``res`` a ``result.Output``; ``report`` a ``metrics.Report``."""

    #: the report's ``extras["machine"]`` and the machine file's kind ("running", "walking")
    name: str
    #: whether its outputs have flight phases, so that the flight-gravity bar applies to them
    has_flight: bool
    #: IK repair passes over frames still jumping or missing their targets (``ik.correct.correct``)
    repair_rounds: int

    def takes(self, summary: GaitSummary) -> bool:
        """Whether this kind's machine models a clip that ``body.gait`` summarised so."""
        ...

    def fit_detailed(self, motion, body, *, mass: float, source: str) -> Any:
        """The machine's fit with everything it measured (``froude fit``): a result with ``.machine``."""
        ...

    def fit(self, motion, body, com, markers, gait, source: str, mass: float) -> tuple[Any, Any]:
        """(fit result, ``synthesis.cycle.ReferenceCycle``) of a clip (``pipeline.prepare``)."""
        ...

    def fit_notes(self, fit) -> tuple[str, ...]:
        """What the user should know of a fit (``fit``'s result): the parts of the take it left out."""
        ...

    def machine_at_speed(self, prep, speed: float, memo: dict) -> Any:
        """The fitted machine re-solved at ``speed`` × the clip's speed; memo: speed factor -> machine."""
        ...

    def human_top(self, prep, retarget) -> Any:
        """The human speed limit for the character (``machine.speed_law.HumanTop``), or None where the
        machine's own cycle bounds the speed."""
        ...

    def scale_path(self, prep, retarget, speed: float, *, n_steps: int, fps: float, speed_model: str,
                   unlimited: bool, base_m_s: float) -> tuple[Any, str, tuple | None]:
        """``scale``'s machine path at speed factor ``speed``: (``MachinePath``, method name, periodic),
        periodic = (machine, stretch, fps) when the path is the steady cycle repeated, else None."""
        ...

    def speed_change(self, prep, retarget, *, to_speed, to_factor, steps, within, lead_steps: int,
                     hold_steps: int, fps, energy: str, policy: str, unlimited: bool,
                     speed_model: str) -> tuple[Any, Any, list, dict]:
        """``accelerate``'s machine path (its arguments): (``MachinePath``, plan, notes, report extras)."""
        ...

    def report_extras(self, prep, res, report) -> dict:
        """This kind's part of an output's physics report (merged into ``Report.extras``)."""
        ...

    def summary_rows(self, report) -> list[tuple[str, str]]:
        """This kind's rows of the result table (``result.summary_rows``)."""
        ...

    def speed_refusal(self, character: str, factor: float, speed_m_s: float, err: Exception) -> str:
        """One line saying why ``character`` cannot move at ``factor`` × (``speed_m_s`` m/s), with the fix."""
        ...


class Running:
    """The running machine: one spring leg, stance and flight (paper §4), its speed changes by the human
    speed law or §5.3's planner."""

    name = "running"
    has_flight = True
    repair_rounds = 1

    def takes(self, summary: GaitSummary) -> bool:
        return summary.kind == "running"

    def fit_detailed(self, motion, body, *, mass: float, source: str):
        return fit_machine_detailed(motion, body, mass=mass, source=source)

    def fit(self, motion, body, com, markers, gait, source: str, mass: float):
        fit = self.fit_detailed(motion, body, mass=mass, source=Path(source).name)
        return fit, extract_cycle(motion, body, gait, com, markers, events=fit_events(fit.machine, motion))

    def fit_notes(self, fit) -> tuple[str, ...]:
        note = unsprung_note(fit.machine)
        return (note,) if note else ()

    def machine_at_speed(self, prep, speed: float, memo: dict):
        hit = memo.get(speed)
        if hit is None:
            hit = memo[speed] = machine_at_speed(prep.machine, speed, prep.law_cadence)
        return hit

    def human_top(self, prep, retarget):
        return prep.human_top(retarget)

    def scale_path(self, prep, retarget, speed, *, n_steps, fps, speed_model, unlimited, base_m_s):
        if not unlimited:
            check_human_speed(prep, retarget, speed, base_m_s)
        if speed_model != "stretch" and abs(speed - 1.0) > 1e-9:
            machine, stretch = prep.machine_at_speed(speed), 1.0
            method = "physical (cycle re-solved at the new speed, human speed law)"
        else:
            machine, stretch, method = prep.machine, speed, "physical"
        path = machine_path(prep.cycle, machine.scaled(retarget.L, retarget.M), retarget.L, prep.origin,
                            stretch=stretch, n_steps=n_steps, fps=fps)
        return path, method, (machine, stretch, fps)

    def speed_change(self, prep, retarget, *, to_speed, to_factor, steps, within, lead_steps, hold_steps, fps,
                     energy, policy, unlimited, speed_model):
        return plan_run_speed_change(prep, retarget, to_speed=to_speed, to_factor=to_factor, steps=steps,
                                     within=within, lead_steps=lead_steps, hold_steps=hold_steps, fps=fps,
                                     energy=energy, policy=policy, unlimited=unlimited, speed_model=speed_model)

    def report_extras(self, prep, res, report) -> dict:
        return {}

    def summary_rows(self, report) -> list[tuple[str, str]]:
        return []

    def speed_refusal(self, character, factor, speed_m_s, err) -> str:
        return (f"{character} cannot run at ×{factor:g} ({speed_m_s:.2f} m/s) on this clip: the simple "
                f"machine has no running cycle there; pick a speed nearer ×1")


class Walking:
    """The walking machine: two spring legs with double support (docs/walking.md), for walks and grounded
    running; faster by its re-solved walking cycle, slower by §5.2's stretch, changes by its own planner
    (the human speed law's sources are runners)."""

    name = "walking"
    has_flight = False
    repair_rounds = 4  # a walk's knee is near straight at contact: more frames need a second solve

    def takes(self, summary: GaitSummary) -> bool:
        return walks(summary)

    def fit_detailed(self, motion, body, *, mass: float, source: str):
        from ..machine.walk_fit import fit_walking_detailed  # lazy: start-up (a run's verbs load no walking code)

        return fit_walking_detailed(motion, body, mass=mass, source=source)

    def fit(self, motion, body, com, markers, gait, source: str, mass: float):
        from ..synthesis.walking import fit_walk  # lazy: start-up (a run's verbs load no walking code)

        return fit_walk(motion, body, com, markers, gait, source, mass)

    def fit_notes(self, fit) -> tuple[str, ...]:
        return ()

    def machine_at_speed(self, prep, speed: float, memo: dict):
        from ..machine.walk_speed import walking_machines_at_speeds  # lazy: start-up

        return walking_machines_at_speeds(prep.machine, [speed], memo)[speed]

    def human_top(self, prep, retarget):
        return None  # the walking cycle itself ends at the walk-run transition (``check_walking_speed``)

    def scale_path(self, prep, retarget, speed, *, n_steps, fps, speed_model, unlimited, base_m_s):
        from ..synthesis.walking import walk_scale_path  # lazy: start-up (a run's verbs load no walking code)

        path, method = walk_scale_path(prep, retarget, speed, n_steps=n_steps, fps=fps)
        return path, method, None

    def speed_change(self, prep, retarget, *, to_speed, to_factor, steps, within, lead_steps, hold_steps, fps,
                     energy, policy, unlimited, speed_model):
        """energy, policy, unlimited and speed_model are the running planner's: a walk's change has its own
        planner (``synthesis.walking.plan_walk_speed_change``; the human speed law's sources are runners)."""
        from ..synthesis.walking import plan_walk_speed_change  # lazy: start-up (a run's verbs load no walking code)

        path, walk_plan = plan_walk_speed_change(prep, retarget, to_speed=to_speed, to_factor=to_factor,
                                                 steps=steps, within=within, lead_steps=lead_steps,
                                                 hold_steps=hold_steps, fps=fps)
        return path, None, list(prep.notes), {"plan": walk_plan}

    def report_extras(self, prep, res, report) -> dict:
        from ..report.walk_report import walking_extras  # lazy: start-up (a run's verbs load no walking code)

        return walking_extras(prep, res, report)

    def summary_rows(self, report) -> list[tuple[str, str]]:
        from ..report.walk_report import walking_rows  # lazy: start-up (a run's verbs load no walking code)

        return walking_rows(report)

    def speed_refusal(self, character, factor, speed_m_s, err) -> str:
        return str(err).splitlines()[0]  # the walking machine says it in m/s already (walk-run transition)


RUNNING: MotionKind = Running()
WALKING: MotionKind = Walking()
#: The kinds ``choose_kind`` tries, in order (the first that takes a clip models it).
KINDS: list[MotionKind] = [WALKING, RUNNING]


def register(kind: MotionKind, first: bool = True) -> None:
    """Add a kind of locomotion (tried before the others when ``first``). Its name must be new."""
    if any(k.name == kind.name for k in KINDS):
        raise ValueError(f"a motion kind named '{kind.name}' is registered already")
    KINDS.insert(0 if first else len(KINDS), kind)


def unregister(name: str) -> None:
    """Remove the kind named ``name`` (tests that add a toy kind take it away again)."""
    KINDS[:] = [k for k in KINDS if k.name != name]


def choose_kind(summary: GaitSummary, source: str = "motion", running_only: bool = False) -> MotionKind:
    """The kind that models a clip (``body.gait``'s one decision about it). running_only: only the running
    machine. Raises NotARunningMotion, in ``info``'s words, for a clip no kind takes (in place, unknown)."""
    for kind in ([RUNNING] if running_only else KINDS):
        if kind.takes(summary):
            return kind
    require_running(summary, source)  # says what the clip is and why no machine models it
    raise AssertionError("require_running passes only running clips, which RUNNING takes")


def kind_named(name: str | None) -> MotionKind:
    """The registered kind called ``name`` (a report's ``extras["machine"]``); running when None."""
    for kind in KINDS:
        if kind.name == (name or RUNNING.name):
            return kind
    raise KeyError(f"no motion kind named '{name}'")
