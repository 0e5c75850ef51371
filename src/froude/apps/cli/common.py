"""What the subcommands share: option types with their supported ranges, the load, character, speed and
output options, the output guard and the work bound.

Every option is checked when it is parsed (argparse calls the ``type``), so a bad value is refused before
any file is read; what needs a file (the character, the outputs against the inputs, the size of the
work) is checked right after, before the long work. Nothing here imports NumPy at module level:
``froude --help`` builds every subcommand's parser.
"""
from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

from ...body.presets import HEIGHT_RANGE_M, MASS_RANGE_KG, PART_SCALE_RANGE, list_presets
from ...errors import FroudeError

#: Reference body mass the fit assumes [kg] and its supported range.
BODY_MASS_RANGE_KG = (20.0, 300.0)
#: Output frame rates froude supports [Hz]: the COM filter (8 Hz cutoff) needs more than 16 Hz.
FPS_RANGE_HZ = (20.0, 1000.0)
#: Metres per file unit accepted by --length-scale (micrometres to hectometres).
LENGTH_SCALE_RANGE = (1e-6, 100.0)
#: Without --force, a command refuses work estimated above either bound (frames of output, memory).
MAX_FRAMES = 200_000
MAX_MEMORY_BYTES = 2 << 30
#: Memory estimate of the synthesis + IK per output frame and joint [bytes], with a margin: measured on
#: CMU 09_01 (31 joints) about 130 B for a 1-hour 'scale' (1.8 GB peak, bench_scale.py --hour), 300 B for
#: 200 strides and 100 B for 'accelerate' over 100 steps (peak RSS, /usr/bin/time).
BYTES_PER_FRAME_JOINT = 400


def say(msg: str = "", quiet: bool = False) -> None:
    """Progress and notes go to stderr, so stdout stays clean for tables and JSON."""
    if not quiet:
        print(msg, file=sys.stderr, flush=True)


# ---- option types ------------------------------------------------------------------------------------
def _fmt(v: float) -> str:
    return f"{v:g}"


def number(lo: float, hi: float, unit: str = "", *, integer: bool = False, lo_open: bool = False):
    """An argparse ``type``: a finite number in [lo, hi] (or (lo, hi] with lo_open), said with its unit.

    The message names the supported range: ``must be 20 to 1000 Hz, got 0``. Integers refuse "2.5";
    Python's "1_0" and "nan"/"inf" are refused for every number.
    """
    unit_s = f" {unit}" if unit else ""
    rng = f"{'more than ' + _fmt(lo) + ' and at most' if lo_open else 'from ' + _fmt(lo) + ' to'} {_fmt(hi)}{unit_s}"

    def parse(text: str):
        t = text.strip()
        try:
            if "_" in t:
                raise ValueError
            value = int(t) if integer else float(t)
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"expected {'a whole number' if integer else 'a number'} {rng}, got '{text}'") from None
        ok = math.isfinite(value) and (lo < value if lo_open else lo <= value) and value <= hi
        if not ok:
            raise argparse.ArgumentTypeError(f"must be {rng}, got {text}")
        return value

    parse.__name__ = "integer" if integer else "number"  # argparse names the type in some messages
    return parse


def speed(what: str):
    """An argparse ``type`` for the one speed syntax (``froude.flow.speed_goal``): returns a SpeedGoal."""

    def parse(text: str):
        from ...flow.speed_goal import (
            parse_speed,  # lazy: start-up (froude --help imports every verb module and no NumPy)
        )

        try:
            return parse_speed(text, what)
        except FroudeError as e:
            raise argparse.ArgumentTypeError(str(e).removeprefix(f"{what}: ")) from None

    parse.__name__ = "speed"
    return parse


def time_range(text: str):
    """An argparse ``type`` for ``--range T0:T1`` [s] (``body.take.parse_time_range``): (T0, T1), either None."""
    from ...body.take import parse_time_range  # lazy: start-up (froude --help imports every verb module and no NumPy)

    try:
        return parse_time_range(text)
    except FroudeError as e:
        raise argparse.ArgumentTypeError(str(e)) from None


# ---- shared options ----------------------------------------------------------------------------------
def add_keep(p) -> None:
    p.add_argument("--keep", action="store_true",
                   help="write the output even if it misses a physics bar (otherwise it is not written, the "
                   "bars missed and the reachable speeds are said, and the exit status is 1)")


def add_unlimited(p) -> None:
    p.add_argument("--unlimited", action="store_true",
                   help="allow a run faster than the human range for the character's size (a step longer "
                   "than 1.4 x stature, a step frequency or stance time no human sprinter of that size "
                   "reaches); otherwise such a speed is refused with the human limit in m/s")


def add_root_option(p) -> None:
    g = p.add_mutually_exclusive_group()
    g.add_argument("--in-place", dest="in_place", action="store_const", const=True, default=None,
                   help="write the output in place (root travel removed, the stance foot sliding back), as "
                   "engines that move the character themselves want (default: as the input is)")
    g.add_argument("--travel", dest="in_place", action="store_const", const=False,
                   help="write the output with its root travel even when the input was in place")


def add_range_option(p) -> None:
    p.add_argument("--range", type=time_range, default=None, metavar="T0:T1",
                   help="model only this part of the take, in seconds (e.g. 1.2:3.0, or 1.2: to the end): its "
                   "speed, cadence and strides; speed factors then refer to it (default: the whole take, "
                   "said aloud when its speed changes)")


def add_quiet(p) -> None:
    p.add_argument("-q", "--quiet", action="store_true", help="no progress or notes on stderr (results still print)")


def add_force(p) -> None:
    p.add_argument("--force", action="store_true",
                   help=f"run work estimated beyond {MAX_FRAMES:,} output frames or {MAX_MEMORY_BYTES >> 30} GiB "
                   "(refused otherwise)")


def add_mass(p, help_text: str = "the reference performer's mass [kg]") -> None:
    lo, hi = BODY_MASS_RANGE_KG
    p.add_argument("--mass", type=number(lo, hi, "kg"), default=70.0,
                   help=f"{help_text}, {_fmt(lo)}-{_fmt(hi)}, default 70")


def add_fps(p, help_text: str = "output frame rate [Hz] (default: the input's)", default=None) -> None:
    lo, hi = FPS_RANGE_HZ
    p.add_argument("--fps", type=number(lo, hi, "Hz"), default=default, help=f"{help_text}; {_fmt(lo)}-{_fmt(hi)}")


def add_load_options(p) -> None:
    lo, hi = LENGTH_SCALE_RANGE
    p.add_argument("--length-scale", type=number(lo, hi, "m per unit", lo_open=False), default=None, metavar="M",
                   help="metres per file unit (default: detected from the motion: the flight gravity, else the "
                   "most human stature; said aloud)")
    p.add_argument("--joint-map", default=None, metavar="FILE.yaml",
                   help="joint roles for unusual joint names, lines 'role: JointName' (e.g. left_knee: Shin_L)")
    p.add_argument("--up", default=None, choices=("Y", "Z"), type=str.upper,
                   help="the file's up axis (default: detected from the motion)")
    p.add_argument("--keep-all-frames", action="store_true",
                   help="do not drop a synthetic T-pose frame or invalid leading/trailing rows")


def add_output_options(p) -> None:
    """How the output BVH is written; by default in the input's conventions (unit, up axis, names, channel
    orders, frame rate)."""
    g = p.add_argument_group("output file (default: the input's conventions)")
    g.add_argument("--units", default=None, choices=("m", "cm", "mm", "in", "cmu"),
                   help="length unit of the output BVH (default: the input's)")
    g.add_argument("--rotations-only", action="store_true",
                   help="no position channels below the root (some readers mishandle them)")


def output_kwargs(args) -> dict:
    """``save_bvh`` options from add_output_options."""
    from ...body.conventions import unit_scale  # lazy: start-up (froude --help imports every verb module and no NumPy)

    return {"length_scale": unit_scale(args.units)[0] if args.units else None,
            "rotations_only": args.rotations_only}


def add_character_options(p) -> None:
    g = p.add_argument_group("character (default: the reference's own body)")
    g.add_argument("--character", default=None, metavar="PRESET|FILE",
                   help=f"a preset ({', '.join(list_presets())}), a character YAML file or a target BVH skeleton")
    (hlo, hhi), (mlo, mhi), (slo, shi) = HEIGHT_RANGE_M, MASS_RANGE_KG, PART_SCALE_RANGE
    g.add_argument("--height", type=number(hlo, hhi, "m"), default=None, metavar="M",
                   help=f"stature [m], {_fmt(hlo)}-{_fmt(hhi)}")
    g.add_argument("--char-mass", dest="char_mass", type=number(mlo, mhi, "kg"), default=None, metavar="KG",
                   help=f"character mass [kg], {_fmt(mlo)}-{_fmt(mhi)}")
    for part in ("leg", "arm", "head", "trunk"):
        g.add_argument(f"--{part}-scale", type=number(slo, shi), default=None, metavar="F",
                       help=f"{part} bone length factor relative to the reference, {_fmt(slo)}-{_fmt(shi)}")


def character_kwargs(args) -> dict:
    return dict(height=args.height, mass=args.char_mass, leg_scale=args.leg_scale, arm_scale=args.arm_scale,
                head_scale=args.head_scale, trunk_scale=args.trunk_scale)


def check_character(args):
    """Resolve the character options now (unknown preset, YAML errors, bad numbers, a target BVH that
    cannot be read), before the fit; returns the Character. The pipeline resolves it again from the same
    options (cheap), so the name and caching stay the pipeline's."""
    from ...body.characters import resolve_character  # lazy: start-up

    return resolve_character(args.character, **character_kwargs(args))


def character_input(args) -> str | None:
    """The character option when it names a file (an input the outputs must not overwrite)."""
    c = getattr(args, "character", None)
    return c if c and c not in list_presets() and Path(c).suffix.lower() in (".yaml", ".yml", ".bvh") else None


# ---- loading -----------------------------------------------------------------------------------------
def check_inputs(*paths) -> None:
    """Every input names an existing regular file (one line otherwise)."""
    for p in paths:
        if p is None:
            continue
        path = Path(p)
        if path.is_dir():
            raise FroudeError(f"{p}: is a folder, expected a file")
        if not path.is_file():
            raise FroudeError(f"{p}: no such file")


def load_clip(path: str, length_scale: float | None = None, keep_all: bool = False, quiet: bool = False,
              joint_map: str | None = None, up: str | None = None):
    """Load a clip (BVH, or glTF/GLB by suffix) and say which units and conventions were read and what
    cleaning did.

    joint_map: a YAML file 'role: JointName' (``body.load_joint_map``); up: "Y"/"Z" (None: detected)."""
    from ...body.model import load_joint_map  # lazy: start-up (froude --help imports every verb module and no NumPy)

    jm = load_joint_map(joint_map) if joint_map else None
    if Path(path).suffix.lower() in (".glb", ".gltf"):
        from ...body.load import load_gltf  # lazy: start-up (froude --help imports every verb module and no NumPy)

        motion = load_gltf(path, length_scale=length_scale, clean=not keep_all, joint_map=jm, up=up)
    else:
        from ...body.load import load_bvh  # lazy: start-up (froude --help imports every verb module and no NumPy)

        motion = load_bvh(path, length_scale=length_scale, clean=not keep_all, joint_map=jm, up=up)
    say_loaded(motion, path, quiet)
    return motion


def say_loaded(motion, path: str, quiet: bool = False) -> None:
    """The load's guesses said aloud: frames, rate, units, conventions, cleaning (commands that can still
    fail on the clip say it after the fit, so a refusal stays one line)."""
    say(f"{path}: {motion.n_frames} frames at {motion.fps:.3f} Hz; units: {motion.meta['units']}", quiet)
    for note in motion.meta.get("conventions", ()):
        say(f"{path}: {note}", quiet)
    for note in motion.meta.get("cleaning", ()):
        say(f"{path}: cleaning: {note}", quiet)


def prepare_clip(args):
    """Load args.clip (with the load options) and fit it: ``pipeline.prepare``; then say the load's notes.

    Nothing is printed before the fit succeeds, so a clip that cannot be used is one line."""
    from ...flow import pipeline  # lazy: start-up (froude --help imports every verb module and no NumPy)

    motion = load_clip(args.clip, args.length_scale, args.keep_all_frames, True, getattr(args, "joint_map", None),
                       getattr(args, "up", None))
    prep = pipeline.prepare(motion, mass=args.mass, time_range=getattr(args, "range", None))
    say_loaded(motion, args.clip, args.quiet)
    return prep


# ---- outputs and the size of the work ----------------------------------------------------------------
def guard_outputs(outputs, inputs=(), folders=()) -> None:
    """The output guard (``froude.io.atomic.check_outputs``): before any work, every output writable,
    none an input or another output."""
    from ...io.atomic import check_outputs  # lazy: start-up (froude --help imports every verb module and no NumPy)

    check_outputs(outputs, inputs, folders=folders)


def bound_work(frames: float, joints: int, force: bool, what: str, quiet: bool = False,
               extra_bytes: float = 0.0) -> bool:
    """Refuse work estimated beyond MAX_FRAMES output frames or MAX_MEMORY_BYTES unless ``force``.

    frames: estimated output frames; joints: joints per frame; extra_bytes: other memory the work needs
    (images of a video). Says the estimate when the work is large (a tenth of a bound or more) and
    returns True then (the caller shows progress); short work stays silent.
    """
    memory = frames * joints * BYTES_PER_FRAME_JOINT + extra_bytes
    if not math.isfinite(frames) or not math.isfinite(memory):
        raise FroudeError(f"{what}: the work cannot be estimated (non-finite size)")
    size = f"about {frames:,.0f} frames and {memory / 2**20:,.0f} MiB"
    if (frames > MAX_FRAMES or memory > MAX_MEMORY_BYTES) and not force:
        raise FroudeError(f"{what}: {size} is beyond the {MAX_FRAMES:,}-frame / {MAX_MEMORY_BYTES >> 30} GiB bound; "
                          "ask for less, or add --force to run it anyway")
    large = frames > MAX_FRAMES / 10 or memory > MAX_MEMORY_BYTES / 10
    if large:
        say(f"{what}: {size}; this takes a while", quiet)
    return large


def print_rows(rows) -> None:
    width = max(len(k) for k, _ in rows)
    for k, v in rows:
        print(f"{k:<{width}}  {v}")


# ---- exports -----------------------------------------------------------------------------------------
#: Output suffixes of a motion (``froude.io.formats.save`` writes them) and of per-frame data.
MOTION_OUTPUTS = (".bvh", ".glb", ".gltf")
DATA_OUTPUTS = (".csv", ".parquet", ".npz")


def add_data_option(p) -> None:
    p.add_argument("--data", default=None, metavar="OUT.csv|.parquet|.npz",
                   help="also write per frame: time, COM position and velocity, ground force (the machine's for "
                   "outputs; eq. 1 from the COM always), each foot's contact and markers, stance/flight phase")


def data_output(args):
    """The --data path with its suffix checked (None when not asked for)."""
    from ...io.atomic import require_suffix  # lazy: start-up (froude --help imports every verb module and no NumPy)

    return None if args.data is None else require_suffix(args.data, DATA_OUTPUTS, "--data output")
