"""The per-frame table of a motion (input or output): COM, ground force, foot contacts and markers, phase,
measured as the report measures them; ``io.framedata`` writes and reads it (its docstring lists the columns)."""
from __future__ import annotations

import numpy as np

from ..body.gait import detect_gait
from ..body.model import BodyModel
from ..errors import FroudeError
from ..io.framedata import AXIS_NAMES
from ..machine.forces import ground_force, smooth_com

__all__ = ["frame_table"]

_MARKERS = ("ankle", "toe", "toe_end")
_FEET = ("left", "right")


def frame_table(motion, body=None, *, machine_path=None) -> dict[str, np.ndarray]:
    """The per-frame columns (``io.framedata``'s docstring) of ``motion`` as {name: (F,) array}, in column order.

    body: the BodyModel (default: built from the skeleton, 70 kg); machine_path: a synthesis.timewarp.MachinePath on
    the same frames (outputs), adding the machine's COM, force and stance.
    """
    if body is None:
        body = BodyModel.from_skeleton(motion.skeleton)
    com, markers = body.com_and_markers(motion)
    _, v, a = smooth_com(com, motion.frame_time)
    force = ground_force(a, body.total_mass)
    gait = detect_gait(motion, body, markers)
    cols: dict[str, np.ndarray] = {"time_s": motion.times}
    for name, arr in (("com_{}_m", com), ("com_v{}_m_s", v), ("com_force_{}_N", force)):
        for k, ax in enumerate(AXIS_NAMES):
            cols[name.format(ax)] = arr[:, k]
    if machine_path is not None:
        if len(machine_path.times) != motion.n_frames:
            raise FroudeError(f"the machine path has {len(machine_path.times)} frames, the motion {motion.n_frames}")
        for name, arr in (("machine_com_{}_m", machine_path.com), ("machine_force_{}_N", machine_path.force)):
            for k, ax in enumerate(AXIS_NAMES):
                cols[name.format(ax)] = arr[:, k]
        for i, foot in enumerate(_FEET):
            cols[f"machine_stance_{foot}"] = machine_path.stance[:, i].astype(np.int8)
    contact = np.asarray(gait.contact, bool)
    for i, foot in enumerate(_FEET):
        cols[f"contact_{foot}"] = contact[:, i].astype(np.int8)
    for i, foot in enumerate(_FEET):
        for m, marker in enumerate(_MARKERS):
            for k, ax in enumerate(AXIS_NAMES):
                cols[f"{foot}_{marker}_{ax}_m"] = markers[:, i, m, k]
    cols["phase"] = np.where(contact[:, 0] & contact[:, 1], "double",
                             np.where(contact[:, 0], "left", np.where(contact[:, 1], "right", "flight")))
    return cols
