"""``froude accelerate``: speed up or slow down over a number of steps (paper §5.3, §6)."""
from __future__ import annotations

import time

from .common import add_load_options, load_clip, say
from .scale import add_character_options, character_kwargs, print_rows


def register(sub) -> None:
    p = sub.add_parser(
        "accelerate", help="speed up or slow down a run over some steps (transition table, paper 5.3)",
        description="Plan touchdown angles step by step so that the simple machine reaches a target speed "
        "(a step is one stance and the flight after it), simulate it, time-warp the reference cycle onto "
        "the planned steps and correct the whole body with IK. Works for any character: the plan is "
        "dimensionless. Writes OUT.bvh and OUT.report.json (with the per-step speed profile).",
        epilog="Examples: froude accelerate run.bvh --to-speed 0.5x --steps 8 -o slow.bvh ; "
        "froude accelerate run.bvh --to-speed 4.5 --within 2.0 --character troll -o troll_fast.bvh",
    )
    p.add_argument("clip", help="reference running clip (BVH)")
    p.add_argument("-o", "--output", required=True, help="output BVH (a .report.json is written beside it)")
    p.add_argument("--to-speed", required=True, metavar="Fx|V",
                   help="goal: a factor of the start speed with an x (0.5x) or a speed in m/s (3.0)")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--steps", type=int, default=None, help="change over this many steps (default 8)")
    g.add_argument("--within", type=float, default=None, metavar="S", help="change within this many seconds")
    p.add_argument("--lead-steps", type=int, default=2, help="steady steps before the change (default 2)")
    p.add_argument("--hold-steps", type=int, default=4, help="steady steps after the change (default 4)")
    p.add_argument("--policy", choices=("ease", "even"), default="ease",
                   help="speed profile: ease (smooth start and end, default) or even (equal change per step)")
    p.add_argument("--plot", default=None, metavar="PNG", help="also plot the speed profile and the transition table")
    p.add_argument("--fps", type=float, default=None, help="output frame rate (default: the input's)")
    p.add_argument("--mass", type=float, default=70.0, help="the reference performer's mass [kg], default 70")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress or notes on stderr")
    add_character_options(p)
    add_load_options(p)
    p.set_defaults(func=run)


def parse_goal(text: str) -> tuple[float | None, float | None]:
    """'0.5x' -> (factor, None); '3.0' or '3.0m/s' -> (None, speed)."""
    from ..errors import FroudeError

    t = text.strip().lower()
    try:
        if t.endswith("x"):
            return float(t[:-1]), None
        if t.endswith("m/s"):
            t = t[:-3]
        return None, float(t)
    except ValueError:
        raise FroudeError(f"cannot read speed goal '{text}': use a factor (0.5x) or a speed in m/s (3.0)") from None


def run(args) -> int:
    from .. import pipeline
    from ..errors import FroudeError

    factor, speed = parse_goal(args.to_speed)
    if not str(args.output).lower().endswith(".bvh"):
        raise FroudeError(f"{args.output}: the output must be a .bvh file")
    for name, v in (("--steps", args.steps), ("--lead-steps", args.lead_steps), ("--hold-steps", args.hold_steps)):
        if v is not None and v < (1 if name == "--steps" else 0):
            raise FroudeError(f"{name} must be {'>= 1' if name == '--steps' else '>= 0'}, got {v}")
    steps = args.steps if (args.steps is not None or args.within is not None) else 8
    t0 = time.perf_counter()
    say(f"fitting the simple machine to {args.clip} ...", args.quiet)
    clip = load_clip(args.clip, args.length_scale, args.keep_all_frames, args.quiet, args.joint_map, args.up)
    prep = pipeline.prepare(clip, mass=args.mass)
    say("planning the steps and synthesising ...", args.quiet)
    res = pipeline.accelerate(
        prep, args.character, to_speed=speed, to_factor=factor, steps=None if args.within else steps,
        within=args.within, lead_steps=args.lead_steps, hold_steps=args.hold_steps, fps=args.fps,
        policy=args.policy, **character_kwargs(args),
    )
    for note in res.notes:
        say(f"note: {note}", args.quiet)
    bvh, rep = pipeline.write_result(res, args.output)
    plan = res.report.extras["plan"]
    rows = res.summary_rows()[:2] + [
        ("start speed", f"{plan['start_speed_m_s']:.3f} m/s"),
        ("goal", f"{plan['target_speed_m_s']:.3f} m/s"),
        ("apex speed per step", " ".join(f"{v:.2f}" for v in plan["apex_speed_m_s"]) + " m/s"),
        ("touchdown angle per step", " ".join(f"{v:.1f}" for v in plan["theta0_deg"]) + " deg"),
    ] + res.summary_rows()[5:]
    print_rows(rows)
    fails = res.report.check_bars()
    print(f"physics bars: {'all met' if not fails else 'NOT met: ' + '; '.join(fails)}")
    if args.plot:
        from ..viz.plan_plot import plot_plan

        for written in plot_plan(res, args.plot):
            say(f"wrote {written}", args.quiet)
    say(f"wrote {bvh} ({res.motion.n_frames} frames) and {rep} in {time.perf_counter() - t0:.2f} s", args.quiet)
    return 0
