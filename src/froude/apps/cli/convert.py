"""``froude convert IN OUT``: a motion from one format to another (BVH <-> glTF/GLB), suffixes decide."""
from __future__ import annotations

from .common import (
    MOTION_OUTPUTS,
    add_data_option,
    add_load_options,
    add_quiet,
    check_inputs,
    data_output,
    guard_outputs,
    number,
    say,
)

#: The one-line summary ``froude --help`` lists.
HELP = "convert a motion between BVH and glTF/GLB (skin, joints, animation, mannequin)"


def register(sub) -> None:
    p = sub.add_parser(
        "convert", help=HELP,
        description="Read IN (.bvh, .glb or .gltf) and write OUT (.bvh, .glb or .gltf; the suffix decides). "
        "glTF/GLB files hold the skeleton as a skin of joint nodes (metres, +Y up), the motion as an "
        "animation (root translation, every joint's rotation) and, unless --no-mesh, a simple mannequin "
        "mesh skinned to it so any viewer shows a body. A GLB froude wrote converts back to the same BVH "
        "joints and channel orders.",
        epilog="Examples: froude convert run.bvh run.glb ; froude convert child.glb child.bvh",
    )
    p.add_argument("input", help="a .bvh, .glb or .gltf file")
    p.add_argument("output", metavar="OUT", help="the output: .bvh, .glb or .gltf (its folder must exist)")
    p.add_argument("--no-mesh", action="store_true", help="glTF/GLB output: skeleton and animation only")
    p.add_argument("--fps", type=number(1, 1000, "Hz"), default=None,
                   help="glTF input: sampling rate [Hz] (default: the file's own for froude files, else the "
                   "animation's key spacing when even, else 30)")
    add_data_option(p)
    add_quiet(p)
    add_load_options(p)
    p.set_defaults(func=run)


def run(args) -> int:
    from ...io.atomic import atomic_group, require_suffix  # lazy: start-up

    require_suffix(args.input, MOTION_OUTPUTS, "input")
    out = require_suffix(args.output, MOTION_OUTPUTS)
    data = data_output(args)
    check_inputs(args.input)
    guard_outputs([out] + ([data] if data else []), [args.input])
    from ...api import load, save  # lazy: start-up (froude --help imports every verb module and no NumPy)

    motion = load(args.input, length_scale=args.length_scale, clean=not args.keep_all_frames, fps=args.fps)
    say(f"{args.input}: {motion.skeleton.n_joints} joints, {motion.n_frames} frames at {motion.fps:.1f} Hz",
        args.quiet)
    with atomic_group():
        save(motion, out, mesh=not args.no_mesh)
        if data is not None:
            from ...io.framedata import write_frame_data  # lazy: start-up
            from ...report.frames import frame_table  # lazy: start-up

            write_frame_data(frame_table(motion), data)
    say(f"wrote {out}" + (f" and {data}" if data else ""), args.quiet)
    return 0
