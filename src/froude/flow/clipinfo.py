"""What is in a clip, as ``froude info`` prints it and ``froude.info`` returns it: skeleton, units, cleaning,
speed, Froude number, contacts, steps, phases, and how fit and scale take a loop or an in-place take."""
from __future__ import annotations

import math

from ..body.gait import GaitSummary, detect_gait, summarize
from ..body.take import analysed_take, running_take
from ..io.jsonable import jsonable


def clip_info(motion, body) -> tuple[dict, GaitSummary]:
    """(the JSON-able summary of a clip in SI units, its gait summary). motion: a Motion; body: its BodyModel.

    A take that turns is summarised along its path, straightened as fit and scale model it
    (``body.path.straighten``): its kind, speed and steps are those of the walk or run the machines see (a
    tight walking turn covers little ground in a straight line and would read as in place); its path as taken
    is the "path" entry."""
    if motion.n_frames < 3:  # too short for a path
        com, markers = body.com_and_markers(motion)
        along, gait, path = motion, detect_gait(motion, body, markers, com), None
    else:  # the feet reconciled with the COM force (body.gait), along the path
        take = analysed_take(motion, body, unroll=False)
        along, com, gait, path = take.motion, take.com, take.gait, take.clip_path.to_dict()
    summary = summarize(along, body, com, gait)
    d = jsonable(info_dict(along, body, summary, gait))
    d["take"] = jsonable(_take(motion, body))
    d["path"] = path  # the path as taken: heading change, speed along it, facing vs travel, per-step figures
    return d, summary


def _take(motion, body) -> dict | None:
    """How fit and scale take a loop or an in-place take (``body.take.running_take``): its notes and the
    speed and cadence measured on the take so analysed (a loop's own stride, an in-place take's speed from
    its feet); None for a take analysed as it is. ``scale`` with no change reproduces these figures."""
    if motion.n_frames < 3:
        return None
    taken, notes = running_take(motion, body)
    if not notes:
        return None
    s = summarize(taken, body)
    return {"notes": notes, "mean_speed_m_s": round(s.mean_speed, 4), "froude_U": round(s.froude, 4),
            "step_frequency_hz": round(s.step_frequency, 4) if math.isfinite(s.step_frequency) else None}


def info_dict(motion, body, summary, gait) -> dict:
    """The JSON-able summary of a clip (SI units)."""
    sk = motion.skeleton
    return {
        "schema": "froude.info/1",
        "file": motion.meta.get("source"),
        "skeleton": {
            "joints": sk.n_joints,
            "dof": sk.n_channels,
            "end_sites": len(sk.end_sites),
            "leg_length_m": round(body.leg_length, 4),
            "height_m": round(body.stature, 4),
            "units": motion.meta.get("units"),
            "length_scale_m_per_unit": motion.meta.get("length_scale"),
        },
        "cleaning": list(motion.meta.get("cleaning", ())),
        "frames": motion.n_frames,
        "frame_rate_hz": round(motion.fps, 3),
        "duration_s": round(motion.duration, 4),
        "kind": summary.kind,
        "verdict": summary.reason,
        "mean_speed_m_s": round(summary.mean_speed, 4),
        "froude_U": round(summary.froude, 4),
        "contacts": [
            {"foot": s.side, "start_s": round(s.start * motion.frame_time, 4),
             "stop_s": round(s.stop * motion.frame_time, 4), "partial": s.partial,
             "ground_m": round(s.ground, 4)}
            for s in gait.stances
        ],
        "stance_times_s": [round(float(t), 4) for t in summary.stance_times],
        "flight_times_s": [round(float(t), 4) for t in summary.flight_times],
        "has_flight_phase": summary.has_flight,
        "double_support_fraction": round(summary.double_support_fraction, 4),
        "step_frequency_hz": _finite(summary.step_frequency),
        "step_length_m": _finite(summary.step_length),
        "com_vertical_excursion_m": round(summary.com_vertical_excursion, 4),
        "ground_height_m": round(gait.ground, 4),
    }


def _finite(v, digits: int = 4):
    """A rounded float, or None (JSON null) for NaN and infinities: JSON has no such numbers."""
    v = float(v)
    return round(v, digits) if math.isfinite(v) else None
