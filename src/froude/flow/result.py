"""An output of scale / accelerate (motion, machine path, targets, physics report) and how it is written."""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from dataclasses import replace as _replace
from pathlib import Path

import numpy as np

from ..body.characters import Retarget
from ..core.constants import UP_AXIS
from ..core.motion import Motion
from ..errors import FroudeError
from ..io.atomic import atomic_group
from ..io.formats import save
from ..io.framedata import write_frame_data
from ..report.frames import frame_table
from ..report.metrics import Report, write_report
from ..report.path_report import path_rows
from ..synthesis.targets import Targets
from ..synthesis.timewarp import MachinePath
from .kinds import kind_named


@dataclass(frozen=True, eq=False)
class Output:
    """An output motion with its machine path, targets and physics report."""

    motion: Motion
    report: Report | None  # None until computed (``pipeline.add_report``; ``report=False`` defers it)
    path: MachinePath | None
    targets: Targets | None
    retarget: Retarget
    method: str
    speed_factor: float
    notes: tuple[str, ...] = field(default=())
    plan: object = None
    extras: dict = field(default_factory=dict)  # merged into report.extras (e.g. the speed plan)

    def summary_rows(self) -> list[tuple[str, str]]:
        """(label, text) rows of the CLI's result table; a figure that cannot be measured reads "n/a"."""
        r = self.report
        assert r is not None, "summary_rows needs the physics report (report=True)"
        f = _shown
        rows = [
            ("character", f"{self.retarget.character.name} (L = {self.retarget.L:.3f}, M = {self.retarget.M:.3f})"),
            ("method", self.method),
        ]
        if r.extras.get("modelled"):
            rows.append(("modelled", r.extras["modelled"]))
        rows += [
            ("speed", f"{f(r.mean_speed_m_s, '.3f')} m/s (x{self.speed_factor:g})"),
            ("Froude number U", f"{f(r.froude_U, '.3f')}"),
            ("step frequency", f"{f(r.step_frequency_hz, '.3f')} Hz"),
            ("stance / flight", f"{f(_mean(r.stance_times_s), '.3f')} s / {f(_mean(r.flight_times_s), '.3f')} s"),
            ("flight gravity", f"{f(r.flight_gravity_m_s2, '.2f')} m/s^2"),
            ("COM tracking", f"RMS {f(r.com_tracking_rms_mm, '.2f')} mm, max {f(r.com_tracking_max_mm, '.2f')} mm"),
            ("foot skate / penetration", f"{f(r.foot_skate_mm, '.2f')} mm / {f(r.penetration_mm, '.2f')} mm "
             f"(ball and tip near the floor: {f(r.foot_skate_floor_mm, '.2f')} mm)"),
            ("feet at rest", _rest_row(r)),
            ("joint jump",
             f"{f(r.max_joint_jump_deg, '.1f')} deg (reference {f(r.reference_max_joint_jump_deg, '.1f')})"),
        ]
        if "path_vs_clip" in r.extras:
            rows += path_rows(r.extras["path_vs_clip"])
        return rows + kind_named(r.extras.get("machine")).summary_rows(r)


def _rest_row(r: Report) -> str:
    """The summary's "feet at rest" cell: the balls' rest heights over the floor and the largest difference of
    a foot marker's from the source's, scaled (or n/a)."""
    h = r.rest_height_mm
    balls = " / ".join(_shown(h.get(side, {}).get("ball"), ".1f") for side in ("left", "right"))
    w = r.rest_height_worst
    off = (f"; off the source's (scaled) by {_shown(r.rest_height_error_mm, '.1f')} mm at most "
           f"({w['foot']} {w['marker']})") if w else ""
    return f"balls {balls} mm over the floor (left / right){off}"


def _shown(v, spec: str) -> str:
    """A figure for a table: formatted, or "n/a" when it could not be measured (None, NaN, infinite)."""
    return "n/a" if v is None or not math.isfinite(v) else format(v, spec)


def _mean(x) -> float:
    return float(np.mean(x)) if len(x) else float("nan")


def report_path(out_path) -> Path:
    p = Path(out_path)
    return p.with_name(p.stem + ".report.json")


def in_place_motion(result: Output) -> Motion:
    """The output with its root travel removed (a treadmill-like loop for engines that move the character
    themselves): the root is moved back by the COM's forward progression, taken straight between the
    machine's touchdowns (constant for a steady output, step by step for an acceleration), so the body
    keeps its bob and sway within each step and the stance foot slides back at the running speed."""
    motion = result.motion
    t = np.arange(motion.n_frames) * motion.frame_time
    fwd = result.path.frame[0] if result.path is not None else _travel_direction(motion, result)
    x = result.path.com @ fwd if result.path is not None else result.retarget.body.com(motion) @ fwd
    td = None if result.path is None else result.path.t_touchdown
    knots = t[[0, -1]] if td is None else np.concatenate([[t[0]], td[(td > t[0]) & (td < t[-1])], [t[-1]]])
    travel = np.interp(t, knots, np.interp(knots, t, x))
    return _replace(motion, root_positions=motion.root_positions - np.outer(travel - travel[0], fwd))


def _travel_direction(motion: Motion, result: Output) -> np.ndarray:
    com = result.retarget.body.com(motion)
    d = com[-1] - com[0]
    d[UP_AXIS] = 0.0
    n = np.linalg.norm(d)
    return d / n if n > 0 else np.eye(3)[0]


def write_result(result: Output, out_path, data=None, in_place: bool | None = None,
                 **bvh_options) -> tuple[Path, ...]:
    """Write OUT (.bvh, .glb or .gltf: ``io.formats.save`` decides by suffix) and OUT.report.json, and
    the per-frame table to ``data`` (.csv/.parquet/.npz) when given: all or none. Returns the paths.
    bvh_options: ``save_bvh``'s (length_scale, up, rotations_only; default: the input's conventions).

    in_place: write the motion without root travel (``in_place_motion``); None: as the input was (an
    in-place take gives in-place outputs). The report is always that of the travelling motion (its speed,
    skate and gravity are physical there) and says which was written.
    """
    out_path = Path(out_path)
    rp = report_path(out_path)
    if in_place is None:
        in_place = bool(result.report.extras.get("input_in_place")) if result.report is not None else False
    if result.report is not None:
        result.report.extras["written"] = "in place (root travel removed)" if in_place else "with root travel"
    with atomic_group():  # every file of the result or none
        save(in_place_motion(result) if in_place else result.motion, out_path, **bvh_options)
        if result.report is None:
            raise FroudeError("a result without its physics report cannot be written: compute it first "
                              "(pipeline.add_report)")
        write_report(result.report, rp)
        if data is None:
            return out_path, rp

        table = frame_table(result.motion, result.retarget.body, machine_path=result.path)
        return out_path, rp, write_frame_data(table, data)



