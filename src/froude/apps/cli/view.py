"""``froude view [CLIP.bvh]``: the live studio in the browser — change character, speed and acceleration
with controls and watch the result run beside the reference, with the simple machine drawn over it."""
from __future__ import annotations

from ...errors import FroudeError
from .common import add_load_options, add_mass, check_inputs, number, say, speed

#: Starting values the studio's controls can show: speed factor and strides (the sliders' ranges; the same
#: numbers as ``froude.apps.studio.session.LIMITS``, which the server enforces; a test keeps them equal).
VIEW_SPEED_RANGE = (0.5, 2.0)
VIEW_STRIDES = (1, 12)


#: The one-line summary ``froude --help`` lists.
HELP = "live studio in the browser: sliders for character, speed, acceleration"


def register(sub) -> None:
    p = sub.add_parser(
        "view", help=HELP,
        description="Open a local web studio (viser) on a running clip; each browser tab is its own session. "
        "Open another clip from the page (button or drag and drop). The reference, the physical result and the "
        "engine-style naive retarget are drawn as solid limbs with the simple machine (COM, spring leg, "
        "contacts, COM trail) and a legend; side (true relative size), front and three-quarter cameras; Space "
        "plays/pauses, arrow keys step frames, onion skin, phase strip, force and speed plots with a playhead. "
        "Controls for the character (presets, height, mass, leg scale), the speed factor (bounded to what "
        "meets every physics bar) and strides, or an acceleration goal and its steps, recompute through the "
        "same pipeline as 'froude scale' / 'froude accelerate'; a table compares reference, physical and "
        "naive. Downloads: BVH (units, rate, in place), the report, per-frame CSV and an MP4. Bad edits "
        "show their message in the page and keep the last good result. "
        "Needs the optional extra: pip install 'froude[studio]'.",
        epilog="The studio binds to 127.0.0.1 (this machine only) unless --host says otherwise (then it warns "
        "and prints the real addresses); open the printed address in a browser. It accepts websocket "
        "connections only from its own page (Origin and Host checked) and checks every control value against "
        "the control's options and limits on the server. Ctrl-C stops it.",
    )
    p.add_argument("clip", nargs="?", default=None,
                   help="running BVH clip (default: the embedded sample, CMU 09_01)")
    p.add_argument("--host", default="127.0.0.1",
                   help="address to bind (default 127.0.0.1; 0.0.0.0 to share on the network)")
    p.add_argument("--port", type=number(0, 65535, integer=True), default=8080,
                   help="port, 0-65535 (default 8080; the next free one if taken)")
    p.add_argument("--open", action="store_true", help="also open the page in the default web browser")
    add_mass(p, "reference body mass [kg]")
    p.add_argument("--character", default="same", help="starting character: a preset name or 'same'")
    p.add_argument("--speed", type=speed("--speed"), default=None, metavar="Fx|Vm/s",
                   help=f"starting speed: a factor (1.2x, or a bare 1.2) or a speed (3.5m/s); the studio's "
                   f"slider spans {VIEW_SPEED_RANGE[0]:g}x-{VIEW_SPEED_RANGE[1]:g}x (default 1x)")
    p.add_argument("--strides", type=number(*VIEW_STRIDES, "strides", integer=True), default=None,
                   help=f"starting output length in strides, {VIEW_STRIDES[0]}-{VIEW_STRIDES[1]} (default 4, and "
                   "for a turning take its whole turn and a stride on)")
    add_load_options(p)
    p.set_defaults(func=run)


def run(args) -> int:
    try:
        import viser  # noqa: F401
    except ImportError:
        raise FroudeError("the studio needs viser: pip install 'froude[studio]'") from None
    from ...body.characters import list_presets  # lazy: start-up (froude --help imports every verb module and no NumPy)
    from ...flow import pipeline  # lazy: start-up (froude --help imports every verb module and no NumPy)
    from ...io.samples import sample_path  # lazy: start-up (froude --help imports every verb module and no NumPy)
    from ..studio import Params, serve  # lazy: start-up (froude --help imports every verb module and no NumPy)

    check_inputs(args.clip)
    if args.character not in ("same", *list_presets()):
        raise FroudeError(f"unknown character '{args.character}': use same or a preset ({', '.join(list_presets())})")
    from ..studio.guard import is_loopback  # lazy: start-up (froude --help imports every verb module and no NumPy)

    if not is_loopback(args.host):
        say(f"froude view: WARNING: --host {args.host} makes the studio reachable from other machines on the "
            "network, with no password; anyone who can reach it can drive it. Use the default 127.0.0.1 unless "
            "you mean to share it.")
    clip = args.clip or str(sample_path())
    from .common import load_clip  # lazy: start-up (froude --help imports every verb module and no NumPy)

    clip = load_clip(clip, args.length_scale, args.keep_all_frames, False, args.joint_map, args.up)
    say(f"froude view: preparing {args.clip or 'the embedded sample (09_01)'} (fit once, reused for every change) ...")
    prep = pipeline.prepare(clip, mass=args.mass)
    strides = args.strides if args.strides is not None else min(pipeline.default_strides(prep), VIEW_STRIDES[1])
    params = Params(character=args.character, speed=_start_factor(prep, args), strides=strides).check()
    code = serve(prep, host=args.host, port=args.port, params=params, open_browser=args.open,
                 announce=lambda m: print(m, flush=True))
    say("froude view: stopped")
    return code


def _start_factor(prep, args) -> float:
    """The --speed goal as the studio's speed factor (a speed in m/s divided by the character's scaled
    speed), refused outside the slider's range."""
    goal = args.speed
    if goal is None:
        return 1.0
    factor = goal.factor
    if factor is None:
        rt = prep.retarget(None if args.character == "same" else args.character)
        factor = goal.factor_of(prep.machine.scaled(rt.L, rt.M).mean_speed_m_s)
    lo, hi = VIEW_SPEED_RANGE
    if not lo <= factor <= hi:
        raise FroudeError(f"--speed {goal} is a factor of {factor:.2f}; the studio's slider spans {lo:g}x to {hi:g}x")
    return factor
