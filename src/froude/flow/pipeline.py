"""fit → modify → synthesise → correct, as plain functions: the one place the CLI, studio and batch call.

    prep = prepare("run.bvh")                                   # load, body model, gait, §4 fit, cycle
    out = scale(prep, character="child", speed=0.7, strides=4)  # §5.1 + §5.2 + §6
    out = accelerate(prep, to_speed=0.5, steps=8)               # §5.3 + §6
    write_result(out, "child.bvh")                              # BVH + child.report.json, atomically

The output stands on the floor y = 0, starts where the reference's COM starts (horizontally) and runs in
the reference's direction of travel.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from dataclasses import replace as _replace
from pathlib import Path

import numpy as np

from ..body.characters import Retarget
from ..body.gait import summarize
from ..body.load import load_bvh
from ..body.model import BodyModel
from ..body.path import unstraighten
from ..body.take import analysed_take, modelled_part, said_on_turn, select_range
from ..core.motion import Motion
from ..errors import FroudeError
from ..ik.correct import correct, tile_stride
from ..report.metrics import BARS, physics_report, source_rest_heights
from ..synthesis.bend import bend
from ..synthesis.targets import Targets, build_targets, raised, stance_only
from ..synthesis.timewarp import MachinePath, machine_path
from .kinds import choose_kind
from .naive import naive_clip, naive_cycle, naive_take
from .prepared import Prepared
from .result import Output, report_path, write_result
from .speed_change import output_steps, speed_range_notes
from .speed_goal import scale_factor

__all__ = ["Output", "PERIODIC_MIN_STRIDES", "Prepared", "ScalePlan", "accelerate", "add_report", "finish",
           "naive_clip", "plan_scale", "prepare", "report_path", "scale", "targets_of", "write_result"]


def prepare(clip, *, mass: float = 70.0, sex: str = "male", joint_map=None, length_scale=None,
            time_range=None, running_only: bool = False) -> Prepared:
    """Load (if given a path), model, find the kind of motion, fit its simple machine, build the cycle.

    time_range: (T0, T1) [s] (either None): model only that part of the take (its speed, cadence and
    strides); the whole take by default. running_only: refuse a walk (NotARunningMotion) before fitting.
    """
    if isinstance(clip, Motion):
        motion, source = clip, str(clip.meta.get("source", "motion"))
    else:
        motion, source = load_bvh(clip, length_scale=length_scale), str(clip)
    if time_range is not None:
        motion = select_range(motion, time_range, Path(source).name)
    body = BodyModel.from_skeleton(motion.skeleton, mass=mass, sex=sex, joint_map=joint_map)
    take = analysed_take(motion, body)
    motion, com, markers, gait, turn = take.motion, take.com, take.markers, take.gait, take.turn
    summary = summarize(motion, body, com, gait)
    kind = choose_kind(summary, source, running_only)  # body.gait's one decision chooses the machine
    with said_on_turn(source, turn):
        fit, cycle = kind.fit(motion, body, com, markers, gait, source, mass)
    machine = fit.machine
    modelled, note = modelled_part(motion, summary, com, gait)
    return Prepared(motion, body, com, markers, gait, summary, machine, cycle, source, fit,
                    modelled=modelled, notes=take.notes + kind.fit_notes(fit) + ((note,) if note else ()),
                    clip_path=take.clip_path,
                    turn=turn, kind=kind)


@dataclass(frozen=True, eq=False)
class ScalePlan:
    """The first half of ``scale``: the character applied, the machine chosen and its path simulated.

    ``plan.finish()`` completes it (targets, IK, report); the studio shows ``path`` and the targets'
    initial motion (``targets_of(prep, plan.path, plan.retarget)``) as an instant preview.
    """

    prep: Prepared
    path: MachinePath | None  # None for the naive method (no machine)
    retarget: Retarget
    speed: float
    notes: tuple
    method: str
    periodic: tuple | None
    naive: Output | None = None

    def finish(self, report: bool = True) -> Output:
        if self.naive is not None:
            return self.naive
        assert self.path is not None  # a physical plan has its machine path
        return finish(self.prep, self.path, self.retarget, self.speed, list(self.notes), self.method,
                      periodic=self.periodic, report=report)


def scale(prep: Prepared, character=None, *, report: bool = True, **options) -> Output:
    """§5.1, §5.2, §6: the reference run on another character, at another speed, for any number of strides.

    character: preset name, YAML/BVH path or Character (None: the reference's own body);
    speed: factor s on the dynamically scaled speed; target_speed: absolute speed [m/s] (overrides speed);
    strides / duration [s]: output length (neither: ``default_strides``, 4 or a turning take's whole turn and a
        stride on); fps: output frame rate (default: the input's);
    method: "physical" (froude) or "naive" (engines: angles copied, root × L, timing unchanged).
    speed_model: "law" (default; "auto" is the same): the machine's cycle re-solved at the new speed with
        the step and stance times of the human speed law (``machine.speed``, ``machine.speed_law``), faster
        and slower alike; "stretch": the paper's §5.2 horizontal stretch, timing kept (steps s times longer).
    unlimited: allow a run faster than the human range for the character's size (the law's step longer
        than 1.4 × stature, a step frequency or stance time no human sprinter of that size reaches);
        False (default) refuses it (BeyondHumanRange, saying the human limit in m/s) before any work.
    report: compute the physics report (False: result.report is None; for benchmarks of the synthesis).
    The other options are ``plan_scale``'s (this is ``plan_scale(...).finish(report)``).
    """
    return plan_scale(prep, character, **options).finish(report=report)


#: Output strides when neither strides nor a duration is asked (``default_strides``).
DEFAULT_STRIDES = 4


def default_strides(prep: Prepared) -> int:
    """The output's strides when none are asked: DEFAULT_STRIDES, and for a turning take at least its whole turn
    and a stride on (an output that stopped mid-turn would be asked for part of the turn and, measured over its
    last stride, still be turning: 9 of 12 walk-turns' children missed the heading bar at 4 strides)."""
    if prep.turn is None:
        return DEFAULT_STRIDES
    return max(DEFAULT_STRIDES, math.ceil(prep.path.n_steps / 2) + 1)


def plan_scale(
    prep: Prepared,
    character=None,
    *,
    speed: float = 1.0,
    target_speed: float | None = None,
    strides: int | None = None,
    duration: float | None = None,
    fps: float | None = None,
    method: str = "physical",
    speed_model: str = "auto",
    unlimited: bool = False,
    **character_numbers,
) -> ScalePlan:
    """The first half of ``scale`` (same arguments): character, machine, path. Cheap: no IK."""
    retarget = prep.retarget(character, **character_numbers)
    fps = prep.motion.fps if fps is None else float(fps)
    if not (np.isfinite(fps) and fps > 0):
        raise FroudeError(f"fps must be > 0, got {fps}")
    notes = list(prep.notes)
    if strides is None and duration is None:
        strides = default_strides(prep)
    m_scaled = prep.machine.scaled(retarget.L, retarget.M)
    base_m_s = m_scaled.mean_speed_m_s  # the character's speed at x1
    speed = scale_factor(speed, target_speed, base_m_s)
    notes += speed_range_notes(speed)
    n_steps = output_steps(strides, duration, m_scaled.step_time * m_scaled.time_unit)
    if method == "naive":
        if prep.turn is not None:
            # the cycle is of the take straightened along its turn: repeating it would walk straight, which is
            # not what engines do with a turning take (they play it, and it turns)
            taken = unstraighten(prep.motion, prep.turn)
            notes.append(f"the naive baseline of a turning take plays the take as it was taken "
                         f"({taken.duration / speed:.2f} s, its whole turn), not {n_steps / 2:g} strides")
            res = naive_take(taken, prep.body, retarget, speed, fps, notes, prep.modelled, prep.output_meta)
        else:
            res = naive_cycle(prep.cycle, retarget, speed, n_steps, fps, prep.origin, prep.output_meta, notes,
                              prep.modelled, bool(prep.motion.meta.get("in_place")))
        assert res.report is not None  # a naive output always has its report
        res.report.extras.update(machine=prep.kind.name, flights=prep.kind.has_flight)  # which bars apply
        return ScalePlan(prep, None, retarget, speed, tuple(notes), "naive", None, naive=res)
    if method != "physical":
        raise FroudeError(f"unknown method '{method}' (physical or naive)")
    if speed_model not in ("auto", "law", "stretch"):
        raise FroudeError(f"unknown speed model '{speed_model}' (law or stretch)")
    path, method, periodic = prep.kind.scale_path(prep, retarget, speed, n_steps=n_steps, fps=fps,
                                                  speed_model=speed_model, unlimited=unlimited,
                                                  base_m_s=base_m_s)
    return ScalePlan(prep, path, retarget, speed, tuple(notes), method, periodic)


def accelerate(
    prep: Prepared,
    character=None,
    *,
    to_speed: float | None = None,
    to_factor: float | None = None,
    steps: int | None = 8,
    within: float | None = None,
    lead_steps: int = 2,
    hold_steps: int = 4,
    fps: float | None = None,
    energy: str = "auto",
    policy: str = "ease",
    report: bool = True,
    unlimited: bool = False,
    speed_model: str = "law",
    **character_numbers,
) -> Output:
    """§5.3 + §6: speed up or slow down to ``to_speed`` [m/s] or ``to_factor`` × the start speed (apex speeds).

    steps: the change takes this many steps (a step = one stance and the flight after it), or
    within: ... this many seconds; lead_steps / hold_steps: steady steps before / after the change.
    The plan is dimensionless, so it is the same for every dynamically similar character.
    unlimited: allow a goal past the human range for the character's size (see ``plan_scale``).
    speed_model (runs): "law" (default): each change step runs the human speed law's cycle at its speed
        (``machine.planner.law``; the goal's is the one ``scale`` runs), so step frequency and length move as
        a runner's do; "planner": the paper's §5.3 planner (fitted K, a, c, T_c kept; θ0, δb per step; energy).
    policy: the profile of the change's speeds ("ease" or "even"), for both models.
    Walks keep their own planner (``synthesis.walking.plan_walk_speed_change``): the law is the runners'.
    The motion's kind plans the change (``kinds.MotionKind.speed_change``).
    """
    retarget = prep.retarget(character, **character_numbers)
    path, plan, notes, extras = prep.kind.speed_change(
        prep, retarget, to_speed=to_speed, to_factor=to_factor, steps=steps, within=within, lead_steps=lead_steps,
        hold_steps=hold_steps, fps=fps, energy=energy, policy=policy, unlimited=unlimited, speed_model=speed_model)
    return finish(prep, path, retarget, 1.0, notes, "physical", plan=plan, report=report, extras=extras)


#: A steady (periodic) output longer than this many strides is corrected by solving the IK of one stride
#: sampled PERIODIC_OVERSAMPLE times finer and tiling it (see finish).
PERIODIC_MIN_STRIDES = 6
PERIODIC_OVERSAMPLE = 4


def targets_of(prep: Prepared, path: MachinePath, retarget: Retarget):
    """(targets, path) where an output is solved (IK) and previewed: the cycle on the machine (build_targets),
    along a turning take's path (bend), on the floor y = 0 as the clip stands on its own (raised)."""
    targets = build_targets(prep.cycle, path, retarget, prep.body, prep.output_meta)
    path = _replace(path, com=targets.com)  # the machine's COM as the character carries it (posture_com_offset)
    bent = bend(targets, path, prep.turn, retarget.L, prep.origin, retarget.body, prep.cycle.order)
    return raised(*bent, retarget.L * prep.cycle.floor_clearance)


def stride_targets(prep: Prepared, retarget: Retarget, periodic: tuple) -> tuple[Targets, float, float]:
    """(targets of one stride of a steady output sampled PERIODIC_OVERSAMPLE times finer, its period [s], that
    rate [Hz]): what ``finish`` solves and tiles; periodic: ScalePlan.periodic (machine, stretch, fps)."""
    machine, stretch, fps = periodic
    m = machine.scaled(retarget.L, retarget.M)
    dense_fps = PERIODIC_OVERSAMPLE * fps
    one_path = machine_path(prep.cycle, m, retarget.L, prep.origin, stretch=stretch, n_steps=2, fps=dense_fps)
    return targets_of(prep, one_path, retarget)[0], 2.0 * m.step_time * m.time_unit, dense_fps


def finish(prep: Prepared, path: MachinePath, retarget: Retarget, speed: float, notes, method: str, plan=None,
           periodic=None, report: bool = True, extras: dict | None = None) -> Output:
    """Targets → IK → report: the common tail of scale and accelerate.

    periodic: (machine, stretch, fps) when the path is the steady cycle repeated: long outputs then solve
    the IK of one stride only, sampled PERIODIC_OVERSAMPLE times finer, and tile it (the result is
    periodic too; ``ik.correct.tile_stride``).
    """
    targets, path = targets_of(prep, path, retarget)
    rest_bar_m = BARS["rest_height_L"] * retarget.body.leg_length  # the report's bar on where a foot rests
    n_strides = len(path.foot_of_step) / 2
    if periodic is not None and n_strides > PERIODIC_MIN_STRIDES and prep.turn is None:
        one_targets, period, dense_fps = stride_targets(prep, retarget, periodic)
        one = correct(one_targets, retarget.body, rest_bar_m=rest_bar_m).motion
        stride = path.contacts[2] - path.contacts[0] if len(path.contacts) > 2 else np.zeros(3)
        motion = tile_stride(one, period, dense_fps, targets, path.times, stride, retarget.body)
    else:
        ik = correct(targets, retarget.body, repair_rounds=prep.kind.repair_rounds,
                     joint_jump_bar_deg=BARS["joint_jump_ratio"] * prep.cycle.max_joint_jump_deg,
                     skate_bar_m=1e-3 * BARS["foot_skate_floor_mm"], rest_bar_m=rest_bar_m)
        if not ik.ok:
            bad = np.flatnonzero(ik.failed)
            notes = list(notes) + [f"IK best effort: {bad.size} frame(s) above tolerance (first frame {bad[0]})"]
        motion = ik.motion
    res = Output(motion, None, path, targets, retarget, method, speed, tuple(notes), plan, dict(extras or {}))
    return add_report(prep, res) if report else res


def add_report(prep: Prepared, res: Output) -> Output:
    """The result with its physics report (docs/architecture.md) computed: tracking against the machine, the loaded
    foot targets and the time-warped reference pose. (Separate so that a viewer can show the motion first.)
    """
    if res.path is None or res.targets is None:
        raise FroudeError("add_report takes a physical result (a machine path and IK targets)")
    report = physics_report(
        res.motion, res.retarget.body, ground_height=0.0, machine_com=res.path.com,
        marker_targets=stance_only(res.targets), reference_pose=res.targets.initial,
        reference_max_joint_jump_deg=prep.cycle.max_joint_jump_deg,
        reference_path=prep.path, reference_leg_length=prep.body.leg_length,
        source_rest_heights=res.retarget.L * source_rest_heights(prep.markers, prep.gait, prep.body.leg_length),
    )
    report.extras.update({"character": res.retarget.character.name, "L": res.retarget.L, "M": res.retarget.M,
                          "speed_factor": res.speed_factor, "method": res.method, "notes": list(res.notes),
                          "machine_apex_speed_m_s": res.path.apex_speed.tolist(), "modelled": prep.modelled,
                          "input_in_place": bool(prep.motion.meta.get("in_place")),
                          "machine": prep.kind.name, "flights": prep.kind.has_flight, **res.extras})
    report.extras.update(prep.kind.report_extras(prep, res, report))
    return _replace(res, report=report)
