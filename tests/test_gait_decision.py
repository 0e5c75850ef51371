"""Issue 29, acceptance 2-4: one decision about what a clip is, contacts that agree with the COM, and units.

Every shared clip (``../shared/data/*``) is checked, in the conventions another tool writes it in
(``rig_variants``: metres, centimetres, inches; 30, 60 and 120 Hz; one foot's toe end site moved by 3 cm,
another performer's marker placement). The COM force of the checks is computed here with SciPy's own
Butterworth filter (``sosfiltfilt``), not with froude's.
"""
from __future__ import annotations

import functools
import json
from dataclasses import replace

import numpy as np
import pytest
from scipy.signal import butter, sosfiltfilt

from froude import BodyModel, load_bvh
from froude.body.gait import FLIGHT_FORCE_BW, WALKING_MACHINE_KINDS, _runs, detect_gait, summarize

import rig_variants as rv
from conftest import (
    ALL_CLIPS,
    BANDAI_RUNS,
    BANDAI_WALKS,
    CMU_TURN_CLIPS,
    LOCO_RUNS,
    LOCO_TURNS,
    LOCO_WALKS,
    clip,
    oracle_fk,
    read_bvh_oracle,
)

EVERY_CLIP = tuple(ALL_CLIPS) + BANDAI_RUNS + BANDAI_WALKS + LOCO_WALKS + LOCO_RUNS + LOCO_TURNS + CMU_TURN_CLIPS
CMU_SCALE = 0.056444
#: A 30 Hz clip is written at 60 and 120 Hz from its first 5 s (every shared 30 Hz clip has 3-10 steps there).
UPSAMPLED_S = 5.0


def _is_cmu(name):
    return not (name.startswith("dataset-") or name.startswith("bandai"))


@functools.cache
def _file(name, variant, tmp_root):
    """Path of one clip written in one variant (cached for the module)."""
    b = read_bvh_oracle(clip(name))
    src = CMU_SCALE if _is_cmu(name) else 0.01
    toe = "LeftToeBase" if _is_cmu(name) else "Toes_L"
    rate, _, unit = variant.partition("/")
    if rate == "toe_up":
        b = rv.shifted_end_site(b, toe, src, (0.0, 0.03, 0.0))
    elif rate == "toe_forward":  # along the foot's travel over the take
        p, _ = oracle_fk(b, 1.0)
        travel = p[-1, b.names.index(toe)] - p[1, b.names.index(toe)]
        travel[1] = 0.0
        b = rv.shifted_end_site(b, toe, src, 0.03 * travel / np.linalg.norm(travel))
    elif rate == "excerpt":  # the part of a 30 Hz take that is written at 60 and 120 Hz
        b = replace(b, values=b.values[: int(round(UPSAMPLED_S / b.frame_time))])
    elif rate != "native":
        hz = int(rate.removesuffix("Hz"))
        native = round(1.0 / b.frame_time)
        if hz < native:
            b = rv.every(b, native // hz, pose_frames=1 if _is_cmu(name) else 0)
        elif hz > native:  # the first UPSAMPLED_S of the take (CI time: a long 30 Hz walk at 120 Hz)
            b = replace(b, values=b.values[: int(round(UPSAMPLED_S / b.frame_time))])
            b = rv.upsampled(b, hz // native, pose_frames=1 if _is_cmu(name) else 0)
    if unit:
        b = rv.units(b, src, rv.UNITS[unit])
    path = f"{tmp_root}/{name.replace('/', '_')}.{variant.replace('/', '_')}.bvh"
    with open(path, "w") as f:
        f.write(rv.bvh_text(b))
    return path


@pytest.fixture(scope="module")
def tmp_root(tmp_path_factory):
    return str(tmp_path_factory.mktemp("decision"))


def _rates(name):
    return ("30Hz", "60Hz") if _is_cmu(name) else ("60Hz", "120Hz")  # the native rate is the other one


def _com_force_bw(com, frame_time):
    """(F,) vertical force of eq. 1 [BW] through SciPy's 8 Hz zero-lag Butterworth (2nd order, run twice)."""
    sos = butter(2, 8.0, fs=1.0 / frame_time, output="sos")
    pad = int(round(0.5 / frame_time))
    y = np.pad(com[:, 1], pad, mode="reflect", reflect_type="odd")  # an odd extension: a smooth edge
    y = sosfiltfilt(sos, y, padtype=None)[pad:-pad]
    return 1.0 + np.gradient(np.gradient(y, frame_time), frame_time) / 9.81


def _edge(frame_time):
    """Frames at each edge where the odd extension above bends the force (a quarter second)."""
    return int(round(0.25 / frame_time))


# ---- acceptance 4: units ----------------------------------------------------------------------------------
#: The variants of the unit test: each unit at the clip's own rate, and the two other rates in inches (where
#: a 1.5 m performer and a 3.8 m giant in centimetres, or a 3.3 m one in CMU units, must be told apart).
def _unit_variants(name):
    return tuple(f"native/{u}" for u in ("metres", "centimetres", "inches")) + tuple(f"{r}/inches"
                                                                                     for r in _rates(name))


@pytest.mark.parametrize("name", EVERY_CLIP)
def test_every_clip_reads_its_stature_in_every_unit_and_rate(name, tmp_root):
    """Metres, centimetres and inches at the clip's own rate, inches at the two others: the stature of the
    clip as shipped within 2 % (before: a brisk walk and a grounded run read as 3.78 m performers in
    inches)."""
    src = CMU_SCALE if _is_cmu(name) else 0.01
    true = BodyModel.from_skeleton(load_bvh(clip(name), length_scale=src).skeleton).stature
    bad = []
    for variant in _unit_variants(name):
        m = load_bvh(_file(name, variant, tmp_root))
        st = BodyModel.from_skeleton(m.skeleton).stature
        if abs(st / true - 1.0) > 0.02:
            bad.append(f"{variant}: {st:.3f} m ({m.meta['units']})")
    assert not bad, f"true stature {true:.3f} m; " + "; ".join(bad)


# ---- acceptance 3: contacts agree with the COM -------------------------------------------------------------
def _disagreements(path):
    m = load_bvh(path)
    body = BodyModel.from_skeleton(m.skeleton)
    com, markers = body.com_and_markers(m)
    gait = detect_gait(m, body, markers, com)
    fy = _com_force_bw(com, m.frame_time)
    e = _edge(m.frame_time)
    inside = lambda a, b: a >= e and b <= m.n_frames - e  # noqa: E731
    out = [f"flight {a * m.frame_time:.3f}-{b * m.frame_time:.3f} s: COM force >= {fy[a:b].min():.2f} BW"
           for a, b in gait.flights if inside(a, b) and fy[a:b].min() >= FLIGHT_FORCE_BW]
    out += [f"double support {a * m.frame_time:.3f}-{b * m.frame_time:.3f} s: COM force {fy[a:b].min():.2f} BW"
            for a, b in _runs(gait.contact.all(axis=1)) if inside(a, b) and fy[a:b].min() <= FLIGHT_FORCE_BW]
    return out, summarize(m, body, com, gait).kind


@pytest.mark.parametrize("name", EVERY_CLIP)
def test_contacts_agree_with_the_com_force(name, tmp_root):
    """Every flight the feet show is a time when the COM force (eq. 1, SciPy's filter) falls below 0.2 BW,
    every double support a time when it stays above; the same with one toe end site moved 3 cm up or
    forward and at the two other frame rates, and the clip is the same kind of motion in each."""
    found, kinds = [], {}
    for variant in ("native", "toe_up", "toe_forward") + tuple(f"{r}/inches" for r in _rates(name)):
        bad, kinds[variant] = _disagreements(_file(name, variant, tmp_root))
        found += [f"{variant}: {b}" for b in bad]
    assert not found, "; ".join(found)
    if not _is_cmu(name):  # the higher rates are written from an excerpt: its kind is the excerpt's
        kinds["excerpt"] = _disagreements(_file(name, "excerpt", tmp_root))[1]
        assert kinds["60Hz/inches"] == kinds["120Hz/inches"] == kinds.pop("excerpt"), kinds
        del kinds["60Hz/inches"], kinds["120Hz/inches"]
    assert len(set(kinds.values())) == 1, kinds


# ---- acceptance 2: one decision ---------------------------------------------------------------------------
@pytest.mark.parametrize("name", EVERY_CLIP)
def test_fit_takes_the_machine_info_names(name, run_cli, tmp_path, monkeypatch):
    """``fit`` dispatches by the decision ``info`` prints: a walk or a grounded run to the walking machine, a
    run to the running one, anything else refused with info's own words (the fitters are replaced by
    recorders here: their own work is tested in test_walking.py and test_fit.py)."""
    from froude.apps.cli import fit as cli_fit
    from froude.errors import FroudeError

    code, out, err = run_cli("info", clip(name), "--json")
    assert code == 0, err
    info = json.loads(out)
    called = []

    def record(kind):
        def fitter(motion, body=None, *a, **k):
            called.append(kind)
            raise FroudeError("recorded")
        return fitter

    monkeypatch.setattr("froude.machine.walk_fit.fit_walking_detailed", record("walking"))
    monkeypatch.setattr("froude.machine.fit.fit_machine_detailed", record("running"))
    monkeypatch.setattr("froude.flow.kinds.fit_machine_detailed", record("running"))  # bound at import there
    assert cli_fit  # the CLI imports the fitters when it runs
    code, out, err = run_cli("fit", clip(name), "-o", tmp_path / "m.json")
    assert code == 2
    if info["kind"] in WALKING_MACHINE_KINDS:
        assert called == ["walking"], (info["kind"], err)
    elif info["kind"] == "running":
        assert called == ["running"], (info["kind"], err)
    else:  # refused before any fit, in info's words
        assert called == [] and info["verdict"] in err, (info["kind"], err)


@pytest.mark.parametrize("name", ["09_01", "02_01", "bandai-locomotion/runs/dataset-2_run_elderly_005"])
def test_the_kinds_of_three_gaits(name):
    """A run flies, a walk vaults over its stance leg with both feet down in between, the elderly "run" of
    the Bandai sample has no flight but bounces on its stance leg (SOURCES.md: between walking and
    running)."""
    m = load_bvh(clip(name))
    s = summarize(m, BodyModel.from_skeleton(m.skeleton))
    expected = {"09_01": "running", "02_01": "walking"}.get(name, "grounded running")
    assert s.kind == expected, s.reason
