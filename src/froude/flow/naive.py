"""The naive baseline (what engines do): joint angles copied, root translation × L, timing unchanged."""
from __future__ import annotations

import math

import numpy as np

from ..body.characters import Retarget, apply_character, resolve_character
from ..body.gait import detect_gait, summarize
from ..body.model import BodyModel
from ..core.constants import UP_AXIS
from ..core.motion import Motion, max_joint_jump_deg
from ..errors import FroudeError
from ..machine.units import similarity
from ..report.metrics import physics_report
from ..synthesis.cycle import ReferenceCycle, sample_cycle
from .result import Output


def naive_cycle(cyc: ReferenceCycle, retarget: Retarget, speed: float, n_steps: int, fps: float,
                origin: np.ndarray, meta: dict, notes, modelled: str, input_in_place: bool) -> Output:
    """What engines do with a run's stride cycle: joint angles copied, root translation × L, timing
    unchanged (× 1/s for speed). origin: (3,) [m] the reference COM's start (put on the floor); meta: the
    output's provenance; modelled / input_in_place: the clip's words for the report."""
    L = retarget.L
    T_stride = cyc.stride_time / speed
    duration = n_steps / 2 * T_stride
    t = np.arange(int(math.floor(duration * fps + 1e-9)) + 1) / fps
    psi = t / T_stride
    rot, data = sample_cycle(cyc, np.mod(psi, 1.0))
    fwd, up, lat = cyc.frame
    origin = np.array(origin, dtype=float)
    origin[UP_AXIS] = 0.0
    # the reference COM path (uniform speed + oscillation) and root offset, all lengths × L
    com = (origin + np.outer(L * (cyc.speed * psi * cyc.stride_time + data["com_forward"]), fwd)
           + np.outer(L * data["com_height"], up) + np.outer(L * data["com_lateral"], lat))
    root = com + (L * data["root_from_com"]) @ cyc.frame
    motion = Motion(retarget.skeleton, root, rot, 1.0 / fps, None, dict(meta))
    return _naive_result(motion, retarget, speed, list(notes), modelled, input_in_place, cyc.max_joint_jump_deg)


def _naive_result(motion: Motion, retarget: Retarget, speed: float, notes: list, modelled: str,
                  input_in_place: bool, reference_jump_deg: float) -> Output:
    """The naive output with its physics report."""
    report = physics_report(motion, retarget.body, reference_max_joint_jump_deg=reference_jump_deg)
    report.extras.update({"character": retarget.character.name, "L": retarget.L, "M": retarget.M,
                          "speed_factor": speed, "method": "naive", "notes": list(notes), "modelled": modelled,
                          "input_in_place": input_in_place})
    return Output(motion, report, None, None, retarget, "naive", speed, tuple(notes))


def naive_clip(motion: Motion, character=None, *, speed: float = 1.0, target_speed: float | None = None,
               fps: float | None = None, performer_mass: float = 70.0, **character_numbers) -> Output:
    """The naive baseline for any clip that loads, running or not (no fit, no cycle): what engines do with
    a clip as it is: joint angles copied, the root's motion × L about the first frame's point on the floor,
    played s times faster (and as long as the clip). ``scale(..., method="naive")`` repeats a stride cycle
    instead when the clip is a straight take the fit models (a turning one it plays as taken, ``naive_take``);
    this is its fallback for jumps and clips the fit refuses.
    target_speed [m/s] is turned into a factor of the clip's own scaled mean speed; performer_mass [kg]:
    the reference performer's (the character's own mass is a character number, ``mass=``).
    """
    body = BodyModel.from_skeleton(motion.skeleton, mass=performer_mass)
    retarget = apply_character(resolve_character(character, **character_numbers), body)
    L = retarget.L
    summary = summarize(motion, body)
    if target_speed is not None:
        base = summary.mean_speed * similarity(L).speed
        if not (base > 0 and np.isfinite(target_speed) and target_speed > 0):
            raise FroudeError(f"cannot run this clip at {target_speed:g} m/s: it does not travel (give a factor)")
        speed = target_speed / base
    if not (np.isfinite(speed) and speed > 0):
        raise FroudeError(f"speed factor must be > 0, got {speed}")
    notes = [f"naive baseline of the clip as it is ({summary.kind}): the fit was not needed"]
    return naive_take(motion, body, retarget, speed, motion.fps if fps is None else float(fps), notes,
                      f"the whole clip ({summary.kind})")


def naive_take(motion: Motion, body: BodyModel, retarget: Retarget, speed: float, fps: float, notes,
               modelled: str, meta: dict | None = None) -> Output:
    """What engines do with a take as it is: joint angles copied, the root's motion × L about the first
    frame's COM on the floor, played ``speed`` times faster at fps [1/s], as long as the take (its path,
    a turn included, scaled by L). body: the take's; meta: the output's provenance (default: the take's)."""
    L = retarget.L
    n = int(math.floor(motion.duration / speed * fps + 1e-9)) + 1
    played = motion.sample(np.arange(n) / fps * speed)
    origin = body.com(motion)[0].copy()
    origin[UP_AXIS] = detect_gait(motion, body).ground
    root = origin + L * (played.root_positions - origin)
    if meta is None:
        meta = {"source": str(motion.meta.get("source", "motion")),
                "length_scale": float(motion.meta.get("length_scale", 1.0))}
    out = Motion(retarget.skeleton, root, played.rotations, 1.0 / fps, None, dict(meta))
    return _naive_result(out, retarget, speed, list(notes), modelled, False, max_joint_jump_deg(motion))
