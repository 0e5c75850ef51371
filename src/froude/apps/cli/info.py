"""``froude info CLIP.bvh``: what is in a clip — skeleton, units, cleaning, speed, steps, phases."""
from __future__ import annotations

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
    p.add_argument("clip", help="BVH file, or glTF/GLB with a skinned animation")
    p.add_argument("--json", action="store_true", help="print the summary as JSON instead of a table")
    add_mass(p, "body mass [kg] for the COM model")
    add_quiet(p)
    add_data_option(p)
    add_load_options(p)
    p.set_defaults(func=run)


def _n(v, spec: str = ".3f") -> str:
    return "n/a" if v is None else format(v, spec)


def _fmt_list(values, unit="s") -> str:
    return ", ".join(f"{v:.3f}" for v in values) + f" {unit}" if len(values) else "none"


def _flight_times(summary, n_contacts: int) -> str:
    """The flights' row: their times, said as a minority of the steps when fewer than half have one (a run into
    a tight turn, CMU 16_51: 2 of 7; what decides running is ``body.gait``'s, the motion row), none without."""
    if not len(summary.flight_times):
        return "no flight phase"
    if summary.has_flight:
        return _fmt_list(summary.flight_times)
    return (f"{_fmt_list(summary.flight_times)} (between {len(summary.flight_times)} of the "
            f"{max(n_contacts - 1, 1)} pairs of contacts)")


def _path_rows(p: dict | None) -> list[tuple[str, str]]:
    """The table rows of the path (``clip_info``'s "path", ``body.path.TakePath.to_dict``): heading change,
    speed along it, facing vs travel, turn, radius and lean per step."""
    if p is None:
        return []
    h = p["heading_change_deg"]
    side = "" if h is None else " (left)" if h > 0 else " (right)" if h < 0 else ""
    f = p["facing_vs_travel_deg"]
    facing = ("n/a" if f is None else f"{f:+.0f} deg (" + ("forwards" if abs(f) < 30 else "backwards" if abs(f) > 150
                                                           else "sideways") + ")")
    steps = p["steps"]
    return [
        ("heading change", f"{_n(h, '+.1f')} deg{side}: COM travel over the last {p['heading_window_s']:.2f} s "
                           "against the first"),
        ("speed along the path", f"{_n(p['path_speed_m_s'])} m/s over {_n(p['path_length_m'], '.2f')} m"),
        ("facing vs travel", facing),
        ("turn per step", " ".join(_n(s["heading_change_deg"], "+.0f") for s in steps) + " deg" if steps else "n/a"),
        ("radius per step", " ".join("straight" if s["radius_m"] is None else f"{s['radius_m']:.1f}"
                                     for s in steps) + " m" if steps else "n/a"),
        ("lean per step", " ".join(_n(s["lean_deg"], "+.0f") for s in steps) + " deg (COM over the stance foot, "
                                                                               "+ = left)" if steps else "n/a"),
    ]


def run(args) -> int:
    check_inputs(args.clip)
    data = data_output(args)
    if data is not None:
        guard_outputs([data], [args.clip])
    from ...body.model import BodyModel  # lazy: start-up (froude --help imports every verb module and no NumPy)
    from ...flow.clipinfo import clip_info  # lazy: start-up (froude --help imports every verb module and no NumPy)

    motion = load_clip(args.clip, args.length_scale, args.keep_all_frames, args.json or args.quiet, args.joint_map,
                       args.up)
    body = BodyModel.from_skeleton(motion.skeleton, mass=args.mass)
    d, summary = clip_info(motion, body)
    from ...io.jsonable import dumps  # lazy: start-up (froude --help imports every verb module and no NumPy)
    if data is not None:
        from ...io.framedata import write_frame_data  # lazy: start-up
        from ...report.frames import frame_table  # lazy: start-up

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
        ("flight times", _flight_times(summary, len(d["contacts"]))),
        ("step frequency", "n/a" if d["step_frequency_hz"] is None else f"{d['step_frequency_hz']:.3f} Hz"),
        ("step length", "n/a" if d["step_length_m"] is None else f"{d['step_length_m']:.3f} m"),
        ("COM vertical excursion",
         f"{_n(d['com_vertical_excursion_m'] and 100 * d['com_vertical_excursion_m'], '.1f')} cm"),
        ("double support",
         f"{_n(d['double_support_fraction'] and 100 * d['double_support_fraction'], '.0f')}% of frames"),
    ]
    rows += _path_rows(d["path"])
    if d["take"] is not None:  # a loop or an in-place take: what fit/scale model
        t = d["take"]
        rows.append(("as analysed", f"{'; '.join(t['notes'])}: {_n(t['mean_speed_m_s'])} m/s, "
                                    f"{_n(t['step_frequency_hz'])} steps/s"))
    width = max(len(k) for k, _ in rows)
    for k, v in rows:
        print(f"{k:<{width}}  {v}")
    return 0
