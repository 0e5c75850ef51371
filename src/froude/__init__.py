"""froude: physically based scaling of human running motion (after N. S. Pollard, 1999).

Quick tour::

    import froude
    result = froude.scale("run.bvh", "child", speed=0.8)   # also froude.fit, froude.accelerate (api.py)
    result.com, result.ground_force, result.contacts       # (F, 3) [m], (F, 3) [N], (F, 2) bool
    result.save("child.glb"); result.save_data("child.csv")
    motion = froude.load_bvh("run.bvh")              # SI units, +Y up, cleaning reported in motion.meta
    body = froude.BodyModel.from_skeleton(motion.skeleton, mass=70.0)
    com = body.com(motion)                           # (F, 3) [m]
    gait = froude.detect_gait(motion, body)          # stances, flights, ground height

The names below are imported on first use (PEP 562), so ``import froude`` -- and with it ``froude --help``,
whose package lives under this one -- costs no NumPy or SciPy import until a name is touched.
"""
from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

__version__ = "0.1.0"

#: Public name -> the module that defines it (one line per name: add new public names here).
_LAZY = {
    "Result": ".api", "accelerate": ".api", "fit": ".api", "ground_reaction_force": ".api", "info": ".api",
    "load": ".api",
    "save": ".api", "scale": ".api",
    "BodyModel": ".body.model", "JointMapError": ".body.model", "find_roles": ".body.model",
    "load_joint_map": ".body.model", "OutputError": ".io.atomic",
    "BeyondHumanRange": ".errors", "BvhError": ".errors", "CharacterError": ".errors", "FitError": ".errors",
    "FroudeError": ".errors",
    "IkError": ".errors", "NotARunningMotion": ".errors",
    "NotAWalkingMotion": ".errors", "PlanError": ".errors",
    "Gait": ".body.gait", "GaitSummary": ".body.gait", "Stance": ".body.gait", "detect_gait": ".body.gait",
    "summarize": ".body.gait",
    "load_bvh": ".body.load", "save_bvh": ".io.bvh",
    "Motion": ".core.motion",
    "sample_path": ".io.samples",
    "Skeleton": ".core.skeleton",
}

#: The public names, written out so that tools see them (tests/test_lint.py checks it equals _LAZY's keys).
__all__ = [
    "BeyondHumanRange", "BodyModel", "BvhError", "CharacterError", "FitError", "FroudeError", "Gait", "GaitSummary",
    "IkError",
    "JointMapError", "Motion", "NotARunningMotion", "NotAWalkingMotion", "OutputError", "PlanError", "Result",
    "Skeleton", "Stance",
    "accelerate", "detect_gait", "find_roles", "fit", "ground_reaction_force", "info", "load", "load_bvh",
    "load_joint_map", "sample_path", "save", "save_bvh", "scale", "summarize",
]


def __getattr__(name: str):
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'froude' has no attribute '{name}'")
    value = getattr(importlib.import_module(module, __name__), name)
    globals()[name] = value  # later look-ups skip this function
    return value


def __dir__():
    return sorted(set(globals()) | set(_LAZY))


if TYPE_CHECKING:  # static analysers and IDEs see the real imports
    from .api import Result, accelerate, fit, ground_reaction_force, info, load, save, scale
    from .body.gait import Gait, GaitSummary, Stance, detect_gait, summarize
    from .body.load import load_bvh
    from .body.model import BodyModel, JointMapError, find_roles, load_joint_map
    from .core.motion import Motion
    from .core.skeleton import Skeleton
    from .errors import (
        BeyondHumanRange,
        BvhError,
        CharacterError,
        FitError,
        FroudeError,
        IkError,
        NotARunningMotion,
        NotAWalkingMotion,
        PlanError,
    )
    from .io.atomic import OutputError
    from .io.bvh import save_bvh
    from .io.samples import sample_path
