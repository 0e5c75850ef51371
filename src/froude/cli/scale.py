"""``froude scale``: the reference run on another character and/or at another speed (§5.1, §5.2, §6)."""
from __future__ import annotations

import time

from ..characters import list_presets
from .common import add_load_options, load_clip, say


def register(sub) -> None:
    p = sub.add_parser(
        "scale", help="retarget a run to a new character and/or speed, physically (paper 5.1, 5.2, 6)",
        description="Fit the simple machine to the clip, scale it to the character by dynamic similarity "
        "(times x sqrt(L), speeds x sqrt(L)), change its speed by horizontal stretching, synthesise any "
        "number of strides and correct the whole body with IK. Writes OUT.bvh (same joint names and "
        "channel orders as the input, the target's bone lengths) and OUT.report.json (the physics report).",
        epilog=f"Presets: {', '.join(list_presets())}. Example: froude scale run.bvh --character child --speed 0.7 -o child.bvh",
    )
    p.add_argument("clip", help="reference running clip (BVH)")
    p.add_argument("-o", "--output", required=True, help="output BVH (a .report.json is written beside it)")
    add_character_options(p)
    g = p.add_argument_group("speed and length")
    g.add_argument("--speed", default="1.0", metavar="S|Vm/s",
                   help="speed factor on the character's dynamically scaled speed (e.g. 0.7), or an absolute "
                   "speed with a unit (e.g. 3.2m/s); default 1.0")
    g.add_argument("--strides", type=int, default=4, help="output strides (two steps each), default 4")
    g.add_argument("--duration", type=float, default=None, metavar="S", help="output length in seconds (overrides --strides)")
    g.add_argument("--fps", type=float, default=None, help="output frame rate (default: the input's)")
    p.add_argument("--method", choices=("physical", "naive"), default="physical",
                   help="physical (froude) or naive (what engines do: angles copied, root x L, timing kept)")
    p.add_argument("--mass", type=float, default=70.0, help="the reference performer's mass [kg], default 70")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress or notes on stderr")
    add_load_options(p)
    p.set_defaults(func=run)


def add_character_options(p) -> None:
    g = p.add_argument_group("character (default: the reference's own body)")
    g.add_argument("--character", default=None, metavar="PRESET|FILE",
                   help=f"a preset ({', '.join(list_presets())}), a character YAML file or a target BVH skeleton")
    g.add_argument("--height", type=float, default=None, help="stature [m]")
    g.add_argument("--char-mass", dest="char_mass", type=float, default=None, metavar="KG", help="character mass [kg]")
    g.add_argument("--leg-scale", type=float, default=None, help="leg bone length factor relative to the reference")
    g.add_argument("--arm-scale", type=float, default=None, help="arm bone length factor")
    g.add_argument("--head-scale", type=float, default=None, help="head and neck factor")
    g.add_argument("--trunk-scale", type=float, default=None, help="trunk factor")


def character_kwargs(args) -> dict:
    return dict(height=args.height, mass=args.char_mass, leg_scale=args.leg_scale, arm_scale=args.arm_scale,
                head_scale=args.head_scale, trunk_scale=args.trunk_scale)


def parse_speed(text: str) -> tuple[float | None, float | None]:
    """'0.7' or '0.7x' -> (factor, None); '3.2m/s' -> (None, 3.2)."""
    from ..errors import FroudeError

    t = text.strip().lower()
    try:
        if t.endswith("m/s"):
            return None, float(t[:-3])
        if t.endswith("x"):
            return float(t[:-1]), None
        return float(t), None
    except ValueError:
        raise FroudeError(f"cannot read speed '{text}': use a factor (0.7 or 0.7x) or a speed (3.2m/s)") from None


def print_rows(rows) -> None:
    width = max(len(k) for k, _ in rows)
    for k, v in rows:
        print(f"{k:<{width}}  {v}")


def run(args) -> int:
    from .. import pipeline
    from ..errors import FroudeError

    factor, absolute = parse_speed(args.speed)
    if factor is not None and not factor > 0:
        raise FroudeError(f"speed factor must be > 0, got {factor}")
    if absolute is not None and not absolute > 0:
        raise FroudeError(f"speed must be > 0 m/s, got {absolute}")
    if not str(args.output).lower().endswith(".bvh"):
        raise FroudeError(f"{args.output}: the output must be a .bvh file")
    t0 = time.perf_counter()
    say(f"fitting the simple machine to {args.clip} ...", args.quiet)
    clip = load_clip(args.clip, args.length_scale, args.keep_all_frames, args.quiet, args.joint_map, args.up)
    prep = pipeline.prepare(clip, mass=args.mass)
    say(f"synthesising ({args.method}) ...", args.quiet)
    res = pipeline.scale(prep, args.character, speed=factor or 1.0, target_speed=absolute, strides=args.strides,
                         duration=args.duration, fps=args.fps, method=args.method, **character_kwargs(args))
    for note in res.notes:
        say(f"note: {note}", args.quiet)
    bvh, rep = pipeline.write_result(res, args.output)
    print_rows(res.summary_rows())
    fails = res.report.check_bars()
    print(f"physics bars: {'all met' if not fails else 'NOT met: ' + '; '.join(fails)}")
    say(f"wrote {bvh} ({res.motion.n_frames} frames) and {rep} in {time.perf_counter() - t0:.2f} s", args.quiet)
    return 0
