"""IK targets (§6): the time-warped reference pose on the target skeleton, the machine's COM and the foot
marker targets with their weights (loaded markers held, swinging feet only guided).
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..body.characters import Retarget
from ..body.footing import SKATE_BAND_L, SKATE_MARKERS, SKATE_REACH_L
from ..body.model import BodyModel
from ..core.constants import UP_AXIS
from ..core.motion import Motion
from .cycle import ReferenceCycle, sample_cycle
from .feet import min_jerk, swing_anchor
from .timewarp import MachinePath

#: IK weights [1/m²] for a reference-sized body (scaled by (reference leg / target leg)² for others);
#: posture pulls at 1e-4 per rad² (the solver's default). The COM is held hardest: it carries the physics
#: (flight gravity needs it to well under a millimetre); loaded foot markers next; swing feet only guide.
COM_WEIGHT = 1e4
STANCE_MARKER_WEIGHT = 1e3
SWING_MARKER_WEIGHT = 1e-2
#: Time [s] over which a foot's marker weight ramps between swing and stance around its events.
WEIGHT_RAMP_S = 0.04
#: Fraction of the stance marker weight every marker of a foot keeps around its contact (see _marker_weights).
LANDING_WEIGHT = 0.1
#: Fraction of SWING_MARKER_WEIGHT a foot marker target out of the leg's reach keeps (see build_targets).
OUT_OF_REACH_SWING = 0.1
#: Half-width [s] of the window over which a marker's lowest target sets its floor band (_floor_top): about
#: a stance and the skate measure's margins on one side.
FLOOR_WINDOW_S = 0.3


@dataclass(frozen=True, eq=False)
class Targets:
    """Initial motion (reference angles, root from the machine COM) and the IK targets and weights."""

    initial: Motion
    com: np.ndarray  # (T, 3) [m]
    markers: np.ndarray  # (T, 2, 3, 3) [m]
    marker_weight: np.ndarray  # (T, 2, 3)
    com_weight: np.ndarray  # (T,)
    #: (T, 2, 3) [m] height below which a foot marker is on or just above the floor, where it must not slide
    #: (the report's stricter skate band about the marker's nearby lowest target); -inf for the markers the
    #: report does not watch there. None: no such band (the IK's repair then leaves released markers alone).
    floor_top: np.ndarray | None = None

    def rows(self, idx: np.ndarray) -> Targets:
        """The targets of some frames (idx: frame indices or a mask)."""
        return Targets(self.initial.with_(root_positions=self.initial.root_positions[idx],
                                          rotations=self.initial.rotations[idx]),
                       self.com[idx], self.markers[idx], self.marker_weight[idx], self.com_weight[idx],
                       None if self.floor_top is None else self.floor_top[idx])


def posture_com_offset(cyc: ReferenceCycle, reference_body: BodyModel, retarget: Retarget) -> np.ndarray:
    """(3,) [m, world]: where the character carries its COM relative to its hips, minus where the reference
    carries its own, scaled by L; the mean over the reference cycle's poses (both bodies in the same poses).

    The machine's COM path is the reference's scaled by L. A body of other proportions carries its COM
    elsewhere over its hips: the troll's heavy trunk and arms 0.13 L above them, the child's large head 0.10 L,
    the reference's 0.05 L (the Bandai walk). Put on the machine's path as it is, such a body walks with its hips
    0.06-0.09 L lower than the reference's, scaled: knees bent 20 deg more through every stance, and at the end
    of a stance the IK reached the COM only by turning the pelvis and the swing knee in one frame (a 46 deg knee
    jump, the Bandai walks as a troll). Carried higher by this offset, the character's hips travel where the
    reference's travel, scaled, and so do its legs. A constant offset changes no force (the machine's dynamics
    hold for any constant shift of its COM path); 0 for a uniformly scaled body.
    """

    def com_from_hips(body: BodyModel) -> np.ndarray:
        pose = Motion(body.skeleton, np.zeros((cyc.n_samples, 3)), cyc.rotations, 1.0, None, {})
        hips = body.joint_positions(pose, [body.roles["left_hip"], body.roles["right_hip"]]).mean(axis=1)
        return (body.com(pose) - hips).mean(axis=0)

    return com_from_hips(retarget.body) - retarget.L * com_from_hips(reference_body)


def build_targets(cyc: ReferenceCycle, path: MachinePath, retarget: Retarget, reference_body: BodyModel,
                  meta: dict) -> Targets:
    """Time-warp the reference cycle onto the machine's steps and set the COM and foot targets.

    reference_body: the clip's (weights are per (leg length)²; the COM target is the machine's path as the
    character's posture carries it, posture_com_offset); meta: the output's provenance (source, length_scale).
    """
    L = retarget.L
    com = path.com + posture_com_offset(cyc, reference_body, retarget)  # (T, 3) [m]
    Rh = path.frame
    phi = np.mod(path.psi, 1.0)
    rot, data = sample_cycle(cyc, phi)
    T = len(path.times)
    anchors, w_ground, swings = _foot_anchors(path)
    rel_world = np.einsum("fpki,ij->fpkj", L * data["marker_rel"], Rh)  # heading frame -> world
    on_ground = anchors[:, :, None, :] + rel_world
    # In mid-swing the foot moves with the body (its offset from the COM, scaled), not along a stretched
    # ground path: a stretched path would leave the trailing foot out of the leg's reach after toe-off
    # when running faster. Near toe-off and touchdown the ground-anchored path takes over.
    com_rel = L * data["marker_from_com"]
    com_rel[..., 1] = L * data["marker_rel"][..., 1]  # heights above the ground as in the anchored path
    with_body = path.com[:, None, None, :] + np.einsum("fpki,ij->fpkj", com_rel, Rh)
    # ... and meets the ground path where the foot is near the floor (_body_path_correction). A walk needs it
    # as a run does: slowed down, its machine carries the COM over the contact other than the reference did,
    # and walk_elderly_005 accelerated to 0.7x put its toe 60 mm behind the lift-off point one 30 Hz frame
    # after it (a 22 mm skate). (It was once left out of walks because it moved a giant's double support; the
    # cause was the reference anchors' event timing, ``feet.foot_anchors(subframe=True)``.)
    with_body += _body_path_correction(cyc, path, L, swings, on_ground[..., UP_AXIS].min(axis=2),
                                       retarget.body.leg_length)
    # In mid-swing the foot keeps at least its reference height below the COM: a machine whose COM flies
    # higher than the reference's at that phase (a faster cycle: shorter stance, longer flight) would
    # otherwise leave the swinging foot at the reference's height above the ground, out of the leg's reach,
    # and the IK straightens the knee and flips it (a 60-70 deg pop at x1.5).
    below_com = path.com[:, None, None, UP_AXIS] + L * (data["marker_from_com"][..., 1]
                                                        - data["com_height"][:, None, None])
    with_body[..., UP_AXIS] = np.maximum(on_ground[..., UP_AXIS], below_com)
    w = w_ground[:, :, None, None]
    markers = w * on_ground + (1.0 - w) * with_body
    initial = _initial_pose(retarget, path.com + (L * data["root_from_com"]) @ Rh, rot, com, path, meta)
    body = retarget.body
    hips = body.joint_positions(initial, [body.roles["left_hip"], body.roles["right_hip"]])  # (T, 2, 3) [m]
    # A walk's landing foot is raised only beyond the time-warped reference pose's own foot: a walking leg
    # lands almost straight, within the run's margins of its reach, and raised there (the Bandai walk scaled
    # to itself: its toe 15-23 mm up at every touchdown) the feet landed 0.5-0.9 frames late at 30 Hz
    markers = within_reach(initial, markers, body, path.frame[0], cyc.order == "walking", hips)
    # Each foot's lowest point rests on the ground at 0 until here (the cycle's heights are above each stance's
    # own lowest point, the thresholds below are tuned so), its markers where the clip's rest above that point
    rest = cyc.rest_heights
    foot_low = np.zeros(2) if rest is None else np.where(np.isfinite(rest).all(axis=1), np.nanmin(rest, axis=1), 0.0)
    if rest is not None:
        markers = _rest_on_floor(markers, path, L * (rest - foot_low[:, None]), toe_bone=cyc.order != "walking")
    reach = _reach_factor(hips, body, markers)
    weight = _marker_weights(path, markers, body.leg_length, fade=cyc.order != "walking",
                             frame_time=float(path.frame_time)) * reach
    # A swinging foot's target beyond the leg's reach keeps only OUT_OF_REACH_SWING of the swing weight: the
    # trailing foot's ground path after an acceleration's longer stance lies 1.2 L from the hip, and at the
    # full swing weight it dragged the pelvis 26 deg off the reference pose, which sprang back in one frame
    # when the path let go (a 20 deg hip jump, 09_04 accelerated to 1.3x). Not nothing: a foot left with no
    # target at all may land anywhere the posture puts it (a toe 0.2 m off at lift-off, 09_01 at 1.3x).
    weight = np.maximum(weight, SWING_MARKER_WEIGHT * (OUT_OF_REACH_SWING + (1.0 - OUT_OF_REACH_SWING) * reach))
    if cyc.order == "walking":  # a walking foot lands and leaves with a straight knee: guide it there
        from .walking import soften_swing_weights  # lazy: a run's scale never loads the walking machine

        weight = soften_swing_weights(path, weight, SWING_MARKER_WEIGHT)
    # Weights are per (leg length)^2, so the trade-off between a position error and a joint angle is the
    # same for a child and a giant (errors in metres grow with size, joint angles do not).
    per_size = (reference_body.leg_length / retarget.body.leg_length) ** 2
    floor_top = _floor_top(markers, retarget.body.leg_length, float(path.frame_time))
    # ... and then each foot where the clip's rests relative to the ground level (one foot's lowest point may
    # rest higher than the other's: CMU 09_01's left toe end site 11 mm above the right's)
    markers = markers.copy()
    markers[..., UP_AXIS] += L * foot_low[None, :, None]
    floor_top = floor_top + L * foot_low[None, :, None]
    return Targets(initial, com, markers, weight * per_size, np.full(T, COM_WEIGHT * per_size), floor_top)


def _initial_pose(retarget: Retarget, root: np.ndarray, rot: np.ndarray, com: np.ndarray, path: MachinePath,
                  meta: dict) -> Motion:
    """The time-warped reference pose (rot (T, J, 4)) on the character, its COM on the COM target com (T, 3) [m].

    root (T, 3) [m]: the reference's root-to-COM offset × L from the machine's COM, where the root goes for a
    body of the reference's proportions. A character with other proportions (a troll's trunk) carries its COM
    elsewhere relative to the root, and when the root is a static reference joint far from the pelvis (the
    Bandai rig's joint_Root, metres from the body through the pelvis offset) the error is metres: the IK would
    start with the feet out of reach. So the pose is translated to put its own COM on the target.
    """
    initial = Motion(retarget.skeleton, root, rot, float(path.frame_time), None, dict(meta))
    return initial.with_(root_positions=root + (com - retarget.body.com(initial)))


def _floor_top(markers: np.ndarray, leg_length: float, frame_time: float) -> np.ndarray:
    """(T, 2, 3) [m]: Targets.floor_top. markers (T, 2, 3, 3) targets [m] (ground at 0); leg_length [m].

    As the physics report's stricter skate measure (metrics.foot_skate_floor_mm) sees it: the ball and the tip
    (SKATE_MARKERS), within SKATE_BAND_L × L of their lowest height about a contact (here the lowest target
    within a stance and its margins, FLOOR_WINDOW_S either side), when that lowest height is within
    SKATE_REACH_L × L of the floor (``body.footing``).
    """
    out = np.full(markers.shape[:3], -np.inf)
    half = max(1, int(round(FLOOR_WINDOW_S / frame_time)))
    for k in SKATE_MARKERS:
        h = np.pad(markers[:, :, k, UP_AXIS], ((half, half), (0, 0)), mode="edge")
        low = np.lib.stride_tricks.sliding_window_view(h, 2 * half + 1, axis=0).min(axis=-1)  # (T, 2)
        out[:, :, k] = np.where(low <= SKATE_REACH_L * leg_length, low + SKATE_BAND_L * leg_length, -np.inf)
    return out


#: Margin [s] about each contact within which a foot marker's lowest target is its rest (_rest_on_floor): as
#: the physics report's (metrics.SKATE_MARGIN_S), so a toe tip lowest at push-off counts.
REST_MARGIN_S = 0.1


def _rest_on_floor(markers: np.ndarray, path: MachinePath, rest: np.ndarray, toe_bone: bool = True) -> np.ndarray:
    """markers (T, 2, 3, 3) [m] with each foot's markers resting at ``rest`` (2, 3) [m] (the clip's, × L, above
    the ground at 0) in every contact: each marker's lowest target about the contact (REST_MARGIN_S either
    side, not past the middle of the swings) moved there, the whole contact by as much, the change fading
    out (min-jerk) from the margin to the middle of the swings. A contact cut by the output's edges is left
    as it is (its lowest point may lie beyond them: a walk's last contact, pulled down by a swinging foot's
    height, dragged the foot along the floor).

    The reference cycle averages the clip's stances at each phase (a low point reached at different phases
    is raised: the mean of dips stays above them), its de-skating tilts a steep toe bone about its held end
    (a folded rig's ball over its toe tip: 14 mm down on one foot of dataset-2_run_masculine_005), and the
    time warp samples the cycle at other phases than the clip's frames: without this one foot rested up to
    1 % of L above or below the clip's, scaled. NaN rest heights (a foot without a whole stance) change
    nothing.
    """
    out = markers.copy()
    t = path.times
    for foot in range(2):
        cols = np.flatnonzero(path.foot_of_step == foot)
        if cols.size == 0 or not np.isfinite(rest[foot]).all():
            continue
        spans: list[tuple[float, float, float, float]] = []
        changes: dict[int, np.ndarray] = {}
        visible: list[np.ndarray] = []
        for on, off, lo, a, b, hi in _rest_windows(path, cols):
            if on < t[0] or off > t[-1]:
                continue  # cut by the output's edge (or a virtual contact beyond it): its lowest point unseen
            inside = (t >= a) & (t <= b)
            whole = a >= t[0] - 1e-9 and b <= t[-1] + 1e-9
            if whole:
                changes[len(spans)] = rest[foot] - markers[inside, foot, :, UP_AXIS].min(axis=0)  # (3,)
            visible.append(rest[foot] - markers[inside, foot, :, UP_AXIS].min(axis=0))
            spans.append((lo, a, b, hi))
        # A contact whose margin the output's edges cut (its toe's lowest point, at push-off, may lie beyond
        # them: CMU 09_06 as a giant ends 0.07 s after a lift-off, and that contact's tip, lowered by its
        # highest visible point, slid 6.5 mm) takes the change of the same foot's nearest whole contact: the
        # cycle is periodic, so consecutive contacts of one foot rest alike. Without a whole contact (the one
        # stride a long output is solved on and tiled) each is moved by what it shows.
        for j, (lo, a, b, hi) in enumerate(spans):
            change = changes[min(changes, key=lambda w: abs(w - j))] if changes else visible[j]
            w = np.where(t < a, min_jerk((t - lo) / max(a - lo, 1e-9)),
                         np.where(t > b, min_jerk((hi - t) / max(hi - b, 1e-9)), 1.0))
            w = np.where((t < lo) | (t > hi), 0.0, w)
            out[:, foot, :, UP_AXIS] += w[:, None] * change[None, :]
        if toe_bone:
            # Each marker is moved up or down by its own change, so the toe bone (ball to tip) would stretch:
            # the higher of the two is put back at the bone's length from the lower, on which the toes pivot,
            # horizontally along the foot (the toes pitched about the resting point, as they are, instead of
            # asking for a longer toe: the IK met the tip and left the ball 4 mm ahead of its held target, and
            # it swung 6 mm forward at lift-off, dash_normal_001 as a giant). Not the ankle: its bone to the ball
            # is steep, and put back so it moved 10-20 mm horizontally for a few mm of height (CMU 09_05 and
            # 09_06 as giants: their held heels turned the feet, the stricter skate 11-43 mm). Not in a walk
            # (toe_bone False): CMU 07_01 as a troll, its stricter skate 2.84 mm without, 8.18 mm with (its foot
            # rolls over one pivot at a time, feet.remove_sliding_rolling, ball and tip pass each other's height
            # and which of them is put back switches there: the likely cause, not yet shown)
            bone = np.linalg.norm(markers[:, foot, 1] - markers[:, foot, 2], axis=-1)  # (T,) [m]
            tip_low = (out[:, foot, 2, UP_AXIS] <= out[:, foot, 1, UP_AXIS])[:, None]  # the lower one holds
            ball = _at_bone_length(out[:, foot, 2], out[:, foot, 1], bone)
            tip = _at_bone_length(out[:, foot, 1], out[:, foot, 2], bone)
            out[:, foot, 1] = np.where(tip_low, ball, out[:, foot, 1])
            out[:, foot, 2] = np.where(tip_low, out[:, foot, 2], tip)
        # In a run the ankle moves as the ball does (after the toe bone's correction above), so the foot bone
        # (ankle to ball) keeps its length: moved by its own rest change, the ankle's target sat up to 5 mm
        # off the one the held ball and tip allow (CMU 09_05 as a giant: the IK's repair traded the two frame
        # by frame and the ball jittered 5 mm sideways on the floor, stricter skate 5.42 mm; main 1.15). The
        # ankle's rest is the foot's posture over the point it rests on, which the report shows and does not
        # bar (rest_height_error). Not in a walk, whose foot rolls heel to toe: CMU 07_01 slowed to 0.6x, its
        # stricter skate 4.68 -> 6.24 mm with it.
        if toe_bone:
            out[:, foot, 0] = markers[:, foot, 0] + (out[:, foot, 1] - markers[:, foot, 1])
    return out


def _rest_windows(path: MachinePath, cols: np.ndarray) -> list[tuple[float, float, float, float, float, float]]:
    """Per contact of one foot (its steps ``cols``, with _contacts_extended's virtual contact either side):
    (on, off, lo, a, b, hi) [s]: the contact, the window [a, b] about it in which a marker's lowest target is
    its rest (REST_MARGIN_S either side, as the physics report's skate windows, so a toe tip lowest at
    push-off counts) and the span [lo, hi] it reaches, to the middle of the swings either side."""
    on, off = _contacts_extended(path, cols)
    out = []
    for i in range(len(on)):
        lo = 0.5 * (off[i - 1] + on[i]) if i > 0 else on[i] - (off[i] - on[i])
        hi = 0.5 * (off[i] + on[i + 1]) if i + 1 < len(on) else off[i] + (off[i] - on[i])
        a, b = max(lo, on[i] - REST_MARGIN_S), min(hi, off[i] + REST_MARGIN_S)
        out.append((float(on[i]), float(off[i]), float(lo), float(a), float(b), float(hi)))
    return out


def _contact_lows(path: MachinePath, height: np.ndarray) -> np.ndarray:
    """(T, 2, 3) [m] each foot marker's lowest target height in the rest window of the contact a frame
    belongs to (_rest_windows), NaN in frames of no whole window inside the output (a contact cut by its
    edges shows no rest). height: (T, 2, 3) [m] the targets'."""
    t = path.times
    out = np.full(height.shape, np.nan)
    for foot in range(2):
        cols = np.flatnonzero(path.foot_of_step == foot)
        if cols.size == 0:
            continue
        for _, _, _, a, b, _ in _rest_windows(path, cols):
            inside = (t >= a) & (t <= b)
            if a >= t[0] and b <= t[-1] and inside.any():
                out[inside, foot] = height[inside, foot].min(axis=0)
    return out


def _at_bone_length(fixed: np.ndarray, moved: np.ndarray, length: np.ndarray) -> np.ndarray:
    """(T, 3) [m] ``moved`` shifted horizontally, away from or toward ``fixed`` (T, 3) [m] along their
    horizontal line, to ``length`` (T,) [m] from it at its own height (unchanged where it cannot be)."""
    v = moved - fixed
    horizontal = [a for a in range(3) if a != UP_AXIS]
    flat = np.linalg.norm(v[:, horizontal], axis=-1)
    want = np.sqrt(np.maximum(length**2 - v[:, UP_AXIS] ** 2, 0.0))
    ok = (flat > 1e-6) & (length > np.abs(v[:, UP_AXIS]))
    out = moved.copy()
    along = fixed[:, horizontal] + v[:, horizontal] * (want / np.maximum(flat, 1e-9))[:, None]
    out[:, horizontal] = np.where(ok[:, None], along, moved[:, horizontal])
    return out


def _leg_reach(body: BodyModel, side: str) -> np.ndarray:
    """(3,) straight-leg distances [m] from the hip to the ankle, the ball and the tip of one foot."""
    r, rest = body.roles, body.skeleton.rest_positions()
    leg = np.linalg.norm(rest[r[f"{side}_knee"]] - rest[r[f"{side}_hip"]]) + np.linalg.norm(
        rest[r[f"{side}_ankle"]] - rest[r[f"{side}_knee"]])
    ankle_toe = np.linalg.norm(rest[r[f"{side}_toe"]] - rest[r[f"{side}_ankle"]])
    toe_end = np.linalg.norm(body.marker_local[0 if side == "left" else 1, 2])
    return np.array([leg, leg + ankle_toe, leg + ankle_toe + toe_end])


#: A foot marker target farther from the hip than its straight-leg reach less LIFT_AT_MARGINS margins of
#: REACH_MARGIN_L × L is raised until it is not (see _lift_out_of_reach) ...
LIFT_AT_MARGINS = 2.0
REACH_MARGIN_L = 0.03
#: ... by at most about this fraction of L (a soft cap: the rise needed grows without bound as the
#: horizontal distance nears the reach; beyond the cap the target stays out of reach and _reach_factor lets
#: it go, by then above the floor band in which the physics report watches it slide).
LIFT_MAX_L = 0.05
#: Horizontal sweep [× L] a raised ball may make by turning about the tip before the tip rises with it
#: (_lift_out_of_reach): under the 5 mm skate bar up to L = 2.5 m.
TOE_SWEEP_L = 0.002
#: Softness [× L] of the limit to which an out-of-reach swing target is drawn in (_lift_out_of_reach).
SWING_SOFT_L = 0.01


def _lift_out_of_reach(hips: np.ndarray, body: BodyModel, markers: np.ndarray,
                       own: np.ndarray | None = None, forward: np.ndarray | None = None) -> np.ndarray:
    """markers (T, 2, 3, 3) [m] with every target beyond the leg's reach raised straight up until it is
    within it (hips (T, 2, 3) [m] of the initial pose; reach from _leg_reach less LIFT_AT_MARGINS margins;
    soft cap LIFT_MAX_L × L). own (T, 2, 3, 3) [m], forward (3,) or (T, 3): the initial pose's own foot
    markers and the heading (per frame on a bent path), if given (a walk): a target ahead of the hip no
    farther from it than the pose's own marker is within reach, the pose reaching it. Not behind the hip:
    there a walking foot pushes off, and raising it as the leg straightens lifts its ball clear of the floor
    (CMU 07_01's giant: a ball 63 mm up, rising about the tip, slid 10 mm in the report's floor band in its
    first frames without it).

    When the body has travelled farther over a planted foot than the leg allows (an acceleration's longer
    stance, a faster run), holding the foot's points where they are ends with the knee locked and the IK
    failing, and releasing them lets the posture swing the toe sideways while it is still on the floor (a
    10-15 mm scuff at lift-off, 09_01 accelerated to 1.3x). Raising them instead is what a foot does at
    toe-off: the heel, then the ball and the tip rise where they stand, so they leave the floor without
    sliding. A target whose horizontal distance alone is out of reach is raised by the cap and released by
    _reach_factor.
    """
    out = markers.copy()
    margin = REACH_MARGIN_L * body.leg_length
    cap = LIFT_MAX_L * body.leg_length
    horizontal = [a for a in range(3) if a != UP_AXIS]
    for i, side in enumerate(("left", "right")):
        reach = _leg_reach(body, side) - LIFT_AT_MARGINS * margin  # (3,)
        rel = markers[:, i] - hips[:, i, None, :]  # (T, 3, 3)
        flat = np.linalg.norm(rel[..., horizontal], axis=-1)  # (T, 3)
        lift_reach = np.broadcast_to(reach[None, :], flat.shape)  # (T, 3)
        if own is not None and forward is not None:
            own_d = np.linalg.norm(own[:, i] - hips[:, i, None, :], axis=-1)  # (T, 3)
            ahead = np.einsum("tkj,tj->tk", rel, np.broadcast_to(forward, (rel.shape[0], 3))) > 0.0
            lift_reach = np.where(ahead, np.maximum(lift_reach, own_d), lift_reach)
        lowest = -np.sqrt(np.maximum(lift_reach**2 - flat**2, 0.0))  # lowest reachable height below the hip
        need = np.where(flat < lift_reach, lowest - rel[..., UP_AXIS], np.inf)  # (T, 3) rise needed [m]
        rise = cap * np.tanh(np.maximum(need, 0.0) / cap)  # (T, 3)
        # The tip rises with the ball beyond what the ball can rise by turning about it: a raised ball whose
        # weight fades leaves the IK to turn the foot about the held tip, and a folded rig's ball joint, 30 deg
        # above the tip, swept 7-13 mm forward on that arc within the report's floor band (dash_normal)
        free = _ball_rise_about_tip(markers[:, i], TOE_SWEEP_L * body.leg_length)
        rise[:, 2] = np.maximum(rise[:, 2], rise[:, 1] - free)
        out[:, i, :, UP_AXIS] += rise
        # A target off the floor (a swinging foot) that is still out of reach is drawn in toward the hip
        # (a soft minimum of its distance and the reach): a faster run's swing targets reach 0.94 L from
        # the hip, and a leg straightened after them flips its knee from frame to frame (x1.7).
        rel = out[:, i] - hips[:, i, None, :]
        d = np.linalg.norm(rel, axis=-1)  # (T, 3)
        soft = SWING_SOFT_L * body.leg_length
        d_in = reach[None, :] - soft * np.logaddexp(0.0, (reach[None, :] - d) / soft)
        # only for a foot wholly off the floor (its lowest target 2-4 caps up): near a contact the stance
        # weights and the lift above decide, and drawing in a raised heel at lift-off turns the toes
        lowest_target = out[:, i, :, UP_AXIS].min(axis=1, keepdims=True)  # (T, 1)
        off_floor = min_jerk((lowest_target - 2.0 * cap) / (2.0 * cap))
        scale = 1.0 + off_floor * (np.minimum(d_in / np.maximum(d, 1e-9), 1.0) - 1.0)
        out[:, i] = hips[:, i, None, :] + rel * scale[..., None]
    return out


def within_reach(initial: Motion, markers: np.ndarray, body: BodyModel, forward: np.ndarray, walking: bool,
                 hips: np.ndarray | None = None) -> np.ndarray:
    """markers (T, 2, 3, 3) [m] with every foot target beyond the leg's reach of the pose ``initial`` raised
    (``_lift_out_of_reach``; forward (3,) or (T, 3): the heading, per frame on a bent path; walking: a walk's
    rule ahead of the hip, against the pose's own feet; hips (T, 2, 3) [m]: the pose's, when already known).

    ``build_targets`` does this on the straight output. A turning take's targets are then bent onto its path
    (``synthesis.bend``), which moves each foot along the curve and sideways by the lean, so the bend does it
    again on what it made: bent as they were built, a giant's two feet in a double support of
    walk-turn-right_feminine_001 were 1.60 and 1.57 m from its hips for a 1.61 m leg, the IK met neither
    (a held tip 14 mm off its target, the report's skate), and 8 of the 12 walk-turns' giants missed a bar."""
    if hips is None:
        hips = body.joint_positions(initial, [body.roles["left_hip"], body.roles["right_hip"]])
    own = body.foot_markers(initial) if walking else None
    return _lift_out_of_reach(hips, body, markers, own, forward)


def _ball_rise_about_tip(foot: np.ndarray, sweep: float) -> np.ndarray:
    """(T,) how far [m] the ball can rise by turning about the tip (the toes' bone rigid) before it has moved
    ``sweep`` [m] horizontally. foot: (T, 3, 3) one foot's marker targets (ankle, ball, tip) [m].

    The ball moves on a circle about the tip: from an angle θ0 above the tip's level, rising to θ1 moves it
    d (cos θ0 − cos θ1) horizontally. Level with the tip (a CMU foot) it rises 0.26 d for 2 % of d; a folded
    rig's ball joint, 30 deg above its tip, only 0.05 d.
    """
    bt = foot[:, 1] - foot[:, 2]
    d = np.maximum(np.linalg.norm(bt, axis=-1), 1e-9)
    s0 = np.clip(bt[:, UP_AXIS] / d, -1.0, 1.0)
    c_min = np.sqrt(1.0 - s0**2) - sweep / d
    s1 = np.where(c_min > 0.0, np.sqrt(np.maximum(1.0 - c_min**2, 0.0)), 1.0)
    return d * np.maximum(s1 - s0, 0.0)


def _reach_factor(hips: np.ndarray, body: BodyModel, markers: np.ndarray) -> np.ndarray:
    """(T, 2, 3) in [0, 1]: 1 where a marker target is within the leg's reach from the hip (hips (T, 2, 3)
    [m]), fading to 0 as it approaches the straight-leg limit (_leg_reach: thigh + shank + the foot's bones to
    that marker), so an unreachable target is released instead of wrenching the body (the foot simply leaves
    a little early).
    """
    out = np.ones(markers.shape[:3])
    margin = 0.03 * body.leg_length
    for i, side in enumerate(("left", "right")):
        reach = _leg_reach(body, side) - 0.5 * margin
        d = np.linalg.norm(markers[:, i] - hips[:, i, None, :], axis=-1)  # (T, 3)
        out[:, i] = min_jerk((reach[None, :] - d) / margin)
    return out


#: Fractions of a swing over which the foot target blends from the ground-anchored path to the
#: body-relative one after toe-off (quickly: the leg is nearly straight at toe-off and cannot trail a
#: ground path that a faster body leaves behind) and back before touchdown (slowly, to land on the contact).
SWING_RELEASE = 0.05
SWING_LANDING = 0.35


@dataclass(frozen=True, eq=False)
class Swings:
    """The swing each frame of each foot is in (_foot_anchors): its lift-off and touchdown times t_off, t_on
    (T, 2) [s], the contact points left and reached c_off, c_on (T, 2, 3) [m] and the progress u (T, 2) in
    stride phase from 0 at lift-off to 1 at touchdown; NaN where the foot is on the ground."""

    t_off: np.ndarray
    t_on: np.ndarray
    c_off: np.ndarray
    c_on: np.ndarray
    u: np.ndarray


def _foot_anchors(path: MachinePath) -> tuple[np.ndarray, np.ndarray, Swings]:
    """Each foot's anchor (T, 2, 3): its contact point on the ground, a min-jerk blend between contacts in
    swing; the weight (T, 2) of the ground-anchored foot path (1 on the ground and at the ends of a swing,
    0 in mid-swing, min-jerk in between); and the swing of each frame (Swings)."""
    T = len(path.times)
    t = path.times
    out = np.zeros((T, 2, 3))
    w_ground = np.ones((T, 2))
    sw_t = np.full((2, T, 2), np.nan)  # (off, on) times
    sw_c = np.full((2, T, 2, 3), np.nan)  # (off, on) contact points
    sw_u = np.full((T, 2), np.nan)
    n = len(path.foot_of_step)
    for foot in range(2):
        idx = np.flatnonzero(path.foot_of_step == foot)
        if idx.size == 0:
            continue
        c = path.contacts[idx]
        td = path.contact_on[idx]
        lo = path.contact_off[idx]
        # virtual contacts one stride before the first and after the last (periodic extension); with a single
        # contact of this foot, the stride comes from both feet's steps (along the heading only: the feet's
        # lateral offsets differ)
        # (the first stride extends backwards, the last one forwards: speeds change in an acceleration)
        if len(c) > 1:
            stride_a, swing_a = c[1] - c[0], td[1] - lo[0]
            stride_b, swing_b = c[-1] - c[-2], td[-1] - lo[-2]
        else:
            fwd = path.frame[0]
            step = (path.contacts[-1] - path.contacts[0]) @ fwd / max(n - 1, 1)
            stride_a = stride_b = 2.0 * step * fwd
            t_stride = 2.0 * (path.t_touchdown[-1] - path.t_touchdown[0]) / max(n - 1, 1)
            swing_a = swing_b = t_stride - (lo[0] - td[0])
        c_ext = np.concatenate([c[:1] - stride_a, c, c[-1:] + stride_b])
        lo_ext = np.concatenate([[td[0] - swing_a], lo, [np.inf]])
        td_ext = np.concatenate([[-np.inf], td, [lo[-1] + swing_b]])
        # for each frame: the last touchdown at or before it (index into *_ext)
        k = np.searchsorted(td_ext, t, side="right") - 1
        in_stance = t < lo_ext[k]
        out[in_stance, foot] = c_ext[k[in_stance]]
        sw = ~in_stance
        k_sw = k[sw]
        t0, t1 = lo_ext[k_sw], td_ext[k_sw + 1]
        # progress in stride phase between liftoff and next touchdown (same measure as the reference)
        p = np.interp(t[sw], t, path.psi)
        p0 = _psi_at(path, t0)
        p1 = _psi_at(path, t1)
        out[sw, foot], u = swing_anchor(p, p0, p1, c_ext[k_sw], c_ext[k_sw + 1])
        w_ground[sw, foot] = 1.0 - min_jerk(u / SWING_RELEASE) * min_jerk((1.0 - u) / SWING_LANDING)
        sw_t[0, sw, foot], sw_t[1, sw, foot] = t0, t1
        sw_c[0, sw, foot], sw_c[1, sw, foot] = c_ext[k_sw], c_ext[k_sw + 1]
        sw_u[sw, foot] = u
    return out, w_ground, Swings(sw_t[0], sw_t[1], sw_c[0], sw_c[1], sw_u)


#: A foot's body-relative path is moved onto its ground-anchored one (_body_path_correction) while the foot's
#: lowest target is below the first of these heights [× L], not at all above the second: above the floor band
#: the physics report watches from wherever the foot rests (0.02 L over a low point up to 0.04 L up).
GAP_HOLD_L = (0.06, 0.10)
#: ... for a gap between the two paths up to the first of these sizes [× L], none from the second: a larger
#: gap comes from a changed speed (x0.5: 0.2 L), where the body path's own pace carries the foot (and a foot
#: held to the ground path's place and moved at the body's pace dragged along the floor, run_tired x0.5).
GAP_SIZE_L = (0.10, 0.15)


def _body_path_correction(cyc: ReferenceCycle, path: MachinePath, L: float, swings: Swings, lowest: np.ndarray,
                          leg_length: float) -> np.ndarray:
    """(T, 2, 3, 3) [m] horizontal correction of the body-relative foot path in swing that makes it meet the
    ground-anchored path at lift-off and touchdown while the foot is near the floor: the gap between the two
    at each end (_ground_minus_body; blended min-jerk over the swing's progress), whole while the foot's
    lowest target (lowest (T, 2) [m] above the ground) is under GAP_HOLD_L[0] × leg_length and gone above
    GAP_HOLD_L[1]; gaps beyond GAP_SIZE_L fade out. L: the length scale [m]; leg_length: the target's [m].

    The two paths agree at a contact only as far as the machine carries its COM over the contact as the
    reference did. A lopsided clip (run_tired: its right stance longer than its left, the machine's steps
    alike) leaves one foot's body path 20-50 mm from the ground path at lift-off; the release to the body
    path (SWING_RELEASE of the swing: one 30 Hz frame) moved a tip still 0.03 L up by that much in a frame,
    a scuff the report sees (the child 39 mm, dash_active's troll 33 mm). Corrected, the foot leaves the
    floor from where it stands and takes up the body's path only once clear of it.
    """
    out = np.zeros((len(path.times), 2, 3, 3))
    sw = ~np.isnan(swings.u)  # (T, 2)
    if not sw.any():
        return out
    feet = np.nonzero(sw)[1]
    gap = []
    for when, at in ((swings.t_off, swings.c_off), (swings.t_on, swings.c_on)):
        g = _ground_minus_body(cyc, path, L, when[sw], at[sw], feet)  # (n, 3, 3)
        size = np.linalg.norm(g, axis=-1).max(axis=-1) / leg_length
        gap.append(g * min_jerk((GAP_SIZE_L[1] - size) / (GAP_SIZE_L[1] - GAP_SIZE_L[0]))[:, None, None])
    s = min_jerk(swings.u[sw])[:, None, None]
    h0, h1 = GAP_HOLD_L[0] * leg_length, GAP_HOLD_L[1] * leg_length
    near_floor = min_jerk((h1 - lowest[sw]) / (h1 - h0))[:, None, None]
    out[sw] = near_floor * (gap[0] * (1.0 - s) + gap[1] * s)
    return out


def _ground_minus_body(cyc: ReferenceCycle, path: MachinePath, L: float, t: np.ndarray, contact: np.ndarray,
                       foot: np.ndarray) -> np.ndarray:
    """(n, 3, 3) [m] horizontal offset of the ground-anchored foot path (anchored at ``contact`` (n, 3) [m])
    from the body-relative one, for the markers of feet ``foot`` (n,) at times t (n,) [s] (anywhere: the
    phase and the COM are extrapolated linearly beyond the path, as for its virtual contacts)."""
    _, data = sample_cycle(cyc, _psi_at(path, t), rotations=False)
    n = np.arange(len(t))
    rel = (L * (data["marker_rel"][n, foot] - data["marker_from_com"][n, foot])) @ path.frame  # (n, 3, 3)
    ts = path.times
    com = np.stack([np.interp(t, ts, path.com[:, i]) for i in range(3)], axis=-1)  # (n, 3)
    if len(ts) > 1:  # linear beyond the ends
        v0 = (path.com[1] - path.com[0]) / (ts[1] - ts[0])
        v1 = (path.com[-1] - path.com[-2]) / (ts[-1] - ts[-2])
        com += np.minimum(t - ts[0], 0.0)[:, None] * v0 + np.maximum(t - ts[-1], 0.0)[:, None] * v1
    out = contact[:, None, :] + rel - com[:, None, :]
    out[..., UP_AXIS] = 0.0
    return out


def _contacts_extended(path: MachinePath, cols: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(on, off) [s] of one foot's contacts (its steps ``cols``) with a virtual contact one stride before the
    first and after the last, the periodic extension _foot_anchors anchors the foot on.

    A clip whose feet stay down long after the load falls (run_tired: the marker contact outlasts the loaded
    stance by 0.05-0.09 of a stride) starts the output in the tail of the previous contact: unweighted, the
    foot there slid 31-68 mm along the floor in the first frames. A walk starts as one foot lands with the
    other still down behind it and ends as the first lands again: those contacts are no step of the path
    either, and held like swinging feet a toe slid 8 mm (07_01 as a troll).
    """
    a, b = path.contact_on[cols], path.contact_off[cols]
    if len(a) > 1:
        before, after = a[1] - a[0], a[-1] - a[-2]
    else:
        n = len(path.foot_of_step)
        before = after = 2.0 * (path.t_touchdown[-1] - path.t_touchdown[0]) / max(n - 1, 1)
    if not before > 0 or not after > 0:
        return a, b
    return np.concatenate([[a[0] - before], a, [a[-1] + after]]), np.concatenate([[b[0] - before], b, [b[-1] + after]])


def _psi_at(path: MachinePath, times: np.ndarray) -> np.ndarray:
    """Stride phase at arbitrary times, extrapolated linearly beyond the path."""
    t, psi = path.times, path.psi
    rate = (psi[-1] - psi[0]) / max(t[-1] - t[0], 1e-9)
    out = np.interp(times, t, psi)
    out = np.where(times < t[0], psi[0] + (times - t[0]) * rate, out)
    return np.where(times > t[-1], psi[-1] + (times - t[-1]) * rate, out)


#: A toe marker (ball, tip) in stance is also held while within these fractions of L of its own lowest target about
#: its whole contact (_contact_lows): at REST_HOLD of the stance weight at the first, not at all from the
#: second (_marker_weights).
REST_BAND_L = (0.005, 0.02)
REST_HOLD = 0.3


def _marker_weights(path: MachinePath, markers: np.ndarray, leg_length: float, fade: bool = True,
                    frame_time: float | None = None) -> np.ndarray:
    """(T, 2, 3) foot marker weights: high for markers that bear load, low for the rest.

    A foot on the ground is weighted by STANCE_MARKER_WEIGHT, ramped (min-jerk over WEIGHT_RAMP_S) around
    each contact; within it each marker's weight falls smoothly from full at ≤ 0.02 L above the ground to
    the swing weight at ≥ 0.05 L. So the loaded point is held still while the rest of the foot may pivot
    about it (push-off on the toes when a faster or longer-legged run needs more reach than the
    reference's foot pose gives). markers: (T, 2, 3, 3) targets [m]; leg_length [m].
    A toe marker that rests above that band (a folded rig's ball, 0.039 L up) is held too while it is at
    its own rest height (within REST_BAND_L of its lowest target about its contact, _contact_lows; frame_time
    [s] of the targets), at REST_HOLD of the stance weight (at 1 the IK split the difference between targets
    that are not quite the foot's shape, each marker's rest its own lowest point). Not the ankle (see below).
    """
    t = path.times
    ramp = np.zeros((len(t), 2))
    landing = np.zeros((len(t), 2))  # the ramp on the touchdown side of each contact only
    for foot in range(2):
        cols = np.flatnonzero(path.foot_of_step == foot)
        if cols.size == 0:
            continue
        a, b = _contacts_extended(path, cols)
        # the contacts that can touch a frame: the last one starting before t + ramp, and the one before it
        k = np.searchsorted(a - WEIGHT_RAMP_S, t, side="right") - 1
        for kk in (k, k - 1):
            ok = kk >= 0
            kc = np.clip(kk, 0, a.size - 1)
            u = np.clip(np.minimum(t - (a[kc] - WEIGHT_RAMP_S), (b[kc] + WEIGHT_RAMP_S) - t) / WEIGHT_RAMP_S, 0.0, 1.0)
            ramp[:, foot] = np.maximum(ramp[:, foot], np.where(ok, u, 0.0))
            # past the ramp the floor fades out over one more ramp: cut there, it released a landing ball still
            # 0.05 L up in one frame, which swung 10-15 mm about the held tip (run_tired, giant and accelerated)
            # (not for a walk: its giant's double support moved 0.020 from the clip's, over the 0.02 it keeps)
            tail = np.clip(1.0 - (t - a[kc] - WEIGHT_RAMP_S) / WEIGHT_RAMP_S, 0.0, 1.0) if fade else 1.0
            keep = ok & (fade | (t <= a[kc] + WEIGHT_RAMP_S))
            landing[:, foot] = np.maximum(landing[:, foot], np.where(keep, np.minimum(u, tail), 0.0))
    height = markers[..., UP_AXIS]  # ground at 0
    lo, hi = 0.02 * leg_length, 0.05 * leg_length
    loaded = min_jerk((hi - height) / (hi - lo))  # 1 at or below lo, 0 at or above hi
    if frame_time is not None:
        # about the frame's own whole contact, not a sliding window: a heel rising at push-off that pauses
        # (dataset-1_walk_normal_001 slowed to 0.5x: its heel target dipped 3 mm 0.4 s after it rose) was
        # lowest in its window and held as at rest, 33 mm above its rest, and the IK turned the knee to reach
        # it: the toe tip slid 18 mm; at an output's first frames a heel rising after a contact cut by the
        # start was lowest in every window there (Bandai dataset-2_walk_active_002 giant: tip slid 6.1 mm)
        low = _contact_lows(path, height)
        r_lo, r_hi = REST_BAND_L[0] * leg_length, REST_BAND_L[1] * leg_length
        near = np.where(np.isfinite(low), (r_hi - (height - low)) / (r_hi - r_lo), 0.0)
        # not the ankle (as on main): in a run it moves with the ball (_rest_on_floor); held as well, over-determining
        # the foot, its hold pulled a straight-legged dash_normal_001 (x1.5 in 12 steps) back 13 mm at
        # lift-off (its tip slid 5.2 mm) and flipped a knee at 1.3x and 120 Hz (a 111 deg joint jump)
        near[..., 0] = 0.0
        loaded = np.maximum(loaded, REST_HOLD * min_jerk(near))
    # Around a touchdown every marker of the foot keeps at least LANDING_WEIGHT of the stance weight: a
    # landing foot follows its targets down to the contact point instead of being left by the posture pull
    # a centimetre lower and still sweeping forward (a scuff the report sees at touchdown). Not at lift-off:
    # there the leg is nearly straight and a pulled toe can flip the knee.
    loaded = np.maximum(loaded, LANDING_WEIGHT * min_jerk(landing)[..., None])
    return SWING_MARKER_WEIGHT + (STANCE_MARKER_WEIGHT - SWING_MARKER_WEIGHT) * min_jerk(ramp)[..., None] * loaded


def stance_only(targets: Targets) -> np.ndarray:
    """Foot marker targets that must be met (loaded markers of feet on the ground), NaN elsewhere."""
    out = targets.markers.copy()
    w = targets.marker_weight
    out[w < 0.5 * w.max()] = np.nan
    return out


def raised(targets: Targets, path: MachinePath, rise: float) -> tuple[Targets, MachinePath]:
    """Targets and their machine path raised by rise [m] (in the order ``bend`` returns them).

    The synthesis puts the clip's ground (``ReferenceCycle.ground``: the median of its stances' lowest points)
    on y = 0, and that ground is ``floor_clearance`` above the clip's floor (a joint centre rests a sole's
    thickness above the floor), so the output solved on them, raised by it × L, stands on its floor y = 0 as
    the clip does on its own. Raised before the IK (which is translation-invariant), so the preview (the
    targets' initial motion) and the result stand on the same floor."""
    if rise == 0.0:
        return targets, path
    up = np.zeros(3)
    up[UP_AXIS] = rise
    path = replace(path, com=path.com + up, contacts=path.contacts + up)
    floor_top = None if targets.floor_top is None else targets.floor_top + rise
    targets = replace(targets, initial=targets.initial.with_(root_positions=targets.initial.root_positions + up),
                      com=targets.com + up, markers=targets.markers + up, floor_top=floor_top)
    return targets, path
