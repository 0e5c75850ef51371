"""The take as froude analyses it: a time range chosen, a loop unrolled, an in-place take given its travel
back, and what part of it the machine stands for (in one line, with a note when the take changes speed).
"""
from __future__ import annotations

import math
from contextlib import contextmanager
from dataclasses import dataclass
from dataclasses import replace as _replace
from pathlib import Path

import numpy as np

from ..core import quat
from ..core.constants import GRAVITY, UP_AXIS
from ..core.motion import Motion
from ..errors import FitError, FroudeError
from .gait import Gait, GaitSummary, detect_gait, ground_velocity, stride_speeds
from .model import BodyModel
from .path import TakePath, is_straight, straighten, take_path, turn_note

#: A take whose stride speeds spread more than this (fastest / slowest − 1) is said to change speed: the
#: output then says which part the machine models and how to choose another (``time_range``).
SPEED_CHANGE_NOTE = 0.10  # a steady CMU run's strides spread 2-5 %


def parse_time_range(text: str) -> tuple[float | None, float | None]:
    """'T0:T1' [s] -> (T0, T1); either side may be empty ('1.5:' from 1.5 s to the end)."""
    a, sep, b = str(text).partition(":")
    try:
        if not sep:
            raise ValueError
        return (float(a) if a.strip() else None), (float(b) if b.strip() else None)
    except ValueError:
        raise FroudeError(f"cannot read time range '{text}': use T0:T1 in seconds (e.g. 1.2:3.0, or 1.2: to the "
                          "end)") from None


def select_range(motion: Motion, time_range, source: str = "motion") -> Motion:
    """The frames of ``motion`` whose times [s] lie in time_range = (T0, T1) (None: the clip's start / end)."""
    t0, t1 = time_range
    t0 = 0.0 if t0 is None else float(t0)
    t1 = motion.duration if t1 is None else float(t1)
    if not (np.isfinite(t0) and np.isfinite(t1) and 0.0 <= t0 < t1):
        raise FroudeError(f"{source}: time range {t0:g}:{t1:g} s is empty or negative")
    if t0 >= motion.duration:
        raise FroudeError(f"{source}: time range starts at {t0:g} s, after the clip's end ({motion.duration:.3f} s)")
    i0 = int(math.ceil(t0 / motion.frame_time - 1e-3))  # a frame time written to 7 digits: 1e-3 frame slack
    i1 = min(motion.n_frames, int(math.floor(t1 / motion.frame_time + 1e-3)) + 1)
    out = motion.cut(i0, i1)
    meta = dict(out.meta)
    meta["time_range_s"] = (i0 * motion.frame_time, (i1 - 1) * motion.frame_time)
    return _replace(out, meta=meta)


def modelled_part(motion: Motion, summary: GaitSummary, com: np.ndarray, gait: Gait) -> tuple[str, str | None]:
    """What the machine of a clip stands for, in one line, and a note when the take's speed changes.

    Returns (description, note or None): "0.00-2.40 s of the take: 3.150 m/s, 2.930 steps/s".
    """
    t0, t1 = motion.meta.get("time_range_s", (0.0, motion.duration))
    loop = motion.meta.get("loop")
    part = (f"a {loop['frames'] * motion.frame_time:.2f} s loop ({loop['frames']} frames, unrolled x{loop['copies']})"
            if loop else f"{t0:.2f}-{t1:.2f} s of the take")
    if motion.meta.get("in_place"):
        part += ", in place (speed from the feet)"
    text = f"{part}: {summary.mean_speed:.3f} m/s, {summary.step_frequency:.3f} steps/s"
    _, v = stride_speeds(com, gait, motion.n_frames)
    note = None
    if v.size >= 2 and v.max() / v.min() - 1.0 > SPEED_CHANGE_NOTE:
        note = (f"the speed changes within the take (first stride {v[0]:.2f} m/s, last {v[-1]:.2f}, strides "
                f"{v.min():.2f}-{v.max():.2f}): the machine runs its mean over {t0:.2f}-{t1:.2f} s, "
                f"{summary.mean_speed:.2f} m/s, and speed factors refer to that; to model one part, give its "
                "time range (--range T0:T1 on scale, fit or accelerate; Python time_range=(t0, t1))")
    return text, note


#: A clip is a loop when its last pose is this close to its first (mean joint angle), relative to the
#: median change between neighbouring frames: below LOOP_DUPLICATE the last frame repeats the first, below
#: LOOP_CONTINUES the first frame follows the last.
LOOP_DUPLICATE = 0.25
LOOP_CONTINUES = 1.5
#: A looping take is unrolled into at least this many copies and at least LOOP_MIN_S seconds.
LOOP_MIN_COPIES = 3
LOOP_MIN_S = 1.5
#: An in-place take travels less than this × L, while its feet slide back faster than IN_PLACE_MIN_FROUDE
#: √(g L) on the ground.
IN_PLACE_MAX_TRAVEL_L = 0.5
IN_PLACE_MIN_FROUDE = 0.3


def unroll_loop(motion: Motion, body: BodyModel) -> tuple[Motion, str] | None:
    """A looping take (one stride or a few that repeat) as several copies in a row, with its travel.

    The take loops when its last pose returns to its first: either repeating it (the last frame is dropped
    when tiling) or one frame before it (the first frame follows the last). Each copy is moved on by the
    loop's horizontal COM travel, so a root-motion loop runs on and an in-place loop stays in place.
    Returns (motion, note) or None when the take does not loop.
    """
    F = motion.n_frames
    if F < 4:
        return None
    rot = quat.make_continuous(motion.rotations)
    # mean over joints: one joint landing fast at the seam (or a glitch at a clip's edge) does not decide
    step = quat.step_angles(rot).mean(axis=1)
    close = float(quat.angle_between(rot[-1], rot[0]).mean())
    typical = float(np.median(step))
    if not typical > 0:
        return None
    com = body.com(motion)
    travel = com[-1] - com[0]
    if close <= LOOP_DUPLICATE * typical:
        n, per_loop = F - 1, travel
    elif close <= LOOP_CONTINUES * typical:
        n, per_loop = F, travel * F / (F - 1)
    else:
        return None
    per_loop = per_loop.copy()
    per_loop[UP_AXIS] = 0.0
    copies = max(LOOP_MIN_COPIES, int(math.ceil(LOOP_MIN_S / (n * motion.frame_time))))
    k = np.repeat(np.arange(copies), n)
    idx = np.tile(np.arange(n), copies)
    root = motion.root_positions[idx] + k[:, None] * per_loop[None, :]
    tr = None if motion.translations is None else motion.translations[idx]
    meta = dict(motion.meta)
    meta["loop"] = {"frames": n, "copies": copies}
    out = _replace(motion, root_positions=root, rotations=rot[idx], translations=tr, meta=meta)
    note = (f"a looping take ({n} frames, {n * motion.frame_time:.2f} s, "
            f"{'last frame repeats the first' if n == F - 1 else 'first frame follows the last'}): "
            f"unrolled {copies} times")
    return out, note


def add_travel(motion: Motion, body: BodyModel, markers: np.ndarray | None = None) -> tuple[Motion, str] | None:
    """An in-place take (root travel removed, the stance foot sliding back) with its travel put back.

    The running velocity is minus the feet's velocity on the ground (``gait.ground_velocity``); the root
    then moves at it. Returns (motion, note), or None when the take travels or its feet do not slide.
    """
    com = body.com(motion)
    L = body.leg_length
    travel = com[-1] - com[0]
    travel[UP_AXIS] = 0.0
    if np.linalg.norm(travel) >= IN_PLACE_MAX_TRAVEL_L * L:
        return None
    if markers is None:
        markers = body.foot_markers(motion)
    v = -ground_velocity(markers, L, motion.frame_time)
    u = float(np.linalg.norm(v))
    if u < IN_PLACE_MIN_FROUDE * math.sqrt(GRAVITY * L):
        return None
    t = np.arange(motion.n_frames) * motion.frame_time
    meta = dict(motion.meta)
    meta["in_place"] = {"speed_m_s": u, "velocity_m_s": v.tolist()}
    out = _replace(motion, root_positions=motion.root_positions + t[:, None] * v[None, :], meta=meta)
    return out, (f"an in-place take: running at {u:.2f} m/s, found from the feet sliding back on the ground; "
                 "its travel is put back for the fit (outputs are written in place too unless --travel)")


def running_take(motion: Motion, body: BodyModel) -> tuple[Motion, list[str]]:
    """The take as froude analyses it: a loop unrolled, an in-place take given its travel back (notes say
    what was done). Other takes are returned as they are."""
    notes = []
    moving = add_travel(motion, body)  # first: an in-place take's contacts are found once it travels
    if moving is not None:
        motion, note = moving
        notes.append(note)
    # only a take too short to fit is unrolled (fewer than two complete stances): a longer one that happens
    # to end near its first pose is analysed as it is
    loop = unroll_loop(motion, body) if _full_stances(motion, body) < 2 else None
    if loop is not None and _full_stances(loop[0], body) >= 2:
        motion, note = loop
        notes.append(note)
    return motion, notes


def _full_stances(motion: Motion, body: BodyModel) -> int:
    return len(detect_gait(motion, body).full_stances)


@dataclass(frozen=True, eq=False)
class AnalysedTake:
    """A take as the machines see it (``analysed_take``): motion, its COM (F, 3) [m] and foot markers
    (F, 2, 3, 3) [m], its contacts (gait), its path as taken (clip_path), the same when it turns (turn, else
    None: then motion is the take straightened along it), and what was done to it (notes)."""

    motion: Motion
    com: np.ndarray
    markers: np.ndarray
    gait: Gait
    clip_path: TakePath
    turn: TakePath | None
    notes: tuple


def analysed_take(motion: Motion, body: BodyModel, unroll: bool = True) -> AnalysedTake:
    """The take ``prepare`` and ``froude fit`` model: a loop unrolled and an in-place take given its travel
    (``running_take``; not when unroll is False: ``info`` shows that part apart), and a take that turns
    straightened along its path (the machines run along it). motion: at least 3 frames (a path)."""
    motion, notes = running_take(motion, body) if unroll else (motion, [])
    com, markers = body.com_and_markers(motion)
    gait = detect_gait(motion, body, markers, com)
    clip_path = take_path(motion, body, com, gait)
    turn = None if is_straight(clip_path) else clip_path
    if turn is not None:
        motion = straighten(motion, turn)
        com, markers = body.com_and_markers(motion)
        gait = detect_gait(motion, body, markers, com)
        notes = list(notes) + [turn_note(turn)]
    return AnalysedTake(motion, com, markers, gait, clip_path, turn, tuple(notes))


@contextmanager
def said_on_turn(source: str, turn):
    """A fit's refusal (FitError) of a turning take says that the fit saw it straightened."""
    try:
        yield
    except FitError as e:
        if turn is None:
            raise
        name = Path(source).name
        raise FitError(f"{'' if name in str(e) else name + ': '}{e} (fitted to the take straightened along its "
                       f"{math.degrees(turn.heading_change_rad):+.0f} deg turn)") from e
