"""``froude info CLIP.bvh``: what is in a clip — skeleton, units, cleaning, speed, steps, phases."""
from __future__ import annotations

import math
import sys

from .common import (
    add_data_option,
    add_load_options,
    add_mass,
    add_quiet,
    check_inputs,
    data_output,
    guard_outputs,
    load_clip,
)

#: The one-line summary ``froude --help`` lists.
HELP = "summarise a BVH clip: skeleton, units, speed, Froude number, steps, phases"


def register(sub) -> None:
    p = sub.add_parser(
        "info", help=HELP,
        description="Summarise a BVH clip: skeleton (joints, DOF, leg length, height, units chosen), duration, "
        "frame rate, mean speed, Froude number U = u/sqrt(g L), foot contacts with stance and flight "
        "times, step frequency and length, COM vertical excursion, and what cleaning did.",
    )
    p.add_argument("clip", help="BVH file")
    p.add_argument("--json", action="store_true", help="print the summary as JSON instead of a table")
    add_mass(p, "body mass [kg] for the COM model")
    add_quiet(p)
    add_data_option(p)
    add_load_options(p)
    p.set_defaults(func=run)


def _take(motion, body) -> dict | None:
    """How fit and scale take a loop or an in-place take (``body.take.running_take``): its notes and the
    speed and cadence measured on the take so analysed (a loop's own stride, an in-place take's speed from
    its feet); None for a take analysed as it is. ``scale`` with no change reproduces these figures."""
    from ...body.gait import summarize
    from ...body.take import running_take

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


def _n(v, spec: str = ".3f") -> str:
    return "n/a" if v is None else format(v, spec)


def _fmt_list(values, unit="s") -> str:
    return ", ".join(f"{v:.3f}" for v in values) + f" {unit}" if len(values) else "none"


def run(args) -> int:
    check_inputs(args.clip)
    data = data_output(args)
    if data is not None:
        guard_outputs([data], [args.clip])
    from ...body.gait import detect_gait, summarize
    from ...body.model import BodyModel

    motion = load_clip(args.clip, args.length_scale, args.keep_all_frames, args.json or args.quiet, args.joint_map,
                       args.up)
    body = BodyModel.from_skeleton(motion.skeleton, mass=args.mass)
    com, markers = body.com_and_markers(motion)
    gait = detect_gait(motion, body, markers, com)  # the feet reconciled with the COM force (body.gait)
    summary = summarize(motion, body, com, gait)
    from ...io.jsonable import dumps, jsonable

    d = jsonable(info_dict(motion, body, summary, gait))
    d["take"] = jsonable(_take(motion, body))
    if data is not None:
        from ...io.framedata import frame_table, write_frame_data

        write_frame_data(frame_table(motion, body), data)
        if not args.json:
            print(f"wrote {data}", file=sys.stderr)
    if args.json:
        print(dumps(d, indent=2))
        return 0
    sk = d["skeleton"]
    rows = [
        ("file", d["file"]),
        ("skeleton", f"{sk['joints']} joints, {sk['dof']} channels, {sk['end_sites']} end sites"),
        ("leg length / height", f"{_n(sk['leg_length_m'])} m / {_n(sk['height_m'])} m"),
        ("units", sk["units"]),
        ("cleaning", "; ".join(d["cleaning"]) or "nothing dropped"),
        ("frames", f"{d['frames']} at {_n(d['frame_rate_hz'], '.1f')} Hz = {_n(d['duration_s'])} s"),
        ("motion", f"{summary.kind}: {summary.reason}"),
        ("mean speed", f"{_n(d['mean_speed_m_s'])} m/s (Froude number U = {_n(d['froude_U'])})"),
        ("foot contacts", " ".join(
            f"{c['foot'][0].upper()}{'*' if c['partial'] else ''}" for c in d["contacts"]
        ) + f"  ({len(d['contacts'])}; * = cut by the clip's edge)"),
        ("stance times", _fmt_list(summary.stance_times)),
        ("flight times", _fmt_list(summary.flight_times) if summary.has_flight else "no flight phase"),
        ("step frequency", "n/a" if d["step_frequency_hz"] is None else f"{d['step_frequency_hz']:.3f} Hz"),
        ("step length", "n/a" if d["step_length_m"] is None else f"{d['step_length_m']:.3f} m"),
        ("COM vertical excursion",
         f"{_n(d['com_vertical_excursion_m'] and 100 * d['com_vertical_excursion_m'], '.1f')} cm"),
        ("double support",
         f"{_n(d['double_support_fraction'] and 100 * d['double_support_fraction'], '.0f')}% of frames"),
    ]
    if d["take"] is not None:  # a loop or an in-place take: what fit/scale model
        t = d["take"]
        rows.append(("as analysed", f"{'; '.join(t['notes'])}: {_n(t['mean_speed_m_s'])} m/s, "
                                    f"{_n(t['step_frequency_hz'])} steps/s"))
    width = max(len(k) for k, _ in rows)
    for k, v in rows:
        print(f"{k:<{width}}  {v}")
    return 0
