"""Scaling walks (issue 17, acceptance 2): child, troll and giant by dynamic similarity on the real walks.

Each output steps at L^-1/2 × the clip's frequency with the clip's Froude number (within 2 %), keeps the
clip's double-support share (within 2 points), meets the skate and penetration bars (≤ 5 mm) and every
other physics bar; the naive retarget keeps the clip's cadence, which the report shows.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from froude.flow import pipeline

from conftest import BANDAI_WALKS, LOCO_RUNS, LOCO_WALKS, MOCAP, WALKING, clip, clip_params

CHARACTERS = ("child", "troll", "giant")

#: Outputs that miss a bar or the double-support share today (none: every walk and character meets them since
#: the rolling foot lands and leaves at its held stance's level, synthesis.feet._contact_level, and a walk's
#: targets are raised only beyond the pose's own reach, synthesis.targets._lift_out_of_reach), measured with
#: `python docs/make_walk_table.py`. An entry (name, character): reason marks that case as a strict xfail.
KNOWN_MISSES: dict[tuple[str, str], str] = {}


def _cases(with_misses: bool):
    out = []
    for p in clip_params(WALKING) + clip_params(BANDAI_WALKS):
        if not isinstance(p, str):  # the data is absent: the skipping parameter, once per character
            out += [pytest.param(None, ch, marks=p.marks) for ch in CHARACTERS]
            continue
        name = p
        for ch in CHARACTERS:
            why = KNOWN_MISSES.get((name, ch)) if with_misses else None
            marks = [pytest.mark.xfail(strict=True, reason=f"issue 17 acceptance 2 not met on {name} as {ch}: "
                                                           f"{why}")] if why else []
            out.append(pytest.param(name, ch, marks=marks, id=f"{name}-{ch}"))
    return out


#: Outputs known to miss issue 30's rest-height bar (a foot's lowest point in stance within 0.3 % of L of the
#: clip's, scaled), measured at e1c635e: the other bars are still asserted, and the miss itself, so that a fix
#: shows here (remove the entry then).
REST_MISSES: dict[tuple[str, str], str] = {}  # none since the IK's repair aims under the rest bar


def _bars_missed(report, key) -> list[str]:
    """check_bars() without a known rest-height miss (REST_MISSES), asserting that it is still missed."""
    fails = report.check_bars()
    if key not in REST_MISSES:
        return fails
    rest = [f for f in fails if " foot rests " in f]
    assert rest, f"{key} now meets the rest-height bar: remove it from REST_MISSES"
    return [f for f in fails if f not in rest]


@pytest.fixture(scope="module")
def walks():
    cache = {}

    def get(name):
        if name not in cache:
            cache[name] = pipeline.prepare(clip(name))
        return cache[name]

    return get


@pytest.mark.parametrize("name,character", _cases(with_misses=False))
def test_scaled_walk_steps_at_the_similar_cadence(name, character, walks):
    prep = walks(name)
    res = pipeline.scale(prep, character)
    r = res.report
    c = r.extras["cadence"]
    L = res.retarget.L
    assert r.extras["machine"] == "walking"
    # step frequency L^-1/2 × the clip's, Froude number the clip's (within 2 %)
    f_clip = 1.0 / prep.machine.reference["step_time_s"]  # measured on the clip's complete steps
    assert c["expected_step_frequency_hz"] == pytest.approx(f_clip / math.sqrt(L), rel=1e-12)
    assert r.step_frequency_hz == pytest.approx(c["expected_step_frequency_hz"], rel=0.02)
    assert r.froude_U == pytest.approx(prep.summary.froude, rel=0.02)
    assert not r.flight_times_s  # a walk never flies
    # the naive retarget would keep the clip's cadence: wrong by √L
    assert c["naive_step_frequency_hz"] == pytest.approx(f_clip, rel=1e-12)
    assert 1.0 + c["naive_error"] == pytest.approx(math.sqrt(L), rel=1e-9)


@pytest.mark.parametrize("name,character", _cases(with_misses=True))
def test_scaled_walk_meets_the_bars_and_keeps_double_support(name, character, walks):
    r = pipeline.scale(walks(name), character).report
    w = r.extras["walking"]
    assert abs(w["double_support_fraction"] - w["clip"]["double_support_fraction"]) <= 0.02
    assert r.foot_skate_mm <= 5.0 and r.penetration_mm <= 5.0
    assert _bars_missed(r, (name, character)) == []


@pytest.mark.parametrize("name", clip_params(WALKING[:1]))
def test_naive_walk_keeps_the_clips_cadence(name, walks):
    prep = walks(name)
    phys = pipeline.scale(prep, "giant").report
    naive = pipeline.scale(prep, "giant", method="naive").report
    # measured on the outputs: the naive giant steps at the clip's frequency, √L too fast
    assert naive.step_frequency_hz == pytest.approx(1.0 / prep.machine.reference["step_time_s"], rel=0.02)
    assert naive.step_frequency_hz / phys.step_frequency_hz > 1.3
    assert naive.extras["machine"] == "walking"


@pytest.mark.parametrize("name", clip_params(WALKING[:1]))
def test_cli_scale_on_a_walk_reports_walking_figures(name, tmp_path, run_cli):
    out = tmp_path / "child.bvh"
    code, stdout, _ = run_cli("scale", clip(name), "--character", "child", "-o", out, "--keep")
    assert code == 0, stdout
    assert "double support" in stdout and "naive retarget steps at" in stdout
    import json

    rep = json.loads((tmp_path / "child.report.json").read_text())
    assert rep["extras"]["machine"] == "walking" and "NaN" not in (tmp_path / "child.report.json").read_text()


@pytest.mark.parametrize("name,speed", [
    pytest.param(name, speed, id=f"{name}-x{speed}")
    for name in ("02_01", "07_01", BANDAI_WALKS[0]) for speed in (1.2, 0.8)
])
def test_walk_at_another_speed_meets_every_bar(name, speed, walks):
    """Issue 17 acceptance 3 on every walk: x0.8 and x1.2 at the asked speed and the similar cadence, every bar met."""
    prep = walks(name)  # skips with the reason when the clip's folder is absent
    r = pipeline.scale(prep, None, speed=speed).report
    assert r.mean_speed_m_s == pytest.approx(speed * prep.summary.mean_speed, rel=0.03)
    assert r.step_frequency_hz == pytest.approx(r.extras["cadence"]["expected_step_frequency_hz"], rel=0.02)
    assert r.foot_skate_mm <= 5.0 and r.penetration_mm <= 5.0
    assert _bars_missed(r, (name, f"x{speed}")) == []


@pytest.mark.parametrize("name", clip_params(WALKING[:1]))
def test_walk_past_the_walk_run_transition_says_so_in_m_s(name, walks, tmp_path, run_cli, monkeypatch):
    """The refusal is known from the machine alone: the CLI says it without searching the reachable speeds
    (that search took 43 s on walk_active_009 at x3, 7 s without it)."""
    from froude.errors import FitError
    from froude.flow import speed_range

    def no_search(*a, **k):
        raise AssertionError("the walk-run refusal searched the reachable speeds")

    monkeypatch.setattr(speed_range, "reachable_speed_range", no_search)
    prep = walks(name)
    with pytest.raises(FitError, match=r"past the walk-run transition .* ask at most \d\.\d\d m/s"):
        pipeline.plan_scale(prep, None, speed=2.0)
    code, _, err = run_cli("scale", clip(name), "--speed", "2", "-o", tmp_path / "fast.bvh")
    # the loading notes first, then the refusal in one line
    assert code == 2 and "walk-run transition" in err.strip().splitlines()[-1] and err.count("walk-run") == 1
    assert not (tmp_path / "fast.bvh").exists()


def _step_speeds(res) -> np.ndarray:
    """(n-1,) the output's COM speed over each step, touchdown to touchdown [m/s] (measured on the motion)."""
    com = res.retarget.body.com(res.motion) @ res.path.frame[0]
    td = res.path.t_touchdown
    x = np.interp(td, np.arange(res.motion.n_frames) * res.motion.frame_time, com)
    return np.diff(x) / np.diff(td)


@pytest.mark.parametrize("name,factor", [(n, f) for n in ("02_01", "07_01", BANDAI_WALKS[0]) for f in (1.3, 0.6)])
def test_walk_accelerates_monotonically(name, factor, walks):
    if MOCAP is None:
        pytest.skip("real clips not found")
    res = pipeline.accelerate(walks(name), None, to_factor=factor, steps=8)
    plan = res.report.extras["plan"]
    v = _step_speeds(res)
    # the measured speed profile moves one way, from the clip's speed to the goal (within 2 %)
    assert np.all(np.sign(factor - 1.0) * np.diff(v) >= -1e-3 * v[:-1]), v
    assert v[0] == pytest.approx(plan["start_speed_m_s"], rel=0.02)
    assert v[-1] == pytest.approx(factor * plan["start_speed_m_s"], rel=0.02)
    assert res.report.foot_skate_mm <= 5.0 and res.report.penetration_mm <= 5.0
    # the report's expected cadence is the plan's walking cycles', and the output steps at it; the naive
    # retarget's is the clip's played at the mean speed factor (07_01 to 1.3x: 2.085 expected, 2.090
    # measured, naive 2.212 Hz; the expected figure was the clip's 1.886 Hz before)
    c = res.report.extras["cadence"]
    assert c["expected_step_frequency_hz"] == pytest.approx(1.0 / np.mean(plan["step_time_s"]), rel=1e-12)
    assert res.report.step_frequency_hz == pytest.approx(c["expected_step_frequency_hz"], rel=0.02)
    assert np.sign(factor - 1.0) * (c["naive_step_frequency_hz"] / c["clip_step_frequency_hz"] - 1.0) > 0.05


@pytest.mark.parametrize("name,factor", [
    pytest.param("02_01", 1.3),
    pytest.param("02_01", 0.6),
    pytest.param("07_01", 1.3),
    pytest.param("07_01", 0.6),
    pytest.param(BANDAI_WALKS[0], 1.3),
    pytest.param(BANDAI_WALKS[0], 0.6),
])
def test_walk_acceleration_meets_every_bar(name, factor, walks):
    if MOCAP is None:
        pytest.skip("real clips not found")
    res = pipeline.accelerate(walks(name), None, to_factor=factor, steps=8)
    assert res.report.check_bars() == []


@pytest.mark.parametrize("name", clip_params(WALKING[:1]))
def test_render_takes_scaled_walks(name, tmp_path, run_cli):
    """Issue 17 acceptance 4: ``render`` takes walks: the child's and the giant's walks in one filmstrip."""
    from PIL import Image

    from froude.body.load import load_bvh

    outs = []
    for who in ("child", "giant"):
        out = tmp_path / f"{who}.bvh"
        code, _, err = run_cli("scale", clip(name), "--character", who, "--strides", "1", "-o", out, "-q",
                               "--keep")
        assert code == 0, err
        outs.append(out)
    # a walk has no flight to weigh its units by: read the outputs in the clip's own units
    scale = load_bvh(clip(name)).meta["length_scale"]
    png = tmp_path / "walks.png"
    code, _, err = run_cli("render", *outs, "--filmstrip", "--length-scale", scale, "-o", png)
    assert code == 0, err
    im = Image.open(png)
    assert im.size[0] > 100 and im.size[1] > 100


def test_skate_floor_ignores_a_swing_before_a_contact_cut_by_the_clip_end():
    # A foot landing heel first in the clip's last frames: the gait cuts a stance there, but its ball is
    # still in the swing, lowest (30 mm up, within reach of the floor) before the stance begins, and moves
    # 20 mm a frame: not a slide. The same ball sliding 10 mm inside that stance is one.
    from froude.body.gait import Gait, Stance
    from froude.core.constants import UP_AXIS
    from froude.report.metrics import foot_skate_floor_mm

    F, L, dt = 60, 0.9, 1.0 / 120.0
    markers = np.zeros((F, 2, 3, 3))
    markers[:, 0, :, UP_AXIS] = 0.3  # foot 0 never near the floor
    ball = markers[:, 1, 1]
    ball[:, UP_AXIS] = 0.03 + 0.0004 * (np.arange(F) - 40) ** 2  # lowest at frame 40, in the swing
    ball[:, 0] = 0.02 * np.arange(F)                             # swinging forward
    markers[:, 1, 2] = ball
    st = Stance(foot=1, start=50, stop=F, ground=0.0, contact_point=np.zeros(3), partial=True)
    gait = Gait(contact=np.zeros((F, 2), bool), stances=(st,), flights=(), ground=0.0, frame_time=dt,
                leg_length=L, double_support_fraction=0.0)
    assert foot_skate_floor_mm(markers, gait, L) == 0.0
    down = markers.copy()
    down[:50, 1, 1:, UP_AXIS] += 0.03                         # a higher swing; the ball and tip come down
    down[50:, 1, 1:, UP_AXIS] = 0.02                          # in the stance, sliding 1 mm a frame
    down[50:, 1, 1:, 0] = down[50, 1, 1, 0] + 0.001 * np.arange(F - 50)[:, None]
    assert foot_skate_floor_mm(down, gait, L) == pytest.approx(9.0)


def test_skate_floor_measures_a_contact_cut_by_the_clip_start_from_the_marker_rest_height():
    # The clip starts just after a toe's contact (run_tired's troll): the gait cuts a stance at frame 0, the
    # tip is lowest there, 30 mm up, and swings forward 15 mm a frame. In the foot's whole stance the tip rests
    # at 0.5 mm: the cut stance's band is measured from there, so the swing is not a slide. The same tip
    # resting on the floor at the clip's start and sliding 1 mm a frame is one.
    from froude.body.gait import Gait, Stance
    from froude.core.constants import UP_AXIS
    from froude.report.metrics import foot_skate_floor_mm

    F, L, dt = 40, 1.0, 1.0 / 30.0
    markers = np.zeros((F, 2, 3, 3))
    markers[:, 0, :, UP_AXIS] = 0.3  # foot 0 never near the floor
    tip = markers[:, 1, 2]
    tip[:, UP_AXIS] = 0.2
    tip[:6, UP_AXIS] = 0.03 + 0.005 * np.arange(6)  # rising from 0.03 L at the first frame
    tip[:6, 0] = 0.015 * np.arange(6)               # and swinging forward
    tip[20:30, UP_AXIS] = 0.0005                   # a whole stance, at rest on the floor
    tip[20:30, 0] = 1.0
    markers[:, 1, 1] = tip + [0.0, 0.1, 0.0]        # the ball well above the floor throughout
    cut = Stance(foot=1, start=0, stop=5, ground=0.0, contact_point=np.zeros(3), partial=True)
    whole = Stance(foot=1, start=20, stop=30, ground=0.0, contact_point=np.zeros(3), partial=False)
    gait = Gait(contact=np.zeros((F, 2), bool), stances=(cut, whole), flights=(), ground=0.0, frame_time=dt,
                leg_length=L, double_support_fraction=0.0)
    assert foot_skate_floor_mm(markers, gait, L) == 0.0
    planted = markers.copy()
    planted[:6, 1, 2, UP_AXIS] = 0.0005                     # on the floor at the clip's start
    planted[:6, 1, 2, 0] = 0.001 * np.arange(6)             # sliding 1 mm a frame
    assert foot_skate_floor_mm(planted, gait, L) == pytest.approx(5.0)
    alone = Gait(contact=gait.contact, stances=(cut,), flights=(), ground=0.0, frame_time=dt, leg_length=L,
                 double_support_fraction=0.0)
    assert foot_skate_floor_mm(markers, alone, L) > 5.0  # no whole stance: the cut one is measured as before


@pytest.mark.parametrize("name", clip_params(WALKING))
def test_clip_double_support_is_over_its_walking_steps(name, walks):
    # CMU 07_01 starts from standing: its first double support (0.139 s) is no walking step, and counted it
    # put the clip's share at 17.6 % where the steps the walking fit takes (and the machine walks) have 14.5 %
    prep = walks(name)
    ref = prep.machine.reference
    clip_ds = pipeline.scale(prep, None).report.extras["walking"]["clip"]["double_support_fraction"]
    assert clip_ds == pytest.approx(ref["double_support_s"] / ref["step_time_s"], abs=0.005)


@pytest.mark.parametrize("name", clip_params(BANDAI_WALKS))
def test_bandai_walk_decelerated_at_120_hz_meets_every_bar(name, walks):
    # two frames before a touchdown the IK flipped the landing knee and left both feet 14-17 mm off (skate
    # 16.6 mm); solved again they met every target, but judged one by one each kept the other flipped
    res = pipeline.accelerate(walks(name), None, to_factor=0.5, steps=8, fps=120.0)
    assert res.report.foot_skate_mm <= 5.0 and res.report.check_bars() == []


@pytest.mark.parametrize("name", clip_params(BANDAI_WALKS))
def test_walk_report_expects_the_cadence_of_the_cycle_walked_past_the_first_law(name, walks):
    """Past x1.4 the Bandai walk's cycle is re-solved with the faster-cadence step time law
    (machine.walk_speed.FAST_STEP_TIME_EXPONENT): the report's expected cadence is that cycle's, not s^0.5's.
    (CMU 07_01 walked it from x1.2875 before the control's pulses; with them it has s^-1/2 cycles to x1.30.)"""
    from froude.machine.walk_speed import STEP_TIME_EXPONENT

    prep = walks(name)
    r = pipeline.scale(prep, None, speed=1.5).report
    c = r.extras["cadence"]
    assert c["expected_step_frequency_hz"] > 1.05 * c["clip_step_frequency_hz"] * 1.5 ** -STEP_TIME_EXPONENT
    assert r.step_frequency_hz == pytest.approx(c["expected_step_frequency_hz"], rel=0.02)


@pytest.mark.slow
def test_a_brisk_walk_goes_faster_with_its_stance_leg_loaded():
    """Issue 29 acceptance 1, walk_active_002 at x1.2 (1.66 m/s, U 0.59): its fitted cycle's single-support
    force falls to 0.004 body weights by x1.12 and the stance leg unloads past x1.125 with either step time
    law, so it was refused ("out of reach ... x0.30-1.11"). The continuation goes on holding the machine's
    force trough at FLIGHT_FORCE_BW (machine.walk_speed.LAWS): every physics bar met, cadence as expected, no
    flight in the output's COM force. And on to x1.3 (1.80 m/s): the held-trough search there stalls at a
    residual of 3e-7, which walk_cycle.TROUGH_HELD_ACCEPT takes (it was refused as out of reach above x1.23)."""
    from froude.body.gait import FLIGHT_FORCE_BW

    prep = pipeline.prepare(clip("bandai-locomotion/walks/dataset-2_walk_active_002"))
    for factor in (1.2, 1.3):
        r = pipeline.scale(prep, None, speed=factor).report
        assert r.check_bars() == [], factor
        v_asked = factor * prep.machine.mean_speed * prep.machine.speed_unit
        assert r.mean_speed_m_s == pytest.approx(v_asked, rel=0.02)
        assert r.step_frequency_hz == pytest.approx(r.extras["cadence"]["expected_step_frequency_hz"], rel=0.02)
        assert r.extras["walking"]["trough_bw"] >= FLIGHT_FORCE_BW


@pytest.mark.parametrize("name", LOCO_WALKS + LOCO_RUNS)
def test_every_locomotion_walk_keeps_its_double_support_as_a_giant(name, walks):
    """Issue 29 acceptance 1 (issue 17's double-support share, within 2 points under pure scaling) on every
    walk and grounded "elderly run" of the locomotion sample, as the giant (where it was worst), with every
    physics bar. The reference anchors set off and arrived half a frame after the walking machine's sub-frame
    events, and the output's feet stood 16 ms longer than its stances (walk_elderly_001: +3.5 points; 7 of
    the 16 walking clips over the bar); ``synthesis.feet.foot_anchors(subframe=True)``. The runs with flights are
    scaled by the running machine: they have no double support, and every bar."""
    prep = walks(name)
    r = pipeline.scale(prep, "giant").report
    if prep.kind.has_flight:
        assert r.extras["machine"] == "running" and "walking" not in r.extras
    else:
        w = r.extras["walking"]
        assert abs(w["double_support_fraction"] - w["clip"]["double_support_fraction"]) <= 0.02
    assert r.check_bars() == [] and r.foot_skate_floor_mm <= 5.0


@pytest.mark.parametrize("name", LOCO_WALKS + LOCO_RUNS)
def test_every_locomotion_walk_fits_with_its_force_landmarks(name, walks):
    """Issue 29 acceptance 1, the fit: every walk and grounded run of the locomotion sample that the walking
    machine models has the clip's force landmarks (two peaks and the trough: within 0.1 BW and 5 % of a step,
    issue 17's bars) and double-support time (5 %). Four did not (elderly_005 trough +9.1 %, feminine_001
    push-off +5.4 %, masculine_007 push-off -12.6 %, normal_002 trough -5.3 %) until a fit outside the bars is
    refined with the weight-acceptance pulse's centre free (``walk_fit._refine_pulse_centre``). The runs with
    flights are the running machine's."""
    prep = walks(name)
    q = getattr(prep.machine, "quality", None)
    if prep.kind.has_flight:
        assert q is None or "peak1_timing_error_step" not in q
        return
    for key in ("peak1", "trough", "peak2"):
        assert abs(q[key + "_error_bw"]) <= 0.1, (key, q[key + "_error_bw"])
        assert abs(q[key + "_timing_error_step"]) <= 0.05, (key, q[key + "_timing_error_step"])
    assert abs(q["double_support_error"]) <= 0.05


def test_a_slowed_walk_lifts_its_foot_where_it_stood(walks):
    """Slowed to 0.7x, walk_elderly_005's toe was put 60 mm behind its lift-off point one 30 Hz frame after
    it (a 22 mm skate): the machine carries the COM over the contact other than the reference did, and a walk's
    swing took up the body-relative path at once. It is joined to the ground path as a run's is
    (``synthesis.targets._body_path_correction``)."""
    r = pipeline.accelerate(walks("bandai-locomotion/walks/dataset-2_walk_elderly_005"), None, to_factor=0.7).report
    assert r.foot_skate_mm <= 5.0 and r.check_bars() == []
