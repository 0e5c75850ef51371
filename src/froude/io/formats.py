"""A motion file chosen by its suffix: the one place output formats are chosen (``froude.save``)."""
from __future__ import annotations

import os
from pathlib import Path

from ..core.motion import Motion
from ..errors import FroudeError

__all__ = ["MOTION_SUFFIXES", "save"]

#: Suffixes froude reads and writes motions as.
MOTION_SUFFIXES = (".bvh", ".glb", ".gltf")


def save(motion: Motion, path: str | os.PathLike, *, mesh: bool = True, **bvh_options) -> Path:
    """Write a motion by suffix: ``.bvh``, or ``.glb``/``.gltf`` (skin, joints, animation, and a mannequin
    mesh unless mesh=False); atomically. Returns the path. (The one place output formats are chosen.)
    bvh_options: ``io.bvh.save_bvh``'s (length_scale, up, rotations_only; default: the input's conventions)."""
    suffix = Path(path).suffix.lower()
    if suffix == ".bvh":
        from .bvh import save_bvh  # lazy: start-up (importing froude.api loads no format module)

        save_bvh(motion, path, **bvh_options)
        return Path(path)
    if suffix in (".glb", ".gltf"):
        from .gltf import save_gltf  # lazy: start-up (importing froude.api loads no format module)

        return save_gltf(motion, path, mesh=mesh)
    raise FroudeError(f"{path}: a motion is written as {', '.join(MOTION_SUFFIXES)}")
