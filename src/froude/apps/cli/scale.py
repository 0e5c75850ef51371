"""``froude scale``: the reference run on another character and/or at another speed (§5.1, §5.2, §6)."""
from __future__ import annotations

import time
from pathlib import Path

from ...body.presets import list_presets
from .common import (
    MOTION_OUTPUTS,
    add_character_options,
    add_data_option,
    add_force,
    add_fps,
    add_keep,
    add_load_options,
    add_mass,
    add_output_options,
    add_quiet,
    add_range_option,
    add_root_option,
    add_unlimited,
    bound_work,
    character_input,
    character_kwargs,
    check_character,
    check_inputs,
    data_output,
    guard_outputs,
    load_clip,
    number,
    output_kwargs,
    prepare_clip,
    print_rows,
    say,
    speed,
)

#: Output length options: strides [1, MAX_STRIDES], duration [s] up to MAX_DURATION_S.
MAX_STRIDES = 10_000
MAX_DURATION_S = 3600.0


#: The one-line summary ``froude --help`` lists.
HELP = "retarget a run to a new character and/or speed, physically (paper 5.1, 5.2, 6)"


def register(sub) -> None:
    p = sub.add_parser(
        "scale", help=HELP,
        description="Fit the simple machine to the clip, scale it to the character by dynamic similarity "
        "(times x sqrt(L), speeds x sqrt(L)), change its speed (the machine's cycle re-solved with the step "
        "length and step frequency runners use at that speed, within the human range for the character's size "
        "unless --unlimited), synthesise any number of strides and "
        "correct the whole body with IK. Writes OUT.bvh or OUT.glb/.gltf (same joint names and "
        "channel orders as the input, the target's bone lengths) and OUT.report.json (the physics report), "
        "both or neither. Every option is checked before the work starts; an output that would replace an "
        "input is refused.",
        epilog=f"Presets: {', '.join(list_presets())}. Example: froude scale run.bvh --character child --speed 0.7x "
        "-o child.bvh",
    )
    p.add_argument("clip", help="reference running clip (BVH, or glTF/GLB with a skinned animation)")
    p.add_argument("-o", "--output", required=True, metavar="OUT.bvh|.glb|.gltf",
                   help="output motion: BVH, or glTF/GLB (skin, joints, animation, a mannequin mesh); "
                   "OUT.report.json is written beside it; its folder must exist")
    add_character_options(p)
    g = p.add_argument_group("speed and length")
    g.add_argument("--speed", type=speed("--speed"), default=None, metavar="Fx|Vm/s",
                   help="a factor on the character's dynamically scaled speed (0.7x, or a bare 0.7) or an "
                   "absolute speed (3.2m/s); default 1x")
    g.add_argument("--strides", type=number(1, MAX_STRIDES, "strides", integer=True), default=None,
                   help=f"output strides (two steps each), 1-{MAX_STRIDES}; default 4, and for a turning take its "
                   "whole turn and a stride on")
    g.add_argument("--duration", type=number(0, MAX_DURATION_S, "s", lo_open=True), default=None, metavar="S",
                   help="output length in seconds (overrides --strides; at least two steps are made)")
    add_fps(g)
    p.add_argument("--method", choices=("physical", "naive"), default="physical",
                   help="physical (froude) or naive (what engines do: angles copied, root x L, timing kept)")
    add_mass(p)
    add_force(p)
    add_data_option(p)
    add_quiet(p)
    add_load_options(p)
    add_output_options(p)
    add_range_option(p)
    add_keep(p)
    add_unlimited(p)
    add_root_option(p)
    p.set_defaults(func=run)


def run(args) -> int:
    from ...flow.pipeline import report_path  # lazy: start-up (froude --help imports every verb module and no NumPy)
    from ...io.atomic import atomic_group, require_suffix  # lazy: start-up

    out = require_suffix(args.output, MOTION_OUTPUTS)
    data = data_output(args)
    check_inputs(args.clip)
    guard_outputs([out, report_path(out)] + ([data] if data else []), [args.clip, character_input(args)])
    check_character(args)
    goal = args.speed
    t0 = time.perf_counter()

    from ...errors import (  # lazy: start-up
        FitError,
        FroudeError,
        NotARunningMotion,
        NotAWalkingMotion,
        PastWalkRunTransition,
    )
    from ...flow import pipeline  # lazy: start-up (froude --help imports every verb module and no NumPy)

    try:
        prep = prepare_clip(args)
    except (FitError, NotARunningMotion, NotAWalkingMotion) as e:
        if args.method != "naive":
            raise
        return _naive_any_clip(args, out, data, goal, e, t0)
    if _bound(prep, args):
        say(f"synthesising ({args.method}) ...", args.quiet)

    try:
        res = pipeline.scale(prep, args.character, speed=goal.factor if goal and goal.factor else 1.0,
                             target_speed=goal.m_s if goal else None, strides=args.strides,
                             duration=args.duration, fps=args.fps, method=args.method, unlimited=args.unlimited,
                             **character_kwargs(args))
    except PastWalkRunTransition as e:  # its message says the fastest walk: no search of the reachable speeds
        raise PastWalkRunTransition(f"{Path(args.clip).name}: {e}") from None
    except FitError as e:
        if args.method != "physical":
            raise
        rng = _speed_range(prep, args)
        asked = goal.m_s if goal and goal.m_s else (goal.factor if goal and goal.factor else 1.0) * rng.base_m_s
        raise FroudeError(f"{Path(args.clip).name}: {asked:.2f} m/s (x{asked / rng.base_m_s:.2f}) is out of reach: "
                          f"{rng.sentence()} ({e})") from None
    for note in res.notes:
        say(f"note: {note}", args.quiet)
    assert res.report is not None  # the pipeline computes it by default
    fails = res.report.check_bars() if args.method == "physical" else []
    if fails and not args.keep:
        rng = _speed_range(prep, args)
        say(f"froude scale: output not written: it misses physics bars ({'; '.join(fails)}); {rng.sentence()}; "
            "--keep writes it anyway")
        return 1
    with atomic_group():
        bvh, rep, *data_written = pipeline.write_result(res, out, data, in_place=args.in_place,
                                                        **output_kwargs(args))
    print_rows(res.summary_rows())
    print(f"physics bars: {'all met' if not fails else 'NOT met (kept): ' + '; '.join(fails)}")
    also = "".join(f" and {d}" for d in data_written)
    say(f"wrote {bvh} ({res.motion.n_frames} frames) and {rep}{also} in {time.perf_counter() - t0:.2f} s", args.quiet)
    return 0


def _naive_any_clip(args, out, data, goal, why, t0) -> int:
    """--method naive on a clip the fit refuses (a walk, a jump, too short): the clip itself, naively."""
    from ...flow import pipeline  # lazy: start-up (froude --help imports every verb module and no NumPy)

    motion = load_clip(args.clip, args.length_scale, args.keep_all_frames, True, getattr(args, "joint_map", None),
                       getattr(args, "up", None))
    say(f"note: {why}; the naive baseline plays the clip as it is", args.quiet)
    res = pipeline.naive_clip(motion, args.character, speed=goal.factor if goal and goal.factor else 1.0,
                              target_speed=goal.m_s if goal else None, fps=args.fps, performer_mass=args.mass,
                              **character_kwargs(args))
    from ...io.atomic import atomic_group  # lazy: start-up (froude --help imports every verb module and no NumPy)

    with atomic_group():  # the whole result or none
        bvh, rep, *data_written = pipeline.write_result(res, out, data, in_place=args.in_place, **output_kwargs(args))
    print_rows(res.summary_rows())
    also = "".join(f" and {d}" for d in data_written)
    say(f"wrote {bvh} ({res.motion.n_frames} frames) and {rep}{also} in {time.perf_counter() - t0:.2f} s", args.quiet)
    return 0


def _speed_range(prep, args):
    """The reachable speeds of the asked character, for a refusal (imported only then: a run that succeeds
    never needs it)."""
    from ...flow.speed_range import reachable_speed_range  # lazy: start-up

    return reachable_speed_range(prep, args.character, unlimited=args.unlimited, **character_kwargs(args))


def _bound(prep, args) -> bool:
    """Estimate the output's frames from the scaled machine's step time; refuse a runaway; note a
    --duration shorter than the two steps froude makes at least. True for long work."""
    from ...flow.pipeline import default_strides  # lazy: start-up (froude --help imports no NumPy)

    rt = prep.retarget(args.character, **character_kwargs(args))
    m = prep.machine.scaled(rt.L, rt.M)
    step_s = m.step_time * m.time_unit
    fps = args.fps or prep.motion.fps
    strides = args.strides if args.strides is not None else default_strides(prep)
    seconds = args.duration if args.duration is not None else 2 * strides * step_s
    if args.duration is not None and args.duration < 2 * step_s:
        say(f"note: --duration {args.duration:g} s is shorter than two steps; the output is two steps "
            f"(about {2 * step_s:.2f} s), the shortest froude makes", args.quiet)
    return bound_work(seconds * fps, prep.motion.skeleton.n_joints, args.force, "froude scale", args.quiet)
