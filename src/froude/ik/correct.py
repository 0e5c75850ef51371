"""The IK correction policy (§6): all frames solved at once, then the frames that missed their targets or
flipped to another branch solved again, harder; the COM made exact by the root; steady outputs solved on
one stride and tiled.
"""
from __future__ import annotations

from dataclasses import replace as _replace

import numpy as np

from ..body.model import BodyModel
from ..core.constants import HORIZONTAL_AXES, UP_AXIS
from ..core.motion import Motion
from ..errors import IkError
from ..synthesis.cycle import nlerp_rows
from ..synthesis.targets import COM_WEIGHT, STANCE_MARKER_WEIGHT, WEIGHT_RAMP_S, Targets, min_jerk
from .solver import DEFAULT_MAX_ERROR, solve_ik
from .tasks import DEFAULT_JOINT_WEIGHT, ComTask, MarkerTask, PostureTask, RootTask

#: IK stops a frame when every weighted error is below this [m], after at most IK_ITERS steps; the COM is
#: then made exact by shifting the root (a root translation moves the COM one to one).
IK_TOL = 1e-3
IK_ITERS = 4
#: Gauss-Newton steps (fresh Jacobian each) of the repair pass. Frames that missed their targets need few:
#: on the 108 scale outputs of the 9 clips, 2 meet every bar as 6 do (same worst skate 4.5 mm, penetration
#: 2.8 mm and joint jump 1.37x the reference's; 0 steps leave 5.9 mm penetration and 5.1 mm skate). A
#: frame that flipped to another branch needs more to come back (accelerating 09_04 to 1.3x keeps a 20 deg
#: knee jump with 3).
IK_REPAIR_ITERS = 2
IK_UNFLIP_ITERS = IK_ITERS + 2
#: Repair passes of a walk's IK (``correct``'s repair_rounds; a run's: 1). On single frames of the Bandai walk at
#: 30 Hz the fast pass stopped 5-100 mm from held foot targets and one pass left 4-25 mm (a held toe 3.4 mm under
#: the floor one frame, 4 mm up the next); the further passes bring them within the bars (docs/walking.md).
WALK_REPAIR_ROUNDS = 4
#: Posture weight [1/rad²] of the trunk, arms and head (the legs take the solver's default, 1e-4).
UPPER_BODY_POSTURE_WEIGHT = 1e-2
#: Joints IK leaves alone: hands, fingers, mass-less joints and the head and neck (kept from the reference).
IK_FREEZE = "auto+head"
#: A joint changing this much more between two frames than in the reference pose there is a branch flip.
BRANCH_JUMP_DEG = 10.0
#: Frames whose COM error, or the error of a foot marker the IK is asked to hold, exceeds this [m] after
#: the fast pass are solved again, harder.
RETRY_COM_ERROR = 3e-3
RETRY_MARKER_ERROR = 3e-3
#: A foot marker the IK is asked to hold has at least this weight (before the per-size factor); lighter
#: ones only guide a swinging foot and may stay centimetres off (their floor is SWING_MARKER_WEIGHT): that
#: is neither a reason to solve again nor a failure.
HELD_MARKER_WEIGHT = 1.0
#: ... and from this fraction of the output's rest-height bar (``correct``'s rest_bar_m) when that is the
#: smaller: a held marker's error at a stance's lowest point is that stance's rest error, and a small
#: character's bar (0.3 % of L: 1.8 mm for CMU 02_01's child) lies under RETRY_MARKER_ERROR, so a tip left
#: 2.2 mm under its target as the heel rises was never solved again (02_01 child, frame 113: rest 0.375 % L).
REST_BAR_SHARE = 0.5


#: The physics report's stricter skate bar [m] (``report.metrics.BARS["foot_skate_floor_mm"]``; the pipeline
#: passes the report's own, and tests/test_ik.py holds this default to it): the repair judges a held marker's
#: error by it. A value, not an import: the IK sits below the report.
SKATE_BAR_M = 5e-3


def correct(targets: Targets, body: BodyModel, on_failure: str = "flag", repair_rounds: int = 1,
            joint_jump_bar_deg: float = np.inf, skate_bar_m: float = SKATE_BAR_M, rest_bar_m: float = np.inf):
    """§6: whole-body IK toward the machine COM and the foot targets, pulled toward the reference pose.

    All frames are solved together with the solver's fast chord iterations. Then one repair pass solves
    again, with a fresh Jacobian every iteration, the few frames whose COM or held foot markers stayed
    above RETRY_COM_ERROR / RETRY_MARKER_ERROR or that jumped to another branch (a knee flipping near full
    extension), warm-started from the neighbouring frame's solution where they jumped; frames are
    independent problems, so this is the same problem solved harder where needed. repair_rounds - 1 further
    passes (a walk's: WALK_REPAIR_ROUNDS) solve the frames still jumping or missing their targets again from
    two starts and keep the best pose, judged on both neighbours (``_repair_later``). Finally the COM is made
    exact by a root translation. joint_jump_bar_deg [deg]: the output's joint-jump bar (the physics report's,
    1.5 x the clip's largest jump), one of the bars a repaired pose is judged on (``_bar_misses``).
    rest_bar_m [m]: the output's rest-height bar (the physics report's, 0.3 % of L): a held marker is solved
    again from REST_BAR_SHARE of it when that is under RETRY_MARKER_ERROR (``_frames_to_retry``).
    """
    res = _fast_pass(targets, body)
    targets, res = _hold_on_floor(targets, body, res)
    held = _held_markers(targets)
    res = _replace(res, failed=_missed(res, held, DEFAULT_MAX_ERROR))
    assert res.com_error is not None and res.com is not None  # the ComTask is always given
    init_jump = _largest_joint_angle_deg(targets.initial.rotations[1:], targets.initial.rotations[:-1])
    retry_m = min(RETRY_MARKER_ERROR, REST_BAR_SHARE * rest_bar_m)
    res, _ = _repair(res, targets, body, held, init_jump, joint_jump_bar_deg, skate_bar_m, retry_m)
    for _ in range(repair_rounds - 1):
        res, n_bad = _repair_later(res, targets, body, held, init_jump, joint_jump_bar_deg, skate_bar_m, retry_m)
        if not n_bad:
            break
    # Make the COM exact: the remaining sub-millimetre error is removed by a root translation (the COM
    # moves one to one with it), which moves the feet by as little, so the flight parabola is exact.
    shift = targets.com - res.com  # the solver's COM of the solved poses (no second FK)
    res = _replace(res, motion=res.motion.with_(root_positions=res.motion.root_positions + shift),
                   com_error=np.zeros(len(shift)), com=targets.com.copy())
    if on_failure == "raise" and not res.ok:
        f = int(np.flatnonzero(res.failed)[0])
        assert res.com_error is not None  # the ComTask is always given
        raise IkError(f"IK cannot reach its targets at frame {f} (COM error {1000 * res.com_error[f]:.1f} mm)")
    return res


def _repair(res, targets: Targets, body: BodyModel, held: np.ndarray, init_jump: np.ndarray,
            jump_bar: float = np.inf, skate_bar_m: float = SKATE_BAR_M, retry_m: float = RETRY_MARKER_ERROR):
    """One repair pass of ``correct``: the frames whose COM or held foot markers (held (F, 6)) stayed above
    RETRY_COM_ERROR / retry_m [m], or that jumped to another branch (a joint changing more than
    BRANCH_JUMP_DEG more than the reference pose's init_jump (F-1,) [deg]), solved again with a fresh
    Jacobian at every step, warm-started from their own solution (from the previous frame's where they
    jumped); a frame keeps the new pose only where it is better (``_better``): missing the held-marker,
    branch-jump and joint-jump bars (jump_bar [deg]) by less in all, in bar units, or as much but fewer of
    them (``_bar_misses``), then by the smaller jump where it jumped, else by the smaller held error, and
    never further over the joint-jump bar. Returns (result, frames tried)."""
    rot = res.motion.rotations
    bad, flip = _frames_to_retry(res, held, init_jump, retry_m)
    if not bad.size:
        return res, 0
    src = np.where(flip[bad], bad - 1, bad)  # a jumped frame starts from its neighbour's solution
    start = res.motion.with_(root_positions=res.motion.root_positions[src], rotations=rot[src])
    sub = targets.rows(bad)
    again = _solve_from(sub, start, body, IK_UNFLIP_ITERS if flip[bad].any() else IK_REPAIR_ITERS)
    again = _replace(again, failed=_missed(again, held[bad], DEFAULT_MAX_ERROR))
    prev = rot[np.maximum(bad - 1, 0)]
    old_jump = _largest_joint_angle_deg(rot[bad], prev)
    new_jump = _largest_joint_angle_deg(again.motion.rotations, prev)
    limit = np.concatenate([[0.0], init_jump])[bad] + BRANCH_JUMP_DEG  # the reference's jump into each frame
    old_held, new_held = _worst_held(res, held)[bad], _worst_held(again, held[bad])
    # by the bars first (a frame that flipped keeping a pose that misses its held markers by centimetres is
    # worse than one jumping a little more than the limit to meet them), then as before: a flipped frame by
    # the smaller jump, the others by the smaller held error
    old = (*_bar_misses(old_jump, limit, jump_bar, old_held, skate_bar_m), np.where(flip[bad], old_jump, old_held))
    new = (*_bar_misses(new_jump, limit, jump_bar, new_held, skate_bar_m), np.where(flip[bad], new_jump, new_held))
    better = _better(new, old) & (again.com_error <= np.maximum(res.com_error[bad], RETRY_COM_ERROR))
    return _merge_rows(res, bad, again, better), int(bad.size)


def _repair_later(res, targets: Targets, body: BodyModel, held: np.ndarray, init_jump: np.ndarray,
                  jump_bar: float = np.inf, skate_bar_m: float = SKATE_BAR_M, retry_m: float = RETRY_MARKER_ERROR):
    """A further repair pass (a walk's, ``correct``'s repair_rounds): the frames that still jump to another
    branch or miss their COM or held foot markers, each solved from its own pose and from the previous
    frame's. A pose is judged by how far it misses the bars in all, in bar units, then how many
    (``_bar_misses``: its larger jump to either neighbour against the reference pose's there plus
    BRANCH_JUMP_DEG and against the joint-jump bar jump_bar [deg], its worst COM or held-marker error against
    the skate bar skate_bar_m [m]), then by its worst held error, and never taken further over the joint-jump bar
    (``_better``); the frame keeps the best of its old pose and the two new ones. Judged on both sides: the
    first pass compares a jumped frame with the previous one only, and one frame mended that way can jump to
    the next (the Bandai walk child's knee jump moved between 1.2 and 1.8 x the reference's with the number
    of such passes). Returns (result, frames tried)."""
    rot = res.motion.rotations
    F = len(rot)
    bad, _ = _frames_to_retry(res, held, init_jump, retry_m)
    if not bad.size:
        return res, 0
    sub = targets.rows(bad)
    prev, nxt = rot[np.maximum(bad - 1, 0)], rot[np.minimum(bad + 1, F - 1)]
    ref = np.concatenate([[0.0], init_jump, [0.0]])  # the reference pose's jumps into and out of each frame
    limit = np.maximum(ref[bad], ref[bad + 1]) + BRANCH_JUMP_DEG

    # a frame's neighbours as they are (within=False), or, within a run of neighbouring frames solved again,
    # in the poses r gives them (within=True)
    at = np.full(F, -1)
    at[bad] = np.arange(bad.size)
    i_prev, i_next = at[np.maximum(bad - 1, 0)], at[np.minimum(bad + 1, F - 1)]

    def score(r, worst, within=False):  # (``_bar_misses``, worst held error [m]) per frame
        p = np.where((i_prev >= 0)[:, None, None], r[i_prev], prev) if within else prev
        n = np.where((i_next >= 0)[:, None, None], r[i_next], nxt) if within else nxt
        both = np.maximum(_largest_joint_angle_deg(r, p), _largest_joint_angle_deg(r, n))
        return (*_bar_misses(both, limit, jump_bar, worst, skate_bar_m), worst)

    best_rot, best_root = rot[bad].copy(), res.motion.root_positions[bad].copy()
    best_com, best_com_err = res.com[bad].copy(), res.com_error[bad].copy()
    best_failed = res.failed[bad].copy()
    best = score(best_rot, _worst_held(res, held)[bad])
    tried = []
    for src in (bad, np.maximum(bad - 1, 0)):
        start = res.motion.with_(root_positions=res.motion.root_positions[src], rotations=rot[src])
        again = _solve_from(sub, start, body, IK_UNFLIP_ITERS)
        tried.append((again, _worst_held(again, held[bad])))
        s = score(again.motion.rotations, tried[-1][1])
        take = _better(s, best)
        best_rot[take], best_root[take] = again.motion.rotations[take], again.motion.root_positions[take]
        best_com[take], best_com_err[take] = again.com[take], again.com_error[take]
        best_failed[take] = _missed(again, held[bad], DEFAULT_MAX_ERROR)[take]
        best = tuple(np.where(take, a, b) for a, b in zip(s, best))
    # A run of neighbouring frames is also judged as a whole, each frame against its neighbours' new poses:
    # frame by frame, two neighbouring frames that flipped together kept each other flipped (the Bandai walk
    # decelerated to 0.5x at 120 Hz: a knee jump of 20 deg into and 22 deg out of two frames whose new poses
    # met every target and jumped 8 and 7 deg to the frames outside). A run takes the poses of one start
    # where its largest excess jump, then its worst held error, is smaller than the frames' choices give.
    runs = np.split(np.arange(bad.size), np.flatnonzero(np.diff(bad) > 1) + 1)
    for again, worst in tried:
        now = score(best_rot, best[3], within=True)
        s = score(again.motion.rotations, worst, within=True)
        for k in runs:
            if k.size < 2 or not _better(_run_score(s, k), _run_score(now, k)):
                continue
            best_rot[k], best_root[k] = again.motion.rotations[k], again.motion.root_positions[k]
            best_com[k], best_com_err[k] = again.com[k], again.com_error[k]
            best_failed[k] = _missed(again, held[bad], DEFAULT_MAX_ERROR)[k]
            in_k = np.isin(np.arange(bad.size), k)
            best = tuple(np.where(in_k, a, b) for a, b in zip(s, best))
    root, rot = res.motion.root_positions.copy(), rot.copy()
    root[bad], rot[bad] = best_root, best_rot
    com, com_err, failed = res.com.copy(), res.com_error.copy(), res.failed.copy()
    com[bad], com_err[bad], failed[bad] = best_com, best_com_err, best_failed
    res = _replace(res, motion=res.motion.with_(root_positions=root, rotations=rot), com_error=com_err,
                   failed=failed, com=com)
    return res, int(bad.size)


#: A released foot marker (lighter than HELD_MARKER_WEIGHT) that the IK leaves in the floor band
#: (Targets.floor_top) more than RETRY_MARKER_ERROR off its target is held there after all, at this fraction of
#: the stance marker weight, ramped over WEIGHT_RAMP_S either side (see _hold_on_floor); at most
#: FLOOR_HOLD_ROUNDS times (a frame next to a held one may sink in turn).
FLOOR_HOLD_WEIGHT = 0.1
FLOOR_HOLD_ROUNDS = 3
#: A target moving slower than this [m/s] is at rest (a held point turning, not a foot travelling).
FLOOR_TARGET_SPEED = 0.05


def _hold_on_floor(targets: Targets, body: BodyModel, res):
    """(targets, res) with the released foot markers that the IK left sliding on the floor held to their targets.

    A marker's weight falls with its target's height (synthesis.targets._marker_weights), so the loaded
    point is held and the rest of the foot may pivot. But a body whose posture carries its feet lower than the
    reference's (a troll: its heavy trunk sets its COM, and so its hips, lower over the same COM path) drops a
    released toe, its target 0.05 L up after lift-off, back to 0.015 L, where it slides with the swing path
    2-3 mm a frame (run_tired as a troll, 10.8 mm); a folded rig's ball, released 0.05 L up within the floor
    band over its 0.039 L rest height, swings 8-9 mm about the tip in one frame (the same, 120 and 30 Hz).
    Such markers are held to their targets (which rise out of the band or stay put) where the achieved pose,
    not the target, is in the band.
    """
    if targets.floor_top is None:
        return targets, res

    per_size = (targets.com_weight / COM_WEIGHT)[:, None, None]  # (F, 1, 1)
    hold = FLOOR_HOLD_WEIGHT * STANCE_MARKER_WEIGHT * per_size
    dt = targets.initial.frame_time
    offsets = np.arange(-int(np.ceil(WEIGHT_RAMP_S / dt)), int(np.ceil(WEIGHT_RAMP_S / dt)) + 1)
    ramp = min_jerk(1.0 - np.abs(offsets) * dt / WEIGHT_RAMP_S)
    # only toward a target above the band, or one at rest in it: a target that itself slides near the floor
    # is the targets' to fix, and holding the foot to it would make it slide the more
    target_h = targets.markers[..., UP_AXIS]
    above = target_h >= targets.floor_top
    still = _horizontal_speed(targets.markers, dt) <= FLOOR_TARGET_SPEED
    for _ in range(FLOOR_HOLD_ROUNDS):
        achieved = body.foot_markers(res.motion)  # (F, 2, 3, 3) [m]
        released = targets.marker_weight < HELD_MARKER_WEIGHT * per_size
        sunk = target_h - achieved[..., UP_AXIS] > RETRY_MARKER_ERROR  # the posture holds it below its target
        err = np.linalg.norm(achieved - targets.markers, axis=-1)
        slides = (_horizontal_speed(achieved, dt) > FLOOR_TARGET_SPEED) & (err > RETRY_MARKER_ERROR)
        sunk = released & (achieved[..., UP_AXIS] < targets.floor_top) & ((sunk & (above | still)) | (slides & still))
        if not sunk.any():
            break
        # each sunk sample spreads the ramp over its neighbours (a max-filter of sunk with the ramp)
        pad = np.pad(sunk.astype(float), ((len(offsets) // 2,) * 2, (0, 0), (0, 0)))
        want = (np.lib.stride_tricks.sliding_window_view(pad, len(offsets), axis=0) * ramp[::-1]).max(axis=-1)
        weight = np.maximum(targets.marker_weight, hold * want)
        rows = np.flatnonzero(np.any(weight > targets.marker_weight, axis=(1, 2)))
        targets = _replace(targets, marker_weight=weight)
        res = _merge_rows(res, rows, _fast_pass(targets.rows(rows), body))
    return targets, res


def _fast_pass(targets: Targets, body: BodyModel):
    """The IK of every frame of ``targets`` from its reference pose, with the solver's fast chord iterations."""
    tasks = [ComTask(body, targets.com, targets.com_weight),
             MarkerTask.feet(body, targets.markers, targets.marker_weight), PostureTask(weight=posture_weights(body))]
    return solve_ik(targets.initial, tasks, body=body, freeze=IK_FREEZE, on_failure="flag", tol=IK_TOL,
                    max_iters=IK_ITERS)


def _horizontal_speed(markers: np.ndarray, dt: float) -> np.ndarray:
    """(F, 2, 3) [m/s] each marker's horizontal speed from the frame before (0 at the first); markers
    (F, 2, 3, 3) [m], dt [s]."""
    out = np.zeros(markers.shape[:3])
    out[1:] = np.linalg.norm(np.diff(markers[..., HORIZONTAL_AXES], axis=0), axis=-1) / dt
    return out


def _merge_rows(res, rows: np.ndarray, again, take=slice(None)):
    """res with the frames ``rows`` taken from ``again`` (an IkResult of those frames only); with ``take``
    (a mask or index into rows), only the frames rows[take]."""
    rows = rows[take]
    root = res.motion.root_positions.copy()
    rot = res.motion.rotations.copy()
    root[rows], rot[rows] = again.motion.root_positions[take], again.motion.rotations[take]
    out = {"com_error": res.com_error.copy(), "com": res.com.copy(), "failed": res.failed.copy(),
           "marker_error": res.marker_error.copy()}
    for name, v in out.items():
        v[rows] = getattr(again, name)[take]
    return _replace(res, motion=res.motion.with_(root_positions=root, rotations=rot), **out)


def _frames_to_retry(res, held: np.ndarray, init_jump: np.ndarray,
                     retry_m: float = RETRY_MARKER_ERROR) -> tuple[np.ndarray, np.ndarray]:
    """(frame indices, flip (F,) bool) of the frames a repair pass solves again: those whose COM or held
    foot markers (held (F, 6)) are above RETRY_COM_ERROR / retry_m [m], or that jumped to another
    branch (flip: a joint turning more than BRANCH_JUMP_DEG beyond the reference pose's init_jump (F-1,)
    [deg] from the frame before)."""
    rot = res.motion.rotations
    flip = np.zeros(len(rot), bool)
    flip[1:] = _largest_joint_angle_deg(rot[1:], rot[:-1]) > init_jump + BRANCH_JUMP_DEG
    bad = np.flatnonzero(flip | (res.com_error > RETRY_COM_ERROR) | _missed(res, held, retry_m))
    return bad, flip


def _bar_misses(jump_deg: np.ndarray, jump_limit_deg: np.ndarray, jump_bar_deg: float, worst_m: np.ndarray,
                skate_bar_m: float = SKATE_BAR_M):
    """((F,) excess over the joint-jump bar, (F,) excess over all bars, (F,) bars missed) of candidate poses,
    excesses in bar units (a fraction of the bar). Each frame's pose is judged on three bars: its jump
    (jump_deg [deg]) above its branch limit (jump_limit_deg [deg]: the reference pose's jump there plus
    BRANCH_JUMP_DEG); the same jump above the output's joint-jump bar (jump_bar_deg [deg], the physics
    report's: 1.5 x the clip's largest jump); its COM or held foot marker error (worst_m [m],
    ``_worst_held``; non-finite: missed without bound) above the report's skate bar (skate_bar_m [m],
    SKATE_BAR_M = 5 mm: a held marker off its target is what a skate is made of; the repair tries
    frames from RETRY_MARKER_ERROR on, but judges them by the output's bar: at 3 mm, CMU 07_01 slowed to
    0.6x took a 17 deg knee jump (ref 1 deg) to bring a ball 8.5 mm off to 6.5 mm, and its tip slid 8.9 mm).
    None ranks above the others (a branch jump is a joint-jump miss's cause, a held marker off its target a
    skate's): a pose meeting the held markers to half a millimetre with a knee jump 1.8 x its branch limit
    misses by 0.8; one keeping a smaller jump but leaving them 27 mm off (the Bandai walk slowed to 0.5x,
    frame 209: 17.8 mm of skate, kept while the jump ranked first) misses by 4.4. By the total first, then
    the count: a count first took a 26 deg jump (1.2 over its limit) to meet a marker 3.6 mm off, CMU 07_01
    as a giant."""
    worst = np.where(np.isfinite(worst_m), worst_m, np.inf)
    over_jump = np.maximum(jump_deg / jump_limit_deg - 1.0, 0.0)
    over_bar = np.maximum(jump_deg / jump_bar_deg - 1.0, 0.0)
    over_held = np.maximum(worst / skate_bar_m - 1.0, 0.0)
    count = (over_jump > 0).astype(int) + (over_bar > 0) + (over_held > 0)
    return over_bar, over_jump + over_bar + over_held, count


def _better(a: tuple, b: tuple) -> np.ndarray:
    """(F,) bool: candidate key a (``_bar_misses``' excess over the joint-jump bar, total excess, bars
    missed, then tie-breaks) is better than b: below it by the total excess, then the count, then the
    tie-breaks (``_less``), and never further over the output's joint-jump bar. That bar is the report's own,
    measured as the report does; a held marker's error is the repair's estimate of a skate. Without the
    guard the Bandai walk as a troll met a held target 32 mm off at frame 16 by a 49 deg jump, 1.78 x the
    clip's largest (the report's bar: 1.5 x)."""
    return (a[0] <= b[0] + 1e-9) & _less(a[1:], b[1:])


def _less(a: tuple, b: tuple) -> np.ndarray:
    """(F,) bool: key a (a tuple of (F,) arrays, most significant first) is lexicographically below key b
    (the excess terms compared with a 1e-9 slack, so that rounding does not decide)."""
    out = np.zeros(np.shape(a[0]), bool)
    tied = np.ones(np.shape(a[0]), bool)
    for x, y in zip(a, b):
        out |= tied & (x < y - 1e-9)
        tied &= np.abs(x - y) <= 1e-9
    return out


def _run_score(s: tuple, k: np.ndarray) -> tuple:
    """A run of neighbouring frames' key (indices k into the per-frame key s of ``_repair_later``): the bars
    its frames miss and by how much in all, then its worst held error."""
    return (s[0][k].max(keepdims=True), s[1][k].sum(keepdims=True), s[2][k].sum(keepdims=True),
            s[3][k].max(keepdims=True))


def _held_markers(targets: Targets) -> np.ndarray:
    """(F, 6) the foot markers the IK is asked to hold (weight >= HELD_MARKER_WEIGHT, per size)."""
    per_size = targets.com_weight / COM_WEIGHT  # (F,): the weights' (reference / target leg)² factor
    return targets.marker_weight.reshape(len(per_size), -1) >= HELD_MARKER_WEIGHT * per_size[:, None]


def _largest_joint_angle_deg(q0: np.ndarray, q1: np.ndarray) -> np.ndarray:
    """(F,) the largest rotation of any joint between two poses per frame [deg], rotations (F, J, 4) each:
    2 acos of the smallest |q0 · q1| (acos falls, so one acos per frame instead of one per joint)."""
    dot = np.abs(np.einsum("fjc,fjc->fj", q0, q1)).min(axis=1)
    return np.degrees(2.0 * np.arccos(np.minimum(dot, 1.0)))


def _worst_held(res, held: np.ndarray) -> np.ndarray:
    """(F,) the largest of the COM error and the held foot markers' errors [m]."""
    return np.maximum(res.com_error, np.where(held, res.marker_error, 0.0).max(axis=1))


def _missed(res, held: np.ndarray, limit: float) -> np.ndarray:
    """(F,) frames whose COM or a held foot marker (held (F, 6)) is more than ``limit`` [m] off its target
    (NaN-safe: a non-finite error misses)."""
    return ~(res.com_error <= limit) | np.any(held & ~(res.marker_error <= limit), axis=1)


def posture_weights(body: BodyModel) -> np.ndarray:
    """(J,) posture weights [1/rad²]: the legs free to meet the feet, the upper body held to the reference.

    The COM is finally placed by the root (see ``correct``), so the trunk, arms and head need not bend to
    move it: they keep the reference's motion (UPPER_BODY_POSTURE_WEIGHT), the legs take the solver's
    default.
    """
    skel = body.skeleton
    w = np.full(skel.n_joints, DEFAULT_JOINT_WEIGHT)
    legs = set()
    for side in ("left", "right"):
        stack = [body.roles[f"{side}_hip"]]
        while stack:
            j = stack.pop()
            legs.add(j)
            stack.extend(skel.children(j))
    for j in range(1, skel.n_joints):
        if j not in legs:
            w[j] = UPPER_BODY_POSTURE_WEIGHT
    return w


def _solve_from(t: Targets, start: Motion, body: BodyModel, max_iters: int):
    """IK of some frames warm-started from ``start`` while still pulled toward the targets' reference pose,
    re-linearised at every one of at most ``max_iters`` steps."""
    tasks = [ComTask(body, t.com, t.com_weight), MarkerTask.feet(body, t.markers, t.marker_weight),
             PostureTask(weight=posture_weights(body), reference=t.initial), RootTask(reference=t.initial)]
    return solve_ik(start, tasks, body=body, freeze=IK_FREEZE, on_failure="flag", tol=IK_TOL,
                    max_iters=max_iters, refresh_jacobian=True)


def tile_stride(one: Motion, stride_period: float, dense_fps: float, targets: Targets, path_times: np.ndarray,
                stride: np.ndarray, body: BodyModel) -> Motion:
    """A steady output's poses from the IK of one stride, tiled (see ``pipeline.finish``).

    The steady cycle is periodic: stride n of the output is stride 0 translated by n stride lengths (COM,
    contacts, foot targets and the time-warped reference pose all repeat). So the IK is solved once, for one
    stride sampled several times finer than the output (``one``, at ``dense_fps`` [Hz]), and each output
    frame (``path_times`` (T,) [s]) takes the pose at its time modulo the stride (``stride_period`` [s];
    root interpolated linearly, rotations by nlerp between samples a few milliseconds apart) plus its
    stride's translation ``stride`` (3,) [m]; finally the COM is made exact by a root translation, as in
    ``correct``. The work is then that of one stride whatever the length, which is what makes long outputs
    (an hour of running) cheap in time and memory.
    """
    stride = stride.copy()
    stride[UP_AXIS] = 0.0
    n, i0, w = stride_samples(path_times, stride_period, dense_fps, one.n_frames)
    root = one.root_positions[i0] * (1 - w[:, None]) + one.root_positions[i0 + 1] * w[:, None] + n[:, None] * stride
    rot = nlerp_rows(one.rotations, i0, i0 + 1, w)
    motion = targets.initial.with_(root_positions=root, rotations=rot)
    return motion.with_(root_positions=root + (targets.com - body.com(motion)))


def stride_samples(path_times: np.ndarray, stride_period: float, dense_fps: float, n_dense: int):
    """Where each output time falls in one stride sampled at dense_fps [Hz] (n_dense samples from 0): (n (T,)
    the stride it is in, i0 (T,) the dense sample before it, w (T,) the weight of the sample after);
    path_times (T,) [s], stride_period [s]."""
    n = np.floor(path_times / stride_period + 1e-9)
    x = (path_times - n * stride_period) * dense_fps  # fractional dense sample
    i0 = np.clip(np.floor(x).astype(int), 0, n_dense - 2)
    return n, i0, x - i0
