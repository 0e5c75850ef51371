"""Issue 5: scaling running to new characters and speeds (§5.1, §5.2, §6), on the real clips."""
from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

import froude
from froude.body.characters import list_presets
from froude.core import quat
from froude.core.constants import GRAVITY
from froude.flow import pipeline
from froude.ik.correct import correct, stride_samples
from froude.report.metrics import BARS, physics_report

from conftest import RUNNING, clip, clip_params, matrix_group

PRESETS = ["child", "troll", "giant", "small"]
SPEEDS = [0.7, 1.0, 1.2]




#: Outputs that miss a bar, measured on this branch (benchmarks/bars_matrix.py --matrix 13 gives the same
#: figures at 120 Hz). None today: the last ones, the stricter skate measure (ball and tip near the floor, a
#: bar since issue 13) at touchdown or lift-off, were met by the skate branch. Every output meets every bar
#: and must keep doing so; a listed one that starts meeting them fails (strict), so that it comes off the list.
SCALE_MISSES: dict = {}


def _scale_cases():
    names = clip_params(RUNNING)
    if not isinstance(names[0], str):
        return names
    cases = []
    for name in names:
        for preset in PRESETS:
            for s in SPEEDS:
                miss = SCALE_MISSES.get((name, preset, s))
                marks = () if miss is None else pytest.mark.xfail(strict=True, reason=miss)
                cases.append(pytest.param(name, preset, s, marks=(*marks, matrix_group(name)),
                                          id=f"{name}-{preset}-x{s}"))
    return cases


@pytest.mark.parametrize("name,preset,s", _scale_cases())
def test_physics_bars_every_preset_and_speed(matrix_outputs, name, preset, s):
    """Acceptance 1: every output of every clip, preset and speed meets the physics bars (docs/architecture.md).
    The outputs are the golden matrix's (``pipeline.scale(prepared, preset, speed=s, strides=4)``), computed
    once for this test and test_golden."""
    rep = matrix_outputs[f"scale/{name}/{preset}/{s:g}"].report
    assert np.isfinite(rep.com_tracking_max_mm) and rep.reference_max_joint_jump_deg > 0
    assert rep.check_bars() == []


@pytest.mark.parametrize("name", clip_params(["09_01", "09_05", "02_03"]))
def test_dynamic_similarity(prepared, name):
    """Acceptance 2: step frequency × L^-1/2 and U unchanged for a scaled character; speed × s and the step
    duration of the human speed law (issue 30: it replaced §5.2's step duration kept) for a speed change."""
    from froude.machine.speed_law import cadence_ratio

    prep = prepared[name]
    same = pipeline.scale(prep, None, speed=1.0, strides=6).report
    for preset in ("child", "troll", "giant"):
        res = pipeline.scale(prep, preset, speed=1.0, strides=6)
        L = res.retarget.L
        assert res.report.step_frequency_hz == pytest.approx(same.step_frequency_hz / np.sqrt(L), rel=0.02)
        assert res.report.froude_U == pytest.approx(same.froude_U, rel=0.02)
    for s in (0.7, 1.2):
        rep = pipeline.scale(prep, None, speed=s, strides=6).report
        assert rep.mean_speed_m_s == pytest.approx(s * same.mean_speed_m_s, rel=0.02)
        law = float(cadence_ratio(s, prep.law_cadence))
        assert rep.step_frequency_hz == pytest.approx(law * same.step_frequency_hz, rel=0.02)


def test_naive_baseline_floats(prepared):
    """Acceptance 3: the engine-style retarget keeps timing, so its flight gravity is L × 9.81."""
    prep = prepared["09_01"]
    naive = pipeline.scale(prep, "child", method="naive", strides=4)
    physical = pipeline.scale(prep, "child", strides=4)
    L = naive.retarget.L
    g = naive.report.flight_gravity_m_s2
    assert abs(g - GRAVITY) / GRAVITY > 0.15
    # the engine keeps the reference's timing, so it keeps the reference's own (mocap-measured) gravity × L
    g_ref = physics_report(prep.motion, prep.body).flight_gravity_m_s2
    assert g == pytest.approx(L * g_ref, rel=0.15)
    assert physical.report.flight_gravity_m_s2 == pytest.approx(GRAVITY, rel=0.03)


@pytest.mark.parametrize("name", clip_params(RUNNING))
def test_ten_strides_no_seam(prepared, name):
    """Acceptance 4: 10 strides from a 1.5-2 stride clip, no visible seam: the largest joint-angle jump
    anywhere (loop points included) is at most 1.5 × the largest in the reference."""
    prep = prepared[name]
    res = pipeline.scale(prep, None, strides=10)
    m = res.motion
    assert len(res.path.foot_of_step) == 20
    jumps = np.degrees(quat.angle_between(m.rotations[1:], m.rotations[:-1])).max(axis=1)
    assert jumps.max() <= 1.5 * res.report.reference_max_joint_jump_deg
    # and at each stride boundary of the machine (the loop points of the cycle) in particular
    seams = np.searchsorted(res.path.times, res.path.t_touchdown[::2])
    assert jumps[np.clip(seams - 1, 0, len(jumps) - 1)].max() <= 1.5 * res.report.reference_max_joint_jump_deg


def test_long_output_is_the_tiled_cycle(prepared):
    """A steady output longer than PERIODIC_MIN_STRIDES is solved on one stride and tiled; it must agree
    with the frame-by-frame solution and still meet the bars.

    The two routes solve slightly different targets: a contact's rest is set by its lowest target in a window
    (synthesis.targets._rest_on_floor), found among the samples of each route, and a toe's dip at push-off
    lasts about a frame at 120 Hz (the troll's tip on 09_03: each contact of the frame-by-frame route moved
    by 6.3-9.9 mm, the tiled stride's by 7.1). So the solutions agree to 2 mm beyond where their targets
    differ, and the targets of a loaded foot differ by less than the report's rest-height bar."""
    prep = prepared["09_03"]
    plan = pipeline.plan_scale(prep, "troll", strides=pipeline.PERIODIC_MIN_STRIDES + 2)
    long = plan.finish()
    assert plan.periodic is not None  # solved on one stride and tiled
    body = long.retarget.body  # solved as the tiled stride is: its repair aims under the rest-height bar
    direct = correct(long.targets, body, rest_bar_m=BARS["rest_height_L"] * body.leg_length).motion
    p_long = long.retarget.body.foot_markers(long.motion)
    p_direct = long.retarget.body.foot_markers(direct)
    d = np.linalg.norm(p_long - p_direct, axis=-1)
    # the tiled route's own targets at the output's times, as tile_stride places its poses
    one, period, dense_fps = pipeline.stride_targets(prep, long.retarget, plan.periodic)
    n, i0, w = stride_samples(long.path.times, period, dense_fps, len(one.com))
    stride = long.path.contacts[2] - long.path.contacts[0]
    stride[1] = 0.0
    w4 = w[:, None, None, None]
    tiled_targets = one.markers[i0] * (1 - w4) + one.markers[i0 + 1] * w4 + n[:, None, None, None] * stride
    d_targets = np.linalg.norm(tiled_targets - long.targets.markers, axis=-1)
    loaded = long.targets.marker_weight >= 0.5 * long.targets.marker_weight.max()
    assert d_targets[loaded].max() < BARS["rest_height_L"] * body.leg_length
    assert (d - d_targets)[loaded].max() < 0.002  # feet on the ground: the same to 2 mm where the targets are
    assert d.max() < 0.03  # swinging feet (weakly guided, several near-equal poses): within 3 cm
    assert not long.report.check_bars()
    assert len(long.path.foot_of_step) == 2 * (pipeline.PERIODIC_MIN_STRIDES + 2)


def test_output_file_and_report(tmp_path, prepared):
    """The CLI writes the BVH with the input's joint names and channel orders, and the report."""
    out = tmp_path / "child.bvh"
    r = subprocess.run([sys.executable, "-m", "froude", "scale", str(clip("09_01")), "--character",
                        "child", "--speed", "0.7", "--strides", "2", "-o", str(out)], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert "Froude number" in r.stdout and "physics bars: all met" in r.stdout
    ref = froude.load_bvh(clip("09_01"))
    got = froude.load_bvh(out)
    assert got.skeleton.names == ref.skeleton.names and got.skeleton.channels == ref.skeleton.channels
    assert got.skeleton.same_topology(ref.skeleton) is None
    rep = json.loads(out.with_name("child.report.json").read_text())
    assert rep["schema"] == "froude.report/1" and rep["extras"]["character"] == "child"
    assert abs(rep["flight_gravity_m_s2"] - GRAVITY) < 0.03 * GRAVITY


@pytest.mark.parametrize("args, needle", [
    (["--character", "elf"], "unknown character 'elf'"),
    (["--char-mass", "0"], "--char-mass: must be from 1 to 5000 kg, got 0"),
    (["--height", "-1"], "--height: must be from 0.3 to 10 m, got -1"),
    (["--speed", "0"], "--speed: factor 0 is outside the supported range 0.1x to 5x"),
    (["--speed", "fast"], "--speed: cannot read 'fast'"),
])
def test_bad_input_one_line_exit_2(tmp_path, args, needle):
    """Acceptance 6: one-line errors and exit status 2, nothing written."""
    out = tmp_path / "o.bvh"
    r = subprocess.run([sys.executable, "-m", "froude", "scale", str(clip("09_01")), *args, "-o", str(out)],
                       capture_output=True, text=True)
    assert r.returncode == 2
    err = [line for line in r.stderr.splitlines() if "error" in line]
    assert len(err) == 1 and needle in err[0], r.stderr
    assert "Traceback" not in r.stderr and not out.exists()


def test_jump_clip_and_topology_mismatch(tmp_path):
    # jumping in place has no machine (walks have theirs since issue 17: tests/test_walk_scale.py)
    r = subprocess.run([sys.executable, "-m", "froude", "scale", str(clip("02_04")), "-o",
                        str(tmp_path / "w.bvh")], capture_output=True, text=True)
    assert r.returncode == 2 and "locomotion" in r.stderr and "Traceback" not in r.stderr
    # a target skeleton with another topology: drop the last joint of a copy of the clip
    text = (clip("09_01")).read_text().replace("JOINT RThumb", "JOINT RThumbX")
    bad = tmp_path / "other.bvh"
    bad.write_text(text)
    r = subprocess.run([sys.executable, "-m", "froude", "scale", str(clip("09_01")), "--character", str(bad),
                        "-o", str(tmp_path / "x.bvh")], capture_output=True, text=True)
    assert r.returncode == 2 and "RThumbX" in r.stderr, r.stderr
    assert not (tmp_path / "x.bvh").exists()


def test_presets_listed_and_yaml_character(tmp_path, prepared):
    assert {"child", "troll", "giant", "small"} <= set(list_presets())
    y = tmp_path / "hobbit.yaml"
    y.write_text("name: hobbit\nheight: 1.1\nmass: 30\nproportions:\n  legs: 0.85\n  head: 1.2\n")
    res = pipeline.scale(prepared["09_02"], str(y), strides=2)
    assert res.retarget.body.stature == pytest.approx(1.1, rel=1e-6)
    assert res.retarget.body.total_mass == pytest.approx(30.0)
    assert not res.report.check_bars()
