"""``froude accelerate``: speed up or slow down over a number of steps (paper §5.3, §6)."""
from __future__ import annotations

import time

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
    number,
    output_kwargs,
    prepare_clip,
    print_rows,
    say,
    speed,
)

#: Steps of a speed change, and of the steady parts around it, froude plans at most.
MAX_STEPS = 500
MAX_STEADY_STEPS = 100
MAX_WITHIN_S = 300.0
PLOT_SUFFIXES = (".png",)


#: The one-line summary ``froude --help`` lists.
HELP = "speed up or slow down a run over some steps (step-by-step plan on the simple machine, paper 5.3)"


def register(sub) -> None:
    p = sub.add_parser(
        "accelerate", help=HELP,
        description="Plan the touchdown angle of every step, and how hard the leg pushes where the angle alone "
        "cannot change the speed, so that the simple machine reaches a target speed (a step is one stance and "
        "the flight after it; each step solved on the simulator), time-warp the reference cycle onto "
        "the planned steps and correct the whole body with IK. Works for any character: the plan is "
        "dimensionless. Writes OUT.bvh (or .glb/.gltf) and OUT.report.json (with the per-step speed profile), "
        "and the plot "
        "if asked, all or none.",
        epilog="Examples: froude accelerate run.bvh --to-speed 0.5x --steps 8 -o slow.bvh ; "
        "froude accelerate run.bvh --to-speed 4.5m/s --within 2.0 --character troll -o troll_fast.bvh",
    )
    p.add_argument("clip", help="reference running clip (BVH, or glTF/GLB with a skinned animation)")
    p.add_argument("-o", "--output", required=True, metavar="OUT.bvh|.glb|.gltf",
                   help="output motion: BVH, or glTF/GLB (skin, joints, animation, a mannequin mesh); "
                   "OUT.report.json is written beside it; its folder must exist")
    p.add_argument("--to-speed", required=True, type=speed("--to-speed"), metavar="Fx|Vm/s",
                   help="goal: a factor of the start speed (0.5x, or a bare 0.5) or a speed (3.0m/s)")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--steps", type=number(1, MAX_STEPS, "steps", integer=True), default=None,
                   help=f"change over this many steps, 1-{MAX_STEPS} (default 8)")
    g.add_argument("--within", type=number(0, MAX_WITHIN_S, "s", lo_open=True), default=None, metavar="S",
                   help=f"change within this many seconds (at most {MAX_WITHIN_S:g})")
    p.add_argument("--lead-steps", type=number(0, MAX_STEADY_STEPS, "steps", integer=True), default=2,
                   help=f"steady steps before the change, 0-{MAX_STEADY_STEPS} (default 2)")
    p.add_argument("--hold-steps", type=number(0, MAX_STEADY_STEPS, "steps", integer=True), default=4,
                   help=f"steady steps after the change, 0-{MAX_STEADY_STEPS} (default 4)")
    p.add_argument("--policy", choices=("ease", "even"), default="ease",
                   help="speed profile: ease (smooth start and end, default) or even (equal change per step)")
    p.add_argument("--plot", default=None, metavar="PNG",
                   help="also plot the speed profile (PNG) and, as PNG-table.png beside it, the transition "
                   "table of the start cycle: the next apex speed the touchdown angle alone reaches")
    add_fps(p)
    add_mass(p)
    add_force(p)
    add_data_option(p)
    add_quiet(p)
    add_character_options(p)
    add_load_options(p)
    add_output_options(p)
    add_range_option(p)
    add_keep(p)
    add_unlimited(p)
    add_root_option(p)
    p.set_defaults(func=run)


def run(args) -> int:
    from ...errors import PlanError  # lazy: start-up (froude --help imports every verb module and no NumPy)
    from ...flow.pipeline import report_path  # lazy: start-up (froude --help imports every verb module and no NumPy)
    from ...io.atomic import atomic_group, require_suffix  # lazy: start-up

    out = require_suffix(args.output, MOTION_OUTPUTS)
    data = data_output(args)
    plot = require_suffix(args.plot, PLOT_SUFFIXES, "plot") if args.plot else None
    check_inputs(args.clip)
    guard_outputs([out, report_path(out), *_plot_files(plot)] + ([data] if data else []),
                  [args.clip, character_input(args)])
    check_character(args)
    goal = args.to_speed
    steps = args.steps if (args.steps is not None or args.within is not None) else 8

    from ...flow import pipeline  # lazy: start-up (froude --help imports every verb module and no NumPy)

    t0 = time.perf_counter()
    prep = prepare_clip(args)
    rt = prep.retarget(args.character, **character_kwargs(args))
    m = prep.machine.scaled(rt.L, rt.M)
    step_s = m.step_time * m.time_unit
    n_steps = (steps if args.within is None else args.within / step_s) + args.lead_steps + args.hold_steps
    if bound_work(n_steps * step_s * (args.fps or prep.motion.fps), prep.motion.skeleton.n_joints, args.force,
                  "froude accelerate", args.quiet):
        say(f"planning {n_steps:.0f} steps and synthesising ...", args.quiet)
    try:
        res = pipeline.accelerate(
            prep, args.character, to_speed=goal.m_s, to_factor=goal.factor, steps=None if args.within else steps,
            within=args.within, lead_steps=args.lead_steps, hold_steps=args.hold_steps, fps=args.fps,
            policy=args.policy, unlimited=args.unlimited, **character_kwargs(args),
        )
    except PlanError as e:
        raise PlanError(f"{e}; {_steady_range(prep, args)}") from None
    for note in res.notes:
        say(f"note: {note}", args.quiet)
    assert res.report is not None  # the pipeline computes it by default
    fails = res.report.check_bars()
    if fails and not args.keep:
        say(f"froude accelerate: output not written: it misses physics bars ({'; '.join(fails)}); "
            f"{_steady_range(prep, args)} (the change of speed on the way can miss a bar even inside them); "
            "--keep writes it anyway")
        return 1
    with atomic_group():
        bvh, rep, *data_written = pipeline.write_result(res, out, data, in_place=args.in_place,
                                                        **output_kwargs(args))
        written = []
        if plot:
            from ...viz.plan_plot import plot_plan  # lazy: start-up

            written = plot_plan(res, plot)
    plan = res.report.extras["plan"]
    head = [r for r in res.summary_rows() if r[0] in ("character", "method", "modelled")]
    tail = [r for r in res.summary_rows() if r[0] not in ("character", "method", "modelled", "speed",
                                                         "Froude number U", "step frequency")]
    rows = head + [
        ("start speed", f"{plan['start_speed_m_s']:.3f} m/s"),
        ("goal", f"{plan['target_speed_m_s']:.3f} m/s"),
        ("apex speed per step", " ".join(f"{v:.2f}" for v in plan["apex_speed_m_s"]) + " m/s"),
        ("touchdown angle per step", " ".join(f"{v:.1f}" for v in plan["theta0_deg"]) + " deg"),
    ] + tail
    print_rows(rows)
    print(f"physics bars: {'all met' if not fails else 'NOT met (kept): ' + '; '.join(fails)}")
    for w in written:
        say(f"wrote {w}", args.quiet)
    also = "".join(f" and {d}" for d in data_written)
    say(f"wrote {bvh} ({res.motion.n_frames} frames) and {rep}{also} in {time.perf_counter() - t0:.2f} s", args.quiet)
    return 0


def _steady_range(prep, args) -> str:
    """The steady speeds whose outputs meet every bar for this character (a goal outside them will not)."""
    from ...flow.speed_range import reachable_speed_range  # lazy: start-up

    return reachable_speed_range(prep, args.character, unlimited=args.unlimited, **character_kwargs(args)).sentence()


def _plot_files(plot):
    """Every file ``plot_plan(res, plot)`` writes (it may add a second figure beside the first)."""
    if plot is None:
        return []
    from ...viz.plan_plot import plan_plot_paths  # lazy: start-up

    return plan_plot_paths(plot)
