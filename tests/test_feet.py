"""Issue 30, points 1 and 3: both feet rest on the floor as the clip's do, and the physics report sees it.

The report is an independent judge: it finds the contacts and the floor from the motion it is given. Here it
is given a real output broken on purpose (one foot floating, one sinking, one sliding, a leap) and each must
fail the matching bar, naming the foot and the frames. The breakages are made on the output's foot points and
COM (the report's ``com_and_markers``), which is what the report reads of a motion. The rest heights of the
clean outputs are checked against an independent reader of the written BVH (tests/conftest.py's oracle).
"""
from __future__ import annotations

import re

import numpy as np
import pytest

from froude.core.constants import HORIZONTAL_AXES, UP_AXIS
from froude.flow import pipeline
from froude.flow.result import write_result
from froude.report.metrics import BARS, physics_report, source_rest_heights

from conftest import clip, oracle_fk, read_bvh_oracle

#: The breakages, as fractions of the leg length L (issue 30's hints: 2 % L up and down).
BREAK_L = 0.02


@pytest.fixture(scope="module")
def output():
    """09_01 scaled to the troll (L = 1.16), 3 strides: the clean output, its body and the source's rest heights."""
    prep = pipeline.prepare(clip("09_01"))
    res = pipeline.scale(prep, "troll", strides=3)
    body = res.retarget.body
    com, markers = body.com_and_markers(res.motion)
    expected = res.retarget.L * source_rest_heights(prep.markers, prep.gait, prep.body.leg_length)
    return res, body, com, markers, expected


def _report(output, com=None, markers=None):
    res, body, com0, mk0, expected = output
    return physics_report(res.motion, body, ground_height=0.0, source_rest_heights=expected,
                          com_and_markers=(com0 if com is None else com, mk0 if markers is None else markers))


def _stance_frames(markers: np.ndarray, foot: int, leg_length: float) -> list[tuple[int, int]]:
    """[start, stop) runs where a foot's lowest marker is within 0.05 L of its lowest height: the test's own
    contact finder, not the report's."""
    h = markers[:, foot, :, UP_AXIS].min(axis=1)
    on = h < h.min() + 0.05 * leg_length
    d = np.diff(np.concatenate([[0], on.astype(np.int8), [0]]))
    return [(int(a), int(b)) for a, b in zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1))]


def _named_frames(message: str) -> list[tuple[int, int]]:
    """[(first, last)] of "frames 12-20, 38-46" in a bar's message."""
    m = re.search(r"frames ([0-9, -]+)", message)
    assert m, message
    out = []
    for part in m.group(1).split(","):
        a, _, b = part.strip().partition("-")
        out.append((int(a), int(b or a)))
    return out


def _overlaps(named, runs) -> bool:
    return any(a <= r1 - 1 and r0 <= b for a, b in named for r0, r1 in runs)


def test_the_clean_output_meets_every_bar(output):
    rep = _report(output)
    assert rep.check_bars() == []
    assert rep.rest_height_error_mm <= 1000.0 * BARS["rest_height_L"] * rep.leg_length_m


def test_rest_heights_against_an_independent_reader(output, tmp_path):
    """The written BVH read back by the oracle: each foot joint's (ankle, ball) lowest point in its stances
    (found by the test from the oracle's joints) is the report's rest height within a millimetre, and the
    ball's (a toe marker, held at its rest) the source's, scaled, within 0.3 % of L. Not the ankle's:
    the bar is the foot's (metrics.rest_height_error), the ankle's rest its posture over the ball; since the
    ankle is no longer held to its own rest (3a8c0ee: held, it over-determined the foot and flipped a knee of
    dash_normal_001 at 1.3x) 09_01's troll's right ankle rests 7.0 mm (0.6 % of L) under the source's, scaled."""
    res, body, _, _, expected = output
    path = tmp_path / "troll.bvh"
    write_result(res, path)
    b = read_bvh_oracle(path)
    P, _ = oracle_fk(b, res.motion.meta["length_scale"])
    rep = res.report
    tol = BARS["rest_height_L"] * body.leg_length
    for foot, side in enumerate(("left", "right")):
        joints = [b.names.index(body.skeleton.names[body.roles[f"{side}_{r}"]]) for r in ("ankle", "toe")]
        pts = np.zeros((len(P), 2, 3, 3))
        pts[:, foot, :2] = P[:, joints]
        pts[:, foot, 2] = P[:, joints[1]]
        runs = [(a, c) for a, c in _stance_frames(pts, foot, body.leg_length) if a > 0 and c < len(P)]
        assert len(runs) >= 2
        for k, name in enumerate(("ankle", "ball")):
            low = float(np.median([P[a:c, joints[k], UP_AXIS].min() for a, c in runs]))
            assert abs(low - rep.rest_height_mm[side][name] / 1000.0) < 1e-3, (side, name)
            if name == "ball":
                assert abs(low - expected[foot, k]) <= tol, (side, name, low, expected[foot, k])


@pytest.mark.parametrize("foot,sign", [(0, +1), (1, -1)], ids=["left-floats", "right-sinks"])
def test_a_floating_or_sinking_foot_fails_the_rest_height_bar(output, foot, sign):
    res, body, com, markers, _ = output
    L = body.leg_length
    broken = markers.copy()
    broken[:, foot, :, UP_AXIS] += sign * BREAK_L * L
    rep = _report(output, markers=broken)
    fails = [f for f in rep.check_bars() if "stance height" in f]
    side = ("left", "right")[foot]
    assert len(fails) == 1 and fails[0].startswith(f"{side} foot rests"), rep.check_bars()
    assert ("above" if sign > 0 else "below") in fails[0]
    assert rep.rest_height_error_mm == pytest.approx(1000.0 * BREAK_L * L, rel=0.1)
    assert _overlaps(_named_frames(fails[0]), _stance_frames(broken, foot, L))
    assert not _overlaps(_named_frames(fails[0]), _stance_frames(broken, 1 - foot, L))


def test_a_sliding_foot_fails_the_skate_bar(output):
    """The left foot slides 20 mm forward through one of its stances (a ramp): the stricter skate bar names
    the left foot and frames of that stance."""
    res, body, com, markers, _ = output
    runs = [(a, b) for a, b in _stance_frames(markers, 0, body.leg_length) if a > 0 and b < len(markers)]
    a, b = runs[len(runs) // 2]
    broken = markers.copy()
    ramp = np.zeros(len(markers))
    ramp[a:b] = np.linspace(0.0, 0.020, b - a)
    ramp[b:] = 0.020
    broken[:, 0, :, HORIZONTAL_AXES[0]] += ramp[:, None]
    rep = _report(output, markers=broken)
    fails = [f for f in rep.check_bars() if f.startswith("foot skate (ball and tip")]
    assert len(fails) == 1 and "left foot" in fails[0], rep.check_bars()
    assert rep.foot_skate_floor_mm > BARS["foot_skate_floor_mm"]
    assert _overlaps(_named_frames(fails[0]), [(a, b)])


def test_a_leap_fails_the_step_length_bar(output):
    """From the middle of one flight on, the body and both feet are 1.5 statures farther along: that step is
    longer than 1.4 x stature and the bar names the frames of its two contacts."""
    res, body, com, markers, _ = output
    L = body.leg_length
    left = [r for r in _stance_frames(markers, 0, L) if r[0] > 0]
    right = [r for r in _stance_frames(markers, 1, L) if r[0] > 0]
    stances = sorted(left + right)
    i = len(stances) // 2
    cut = (stances[i - 1][1] + stances[i][0]) // 2  # in the flight between two stances
    heading = com[-1] - com[0]
    heading[UP_AXIS] = 0.0
    jump = 1.5 * body.stature * heading / np.linalg.norm(heading)
    c2, m2 = com.copy(), markers.copy()
    c2[cut:] += jump
    m2[cut:] += jump
    rep = _report(output, com=c2, markers=m2)
    fails = [f for f in rep.check_bars() if f.startswith("step of")]
    assert len(fails) == 1, rep.check_bars()
    assert rep.max_step_length_m > BARS["step_length_stature"] * rep.stature_m
    named = _named_frames(fails[0])
    assert _overlaps(named, [stances[i - 1]]) and _overlaps(named, [stances[i]])
    clean = _report(output)
    assert clean.max_step_length_m < BARS["step_length_stature"] * clean.stature_m


def test_unmeasurable_rest_heights_are_null_with_a_reason(output):
    res, body, com, markers, _ = output
    rep = physics_report(res.motion, body, ground_height=0.0, com_and_markers=(com, markers))
    d = rep.to_dict()
    assert d["rest_height_error_mm"] is None and "source rest heights" in d["unmeasured"]["rest_height_error_mm"]
    assert d["rest_height_mm"]["left"]["ball"] is not None


def test_a_small_characters_stance_foot_rests_where_the_clips_does():
    """CMU 02_01 (a walk) as the child (its body's leg 0.60 m: the rest bar, 0.3 % of L, is 1.8 mm). The IK solved again
    only held markers more than 3 mm off their targets, and left the right toe tip 2.2 mm under its target as
    the heel rose (frame 113): the foot rested 0.375 % of L under the clip's, scaled. Now a held marker is
    solved again from half the output's rest bar (``ik.correct.REST_BAR_SHARE``)."""
    res = pipeline.scale(pipeline.prepare(clip("02_01")), "child")
    rep = res.report
    assert rep.rest_height_error_mm <= 1000.0 * BARS["rest_height_L"] * rep.leg_length_m, rep.rest_height_worst


def _knee_deg(p_world_joint: np.ndarray, roles: dict, side: str) -> np.ndarray:
    """(F,) [deg] the angle at the knee between thigh and shank (180 straight) of joint positions (F, J, 3)."""
    hip, knee, ankle = (p_world_joint[:, roles[f"{side}_{j}"]] for j in ("hip", "knee", "ankle"))
    u, v = hip - knee, ankle - knee
    cos = np.sum(u * v, axis=-1) / (np.linalg.norm(u, axis=-1) * np.linalg.norm(v, axis=-1))
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))


@pytest.mark.parametrize("name, character", [("bandai-locomotion/walks/dataset-2_walk_feminine_001", "troll"),
                                             ("07_01", "child"),
                                             ("bandai-locomotion/runs/dataset-2_run_masculine_001", "troll")])
def test_a_character_of_other_proportions_stands_as_tall_as_the_clip(name, character):
    """A character whose COM sits higher over its hips than the clip's (the troll's trunk and arms, the child's
    head) walks and runs on legs bent as the clip's, not crouched: its COM target is the machine's path carried
    by its own posture (``synthesis.targets.posture_com_offset``). Without it each leg's knee was bent 10-26 deg
    more than the time-warped reference pose's, on average over its stance, in each of these (and the troll's
    walk popped a knee 46 deg in one frame at the end of a stance); now within 6 deg. Judged on the output's
    joint positions against the reference pose's, in the frames where the foot is held."""
    from froude.core.kinematics import fk

    res = pipeline.scale(pipeline.prepare(clip(name)), character, strides=4)
    roles = res.retarget.body.roles
    p_out, _ = fk(res.motion)
    p_ref, _ = fk(res.targets.initial)
    w = res.targets.marker_weight
    held = (w >= 0.5 * w.max()).any(axis=2)  # (F, 2): the foot is on the ground
    for i, side in enumerate(("left", "right")):
        more_bent = (_knee_deg(p_ref, roles, side) - _knee_deg(p_out, roles, side))[held[:, i]].mean()
        assert more_bent < 6.0, f"{character}'s {side} knee bent {more_bent:.1f} deg more than the clip's in stance"
    assert not res.report.check_bars()


def test_a_foot_swinging_low_past_the_floor_is_no_skate():
    """The stricter skate counts a marker's slide near the floor about a contact only where the low frames
    meet the contact: Bandai dataset-2_walk_elderly_001's toes clear the floor by 2-10 mm in mid-swing,
    within the skate band, at 80-100 mm a frame, and the report counted that as a slide on the floor (the clip
    itself 77.4 mm, frames 376-378; its x0.8 output 98.5 mm, frames 91-92). A slide within a contact is still
    caught (test_a_sliding_foot_fails_the_skate_bar)."""
    prep = pipeline.prepare(clip("bandai-locomotion/walks/dataset-2_walk_elderly_001"))
    rep = physics_report(prep.motion, prep.body)
    frames = rep.skate_worst.get("frames", [])
    assert not any(a <= 377 < b for a, b in frames), rep.skate_worst  # the mid-swing dip is not the worst
    assert rep.foot_skate_floor_mm < 20.0, rep.skate_worst  # what is left is the clip's own toe in stance
    out = pipeline.scale(prep, None, speed=0.8).report
    assert out.foot_skate_floor_mm <= BARS["foot_skate_floor_mm"], out.skate_worst
