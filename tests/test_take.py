"""Issue 13 (any running take) and issue 12 point 3 (frame rates): cadence and speed at identity, low
frame rates, strict report JSON — on the real clips."""
from __future__ import annotations

import json

import numpy as np
import pytest

from froude.body.gait import detect_gait, summarize
from froude.body.load import load_bvh
from froude.body.model import BodyModel
from froude.body.take import select_range
from froude.flow import pipeline
from froude.flow.speed_range import reachable_speed_range

from conftest import BANDAI_RUNS, RUNNING, clip, clip_params


def _summary(motion):
    body = BodyModel.from_skeleton(motion.skeleton)
    return summarize(motion, body)


def _strict(text: str):
    """json.loads that refuses NaN/Infinity (what a strict parser does)."""
    def bad(token):
        raise ValueError(f"non-standard JSON token {token}")
    return json.loads(text, parse_constant=bad)


# dash_normal is a one-stride loop: its cadence is the loop's (test_bandai_one_stride_loop), which a
# 20-frame clip's own contacts (one step of it) do not give to 1 %
BANDAI_STRIDING = [n for n in BANDAI_RUNS if n != "dataset-1_dash_normal_001"]


@pytest.mark.parametrize("name", clip_params(RUNNING) + clip_params(BANDAI_STRIDING))
def test_identity_cadence_and_speed(name):
    """Issue 13 acceptance 1: ``scale`` with no change steps at the clip's step frequency and speed (info)."""
    motion = load_bvh(clip(name))
    info = _summary(motion)
    rep = pipeline.scale(pipeline.prepare(motion)).report
    assert rep.step_frequency_hz == pytest.approx(info.step_frequency, rel=0.01)
    assert rep.mean_speed_m_s == pytest.approx(info.mean_speed, rel=0.01)


#: (clip, fps) -> the bar missed at identity, measured; the test expects exactly that miss (and fails when it
#: goes away, so that it comes off the list).
LOW_RATE_MISSES: dict = {}


@pytest.mark.parametrize("fps", [24, 25, 30, 50, 60])
@pytest.mark.parametrize("name", clip_params(["09_01", "02_03"]))
def test_low_frame_rates_fit_and_report(name, fps):
    """Issue 12 point 3: 4-5-frame stances fit as delivered; flight gravity measured at the output's own
    rate; the machine agrees with the 120 Hz one; cadence and speed at identity within 1 %."""
    full = load_bvh(clip(name))
    motion = full.resample(fps)
    prep = pipeline.prepare(motion)
    ref = pipeline.prepare(full).machine
    m = prep.machine
    assert m.K == pytest.approx(ref.K, rel=0.06)
    assert np.degrees(m.theta0) == pytest.approx(np.degrees(ref.theta0), abs=1.0)
    info = prep.summary
    assert info.step_frequency == pytest.approx(_summary(full).step_frequency, rel=0.015)
    res = pipeline.scale(prep, strides=4)
    rep = res.report
    assert rep.frame_rate_hz == pytest.approx(fps)
    assert rep.flight_gravity_m_s2 == pytest.approx(9.81, rel=0.03)
    assert rep.step_frequency_hz == pytest.approx(info.step_frequency, rel=0.01)
    assert rep.mean_speed_m_s == pytest.approx(info.mean_speed, rel=0.01)
    miss = LOW_RATE_MISSES.get((name, fps))
    if miss is None:
        assert rep.check_bars() == []
    else:
        names = [f.split(" mm")[0].rsplit(" ", 1)[0] for f in rep.check_bars()]
        assert names == [miss.split(" mm")[0].rsplit(" ", 1)[0]]


def test_report_json_is_strict_with_reasons(tmp_path):
    """Issue 12 acceptance 5: a figure that cannot be measured is null with a reason, never NaN."""
    motion = load_bvh(clip("09_01"))
    res = pipeline.scale(pipeline.prepare(motion), strides=2)
    _, rp = pipeline.write_result(res, tmp_path / "out.bvh")
    d = _strict(rp.read_text())
    assert d["flight_gravity_m_s2"] == pytest.approx(9.81, rel=0.03)
    assert d["unmeasured"] == {}
    # the naive baseline has no machine to track: null, with the reason
    naive = pipeline.scale(pipeline.prepare(motion), method="naive", strides=2)
    _, rp = pipeline.write_result(naive, tmp_path / "naive.bvh")
    d = _strict(rp.read_text())
    assert d["com_tracking_rms_mm"] is None and "machine" in d["unmeasured"]["com_tracking_rms_mm"]
    # a motion with no flight at all: flight gravity null with its reason
    from froude.report.metrics import physics_report

    still = motion.with_(root_positions=np.repeat(motion.root_positions[:1], 40, axis=0),
                         rotations=np.repeat(motion.rotations[:1], 40, axis=0))
    d = _strict(physics_report(still).to_json())
    assert d["flight_gravity_m_s2"] is None and "flight" in d["unmeasured"]["flight_gravity_m_s2"]


def test_machine_json_is_strict(tmp_path):
    motion = load_bvh(clip("09_01")).resample(30)
    m = pipeline.prepare(motion).machine
    m.save(tmp_path / "m.json")
    _strict((tmp_path / "m.json").read_text())


def _speeding_up(motion, gain=0.35):
    """A take that speeds up: the clip played faster and faster (source time t + gain t² / (2 T))."""
    T = motion.duration * 0.8
    t = np.arange(int(T * motion.fps)) / motion.fps
    return motion.time_warp(t + 0.5 * gain * t * t / T)


@pytest.mark.parametrize("name", clip_params(["02_03"]))
def test_changing_speed_says_what_is_modelled(name, run_cli, tmp_path):
    """Issue 13: a take whose speed changes: the machine runs its mean (info's), says so, and speed factors
    refer to what it printed; --range T0:T1 models a part instead."""
    motion = _speeding_up(load_bvh(clip(name)))
    prep = pipeline.prepare(motion)
    info = _summary(motion)
    assert any("speed changes within the take" in n for n in prep.notes)
    for s in (1.0, 1.2):
        rep = pipeline.scale(prep, speed=s).report
        assert rep.mean_speed_m_s == pytest.approx(s * info.mean_speed, rel=0.01)
    assert pipeline.scale(prep).report.step_frequency_hz == pytest.approx(info.step_frequency, rel=0.01)
    # a part of the take: its own speed
    part = pipeline.prepare(motion, time_range=(0.0, 0.97))
    cut = select_range(motion, (0.0, 0.97))
    assert part.summary.mean_speed == pytest.approx(_summary(cut).mean_speed, rel=1e-9)
    assert part.summary.mean_speed < 0.97 * info.mean_speed
    rep = pipeline.scale(part).report
    assert rep.mean_speed_m_s == pytest.approx(part.summary.mean_speed, rel=0.01)
    # the CLI prints what it models
    code, out, err = run_cli("scale", clip(name), "--range", "0.05:", "-o", tmp_path / "o.bvh")
    assert code == 0 and "modelled  " in out and "0.05-1.43 s of the take" in out
    code, out, err = run_cli("scale", clip(name), "--range", "x", "-o", tmp_path / "p.bvh")
    assert code == 2 and "T0:T1" in err and len(err.strip().splitlines()) == 1


@pytest.mark.parametrize("name", clip_params(RUNNING))
def test_speed_range_outputs_or_refusals(name):
    """Issue 13 acceptance 4: --speed 0.5, 0.7, 1.5, 1.8, 2.0: inside the reachable range the output meets
    every bar (joint jump included); outside it ``scale`` refuses (see the CLI test)."""
    prep = pipeline.prepare(load_bvh(clip(name)))
    rng = reachable_speed_range(prep)
    # every run reaches x0.7-1.2; the slow end is x0.30-0.52 (09_03: a knee pop at lift-off below x0.5,
    # benchmarks/bars_matrix.py --matrix speeds), so 0.5 may be refused, with the range
    assert not rng.empty and rng.lo <= 0.7 and 1.2 <= rng.hi
    assert rng.hi_m_s == pytest.approx(rng.hi * prep.summary.mean_speed, rel=1e-6)
    for s in (0.5, 0.7, 1.5, 1.8, 2.0):
        if rng.lo <= s <= rng.hi:
            rep = pipeline.scale(prep, speed=s).report
            assert not rep.check_bars(), (s, rep.check_bars())
    # the ends themselves were produced and met every bar
    assert not pipeline.scale(prep, speed=rng.hi).report.check_bars()


def test_speed_refusals_name_the_reachable_range(run_cli, tmp_path):
    # 09_04: its range ends at a bar (x1.96, a joint jump at x2.0) below its human top (x2.90); a range that
    # ends at the human top is refused with the human limit instead (tests/test_speed_law.py)
    path = clip("09_04")
    prep = pipeline.prepare(load_bvh(path))
    rng = reachable_speed_range(prep)
    assert rng.human_top is not None and rng.hi < rng.human_top
    # the first speed above the range that was tried and missed a bar: refused, in one line with the range
    bad = next(s for s, met, _ in rng.probes if not met and s > rng.hi)
    code, out, err = run_cli("scale", path, "--speed", f"{bad}", "-o", tmp_path / "fast.bvh")
    assert code in (1, 2) and not (tmp_path / "fast.bvh").exists()  # 1: misses a bar; 2: no cycle
    line = [l for l in err.splitlines() if f"x{rng.lo:.2f}-{rng.hi:.2f}" in l]
    assert len(line) == 1 and "m/s" in line[0] and "steady speeds" in line[0]  # walks and runs alike
    # an output that would miss a bar: not written, exit 1, unless --keep
    code, out, err = run_cli("scale", path, "--speed", f"{bad}", "-o", tmp_path / "b.bvh")
    if code == 1:
        assert not (tmp_path / "b.bvh").exists() and "misses physics bars" in err and "--keep" in err
        code, out, err = run_cli("scale", path, "--speed", f"{bad}", "--keep", "-o", tmp_path / "b.bvh")
        assert code == 0 and (tmp_path / "b.bvh").exists() and "NOT met (kept)" in out
    else:  # a cycle that does not exist at that speed
        assert code == 2 and "out of reach" in err


def test_acceleration_refusals_are_in_metres_per_second(run_cli, tmp_path):
    """An unreachable acceleration goal: one line in m/s and x with the machine's and the bars' ranges (no
    dimensionless U, no solver internals), exit 2, nothing written."""
    path = clip("09_01")
    prep = pipeline.prepare(load_bvh(path))
    rng = reachable_speed_range(prep)
    for goal, words in (("3x", "beyond the human range"), ("2x", "too abrupt")):
        code, out, err = run_cli("accelerate", path, "--to-speed", goal, "-o", tmp_path / "a.bvh")
        line = [l for l in err.splitlines() if "error" in l]
        assert code == 2 and not (tmp_path / "a.bvh").exists(), err
        assert len(line) == 1 and words in line[0] and "U =" not in line[0] and "[" not in line[0], line
        if goal == "3x":  # past the human top (x2.67): the human limit in m/s, before any planning
            assert "the human limit is" in line[0] and "m/s" in line[0]
        else:
            assert f"x{rng.lo:.2f}-{rng.hi:.2f} ({rng.lo_m_s:.2f}-{rng.hi_m_s:.2f} m/s" in line[0]


# ---- loops and in-place takes (issue 13 acceptance 2) ---------------------------------------------------
def _in_place(motion):
    """The take with its root travel removed (the COM's mean horizontal velocity taken off the root)."""
    from dataclasses import replace

    body = BodyModel.from_skeleton(motion.skeleton)
    com = body.com(motion)
    v = (com[-1] - com[0]) / motion.duration
    v[1] = 0.0
    t = np.arange(motion.n_frames) * motion.frame_time
    return replace(motion, root_positions=motion.root_positions - t[:, None] * v[None, :])


def _one_stride_loop(motion):
    """One stride of a run as a loop, as animators make them: from a touchdown to the frame before the same
    foot's next touchdown, the pose mismatch at the seam spread linearly over the stride (SciPy rotations)."""
    from dataclasses import replace

    from scipy.spatial.transform import Rotation as R

    body = BodyModel.from_skeleton(motion.skeleton)
    st = [s for s in detect_gait(motion, body).stances if s.start > 0]
    i0 = st[0].start
    i1 = next(s.start for s in st if s.foot == st[0].foot and s.start > i0)
    n = i1 - i0
    xyzw = lambda q: np.roll(q, -1, axis=-1)  # noqa: E731  froude's (w, x, y, z) -> SciPy's (x, y, z, w)
    delta = (R.from_quat(xyzw(motion.rotations[i1])).inv() * R.from_quat(xyzw(motion.rotations[i0]))).as_rotvec()
    rot = np.stack([np.roll((R.from_quat(xyzw(motion.rotations[i0 + k])) * R.from_rotvec(delta * k / n)).as_quat(),
                            1, axis=-1) for k in range(n)])
    root = motion.root_positions[i0:i1].copy()
    root[:, 1] -= (motion.root_positions[i1, 1] - motion.root_positions[i0, 1]) * np.arange(n) / n
    return replace(motion, root_positions=root, rotations=rot, translations=None)


# the loop: test_bandai_one_stride_loop
@pytest.mark.parametrize("name", clip_params(RUNNING) + clip_params(BANDAI_STRIDING))
def test_in_place_speed_found_from_the_feet(name):
    motion = load_bvh(clip(name))
    prep = pipeline.prepare(_in_place(motion))
    assert any("in-place take" in n for n in prep.notes)
    # acceptance 2 asks 3 %: the speed of each contact's planted third, a median over contacts (measured
    # -1.1 % to +0.5 % on the 9 runs; the median over every resting frame read 0.6-4.7 % low)
    assert prep.summary.mean_speed == pytest.approx(_summary(motion).mean_speed, rel=0.03)


def test_in_place_run_through_fit_scale_accelerate(run_cli, tmp_path):
    motion = load_bvh(clip("09_01"))
    prep = pipeline.prepare(_in_place(motion))
    assert prep.summary.mean_speed == pytest.approx(_summary(motion).mean_speed, rel=0.03)
    res = pipeline.scale(prep, "child")
    assert not res.report.check_bars()
    bvh, _ = pipeline.write_result(res, tmp_path / "child.bvh")  # in place, as the input
    back = load_bvh(bvh)
    body = BodyModel.from_skeleton(back.skeleton)
    com = body.com(back)
    assert np.linalg.norm((com[-1] - com[0])[[0, 2]]) < 0.1 * body.leg_length
    _, rp = pipeline.write_result(res, tmp_path / "travel.bvh", in_place=False)
    assert _strict(rp.read_text())["extras"]["written"] == "with root travel"
    acc = pipeline.accelerate(prep, to_factor=0.7, steps=6)
    assert not acc.report.check_bars()
    fit_out = tmp_path / "m.json"
    from froude.io.bvh import save_bvh

    save_bvh(_in_place(motion), tmp_path / "in_place.bvh")
    code, out, err = run_cli("fit", tmp_path / "in_place.bvh", "-o", fit_out)
    assert code == 0 and "in-place take" in err and fit_out.exists()


def test_one_stride_loop_through_fit_scale_accelerate(run_cli, tmp_path):
    """A one-stride loop (made from a CMU run) fits, scales and accelerates; its speed and cadence are the
    loop's own; the same loop in place too."""
    motion = load_bvh(clip("09_01"))
    loop = _one_stride_loop(motion)
    prep = pipeline.prepare(loop)
    assert any("looping take" in n for n in prep.notes) and "loop" in prep.modelled
    info = _summary(motion)
    assert prep.summary.mean_speed == pytest.approx(info.mean_speed, rel=0.03)
    rep = pipeline.scale(prep).report
    assert rep.step_frequency_hz == pytest.approx(prep.summary.step_frequency, rel=0.01)
    assert rep.mean_speed_m_s == pytest.approx(prep.summary.mean_speed, rel=0.01)
    assert not rep.check_bars()
    assert not pipeline.accelerate(prep, to_factor=1.3, steps=6).report.check_bars()
    # the same loop in place: speed from the feet
    still = pipeline.prepare(_in_place(loop))
    assert still.summary.mean_speed == pytest.approx(info.mean_speed, rel=0.04)
    from froude.io.bvh import save_bvh

    save_bvh(loop, tmp_path / "loop.bvh")
    code, out, err = run_cli("fit", tmp_path / "loop.bvh", "-o", tmp_path / "m.json")
    assert code == 0 and "looping take" in err


@pytest.mark.parametrize("name", clip_params(["dataset-1_dash_old_001", "dataset-1_dash_active_001",
                                              "dataset-1_dash_feminine_001"]))
def test_bandai_30hz_fit_as_delivered(name):
    """Issue 13 acceptance 5 / issue 12 point 3: 30 Hz clips with 4-5-frame stances fit as delivered;
    the output at the clip's own 30 Hz meets the bars (flight gravity measured at 30 Hz)."""
    motion = load_bvh(clip(name))
    assert motion.fps == pytest.approx(30.0, rel=1e-4)
    prep = pipeline.prepare(motion)
    m = prep.machine
    assert m.periodicity <= 1e-6 and 5 <= m.K <= 40
    rep = pipeline.scale(prep).report
    assert rep.frame_rate_hz == pytest.approx(30.0, rel=1e-4)
    assert rep.flight_gravity_m_s2 == pytest.approx(9.81, rel=0.03)
    assert not rep.check_bars(), rep.check_bars()


def test_info_says_how_a_loop_and_an_in_place_take_are_analysed(run_cli, tmp_path):
    """Issue 13 acceptance 1 for takes that are not analysed as they are: ``info`` prints the loop's own
    cadence and the in-place take's speed found from its feet, and ``scale`` with no change reproduces
    them within 1 % (the raw 20-frame loop's two contacts give 3.08 steps/s; its stride, 3.000)."""
    from froude.io.bvh import save_bvh

    loop = clip("dataset-1_dash_normal_001")
    still = tmp_path / "in_place.bvh"
    motion = load_bvh(clip("09_01"))
    save_bvh(_in_place(motion), still)
    for path, word in ((loop, "looping take"), (still, "in-place take")):
        code, text, err = run_cli("info", path, "--json")
        assert code == 0, err
        take = _strict(text)["take"]
        assert any(word in n for n in take["notes"])
        rep = pipeline.scale(pipeline.prepare(load_bvh(path))).report
        assert rep.step_frequency_hz == pytest.approx(take["step_frequency_hz"], rel=0.01)
        assert rep.mean_speed_m_s == pytest.approx(take["mean_speed_m_s"], rel=0.01)
    assert take["mean_speed_m_s"] == pytest.approx(_summary(motion).mean_speed, rel=0.03)
    code, text, err = run_cli("info", clip("09_01"), "--json")
    assert _strict(text)["take"] is None  # a take analysed as it is


def test_bandai_one_stride_loop(run_cli, tmp_path):
    """Issue 13 acceptance 2: the Bandai one-stride loop goes through fit, scale and accelerate."""
    path = clip("dataset-1_dash_normal_001")
    prep = pipeline.prepare(load_bvh(path))
    assert any("looping take" in n for n in prep.notes)
    rep = pipeline.scale(prep).report
    assert not rep.check_bars(), rep.check_bars()
    assert rep.step_frequency_hz == pytest.approx(prep.summary.step_frequency, rel=0.01)
    assert rep.mean_speed_m_s == pytest.approx(prep.summary.mean_speed, rel=0.01)
    assert pipeline.accelerate(prep, to_factor=0.7, steps=6).report.flight_gravity_m_s2 == pytest.approx(9.81, rel=0.03)
    code, out, err = run_cli("fit", path, "-o", tmp_path / "m.json")
    assert code == 0 and "looping take" in err
    code, out, err = run_cli("scale", path, "--character", "child", "-o", tmp_path / "c.bvh")
    assert code in (0, 1) and "looping take" in err


# ---- classification (issue 13 acceptance 6) -------------------------------------------------------------
from conftest import ALL_CLIPS, BANDAI_WALKS  # noqa: E402

KINDS = {"02_01": "walking", "07_01": "walking", "02_04": "in place", "dataset-1_walk_normal_001": "walking"}


@pytest.mark.parametrize("name", clip_params(list(ALL_CLIPS)) + clip_params(list(BANDAI_RUNS) + list(BANDAI_WALKS)))
def test_classification_robust(name):
    """Walks, the jump and runs are told apart at the clip's rate, at 30 and 60 Hz, and with one noisy
    moment (the root thrown 8 cm up for 30 ms) anywhere in the clip."""
    from dataclasses import replace

    from froude.body.gait import flight_share

    motion = load_bvh(clip(name))
    body = BodyModel.from_skeleton(motion.skeleton)
    want = KINDS.get(name, "running")
    for fps in (None, 30, 60):
        m = motion if fps is None else motion.resample(fps)
        assert summarize(m, body).kind == want, (name, fps)
        width = max(1, int(round(0.03 * m.fps)))
        for k in np.linspace(2, m.n_frames - 2 - width, 10).astype(int):
            rp = m.root_positions.copy()
            rp[k:k + width, 1] += 0.08
            assert summarize(replace(m, root_positions=rp), body).kind == want, (name, fps, k)
    share = flight_share(detect_gait(motion, body))
    assert (share >= 0.5) == (want == "running") or want == "in place"


@pytest.mark.parametrize("name", clip_params(list(ALL_CLIPS)) + clip_params(list(BANDAI_RUNS) + list(BANDAI_WALKS)))
def test_naive_on_any_clip(name, run_cli, tmp_path):
    """Issue 13: --method naive works on any clip that loads (walks and the jump too: the clip as it is)."""
    out = tmp_path / "naive.bvh"
    code, stdout, err = run_cli("scale", clip(name), "--method", "naive", "--character", "child", "--speed", "0.8",
                                "-o", out)
    assert code == 0, err
    assert out.exists() and "naive" in stdout
    d = _strict(out.with_name("naive.report.json").read_text())
    assert d["extras"]["method"] == "naive" and d["frame_rate_hz"] > 0
    back = load_bvh(out)
    assert np.all(np.isfinite(back.root_positions)) and back.n_frames > 10
