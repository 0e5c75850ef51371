"""The live studio (``froude view``): what it draws, how it survives bad edits, tabs, comparison.

The page end to end in a browser is tests/test_studio_browser.py.
"""
from __future__ import annotations

import socket

import numpy as np
import pytest

from froude import pipeline
from froude.errors import FroudeError
from froude.kinematics import fk
from froude.samples import sample_path
from froude.studio.session import Params, Session
from froude.studio.tracks import bone_segments, motion_hash, spring_legs, trail_segments


@pytest.fixture(scope="module")
def session():
    return Session(pipeline.prepare(sample_path()))


# ---- what is drawn (no viser) ---------------------------------------------------------------------------
def test_bone_segments_join_fk_joint_positions(session):
    motion = session.prep.motion
    seg, _, _ = bone_segments(motion)
    p, R = fk(motion)
    sk = motion.skeleton
    child = np.flatnonzero(sk.parents >= 0)
    assert seg.shape == (motion.n_frames, len(child) + len(sk.end_sites), 2, 3)
    np.testing.assert_allclose(seg[:, : len(child), 0], p[:, sk.parents[child]], atol=1e-5)
    np.testing.assert_allclose(seg[:, : len(child), 1], p[:, child], atol=1e-5)
    j, off = sk.end_sites[0]
    tip = p[:, j] + np.einsum("fij,j->fi", R[:, j], off)
    np.testing.assert_allclose(seg[:, len(child), 1], tip, atol=1e-5)


def test_spring_legs_only_in_stance_and_trail_follows_path():
    com = np.array([[0.0, 1.0, 0.0], [0.1, 1.0, 0.0], [0.2, 1.0, 0.0]])
    contact = np.full((3, 2, 3), np.nan)
    contact[1, 0] = [0.15, 0.0, 0.0]
    legs = spring_legs(com, contact)
    np.testing.assert_allclose(legs[1, 0], [[0.1, 1, 0], [0.15, 0, 0]])
    np.testing.assert_allclose(legs[0, :, 1], com[[0, 0]])  # no stance: a zero-length leg at the COM
    np.testing.assert_allclose(legs[1, 1, 1], com[1])
    tr = trail_segments(np.linspace([0, 1, 0], [1, 1, 0], 10), stride=4)
    np.testing.assert_allclose(tr[0, 0], [0, 1, 0])
    np.testing.assert_allclose(tr[-1, 1], [1, 1, 0])
    np.testing.assert_allclose(tr[1:, 0], tr[:-1, 1])  # a connected polyline


def test_motion_hash_sees_changes_not_the_sign_of_zero(session):
    m = session.prep.motion
    rp = m.root_positions.copy()
    rp[0, 0] = 0.0
    neg = rp.copy()
    neg[0, 0] = -0.0
    assert motion_hash(m.with_(root_positions=rp)) == motion_hash(m.with_(root_positions=neg))
    assert motion_hash(m) == motion_hash(m.with_(root_positions=m.root_positions.copy()))
    assert motion_hash(m) != motion_hash(m.with_(root_positions=m.root_positions + 1e-3))


def test_preview_is_the_results_machine_and_skeleton(session):
    p = Params(character="child", speed=1.2, strides=2)
    pre, res = session.preview(p), session.solve(p)
    assert pre.preview and pre.result is None and not res.preview
    assert pre.n_frames == res.n_frames
    np.testing.assert_allclose(pre.track.com, res.track.com)  # the machine COM is the same path
    assert res.result.retarget.character.name == "child"
    # the child is smaller than the reference: its bones are shorter
    ref_len = np.linalg.norm(np.diff(session.reference.segments[0], axis=1), axis=-1).sum()
    child_len = np.linalg.norm(np.diff(res.track.segments[0], axis=1), axis=-1).sum()
    assert child_len < 0.9 * ref_len
    assert session.preview(Params(mode="accelerate")) is None


@pytest.mark.parametrize("bad, words", [
    (Params(height=0.0), "Height 0 m is outside 0.5 m to 4 m"),
    (Params(speed=0.0), "Speed 0× is outside 0.5× to 2×"),
    (Params(mode="accelerate", to_factor=2.0, steps=1),
     r"cannot go from \d.\d\d m/s to \d.\d\d m/s \(×2\) in 1 steps: use more"),
])
def test_bad_params_raise_one_line_froude_errors(session, bad, words):
    with pytest.raises(FroudeError, match=words):
        session.solve(bad)


def test_studio_keeps_last_good_result_on_bad_edits(session):
    pytest.importorskip("viser")
    from froude.studio.app import Studio

    studio = Studio(session.prep, port=_free_port())
    try:
        tab = studio.open_tab()
        good = tab.good
        for bad in (Params(height=0.0), Params(mode="accelerate", to_factor=2.0, steps=1), Params(leg_scale=0.0)):
            tab.apply(bad)
            assert tab.good is good and tab.shown is good
            assert "status=error" in tab.gui_state.content
            assert tab.message.startswith("error: ")
        t = tab.apply(Params(speed=1.3))
        assert tab.good is not good and tab.good.params.speed == 1.3
        assert "status=ok" in tab.gui_state.content and tab.good.hash in tab.gui_state.content
        assert t.result_compute > 0
    finally:
        studio.stop()


def test_studio_previews_only_when_the_result_would_be_slow(session, monkeypatch):
    """A quick result goes straight to the page; an expected-slow one shows the IK-free preview first."""
    pytest.importorskip("viser")
    from froude.studio import app
    from froude.studio.app import Studio

    studio = Studio(session.prep, port=_free_port())
    tab = studio.open_tab()
    shown = []
    publish = tab._publish
    monkeypatch.setattr(tab, "_publish",
                        lambda solved, status=None: (shown.append(solved), publish(solved, status)))
    try:
        tab.apply(Params(speed=1.05))  # a warm solve sets the expectation
        quick = tab.expected_seconds(Params(speed=1.1))
        assert 0 < quick < app.SLOW_RESULT_S  # 4 strides of the sample: the last solve was quick
        assert tab.expected_seconds(Params(speed=1.1, strides=400)) > app.SLOW_RESULT_S  # scales with length
        shown.clear()
        t = tab.apply(Params(speed=1.1))
        assert np.isnan(t.preview_compute) and [s.preview for s in shown] == [False, False]  # result, then report
        shown.clear()
        monkeypatch.setattr(app, "SLOW_RESULT_S", 0.0)
        t = tab.apply(Params(speed=1.15))
        assert t.preview_compute > 0 and [s.preview for s in shown] == [True, False, False]
        assert tab.good.params.speed == 1.15 and "status=ok" in tab.gui_state.content
    finally:
        studio.stop()


def test_naive_comparison_and_clip_facts(session):
    """The naive retarget (engines' way) beside the physical one, with the numbers that tell them apart."""
    pytest.importorskip("viser")
    from froude.studio.app import Studio

    studio = Studio(session.prep, port=_free_port())
    try:
        tab = studio.open_tab()
        tab.apply(Params(character="child", speed=1.2))
        tab._solve_naive()
        assert tab.naive is not None and tab.naive.result.method == "naive"
        assert tab.naive.track.body.stature == pytest.approx(tab.good.track.body.stature)
        table = tab._table_md()
        assert "| speed [m/s] |" in table and "| foot skate [mm] | — |" in table and len(table.splitlines()) == 9
        facts = tab._facts_md()
        assert "120 frames/s" in facts and "Froude number" in facts and "m/s" in facts
        tab.apply(Params(mode="accelerate", to_factor=1.2, steps=8))
        tab._solve_naive()
        assert tab.naive is None and "scale only" in tab.message
        v = tab.good.track.speed_m_s
        assert v[-10:].mean() > 1.1 * v[:10].mean()  # the speed profile of the acceleration rises
    finally:
        studio.stop()


def test_two_tabs_hold_two_sessions(session):
    """Each tab its own parameters, result and scene (acceptance 15.4, without a browser)."""
    pytest.importorskip("viser")
    from froude.studio.app import Studio

    studio = Studio(session.prep, port=_free_port())
    try:
        a, b = studio.open_tab(), studio.open_tab()
        a.apply(Params(character="child"))
        assert a.good.params.character == "child" and b.good.params.character == "same"
        assert b.good is studio.first and a.result is not b.result
    finally:
        studio.stop()


def test_view_cli_refuses_bad_clips_in_one_line(tmp_path, capsys):
    from conftest import clip
    from froude.cli import main as cli_main

    assert cli_main(["view", str(tmp_path / "missing.bvh"), "--port", "0"]) == 2
    assert cli_main(["view", str(clip("02_01")), "--port", "0"]) == 2  # walking, not running
    err = capsys.readouterr().err.strip().splitlines()
    errors = [line for line in err if line.startswith("froude view: error:")]
    assert len(errors) == 2 and "missing.bvh" in errors[0] and "walking" in errors[1]
    # no traceback: only the errors, the loader's notes on the clip (units ...) and the progress line
    assert all(line in errors or line.startswith(("froude view: preparing", str(clip("02_01")))) for line in err)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]
