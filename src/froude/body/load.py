"""Reading a motion file as froude works in it: the file's numbers (``froude.io``) made SI and +Y up with
the conventions read from the motion by the body's joint roles (``body.conventions.understand``).

io reads what a file says; knowing a body (its roles, its stature, its gait) is this layer's, so the
reading and the understanding meet here.
"""
from __future__ import annotations

import os

from ..core.motion import Motion
from ..errors import BvhError, FroudeError
from ..io.bvh import read_bvh
from ..io.gltf import read_gltf
from .conventions import understand


def load_bvh(path: str | os.PathLike, *, length_scale: float | None = None, clean: bool = True,
             joint_map=None, up: str | None = None) -> Motion:
    """Read a BVH file into a ``Motion`` in SI units (+Y up).

    path: the file.
    length_scale: metres per file unit; None detects it from the motion (``conventions.choose_unit``:
        the flight gravity, else the most human stature; meta["units"] says which and why).
    joint_map: role -> joint name for rigs whose joint names are not recognised (``body.find_roles``).
    up: "Y" or "Z", the file's up axis; None detects it from the motion (meta["up_axis"]).
    clean: drop (and report in meta["cleaning"]) a synthetic rest/T-pose first frame and invalid
        leading/trailing rows (all-zero, NaN or inf). With clean=False every row is kept and any
        non-finite value is an error.
    Raises BvhError (file and line in the message) on anything malformed; a unit that cannot be told
    is reported at the ROOT's line.
    """
    raw, root_line = read_bvh(path, clean=clean)
    try:
        motion, conv = understand(raw, joint_map=joint_map, length_scale=length_scale, up=up)
    except ValueError as e:
        raise BvhError(str(e), raw.meta["source"], root_line) from None
    meta = {
        "source": raw.meta["source"],
        "length_scale": conv["length_scale"],
        "units": conv["units"],
        "units_ambiguous": conv["units_ambiguous"],
        "up_axis": conv["up_axis"],
        "conventions": conv["notes"],
        "cleaning": raw.meta["cleaning"],
        "first_line": raw.meta["first_line"],
    }
    return motion.with_(meta=meta)


def load_gltf(path: str | os.PathLike, *, fps: float | None = None, clean: bool = True, joint_map=None,
              length_scale: float | None = None, up: str | None = None) -> Motion:
    """Read the first skin's skeleton and the first animation of a .glb/.gltf file (``io.gltf.read_gltf``)
    as a Motion, read as ``load_bvh`` reads a BVH file (SI units, +Y up, the conventions of
    ``conventions.understand``).

    fps: sampling rate (default: the file's own for froude files, else the animation's key spacing when it
    is even, else 30 Hz). A synthetic pose first frame is dropped as ``load_bvh`` does unless clean=False.
    Joints' rest rotations (bind orientations) are kept: the body is then measured in a standing frame of
    the motion. joint_map, length_scale (metres per file unit; default 1: glTF is in metres) and up
    (default "Y", glTF's) as for ``load_bvh``.
    Raises FroudeError (one line) for files froude cannot read as a skeletal animation.
    """
    raw = read_gltf(path, fps=fps, clean=clean)
    try:
        motion, conv = understand(raw, joint_map=joint_map, length_scale=1.0 if length_scale is None else length_scale,
                                  up=up or "Y")
    except ValueError as e:
        raise FroudeError(f"{raw.meta['source']}: {e}") from None
    units = "metres (glTF)" if length_scale is None else conv["units"]
    meta = {"source": raw.meta["source"], "units": units, "length_scale": conv["length_scale"],
            "up_axis": conv["up_axis"], "conventions": conv["notes"] + raw.meta["conventions"],
            "cleaning": raw.meta["cleaning"]}
    return motion.with_(meta=meta)
