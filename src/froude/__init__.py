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
"""
from .api import Result, accelerate, fit, ground_reaction_force, load, save, scale
from .body import BodyModel, find_roles, load_joint_map
from .errors import BvhError, CharacterError, FitError, FroudeError, IkError, NotARunningMotion, PlanError
from .gait import Gait, GaitSummary, Stance, detect_gait, summarize
from .io.bvh import load_bvh, save_bvh
from .motion import Motion
from .samples import sample_path
from .skeleton import Skeleton

__version__ = "0.1.0"

__all__ = [
    "Result", "accelerate", "fit", "ground_reaction_force", "load", "save", "scale",
    "BodyModel", "BvhError", "CharacterError", "FitError", "FroudeError", "Gait", "GaitSummary", "IkError",
    "Motion", "NotARunningMotion", "PlanError", "Skeleton", "Stance", "detect_gait", "find_roles",
    "load_bvh", "load_joint_map", "sample_path", "save_bvh", "summarize",
]
