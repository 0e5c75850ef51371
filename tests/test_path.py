"""Issue 28: the path of a take (``froude.body.path``) and what ``froude info`` says about it.

Acceptance 4: on every shared turning clip the total heading change ``info`` reports agrees within 5 degrees
with the figure in the clip's SOURCES.md. The figures are read from those files here, not copied.
"""
from __future__ import annotations

import csv
import json
import math
import os
import re
from pathlib import Path

import numpy as np
import pytest

from froude.body.path import direction_of, heading_change, smooth_path, unsmooth_path, wrap_angle, yaw_of
from froude.core.constants import UP
from froude.errors import FroudeError
from froude.flow import pipeline

from conftest import BANDAI_LOCO, CMU_TURN_CLIPS, CMU_TURNS, LOCO_TURNS, clip, oracle_fk, read_bvh_oracle

#: SOURCES.md figures a clip's measured heading change may differ from [deg] (acceptance 28.4).
HEADING_TOL_DEG = 5.0
#: Clips where the acceptance does not hold, with the measured reason (strict: one that starts to hold
#: comes off the list).
HEADING_MISSES = {
    "cmu-turns/16_18": "info reads +86.0 deg where SOURCES.md says 94: the walker is still turning in the last "
                       "stride (the path's heading moves 8 deg over its last second); the file's 0.6 s window "
                       "reads the last half stride, info's window is one stride (1.08 s) so the sway cancels",
}


def _sources_heading_deg(name: str) -> float | None:
    """The heading change [deg] SOURCES.md gives for a clip (None: the file gives none, '-')."""
    kind, _, rest = name.partition("/")
    if kind == "bandai-locomotion":
        text = (BANDAI_LOCO / "SOURCES.md").read_text()
        m = re.search(rf"^\| {re.escape(rest)}\.bvh \|(?:[^|]*\|){{3}} *([+-]?\d+|-) *\|", text, re.M)
        assert m, f"{rest} not in SOURCES.md"
        return None if m.group(1) == "-" else float(m.group(1))
    text = (CMU_TURNS / "SOURCES.md").read_text()
    m = re.search(rf"^\| {re.escape(rest)}\.bvh \|.*?turns about (\d+) degrees to the (left|right)", text, re.M)
    assert m, f"{rest} not in SOURCES.md"
    return float(m.group(1)) * (1.0 if m.group(2) == "left" else -1.0)


def _cases():
    return [pytest.param(n, marks=[pytest.mark.xfail(strict=True, reason=HEADING_MISSES[n])]
                         if n in HEADING_MISSES else ())
            for n in (LOCO_TURNS + CMU_TURN_CLIPS) or [None]]


@pytest.mark.parametrize("name", _cases())
def test_info_heading_change_agrees_with_sources(run_cli, name):
    """Acceptance 28.4 on every shared turning clip; the backward walk (no figure) faces against its travel."""
    if name is None:
        pytest.skip("the turning clips are absent")
    code, out, _ = run_cli("info", clip(name), "--json")
    assert code == 0
    path = json.loads(out)["path"]
    want = _sources_heading_deg(name)
    if want is None:  # dataset-1_walk-back: a backward walk
        assert abs(path["facing_vs_travel_deg"]) > 170
        assert abs(path["heading_change_deg"]) < HEADING_TOL_DEG
        return
    assert abs(path["heading_change_deg"] - want) <= HEADING_TOL_DEG, (path["heading_change_deg"], want)
    steps = path["steps"]
    assert len(steps) >= 3
    assert abs(path["facing_vs_travel_deg"]) < 15  # these walk and run forwards (walk-left/right: 12 deg off)
    if abs(want) < 45:
        return
    # the steps' heading changes add up to the turn (the per-step figures are of the smoothed path, which
    # also turns before the first touchdown and after the last one: only most of the turn lies between them)
    turn = sum(s["heading_change_deg"] for s in steps)
    assert 0.6 * abs(want) <= abs(turn) <= 1.1 * abs(want) and turn * want > 0


def test_info_table_reports_the_path(run_cli):
    """The table's path rows: heading change with its side, speed along the path; the mean speed is the take's as
    fit and scale model it (straightened along its path), so it is the speed along the path too."""
    code, out, _ = run_cli("info", clip("bandai-locomotion/turns/dataset-2_walk-turn-left_normal_001"))
    assert code == 0
    rows = dict((line[:24].strip(), line[24:].strip()) for line in out.splitlines())
    assert rows["heading change"].endswith("against the first") and "(left)" in rows["heading change"]
    v_path = float(rows["speed along the path"].split()[0])
    v_mean = float(rows["mean speed"].split()[0])
    # the issue: 1.04 m/s along the path, where a straight line from start to end gives 0.79 m/s (what info and
    # the machine once said)
    assert abs(v_path - 1.03) < 0.05 and abs(v_mean - v_path) < 0.03 * v_path
    assert len(rows["turn per step"].split()) >= 4 and rows["facing vs travel"].endswith("(forwards)")


# ---- hand-made paths with answers known by hand ----------------------------------------------------------
def test_heading_sign_and_wrap():
    """+ = left seen from above: with Y up, travel along +X turned towards -Z is a left turn."""
    assert yaw_of(np.array([1.0, 0.0, 0.0])) == pytest.approx(0.0)
    assert yaw_of(np.array([0.0, 0.0, -1.0])) == pytest.approx(math.pi / 2)
    # left of a direction is UP x direction (the runner's right is direction x UP)
    for a in (-2.0, 0.3, 3.0):
        d = direction_of(a)
        assert yaw_of(d) == pytest.approx(a) and np.allclose(direction_of(a + math.pi / 2), np.cross(UP, d))
    assert wrap_angle(3 * math.pi / 2) == pytest.approx(-math.pi / 2)
    assert wrap_angle(math.pi) == pytest.approx(math.pi)


def _arc(turn_rad: float, radius: float, speed: float, dt: float, straight_s: float):
    """(F, 3) a COM that walks straight, turns turn_rad on a circle of radius [m], walks straight on."""
    v = speed * dt
    pts, p, psi = [], np.zeros(3), 0.0
    n_turn = int(round(abs(turn_rad) * radius / v))
    n_str = int(round(straight_s / dt))
    for i in range(2 * n_str + n_turn):
        pts.append(p.copy())
        if n_str <= i < n_str + n_turn:
            psi += turn_rad / n_turn
        p = p + v * direction_of(psi)
    com = np.array(pts)
    com[:, 1] = 0.9
    return com


@pytest.mark.parametrize("turn_deg", [90.0, -45.0, 0.0])
def test_heading_change_of_an_arc_with_sway(turn_deg):
    """A circular turn between straight parts, with a side-to-side sway of 3 cm at the stride period: the
    heading change is the arc's within 0.5 deg; the stride-smoothed path keeps the arc's length."""
    dt, stride, speed = 1 / 120, 1.1, 1.2
    com = _arc(math.radians(turn_deg), 1.5, speed, dt, straight_s=3.0)
    t = np.arange(len(com)) * dt
    vel = np.gradient(com, dt, axis=0)
    left = np.cross(UP, vel / np.linalg.norm(vel, axis=1, keepdims=True))
    swayed = com + 0.03 * np.sin(2 * math.pi * t / stride)[:, None] * left
    h, w = heading_change(swayed, dt, stride)
    assert w == pytest.approx(stride, abs=dt)
    assert math.degrees(h) == pytest.approx(turn_deg, abs=0.5)
    p = smooth_path(swayed, int(round(stride / dt)))
    length = np.linalg.norm(np.diff(p[:, [0, 2]], axis=0), axis=1).sum()
    assert length == pytest.approx(speed * t[-1], rel=0.01)


def test_the_travel_line_undoes_the_stride_average():
    """A 90 deg turn of radius 1.2 m ending a stride before the take does, with a 3 cm sway: the stride
    average (the path) cuts the corner; travelled again and averaged again (an output made along the path,
    measured as the clip), it would be 3.4 % shorter and turn 7 deg less over its end chords than the walker.
    The travel line (``unsmooth_path``) averaged once more gives back the path, and its own length and end
    chords are the walker's within 0.5 % and 1.5 deg."""
    dt, stride, speed = 1 / 120, 1.1, 1.2
    com = _arc(math.radians(90.0), 1.2, speed, dt, straight_s=stride)
    t = np.arange(len(com)) * dt
    vel = np.gradient(com, dt, axis=0)
    left = np.cross(UP, vel / np.linalg.norm(vel, axis=1, keepdims=True))
    swayed = com + 0.03 * np.sin(2 * math.pi * t / stride)[:, None] * left
    n_box = int(round(stride / dt))
    path = smooth_path(swayed, n_box)
    track = unsmooth_path(path, n_box)

    def length(x):
        return np.linalg.norm(np.diff(x[:, [0, 2]], axis=0), axis=1).sum()

    def end_chord_turn_deg(x):
        return math.degrees(heading_change(x, dt, stride)[0])

    true_length = length(com)
    twice = smooth_path(path, n_box)
    assert np.abs(smooth_path(track, n_box) - path)[:, [0, 2]].max() < 0.01  # [m]
    assert abs(length(track) / true_length - 1) < 0.005 < abs(length(twice) / true_length - 1)
    walker = end_chord_turn_deg(swayed)
    assert abs(end_chord_turn_deg(track) - walker) < 1.5 < abs(end_chord_turn_deg(twice) - walker)


def _swayed_arc(stride: float, dt: float):
    """(walker's line (F, 3), its COM swaying 3 cm sideways at the stride and surging 1.5 cm along at the step
    period (F, 3), its steps (a touchdown every half stride, feet alternating)): a 90 deg turn of radius 1.2 m
    between straight parts of two strides each."""
    from froude.body.path import PathStep

    com = _arc(math.radians(90.0), 1.2, 1.2, dt, straight_s=2 * stride)
    t = np.arange(len(com)) * dt
    vel = np.gradient(com, dt, axis=0)
    fwd = vel / np.linalg.norm(vel, axis=1, keepdims=True)
    left = np.cross(UP, fwd)
    swayed = (com + 0.03 * np.sin(2 * math.pi * t / stride)[:, None] * left
              + 0.015 * np.sin(4 * math.pi * t / stride)[:, None] * fwd)
    on = np.arange(0.1, t[-1] - 0.5 * stride, 0.5 * stride)
    steps = tuple(PathStep(i % 2, a, a + 0.5 * stride, 0.0, 0.0, math.inf, 0.0, 0.0, 0.0) for i, a in enumerate(on))
    return com, swayed, steps


def test_the_travel_line_is_the_com_without_its_sway():
    """The travel line the output is bent along is the walker's COM less its periodic sway (``unswayed_track``):
    on a 90 deg turn of radius 1.2 m with a 3 cm sway and a 1.5 cm surge, it lies within 6 mm of the line the
    walker swayed about (4.9 mm; the stride average's inverse, ``unsmooth_path``, 17.7 mm off in the turn), and
    averaged over a stride it gives back the path closer than the inverse does (4.0 mm against 6.4; not
    exactly: a sway that turns with the path does not average out, and the path is itself 5.1 mm off the
    walker's line averaged). At its ends it is the path, so its end directions are the travel over the end
    strides."""
    from froude.body.path import unswayed_track

    dt, stride = 1 / 120, 1.1
    com, swayed, steps = _swayed_arc(stride, dt)
    n_box = int(round(stride / dt))
    path = smooth_path(swayed, n_box)
    heading = np.unwrap(yaw_of(np.gradient(path, dt, axis=0)))
    track = unswayed_track(swayed, path, heading, steps, dt, stride)
    inner = slice(n_box, len(com) - n_box)  # the end strides go over to the path

    def off_mm(x):
        return 1000 * np.abs(x - com)[inner][:, [0, 2]].max()

    inverse = unsmooth_path(path, n_box)
    assert off_mm(track) < 6.0 < 15.0 < off_mm(inverse)

    def averaged_off_mm(x):
        return 1000 * np.abs(smooth_path(x, n_box) - path)[:, [0, 2]].max()

    assert averaged_off_mm(track) < 4.5 < averaged_off_mm(inverse)
    assert np.abs(track - path)[[0, -1]][:, [0, 2]].max() < 1e-12


def test_no_sway_is_taken_off_without_alternating_steps():
    """Without three steps whose feet alternate there is no stride phase to hang a sway on: ``unswayed_track``
    says so (None) and the travel line is the stride average's inverse."""
    from dataclasses import replace

    from froude.body.path import stride_phase, unswayed_track

    dt, stride = 1 / 120, 1.1
    _, swayed, steps = _swayed_arc(stride, dt)
    same_foot = tuple(replace(s, foot=0) for s in steps)
    assert stride_phase(steps, len(swayed), dt) is not None
    assert stride_phase(same_foot, len(swayed), dt) is None and stride_phase(steps[:2], len(swayed), dt) is None
    path = smooth_path(swayed, int(round(stride / dt)))
    assert unswayed_track(swayed, path, np.zeros(len(swayed)), same_foot, dt, stride) is None


# ---- machines along the path, and never silently straight (issue 28 points 2 and 4) ---------------------
#: A turning walk that today's walking machine fits (the other turns: see docs/path.md for which pass).
TURN = "bandai-locomotion/turns/dataset-2_walk-turn-left_masculine_001"


def _oracle_heading_deg(bvh_path, window_s: float) -> float:
    """Heading change [deg] of a BVH file's pelvis track measured with the tests' own reader: its travel
    direction (a chord) over the last window_s minus over the first, + = left with Y up."""
    b = read_bvh_oracle(bvh_path)
    p, _ = oracle_fk(b, 1.0)  # file units: a direction does not depend on them
    hips = p[:, b.names.index("Hips")]
    n = int(round(window_s / b.frame_time))
    first, last = hips[n] - hips[0], hips[-1] - hips[-1 - n]
    yaw = [math.atan2(-d[2], d[0]) for d in (first, last)]
    return math.degrees(math.remainder(yaw[1] - yaw[0], 2 * math.pi))


def test_a_turning_walk_is_scaled_along_its_path(prepared, tmp_path):
    """The walking machine runs along the straightened take and the output is rolled back onto the path
    scaled: the child turns as the clip does (+94.5 deg) within 3 deg, by its report and by the tests' own
    BVH reader on the written file; facing vs travel within 5 deg; speed along the path x sqrt(L) within 2 %; every
    bar met (the clip's straight-line speed, 0.93 m/s, was what the machine ran before)."""
    prep = prepared[TURN]
    assert prep.turn is not None and prep.summary.mean_speed == pytest.approx(prep.path.path_speed_m_s, rel=0.02)
    strides = math.ceil(prep.path.n_steps / 2) + 1  # the whole turn and a stride on
    res = pipeline.scale(prep, "child", strides=strides)
    cmp = res.report.extras["path_vs_clip"]
    h = cmp["heading_change_deg"]
    assert h["clip"] == pytest.approx(94.5, abs=1.0) and abs(h["output"] - h["clip"]) <= 3.0
    f = cmp["facing_vs_travel_deg"]
    assert abs(f["output"] - f["clip"]) <= 5.0
    v = cmp["path_speed_m_s"]
    # acceptance 1's 2 %: the output travels the clip's travel line, not its stride-averaged path (averaged
    # twice, it was 2.4 % slow: docs/path.md)
    assert v["output"] == pytest.approx(v["clip"] * math.sqrt(res.retarget.L), rel=0.02)
    assert res.report.check_bars() == []  # the rest-height bar too (its left toe tip was 2.6 mm low, 0.41 % L)
    out = tmp_path / "child.bvh"
    pipeline.write_result(res, out)
    stride_s = 2.0 / res.report.step_frequency_hz
    assert abs(_oracle_heading_deg(out, stride_s) - h["output"]) <= 3.0


def _lean_rows_by_hand(clip_path, out_path, L: float) -> list[tuple[float, float]]:
    """(output lean, clip lean) [deg] per turning output step (> 2 deg), by the tests' own matching: the clip's
    steps of the same foot whose touchdowns lie on either side of the output step's touchdown along the
    path (arc length / L), interpolated linearly."""
    def td_arc(p):
        return [float(np.interp(s.t0_s / p.frame_time, np.arange(p.arc_length_m.size), p.arc_length_m))
                for s in p.steps]

    c_arc, rows = td_arc(clip_path), []
    for s, a in zip(out_path.steps, td_arc(out_path)):
        if abs(math.degrees(s.heading_change_rad)) <= 2.0:
            continue
        mine = [(ca, math.degrees(c.lean_rad)) for c, ca in zip(clip_path.steps, c_arc) if c.foot == s.foot]
        before = [m for m in mine if m[0] <= a / L]
        after = [m for m in mine if m[0] > a / L]
        if not before or not after:
            continue
        (a0, l0), (a1, l1) = before[-1], after[0]
        rows.append((math.degrees(s.lean_rad), l0 + (l1 - l0) * (a / L - a0) / (a1 - a0)))
    return rows


@pytest.fixture(scope="module")
def turn_giant(prepared):
    """The giant's output of TURN over the whole turn and a stride on."""
    prep = prepared[TURN]
    return pipeline.scale(prep, "giant", strides=math.ceil(prep.path.n_steps / 2) + 1)


def test_the_output_leans_into_the_turn_and_its_force_closes(prepared, turn_giant):
    """Issue 28 acceptance 2 and 3 under pure scaling (the giant): each turning step leans (COM over the
    stance foot, frontal plane) as the clip's step at the same place within 2 deg (the repeated reference
    stride alone leaned -1.7..+0.7 deg into turns where the clips lean +0.8..+4.5); over each turning
    stride the mean force across the path from the output's COM is m v^2/r within 10 %, and the force per
    weight is the clip's at the same place (dynamic similarity keeps v^2/(g r)) within 0.03 body weights."""
    from froude.body.gait import detect_gait
    from froude.body.path import take_path

    prep, res = prepared[TURN], turn_giant
    body = res.retarget.body
    com, markers = body.com_and_markers(res.motion)
    out_path = take_path(res.motion, body, com, detect_gait(res.motion, body, markers, com))
    rows = _lean_rows_by_hand(prep.path, out_path, res.retarget.L)
    assert len(rows) >= 4, rows
    assert all(abs(o - c) <= 2.0 for o, c in rows), rows
    # into the turn (+, a left turn) over the turning steps: the clip's mean is +2.5 deg here
    assert np.mean([o for o, _ in rows]) == pytest.approx(np.mean([c for _, c in rows]), abs=1.0)
    cmp = res.report.extras["path_vs_clip"]
    forces = cmp["force_per_turning_stride"]
    assert len(forces) >= 4 and all(r["met"] for r in forces), forces
    peak = max(forces, key=lambda r: r["force_bw"])
    assert peak["force_bw"] > 0.08  # a turn of r = 1.2 m at 1 m/s: v^2/(g r) = 0.085
    scaled = [r for r in forces if r.get("clip_force_bw_scaled") is not None]
    assert len(scaled) >= 3 and all(abs(r["force_bw"] - r["clip_force_bw_scaled"]) <= 0.03 for r in scaled), scaled
    assert [r for r in cmp["lean_per_turning_step"] if not r["met"]] == []


def test_the_output_slows_into_the_turn_as_the_clip_does(prepared, turn_giant):
    """Issue 28 acceptance 1 (the path per step) under pure scaling: a walker slows into a turn (TURN: to 0.87
    of its mean speed where it turns most), and an output at one speed, measured as the clip is (its COM
    averaged over a stride in time), turned up to 6 deg less per step than the clip's path over the same
    stretch. Each output step's speed along its path, over the output's mean, is the clip's over one clip
    step around the same place (arc length / L), over the clip's mean, within 5 %
    (``TakePath.speed_factors``). The clip's figure is computed here from its arc length."""
    from froude.body.gait import detect_gait
    from froude.body.path import take_path

    prep, res = prepared[TURN], turn_giant
    L, body = res.retarget.L, res.retarget.body
    com, markers = body.com_and_markers(res.motion)
    out = take_path(res.motion, body, com, detect_gait(res.motion, body, markers, com))
    arc_c = np.maximum.accumulate(prep.path.arc_length_m)
    t_c = np.arange(arc_c.size) * prep.path.frame_time
    half = 0.5 * prep.machine.t_step * prep.machine.time_unit
    frames = np.arange(out.arc_length_m.size)
    rows = []
    for st in out.steps:
        a0, a1 = (float(np.interp(t / out.frame_time, frames, out.arc_length_m)) / L for t in (st.t0_s, st.t1_s))
        t_mid = float(np.interp(0.5 * (a0 + a1), arc_c, t_c))
        if a1 > arc_c[-1] or not half <= t_mid <= t_c[-1] - half:
            continue
        v_clip = (np.interp(t_mid + half, t_c, arc_c) - np.interp(t_mid - half, t_c, arc_c)) / (2 * half)
        rows.append((st.speed_m_s / out.path_speed_m_s, v_clip / prep.path.path_speed_m_s))
    assert len(rows) >= 5 and min(c for _, c in rows) < 0.9, rows  # the clip slows where it turns
    assert all(abs(o / c - 1.0) <= 0.05 for o, c in rows), rows


def test_the_turning_giant_meets_every_bar(turn_giant):
    """Every bar met by the giant's turn, the stricter skate included (5.11 mm over frames 100-126 while the IK
    repair ranked a joint jump above a held toe 4-6 mm off its target; 2.81 mm since, ik.correct._bar_misses;
    5.54 mm with a walk's sub-frame anchors, the feet of its double support bent out of the legs' reach, 1.25
    mm since the bend keeps them within it, synthesis.targets.within_reach)."""
    assert turn_giant.report.check_bars() == [] and turn_giant.report.foot_skate_floor_mm <= 5.0


#: Walk-turns the walking machine refuses (issue 29's fit; docs/path.md), and giants known to miss a bar:
#: strict xfails, so a fix shows.
REFUSED_TURNS = {"dataset-2_walk-turn-left_elderly_001": "no periodic walking cycle found",
                 "dataset-2_walk-turn-right_elderly_001": "no periodic walking cycle found"}
GIANT_MISSES = {"dataset-1_walk-back_normal_001": "a straight take walked backwards: the giant's right ball and "
                "tip slide 12.7 mm (17.3 before the walks' sub-frame anchors) over frames 41-54; not investigated"}


def test_a_refused_walk_says_what_it_is(run_cli, tmp_path):
    """A walk the walking machine refuses is said in the user's terms: the step, its double support, the speed
    and the stance force the cycle had to meet, as info measures the take (its step frequency, its speed along
    the path), in one line, exit 2, nothing written."""
    name = clip("bandai-locomotion/turns/dataset-2_walk-turn-left_elderly_001")
    out = tmp_path / "giant.bvh"
    code, _, err = run_cli("scale", name, "--character", "giant", "-o", out, "-q")
    assert code == 2 and err.count("\n") == 1 and not out.exists(), err
    m = re.search(r"its steps: ([\d.]+) s, (\d+) % of each in double support, ([\d.]+) m/s; its vertical force over a "
                  r"stance: peaks ([\d.]+) and ([\d.]+), trough ([\d.]+) body weights", err)
    assert m, err
    code, js, _ = run_cli("info", name, "--json")
    d = json.loads(js)
    assert abs(float(m[1]) * d["step_frequency_hz"] - 1.0) < 0.03, (m[1], d["step_frequency_hz"])
    assert abs(float(m[3]) / d["path"]["path_speed_m_s"] - 1.0) < 0.05, (m[3], d["path"]["path_speed_m_s"])
    assert 0.5 < float(m[6]) < min(float(m[4]), float(m[5])), err


def _giant_case(name: str):
    stem = name.rsplit("/", 1)[-1]
    marks = ([pytest.mark.xfail(strict=True, raises=FroudeError, reason=REFUSED_TURNS[stem])] if stem in REFUSED_TURNS
             else [pytest.mark.xfail(strict=True, reason=GIANT_MISSES[stem])] if stem in GIANT_MISSES else [])
    return pytest.param(name, id=stem, marks=marks)


#: Walk-turns whose giant misses acceptance 1's turn per step (strict xfails: a fix shows), measured as below.
STEP_TURN_MISSES = {
    "dataset-2_walk-turn-right_exhausted_001": "an erratic walk: the steps at its sharp turn (48 deg in one clip "
    "step) turn 4-5 deg and 15-21 % off the clip's path over the same stretch",
}


def _step_turn_case(name: str):
    stem = name.rsplit("/", 1)[-1]
    marks = ([pytest.mark.xfail(strict=True, raises=FroudeError, reason=REFUSED_TURNS[stem])] if stem in REFUSED_TURNS
             else [pytest.mark.xfail(strict=True, reason=STEP_TURN_MISSES[stem])] if stem in STEP_TURN_MISSES else [])
    return pytest.param(name, id=stem, marks=marks)


@pytest.mark.slow  # a scale of each walk-turn (2-4 s)
@pytest.mark.parametrize("name", [_step_turn_case(n) for n in LOCO_TURNS if "walk-turn" in n])
def test_a_walk_turn_keeps_its_turn_per_step(prepared, name):
    """Issue 28 acceptance 1, heading and radius per step, on every walk-turn as the giant: every output step
    turns as the clip's path over the same stretch (the step's arc length / L) within 3 deg, and the steps
    turning 10 deg or more with the same radius in leg lengths within 5 %. On walk-turn-left_feminine_001: at
    one speed along a travel line with one correction (before 29 Nov) the worst step was 2.9 deg and 10.3 % off;
    with the clip's speed along the turn (``TakePath.speed_factors``) 1.6 deg and 5.5 %; with the travel line's
    second term (``body.path.unsmooth_path``) 1.4 deg and 4.6 %; along the COM less its sway
    (``unswayed_track``) 0.7 deg and 3.7 %, and 5.1 % since the machine walks the take's mean cadence (which
    took 4 other outputs inside the bar, ``benchmarks/turns_matrix.py``); 3.6 % since the take's step frequency
    counts a stance without a midstance as a step (``body.gait.step_period``)."""
    from froude.body.gait import detect_gait
    from froude.body.path import take_path

    prep = prepared[name]
    res = pipeline.scale(prep, "giant", strides=math.ceil(prep.path.n_steps / 2) + 1)
    L, body = res.retarget.L, res.retarget.body
    com, markers = body.com_and_markers(res.motion)
    out = take_path(res.motion, body, com, detect_gait(res.motion, body, markers, com))
    arc_c, psi_c = prep.path.arc_length_m, prep.path.heading_rad
    frames = np.arange(out.arc_length_m.size)
    turns = []
    for st in out.steps:
        a0, a1 = (float(np.interp(t / out.frame_time, frames, out.arc_length_m)) / L for t in (st.t0_s, st.t1_s))
        if a1 <= arc_c[-1]:
            turns.append((math.degrees(st.heading_change_rad),
                          math.degrees(np.interp(a1, arc_c, psi_c) - np.interp(a0, arc_c, psi_c))))
    assert len(turns) >= 5 and max(abs(c) for _, c in turns) > 20.0, turns
    assert all(abs(o - c) <= 3.0 for o, c in turns), turns
    assert all(abs(c / o - 1.0) <= 0.05 for o, c in turns if abs(c) >= 10.0), turns


@pytest.mark.slow  # a scale of each turn (3-5 s)
@pytest.mark.parametrize("name", [_giant_case(n) for n in LOCO_TURNS])
def test_every_walk_turn_scaled_to_a_giant_meets_every_bar(name, prepared):
    """The giant's output of every walk-turn (and the two walks at an angle, the backward walk) meets every
    physics bar, the path's among them and the stricter skate included: 8 of the 12 missed one while the bent
    feet of a double support were left out of the legs' reach (a held tip 14 mm off its target on
    walk-turn-right_feminine_001; synthesis.targets.within_reach); 2 (5.0 and 7.3 mm, the toes of a planted
    foot) when the travel line took off the COM's sway, until each foot was bent as one piece
    (synthesis.bend.foot_places)."""
    prep = prepared[name]
    r = pipeline.scale(prep, "giant", strides=math.ceil(prep.path.n_steps / 2) + 1).report
    assert r.check_bars() == [] and r.foot_skate_floor_mm <= 5.0


def test_a_lost_turn_is_a_missed_bar_said_in_degrees(prepared):
    """Never silently straight: an output of a turning clip that walks straight (here the take straightened
    along its path, which the machines see) misses a bar that says so in degrees."""
    from froude.report.metrics import physics_report

    prep = prepared[TURN]
    rep = physics_report(prep.motion, prep.body, reference_path=prep.path, reference_leg_length=prep.body.leg_length)
    miss = [f for f in rep.check_bars() if f.startswith("the output turns")]
    assert len(miss) == 1 and "where the clip turns +95 deg" in miss[0], rep.check_bars()
    assert abs(rep.extras["path_vs_clip"]["heading_change_deg"]["output"]) < 3.0


def test_a_straight_take_that_veers_is_met_and_said(prepared):
    """A straight run (09_05 veers +1.8 deg) is modelled straight, not straightened (its outputs are the
    goldens'): the path bar is met and the note says so."""
    prep = prepared["09_05"]
    assert prep.turn is None
    cmp = pipeline.scale(prep, "giant").report.extras["path_vs_clip"]
    assert cmp["heading_change_deg"]["intended"] == 0.0 and abs(cmp["heading_change_deg"]["output"]) < 1.0
    assert cmp["misses"] == [] and "veers +1.8 deg" in cmp["notes"][0]


def test_the_turning_run_is_a_run(run_cli, tmp_path):
    """CMU 16_51 (a run turning 82 deg) read "unknown: no flight phase": its turn's feet gaps last 3 frames at
    120 Hz, shorter than a flight must last, and the COM's force stays above 0.2 BW in most of them (the gait
    decision closes those, body.gait). It runs: flights where the COM says so.
    (Its child misses physics bars, said in one line, and is not written: docs/path.md.)"""
    code, out, _ = run_cli("info", clip("cmu-turns/16_51"), "--json")
    d = json.loads(out)
    assert code == 0 and d["kind"] == "running", d["verdict"]
    assert len(d["flight_times_s"]) >= 2
    out = tmp_path / "child.bvh"
    code, _, err = run_cli("scale", clip("cmu-turns/16_51"), "--character", "child", "-o", out, "-q")
    assert code in (1, 2) and err.count("\n") == 1 and "Traceback" not in err and not out.exists()


def test_a_braking_stance_does_not_refuse_the_run(run_cli, tmp_path):
    """CMU 16_51 enters its turn with a braking plant (the right foot at 0.33 s) in which the leg's force does
    not rise as it shortens: the spring fit of that stance has K < 0, and one stance refused the whole take
    ("the leg does not act as a spring"). The machine's leg is fitted to the other stances; the stance is
    named, in the fit's table and in scale's notes."""
    js = tmp_path / "fit.json"
    code, out, err = run_cli("fit", clip("cmu-turns/16_51"), "-o", js)
    assert code == 0, err
    rows = [ln for ln in out.splitlines() if "not a spring" in ln]
    assert len(rows) == 1 and rows[0].split()[1] == "right" and abs(float(rows[0].split()[2]) - 0.33) < 0.02, out
    d = json.loads(js.read_text())
    assert d["cycle"]["K"] > 0 and [st["fit"] is None for st in d["stances"] if not st["partial"]] == \
        [False, True, False, False, False, False]
    code, _, err = run_cli("scale", clip("cmu-turns/16_51"), "--character", "child", "-o", tmp_path / "c.bvh",
                           "--keep")
    assert code == 0 and "1 of 6 stances (the right foot's at 0.33 s) do not act as a spring" in err, err


def test_a_toe_off_is_not_a_stance(run_cli):
    """CMU 16_18 starts with its left foot rolling off the floor: every marker of it rose over the contact
    threshold for 60 ms between the heel's rise and the toe's (0.00-0.03 s and 0.09-0.14 s), and info read a
    0.05 s stance and two left stances in a row. A foot that lifts for less than a swing has not stepped
    (``body.gait.MIN_SWING_S``): the contacts alternate and each complete one lasts a walker's stance."""
    code, out, err = run_cli("info", clip("cmu-turns/16_18"), "--json")
    assert code == 0, err
    d = json.loads(out)
    feet = [c["foot"] for c in d["contacts"]]
    assert all(a != b for a, b in zip(feet, feet[1:])), feet
    assert min(d["stance_times_s"]) > 0.5, d["stance_times_s"]


def test_a_lean_missed_for_speed_says_the_speeds(prepared):
    """The running machine runs a take's mean speed; CMU 16_51 brakes into its turn (3.1 m/s before it, 2.3 in
    it), so its child runs the turn faster than the clip (scaled) and leans further into it, as
    tan phi = v^2 / (g r) says: a missed bar, and its sentence gives both speeds, each measured along its own
    path (the output's step, the clip's at that place x sqrt(L))."""
    prep = prepared["cmu-turns/16_51"]
    res = pipeline.scale(prep, "child")
    cmp = res.report.extras["path_vs_clip"]
    rows = [r for r in cmp["lean_per_turning_step"] if not r["met"]]
    assert rows, cmp["lean_per_turning_step"]
    worst = max(rows, key=lambda r: abs(r["lean_deg"] - r["wanted_deg"]))
    assert worst["speed_m_s"] > 1.1 * worst["clip_speed_m_s"] and worst["lean_deg"] > worst["wanted_deg"], worst
    text = next(m for m in cmp["misses"] if m.startswith("the output leans"))
    assert f"at {worst['clip_speed_m_s']:.2f} m/s (scaled), the output at {worst['speed_m_s']:.2f}" in text, text


def test_a_braking_stance_is_a_step_of_the_cadence():
    """The step frequency counts consecutive midstances as one step apart; CMU 16_51's first three stances
    (stutter steps braking into the turn) have none, the COM staying behind the planted foot, and the
    clip read 2.83 steps/s. Its touchdowns (another measure: the feet's contacts) step at 5.1 per second."""
    from froude.body.gait import detect_gait, summarize
    from froude.body.load import load_bvh
    from froude.body.model import BodyModel

    motion = load_bvh(clip("cmu-turns/16_51"))
    body = BodyModel.from_skeleton(motion.skeleton, mass=70.0)
    com, markers = body.com_and_markers(motion)
    gait = detect_gait(motion, body, markers, com)
    on = np.sort([st.t_on for st in gait.stances if st.start > 0]) * gait.frame_time
    f_touchdowns = (len(on) - 1) / (on[-1] - on[0])
    f = summarize(motion, body, com, gait).step_frequency
    assert abs(f / f_touchdowns - 1.0) < 0.05, (f, f_touchdowns)


# ---- every verb on a turn (issue 28 acceptance 5) ------------------------------------------------------
def test_the_studio_draws_a_turns_reference_as_taken(prepared, tmp_path):
    """The machines see a turning take straightened; the studio's reference is the take as it was taken: its
    BVH turns as the clip's file does (the tests' own reader, within 0.5 deg), its contacts lie under its own
    feet, and the straightened take (what it drew before) does not turn."""
    from froude.apps.studio.tracks import reference_track
    from froude.io.bvh import save_bvh

    prep = prepared[TURN]
    track = reference_track(prep)
    window_s = 1.0
    save_bvh(track.motion, tmp_path / "reference.bvh")
    save_bvh(prep.motion, tmp_path / "straightened.bvh")
    want = _oracle_heading_deg(clip(TURN), window_s)
    assert abs(_oracle_heading_deg(tmp_path / "reference.bvh", window_s) - want) <= 0.5
    assert abs(_oracle_heading_deg(tmp_path / "straightened.bvh", window_s)) <= 0.3 * abs(want)
    markers = prep.body.com_and_markers(track.motion)[1]  # (F, 2, 3, 3)
    feet = np.array([markers[(s.start + s.stop - 1) // 2, s.foot].mean(axis=0)
                     for s in prep.gait.stances])
    horizontal = np.array([1.0, 1.0, 1.0]) - UP
    assert np.abs((feet - track.contacts) * horizontal).max() <= 0.15  # a foot's length, not a stride


def test_the_naive_retarget_of_a_turn_turns(prepared, tmp_path):
    """The studio's naive comparison (engines' way) of a turning take plays the take as taken, so it turns as
    the clip's file does (the tests' own reader, within 3 deg), scaled by L; it repeated the straightened
    stride cycle before and walked straight (-2.0 deg against the file's +94.1). The same for
    ``scale(..., method="naive")``."""
    pytest.importorskip("viser")
    from test_studio import _free_port

    from froude.apps.studio.app import Studio
    from froude.io.bvh import save_bvh

    prep = prepared[TURN]
    window_s = 1.0
    want = _oracle_heading_deg(clip(TURN), window_s)
    studio = Studio(prep, port=_free_port())
    try:
        tab = studio.open_tab()
        tab._solve_naive()
        assert tab.naive is not None and tab.naive.result.method == "naive"
        save_bvh(tab.naive.result.motion, tmp_path / "naive.bvh")
        assert abs(_oracle_heading_deg(tmp_path / "naive.bvh", window_s) - want) <= 3.0
        assert any("plays the take as it was taken" in n for n in tab.naive.result.notes)
    finally:
        studio.stop()
    child = pipeline.scale(prep, "child", method="naive", speed=1.2)
    save_bvh(child.motion, tmp_path / "child.bvh")
    assert abs(_oracle_heading_deg(tmp_path / "child.bvh", window_s / 1.2) - want) <= 3.0
    # the whole take, played 1.2 times faster
    assert abs(child.motion.duration - prep.motion.duration / 1.2) <= child.motion.frame_time


@pytest.mark.browser
@pytest.mark.timeout(600)
def test_studio_takes_a_turn(tmp_path):
    """The studio opens a turning walk: its facts say the turn, the child comes out along the path (the
    downloaded BVH turns, by the tests' own reader), and a screenshot of the scene is kept."""
    from test_studio_browser import (
        CHROMIUM,
        CHROMIUM_ARGS,
        VIEWPORT,
        _close_toasts,
        _download,
        _pick,
        _wait_state,
        running_studio,
    )

    if not Path(CHROMIUM).exists():
        pytest.skip(f"{CHROMIUM} is missing (apt-get install chromium; scripts/test installs it)")
    pw = pytest.importorskip("playwright.sync_api")
    pytest.importorskip("viser")
    turn = clip(TURN)
    shots = Path(os.environ.get("FROUDE_STUDIO_SHOTS", tmp_path / "shots"))
    shots.mkdir(parents=True, exist_ok=True)
    with running_studio([str(turn)], timeout_s=240) as (proc, url):  # the walking fit comes first
        with pw.sync_playwright() as p:
            ctx = p.chromium.launch_persistent_context(
                str(tmp_path / "chromium-profile"), executable_path=CHROMIUM, args=CHROMIUM_ARGS, headless=True,
                viewport=VIEWPORT, accept_downloads=True)
            try:
                page = ctx.new_page()
                page.goto(url)
                s0 = _wait_state(page, status="ok", timeout=180)
                assert s0["clip"] == turn.name
                facts = page.get_by_text("frames/s").first.inner_text()
                assert "turns +95° over" in facts, facts
                _pick(page, "Character", "child")
                _wait_state(page, status="ok", character="child", timeout=180)
                _close_toasts(page)
                page.wait_for_timeout(2500)
                page.screenshot(path=str(shots / "turn_child.png"))
                bvh = _download(page, "Download BVH", tmp_path)
            finally:
                ctx.close()
        print(f"studio screenshots: {shots}")
    # the studio's own strides: the output turns in proportion to its steps, at most as the clip
    got = _oracle_heading_deg(bvh, 1.0)
    assert 45.0 <= got <= 94.5 + 3.0, got


@pytest.mark.slow
def test_a_batch_of_a_turn_and_a_straight_run(run_cli, tmp_path):
    """A batch of a turning walk and a straight run (one Dask worker): both done with every bar met, and the
    turn's output turns (the tests' own reader on the written file), the straight run's does not."""
    pytest.importorskip("dask")
    turn, straight = clip(TURN), clip("09_01")
    plan = tmp_path / "plan.yaml"
    plan.write_text("characters: [child]\nspeeds: [1.0]\nstrides: 4\n")
    out = tmp_path / "out"
    code, _, err = run_cli("batch", turn, straight, "--plan", plan, "-o", out, "--workers", "1", "-q")
    assert code == 0, err
    # clip ids are the paths below the inputs' common folder
    rows = {Path(r["clip"]).name: r for r in csv.DictReader((out / "index.csv").open())}
    assert set(rows) == {turn.stem, "09_01"} and all(r["status"] == "ok" for r in rows.values()), rows
    assert rows["09_01"]["bars_met"] == "yes" and rows[turn.stem]["bars_met"] == "yes", rows
    stride_s = 2.0 / float(rows[turn.stem]["step_frequency_hz"])
    assert _oracle_heading_deg(out / rows[turn.stem]["output"], stride_s) > 45.0  # 4 strides of the child
    assert abs(_oracle_heading_deg(out / rows["09_01"]["output"], 0.6)) < 5.0


def test_fit_models_the_take_that_scale_models(prepared, run_cli, tmp_path):
    """``froude fit`` of a turning take fits the take straightened along its path, as ``prepare`` does for
    every verb: the same machine, and the note that says so (it fitted the turning take as it was, with the
    straight machine's sagittal plane cutting across the turn)."""
    out = tmp_path / "turn.machine.json"
    code, _, err = run_cli("fit", clip(TURN), "-o", out)
    assert code == 0, err
    written = json.loads(out.read_text())["cycle"]
    fitted = prepared[TURN].machine.to_dict()["cycle"]
    assert written.keys() == fitted.keys()
    for k, v in fitted.items():
        assert written[k] == pytest.approx(v, rel=1e-9, abs=1e-12), k
    assert "a turning take" in err and "runs along its path" in err


#: Turning clips whose own strides do not close the force bar (measured 29 Nov: force across the path against
#: m v^2/r of the stride, body weights): strict xfails.
#: (walk-turn-right_exhausted_001: -0.074 against -0.087 and 16_18: 0.082 against 0.093, until the bar read the
#: mean force across the path over the chord factor of the stride's turn: -0.079 and 0.087 now.)
FORCE_OPEN_CLIPS: dict[str, str] = {}


def test_the_force_bar_closes_around_a_circle():
    """A COM going around a circle of radius 0.8 m at a steady 1.2 m/s, steps of 0.58 s turning 50 deg each:
    the force across the path is m v^2 / r = 0.183 body weights at every instant, and the bar reads it so on
    every stride (within 0.5 %). Measured as the velocity's change over the stride across its middle, it read
    the chord of the turn, 2 v sin(dpsi/2), 12 % short of v dpsi on these 100 deg strides: a missed bar on a
    perfect circle."""
    from froude.body.path import PathStep, TakePath
    from froude.core.constants import GRAVITY
    from froude.report.path_report import force_per_stride

    dt, v, r, step_s = 1 / 120, 1.2, 0.8, 0.58
    t = np.arange(int(4.0 / dt)) * dt
    psi = v / r * t
    p = r * np.stack([np.sin(psi), np.zeros_like(psi), 1.0 - np.cos(psi)], axis=1)
    vel = v * np.stack([np.cos(psi), np.zeros_like(psi), np.sin(psi)], axis=1)
    heading = np.unwrap(yaw_of(vel))

    def u(ts):
        return tuple(float(np.interp(ts, t, vel[:, k])) for k in range(3))

    on = np.arange(0.1, t[-1] - step_s, step_s)
    turn = float(heading[1] - heading[0]) / dt * step_s  # the heading's change over a step (its sign: the turn's)
    steps = tuple(PathStep(i % 2, a, a + step_s, v * step_s, turn, v * step_s / turn, v, 0.0, 0.0, u(a), u(a + step_s))
                  for i, a in enumerate(on))
    path = TakePath(dt, p, v * t, heading, np.full_like(t, 1 / r), np.full_like(t, v), heading,
                    np.zeros_like(t), float(heading[-1] - heading[0]), 0.6, 2 * step_s, steps, p)
    rows = force_per_stride(path)
    assert len(rows) == len(steps) - 1
    for row in rows:
        assert abs(row["m_v2_r_bw"]) == pytest.approx(v * v / r / GRAVITY, rel=1e-3)
        assert row["force_bw"] == pytest.approx(row["m_v2_r_bw"], rel=5e-3) and row["met"], row


@pytest.mark.parametrize("name", [pytest.param(n, marks=[pytest.mark.xfail(strict=True, reason=FORCE_OPEN_CLIPS[n])]
                                               if n in FORCE_OPEN_CLIPS else ()) for n in LOCO_TURNS + CMU_TURN_CLIPS])
def test_the_force_bar_holds_on_the_clips_themselves(name):
    """Acceptance 28.3's bar, applied to each shared turning clip's own path: every turning stride's force across
    the path closes on m v^2/r within 10 %. The walkers slow into a turn and speed up out of it; the force
    across the path's heading at a stride's middle took a share of that braking and pushing where the heading
    was not the bisector of the stride's two velocities, and 12 of the 89 turning strides of the clips missed
    the bar (walk-turn-left_exhausted_001: 0.031 body weights against 0.049). ``report.path_report.
    force_per_stride`` takes that share off."""
    from froude.body.load import load_bvh
    from froude.body.model import BodyModel
    from froude.body.path import is_straight
    from froude.body.take import analysed_take
    from froude.report.path_report import force_per_stride

    motion = load_bvh(clip(name))
    path = analysed_take(motion, BodyModel.from_skeleton(motion.skeleton)).clip_path
    rows = force_per_stride(path)
    assert rows or is_straight(path)  # a turn has turning strides (a straight take may: a veer)
    assert all(r["met"] for r in rows), [r for r in rows if not r["met"]]


def test_scale_of_a_turn_makes_the_whole_turn_by_default(run_cli, tmp_path):
    """`froude scale TURN --character child` without --strides: the output makes the clip's whole turn and a
    stride on (``pipeline.default_strides``) and meets every bar. At the 4 strides every other take gets it
    stopped in the turn: asked for 8 of the clip's steps' share of the turn and measured over its last
    stride while still turning, 9 of the 12 walk-turns' children were refused (walk-turn-left_exhausted_001:
    +72 deg where +94 was asked). --strides still gives what it says."""
    src = clip("bandai-locomotion/turns/dataset-2_walk-turn-left_exhausted_001")
    code, _, err = run_cli("scale", src, "--character", "child", "-o", tmp_path / "c.bvh", "-q")
    assert code == 0, err
    rep = json.loads((tmp_path / "c.report.json").read_text())
    h = rep["extras"]["path_vs_clip"]["heading_change_deg"]
    assert h["intended"] == h["clip"] and abs(h["output"] - h["clip"]) <= 3.0, h
    code, _, err = run_cli("scale", src, "--character", "child", "--strides", "2", "-o", tmp_path / "s.bvh", "-q",
                           "--keep")
    assert code in (0, 1), err
    n = json.loads((tmp_path / "s.report.json").read_text())["n_frames"]
    assert n < json.loads((tmp_path / "c.report.json").read_text())["n_frames"] / 2


def test_a_batch_of_turns_and_straight_clips(run_cli, tmp_path):
    """Issue 28 acceptance 5, batch: two walk-turns and a straight walk with a plan that gives no length: every
    output is written (status ok) and each turn makes its whole turn (the plan's default length is the
    pipeline's, ``pipeline.default_strides``; at 4 strides walk-turn-left_exhausted_001's child stopped in its
    turn and was refused)."""
    import csv

    names = ["bandai-locomotion/turns/dataset-2_walk-turn-left_exhausted_001",
             "bandai-locomotion/turns/dataset-2_walk-turn-right_feminine_001",
             "bandai-locomotion/walks/dataset-2_walk_normal_002"]
    plan = tmp_path / "plan.yaml"
    plan.write_text("characters: [child]\n")
    out = tmp_path / "out"
    code, _, err = run_cli("batch", *[clip(n) for n in names], "--plan", plan, "-o", out, "--workers", 1, "-q")
    with open(out / "index.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert code == 0 and len(rows) == 3 and all(r["status"] == "ok" for r in rows), (err, rows)
    for r in rows:
        rep = json.loads(pipeline.report_path(out / r["output"]).read_text())
        h = (rep["extras"].get("path_vs_clip") or {}).get("heading_change_deg")
        if "turn" in r["clip"]:
            assert h and abs(h["output"] - h["clip"]) <= 3.0 and abs(h["clip"]) > 80.0, (r["clip"], h)


def test_a_shorter_output_is_asked_the_share_of_the_turn_its_stretch_makes(prepared):
    """``intended_heading_change`` for an output shorter than the clip: the clip's turn times the share of it
    that the clip's path makes over the stretch the output covers (to half a stride before its end: the travel
    over the output's last stride), not the share of the clip's steps (a take turns in a few of its steps). On
    walk-turn-left_active_001 (its turn in the middle of 9 steps): an output covering the path up to half a
    stride past where it has turned half its heading is asked half the turn; one covering the first 10 % of
    the path and half a stride, almost none of it, where the steps' share asks a tenth."""
    from froude.report.path_report import intended_heading_change

    path = prepared["bandai-locomotion/turns/dataset-2_walk-turn-left_active_001"].path
    arc, psi = np.maximum.accumulate(path.arc_length_m), path.heading_rad
    whole, total = psi[-1] - psi[0], path.travel_heading_change_rad
    half_stride = 0.5 * path.stride_s * path.path_speed_m_s  # the output's last stride travels half of it before
    half_way = float(arc[np.argmax(np.abs(psi - psi[0]) >= 0.5 * abs(whole))]) + half_stride
    assert intended_heading_change(path, 0.5 * path.n_steps, half_way) == pytest.approx(0.5 * total, rel=0.02)
    start = 0.1 * float(arc[-1]) + half_stride
    share = float(np.interp(start - half_stride, arc, psi) - psi[0]) / whole
    assert abs(share) < 0.05  # the take walks straight before it turns
    assert intended_heading_change(path, 0.1 * path.n_steps, start) == pytest.approx(total * share, abs=1e-12)
    assert intended_heading_change(path, 0.1 * path.n_steps) == pytest.approx(0.1 * total, rel=1e-12)
    assert intended_heading_change(path, 2.0 * path.n_steps, 2.0 * float(arc[-1])) == total


def test_a_rig_whose_root_stays_put_turns_at_its_hips(prepared):
    """Bandai's joint_Root stays put in a take and holds the Hips: the straightening turns the Hips within it,
    not the root (``body.path.yaw_carrier``), and puts the take back exactly. Turned at the root, the body's
    heading was split between the root and the Hips, the reference stride's two rotations jumped at its loop
    by a stride's turn, and walk-turn-right_normal_001's child turned its root 28 deg in one frame (a joint
    jump of 30.6 deg against 26.7 allowed); its child now meets every bar. CMU's root is the hips itself."""
    from froude.body.path import straighten, unstraighten, yaw_carrier

    prep = prepared["bandai-locomotion/turns/dataset-2_walk-turn-right_normal_001"]
    m = prep.motion  # straightened
    assert m.skeleton.names[yaw_carrier(m)] == "Hips"
    assert np.ptp(m.rotations[:, 0], axis=0).max() == 0.0
    joints = list(range(m.skeleton.n_joints))
    again = straighten(unstraighten(m, prep.turn), prep.turn)
    assert np.abs(prep.body.joint_positions(again, joints) - prep.body.joint_positions(m, joints)).max() < 1e-9
    from froude.io.bvh import read_bvh

    assert yaw_carrier(read_bvh(clip("cmu-turns/16_51"))[0]) == 0
    r = pipeline.scale(prep, "child").report
    assert r.check_bars() == [], r.check_bars()
