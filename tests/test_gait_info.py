"""Ground, contacts and phases on the real clips, and ``froude info`` (JSON and table) end to end."""
from __future__ import annotations

import json
import re

import numpy as np
import pytest

from froude import BodyModel, NotARunningMotion, detect_gait, load_bvh, summarize
from froude.body.gait import require_running

from conftest import RUNNING, WALKING, clip, clip_params


def _info_json(run_cli, name, *extra):
    code, out, err = run_cli("info", clip(name), "--json", *extra)
    assert code == 0, err
    return json.loads(out)


def _info_table(run_cli, name):
    code, out, err = run_cli("info", clip(name))
    assert code == 0, err
    return dict(re.split(r"\s{2,}", line.strip(), maxsplit=1) for line in out.splitlines() if line.strip())


# ---- acceptance 4 -----------------------------------------------------------------------------------------
def test_info_json_on_09_01(run_cli):
    d = _info_json(run_cli, "09_01")
    assert d["schema"] == "froude.info/1"
    assert abs(d["mean_speed_m_s"] - 3.5) <= 0.05 * 3.5
    assert 3 <= len(d["contacts"]) <= 4
    assert d["stance_times_s"], "no complete stance measured"
    assert all(0.12 <= t <= 0.25 for t in d["stance_times_s"]), d["stance_times_s"]
    assert d["has_flight_phase"] is True and len(d["flight_times_s"]) >= 2
    assert all(0.05 <= t <= 0.25 for t in d["flight_times_s"])
    assert d["kind"] == "running"
    # contacts alternate feet
    feet = [c["foot"] for c in d["contacts"]]
    assert all(a != b for a, b in zip(feet, feet[1:]))
    assert d["frames"] == 148 and d["frame_rate_hz"] == pytest.approx(120, abs=0.01)
    assert d["skeleton"]["joints"] == 31 and d["skeleton"]["dof"] == 96
    assert 0.85 <= d["skeleton"]["leg_length_m"] <= 0.87
    assert d["froude_U"] == pytest.approx(d["mean_speed_m_s"] / np.sqrt(9.81 * d["skeleton"]["leg_length_m"]),
                                          rel=1e-3)


def test_info_table_on_09_01(run_cli):
    t = _info_table(run_cli, "09_01")
    speed = float(t["mean speed"].split()[0])
    assert abs(speed - 3.5) <= 0.05 * 3.5
    contacts = t["foot contacts"].split("(")[0].split()
    assert 3 <= len(contacts) <= 4 and all(re.fullmatch(r"[LR]\*?", c) for c in contacts)
    stances = [float(x) for x in t["stance times"].replace(" s", "").split(",")]
    assert all(0.12 <= s <= 0.25 for s in stances)
    assert t["flight times"] != "no flight phase"
    assert [float(x) for x in t["flight times"].replace(" s", "").split(",")]
    assert t["motion"].startswith("running")


def test_info_on_02_01_walk_has_no_flight_phase(run_cli):
    d = _info_json(run_cli, "02_01")
    assert d["has_flight_phase"] is False and d["flight_times_s"] == []
    assert d["kind"] == "walking"
    assert d["double_support_fraction"] > 0.1
    t = _info_table(run_cli, "02_01")
    assert t["flight times"] == "no flight phase"
    assert t["motion"].startswith("walking")


@pytest.mark.parametrize("name", ["cmu-turns/16_51", "02_04"])
def test_info_lists_flights_fewer_than_half_the_steps_have(run_cli, name):
    """A run into a tight turn (CMU 16_51: flights between 2 of its 7 pairs of contacts) and a jump in place (02_04:
    one flight of half a second) printed "flight times: no flight phase" beside the flights their JSON lists:
    the row lists them, said as a minority of the steps."""
    d = _info_json(run_cli, name)
    t = _info_table(run_cli, name)
    assert d["flight_times_s"] and not d["has_flight_phase"]
    listed = [float(x) for x in t["flight times"].split(" s ")[0].split(",")]
    assert listed == pytest.approx(d["flight_times_s"], abs=1e-3)
    assert f"between {len(listed)} of the {len(d['contacts']) - 1} pairs of contacts" in t["flight times"]


def test_info_json_is_the_only_stdout(run_cli):
    code, out, err = run_cli("info", clip("09_01"), "--json")
    json.loads(out)  # nothing but JSON on stdout
    assert err == ""  # --json is quiet


def test_info_mass_option_changes_nothing_kinematic(run_cli):
    a = _info_json(run_cli, "09_01")
    b = _info_json(run_cli, "09_01", "--mass", "55")
    assert a["mean_speed_m_s"] == b["mean_speed_m_s"] and a["contacts"] == b["contacts"]


def test_info_help_and_usage_errors(run_cli):
    code, out, err = run_cli("info", "--help")
    assert code == 0 and "--json" in out
    code, out, err = run_cli("info")
    # one line naming what is missing and where the usage is
    assert code == 2 and err.count("\n") == 1 and "required: clip" in err and "froude info --help" in err


# ---- every clip: the right kind of motion ------------------------------------------------------------------
@pytest.mark.parametrize("name", clip_params(RUNNING))
def test_running_clips_are_running(name):
    motion = load_bvh(clip(name))
    body = BodyModel.from_skeleton(motion.skeleton)
    s = summarize(motion, body)
    assert s.kind == "running", s.reason
    assert s.has_flight and s.double_support_fraction == 0.0
    target = 2.59 if name == "02_03" else 3.5  # SOURCES.md
    assert abs(s.mean_speed - target) <= 0.06 * target
    assert 3 <= s.n_contacts <= 5
    assert np.all((s.stance_times >= 0.12) & (s.stance_times <= 0.30))
    assert 1.2 <= s.step_length <= 1.45 or name == "02_03"
    assert abs(s.heading[2]) > 0.999  # they all run along +Z
    require_running(s, name)


@pytest.mark.parametrize("name", clip_params(WALKING))
def test_walking_clips_are_walking(name):
    motion = load_bvh(clip(name))
    s = summarize(motion, BodyModel.from_skeleton(motion.skeleton))
    assert s.kind == "walking" and not s.has_flight
    with pytest.raises(NotARunningMotion, match="walking"):
        require_running(s, name)


def test_jumping_in_place_is_not_locomotion():
    motion = load_bvh(clip("02_04"))
    s = summarize(motion, BodyModel.from_skeleton(motion.skeleton))
    assert s.kind == "in place"
    with pytest.raises(NotARunningMotion):
        require_running(s, "02_04")


# ---- ground, contacts, robustness ---------------------------------------------------------------------------
def test_ground_height_and_contact_points(run_cli):
    motion = load_bvh(clip("09_01"))
    body = BodyModel.from_skeleton(motion.skeleton)
    markers = body.foot_markers(motion)
    gait = detect_gait(motion, body, markers)
    lowest = markers[..., 1].min(axis=(1, 2))
    assert abs(gait.ground - np.percentile(lowest, 5)) < 0.03
    for s in gait.stances:
        assert abs(s.contact_point[1] - s.ground) < 0.03
        # the stance foot hardly slides: its lowest marker stays within a foot length
        assert np.ptp(markers[s.start : s.stop, s.foot, :, 2].min(axis=1)) < 0.3
        assert gait.contact[s.start : s.stop, s.foot].all()
    # flights lie between stances and have no foot down
    for a, b in gait.flights:
        assert not gait.contact[a:b].any()


def test_contacts_are_robust_to_marker_noise():
    """1-3 mm of white noise on every foot marker (optical mocap is ~1 mm) changes no contact or flight and
    moves complete stances by at most 2 frames (17 ms). A stance cut by the clip's edge may end later:
    its toe-off speed hovers at the threshold (measured: up to 8 frames in 4 of 30 seeds)."""
    motion = load_bvh(clip("09_01"))
    body = BodyModel.from_skeleton(motion.skeleton)
    markers = body.foot_markers(motion)
    clean = detect_gait(motion, body, markers)
    rng = np.random.default_rng(0)
    for sigma in (0.001, 0.002, 0.003):
        for _ in range(5):
            g = detect_gait(motion, body, markers + rng.normal(scale=sigma, size=markers.shape))
            assert [(s.foot, s.partial) for s in g.stances] == [(s.foot, s.partial) for s in clean.stances]
            assert len(g.flights) == len(clean.flights)
            for a, b in zip(g.stances, clean.stances):
                if not b.partial:
                    assert abs(a.start - b.start) <= 2 and abs(a.stop - b.stop) <= 2
            # the ground is a minimum over each stance, so white noise biases it down by ~2 sigma
            assert abs(g.ground - clean.ground) <= 3 * sigma


@pytest.mark.parametrize("factor", [0.5, 2.0])
def test_thresholds_scale_with_leg_length(factor):
    """A dynamically similar copy (lengths x L, times x sqrt(L)) has the same contacts, frame for frame."""
    motion = load_bvh(clip("09_01"))
    scaled = motion.with_(skeleton=motion.skeleton.scaled(factor), root_positions=motion.root_positions * factor,
                          frame_time=motion.frame_time * np.sqrt(factor))
    g0 = detect_gait(motion, BodyModel.from_skeleton(motion.skeleton))
    body = BodyModel.from_skeleton(scaled.skeleton)
    g1 = detect_gait(scaled, body)
    assert body.leg_length == pytest.approx(factor * g0.leg_length)
    np.testing.assert_array_equal(g1.contact, g0.contact)
    s0, s1 = summarize(motion, BodyModel.from_skeleton(motion.skeleton)), summarize(scaled, body)
    assert s1.froude == pytest.approx(s0.froude)
    assert s1.mean_speed == pytest.approx(s0.mean_speed * np.sqrt(factor))
