"""The live studio (``froude view``): what it draws, how it survives bad edits, and the page end to end.

The browser test drives the real page in headless Chromium through its controls (typing into the
speed box, picking a character from the dropdown, clicking buttons) and checks the runner changed via
the page's state line and a downloaded BVH. Screenshots go to a tmp dir (path printed with -s).
"""
from __future__ import annotations

import os
import re
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from froude import pipeline
from froude.errors import FroudeError
from froude.kinematics import fk
from froude.samples import sample_path
from froude.studio.session import Params, Session
from froude.studio.tracks import bone_segments, motion_hash, spring_legs, trail_segments

CHROMIUM = "/usr/bin/chromium"
CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update", "--disable-sync"]


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
    (Params(mode="accelerate", to_factor=2.0, steps=1), r"cannot go from \d.\d\d m/s to \d.\d\d m/s \(×2\) in 1 steps: use more"),
])
def test_bad_params_raise_one_line_froude_errors(session, bad, words):
    with pytest.raises(FroudeError, match=words):
        session.solve(bad)


def test_studio_keeps_last_good_result_on_bad_edits(session):
    pytest.importorskip("viser")
    from froude.studio.app import Studio

    studio = Studio(session.prep, port=_free_port())
    try:
        good = studio.good
        for bad in (Params(height=0.0), Params(mode="accelerate", to_factor=2.0, steps=1), Params(leg_scale=0.0)):
            studio.apply(bad)
            assert studio.good is good and studio.shown is good
            assert "status=error" in studio.gui_state.content
            assert studio.message.startswith("error: ")
        t = studio.apply(Params(speed=1.3))
        assert studio.good is not good and studio.good.params.speed == 1.3
        assert "status=ok" in studio.gui_state.content and studio.good.hash in studio.gui_state.content
        assert t.result_compute > 0
    finally:
        studio.stop()


def test_studio_previews_only_when_the_result_would_be_slow(session, monkeypatch):
    """A quick result goes straight to the page; an expected-slow one shows the IK-free preview first."""
    pytest.importorskip("viser")
    from froude.studio import app
    from froude.studio.app import Studio

    studio = Studio(session.prep, port=_free_port())
    shown = []
    publish = studio._publish
    monkeypatch.setattr(studio, "_publish", lambda solved, status=None: (shown.append(solved), publish(solved, status)))
    try:
        quick = studio.expected_seconds(Params(speed=1.1))
        assert 0 < quick < app.SLOW_RESULT_S  # 4 strides of the sample: the last solve was quick
        assert studio.expected_seconds(Params(speed=1.1, strides=400)) > app.SLOW_RESULT_S  # scales with length
        t = studio.apply(Params(speed=1.1))
        assert np.isnan(t.preview_compute) and [s.preview for s in shown] == [False, False]  # result, then report
        shown.clear()
        monkeypatch.setattr(app, "SLOW_RESULT_S", 0.0)
        t = studio.apply(Params(speed=1.15))
        assert t.preview_compute > 0 and [s.preview for s in shown] == [True, False, False]
        assert studio.good.params.speed == 1.15 and "status=ok" in studio.gui_state.content
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


# ---- the page, end to end ---------------------------------------------------------------------------
def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _state(page) -> dict:
    text = page.locator("code", has_text="state:").first.inner_text()
    return dict(kv.split("=", 1) for kv in text.split("state:", 1)[1].split())


def _wait_state(page, timeout=30.0, **want) -> dict:
    """Poll the page's state line until every key has the wanted value (callables: a predicate)."""
    t_end = time.monotonic() + timeout
    st = {}
    while time.monotonic() < t_end:
        st = _state(page)
        if all((v(st.get(k)) if callable(v) else st.get(k) == str(v)) for k, v in want.items()):
            return st
        time.sleep(0.1)
    raise AssertionError(f"page state never reached {want}; last: {st}")


def _wait_value_change(box, old: str, timeout: float = 10.0) -> str:
    t_end = time.monotonic() + timeout
    while time.monotonic() < t_end:
        v = box.input_value()
        if v != old:
            return v
        time.sleep(0.1)
    raise AssertionError(f"value stayed {old}")


def _row_input(page, label: str):
    """The text/number input in the GUI row whose label is ``label`` (for a slider: its number box)."""
    return page.locator(f"xpath=//label[normalize-space(text())='{label}']"
                        "/ancestor::div[contains(@class,'mantine-Flex-root')][1]//input[not(@type='hidden')]").first


def _type(page, label: str, value: str) -> None:
    box = _row_input(page, label)
    box.click(timeout=10000)
    box.press("Control+A")
    box.type(value)
    box.press("Enter")


def _pick(page, label: str, option: str) -> None:
    page.get_by_label(label, exact=True).click()
    page.get_by_role("option", name=option, exact=True).click()


@pytest.mark.browser
@pytest.mark.timeout(90)
def test_studio_in_the_browser(tmp_path):
    if not Path(CHROMIUM).exists():
        pytest.skip(f"{CHROMIUM} is missing (apt-get install chromium)")
    pw = pytest.importorskip("playwright.sync_api")
    pytest.importorskip("viser")
    from froude.io.bvh import load_bvh

    shots = Path(os.environ.get("FROUDE_STUDIO_SHOTS", tmp_path))
    shots.mkdir(parents=True, exist_ok=True)
    port = _free_port()
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    proc = subprocess.Popen([sys.executable, "-m", "froude.cli", "view", "--port", str(port)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    lines, url = [], []

    def read_stdout():
        for line in proc.stdout:
            lines.append(line)
            m = re.search(r"froude studio: (http://\S+)", line)
            if m:
                url.append(m.group(1))

    threading.Thread(target=read_stdout, daemon=True).start()
    try:
        t_end = time.monotonic() + 40
        while not url and proc.poll() is None and time.monotonic() < t_end:
            time.sleep(0.1)
        assert url, f"no address printed; exit {proc.poll()}; stdout {lines}"
        assert url[0] == f"http://127.0.0.1:{port}"

        with pw.sync_playwright() as p:
            ctx = p.chromium.launch_persistent_context(
                str(tmp_path / "chromium-profile"), executable_path=CHROMIUM, args=CHROMIUM_ARGS, headless=True,
                viewport={"width": 1200, "height": 760}, accept_downloads=True)
            try:
                page = ctx.new_page()
                page.goto(url[0])
                page.wait_for_selector("code:has-text('state:')", timeout=30000)
                s0 = _wait_state(page, status="ok")
                assert (s0["character"], s0["mode"], s0["speed_factor"]) == ("same", "scale", "1")
                # it plays: the scrubber moves; Pause stops it (and spares software WebGL the redraws)
                t_box = _row_input(page, "Time [s]")
                t_a = t_box.input_value()
                _wait_value_change(t_box, t_a)
                page.get_by_role("button", name="Pause").click()
                page.get_by_role("button", name="Play").wait_for(timeout=5000)
                _type(page, "Time [s]", "0.8")  # scrub to mid-stance of a step
                webgl = page.locator(".mantine-Notification-root", has_text="WebGL").locator("button")
                if webgl.count():  # viser's note that Chromium renders in software: not part of the studio
                    webgl.first.click()
                    page.wait_for_timeout(500)
                page.screenshot(path=str(shots / "studio_start.png"))

                # speed: type into the slider's number box
                _type(page, "Speed factor", "1.3")
                s1 = _wait_state(page, status="ok", speed_factor="1.3")
                assert s1["hash"] != s0["hash"]
                assert float(s1["speed_m_s"]) > 1.2 * float(s0["speed_m_s"])

                # character: pick a preset from the dropdown
                _pick(page, "Character", "child")
                s2 = _wait_state(page, status="ok", character="child")
                assert s2["hash"] != s1["hash"] and s2["n_frames"] != s1["n_frames"]
                page.wait_for_timeout(1000)
                page.screenshot(path=str(shots / "studio_child.png"))

                # the result downloads as BVH: the child's skeleton, the frames on screen
                with page.expect_download(timeout=15000) as dl:
                    page.get_by_role("button", name="Download BVH").click()
                got = tmp_path / dl.value.suggested_filename
                dl.value.save_as(got)
                assert got.suffix == ".bvh" and "child" in got.name
                out = load_bvh(got)
                assert out.n_frames == int(s2["n_frames"])
                ref = load_bvh(sample_path())
                assert out.skeleton.standing_height() < 0.9 * ref.skeleton.standing_height()

                # bad edits: the message shows, the last good result stays, the studio lives
                _type(page, "Height [m]", "0")
                s3 = _wait_state(page, status="error")
                assert s3["hash"] == s2["hash"]
                page.wait_for_selector("text=Height 0 m is outside", timeout=10000)
                _type(page, "Height [m]", "1.1")
                s4 = _wait_state(page, status="ok", hash=lambda h: h != s2["hash"])
                _pick(page, "Mode", "accelerate")
                s4 = _wait_state(page, status="ok", mode="accelerate", steps="16")
                _type(page, "Goal speed factor", "2")
                _type(page, "Steps to change", "1")
                _wait_state(page, status="error", hash=s4["hash"])
                page.wait_for_selector("text=cannot go from", timeout=10000)
                page.wait_for_timeout(500)
                page.screenshot(path=str(shots / "studio_error.png"))
                _type(page, "Steps to change", "16")
                _type(page, "Goal speed factor", "1.1")
                s5 = _wait_state(page, status="ok", mode="accelerate", to_factor="1.1")
                assert int(s5["n_frames"]) > int(s2["n_frames"])  # 16 steps of change + lead + hold
                page.screenshot(path=str(shots / "studio_accelerate.png"))
                page.get_by_text("vertical leg force").scroll_into_view_if_needed()
                page.screenshot(path=str(shots / "studio_numbers.png"))
                assert proc.poll() is None
            finally:
                ctx.close()
        print(f"\nstudio screenshots: {shots}")
    finally:
        if proc.poll() is None:
            proc.send_signal(signal.SIGINT)  # Ctrl-C: a clean stop, exit 0, no traceback
        try:
            proc.wait(timeout=15)
        except subprocess.TimeoutExpired:
            proc.kill()
            raise
    err = proc.stderr.read()
    assert proc.returncode == 0, err[-2000:]
    assert "Traceback" not in err, err[-2000:]
