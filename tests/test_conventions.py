"""Any rig, any file: the same real motion re-expressed in other conventions reads the same.

Each shared running clip is rewritten by ``rig_variants`` (independent of froude) in other units, Z-up,
a folded bind pose, other naming families, under a static extra root, with six channels on every joint
and at 30/60 Hz; froude's reading of it (info, fit, scale) must agree with its reading of the original.
Also: froude's own outputs read back at their true size, and the load-time conventions units.
"""
from __future__ import annotations

import functools
import json
import math
from pathlib import Path

import numpy as np
import pytest

from froude.body import conventions
from froude.body.gait import detect_gait, summarize
from froude.body.load import load_bvh
from froude.body.model import BodyModel, find_roles

import rig_variants as rv
from conftest import BANDAI, BANDAI_RUNS, BANDAI_WALKS, MOCAP, RUNNING, clip, clip_params, read_bvh_oracle

CMU_SCALE = 0.056444


def _kind(name):
    return "bandai" if name.startswith("dataset-") else "cmu"


def _variants(name):
    """name -> function(OracleBvh) for the variants of one clip."""
    kind = _kind(name)
    src = 0.01 if kind == "bandai" else CMU_SCALE
    parts = rv.BANDAI_PARTS if kind == "bandai" else rv.CMU_PARTS
    out = {}
    for unit, s in rv.UNITS.items():
        if s != src:
            out[unit] = functools.partial(rv.units, metres_per_unit_from=src, metres_per_unit_to=s)
    out["z_up"] = rv.z_up
    out["folded"] = rv.folded
    for fam in rv.FAMILIES:
        if not (fam == "bandai" and kind == "bandai"):
            out[fam] = functools.partial(rv.renamed, family=fam, parts=parts)
    out["extra_root"] = rv.extra_root
    # Character Creator names with its twist and "share" helper bones, under its static root
    cc = functools.partial(rv.renamed, family="cc", parts=parts)
    helpers = {f"CC_Base_{s}_{n}": [f"CC_Base_{s}_{n}Twist01", f"CC_Base_{s}_{n}Twist02"]
               for s in "LR" for n in ("Thigh", "Calf", "Upperarm", "Forearm")}
    helpers.update({f"CC_Base_{s}_Calf": [f"CC_Base_{s}_KneeShareBone"] for s in "LR"})
    out["cc_helpers"] = lambda b: rv.extra_root(rv.with_helpers(cc(b), helpers), "CC_Base_BoneRoot")
    out["six_channels"] = rv.six_channels
    if kind == "cmu":  # 120 Hz clips; the Bandai clips are 30 Hz already
        out["60Hz"] = functools.partial(rv.every, n=2, pose_frames=1)  # the CMU files open with a T-pose row
        out["30Hz"] = functools.partial(rv.every, n=4, pose_frames=1)
        # the same take written at 30 Hz through an anti-alias filter, as a resampler writes it
        out["30Hz_lowpass"] = functools.partial(rv.resampled, n=4, pose_frames=1)
    return out


def _cases(names):
    if clip_params(names)[0] is not None and isinstance(clip_params(names)[0], str):
        return [(n, v) for n in names for v in _variants(n)]
    return [pytest.param(None, None, marks=pytest.mark.skip(reason="real clips not found"))]


@functools.cache
def _variant_file(name, variant, tmp_root):
    b = read_bvh_oracle(clip(name))
    path = f"{tmp_root}/{name}.{variant}.bvh"
    with open(path, "w") as f:
        f.write(rv.bvh_text(_variants(name)[variant](b)))
    return path


@pytest.fixture(scope="module")
def tmp_root(tmp_path_factory):
    return str(tmp_path_factory.mktemp("variants"))


@functools.cache
def _info(path):
    motion = load_bvh(path)
    body = BodyModel.from_skeleton(motion.skeleton)
    com, markers = body.com_and_markers(motion)
    gait = detect_gait(motion, body, markers)
    s = summarize(motion, body, com, gait)
    return {"speed": s.mean_speed, "froude": s.froude, "leg": body.leg_length, "step_hz": s.step_frequency,
            "height": body.stature, "units": motion.meta["units"], "scale": motion.meta["length_scale"]}


ALL_RUNS = RUNNING + BANDAI_RUNS


@pytest.mark.parametrize("name,variant", _cases(ALL_RUNS))
def test_info_is_the_same_in_every_convention(name, variant, tmp_root):
    """Speed, Froude number, leg length and step frequency within 1 % (issue 12, acceptance 1), at 30 and
    60 Hz too: the step period is timed at midstance, where the COM passes over the planted ball, which a
    30 Hz frame does not quantise (gait.midstance_times)."""
    ref = _info(str(clip(name)))
    got = _info(_variant_file(name, variant, tmp_root))
    for key in ("speed", "froude", "leg", "step_hz"):
        assert got[key] == pytest.approx(ref[key], rel=0.01), (key, got, ref)
    # the height is read in a pose from the motion when the rest pose is folded: a few per cent apart
    assert got["height"] == pytest.approx(ref["height"], rel=0.06 if variant == "folded" else 0.005)


#: run_tired among them: its feet rest on the floor, barely loaded, long before its load rises and after it falls
#: (loaded stances 0.23-0.30 s of 0.33-0.50 s contacts); its cycle is phased by the load (cycle.loaded_events)
FIT_CLIPS = ("09_01", "09_05", "02_03", "dataset-1_dash_old_001", "dataset-1_dash_active_001",
             "dataset-1_run_tired_001")


@functools.cache
def _fit(path):
    from froude.machine.fit import fit_machine_detailed

    motion = load_bvh(path)
    m = fit_machine_detailed(motion).machine
    return m.K, m.theta0


def _assert_same_fit(name, path):
    K0, th0 = _fit(str(clip(name)))
    K, th = _fit(path)
    assert K == pytest.approx(K0, rel=0.03), (K, K0)
    assert abs(math.degrees(th - th0)) <= 0.5, (math.degrees(th), math.degrees(th0))


RATE_VARIANTS = ("60Hz", "30Hz", "30Hz_lowpass")


@pytest.mark.parametrize("name,variant", [c for c in _cases(FIT_CLIPS) if c[-1] not in RATE_VARIANTS])
def test_fit_is_the_same_in_every_convention(name, variant, tmp_root):
    """K within 3 %, θ0 within 0.5° (issue 12, acceptance 1)."""
    _assert_same_fit(name, _variant_file(name, variant, tmp_root))


# Measured (K, θ0 of the 30 Hz thinning against the 120 Hz clip). The cause is the thinned file, not the
# fit: the CMU COM moves 0.5-2 mm above 15 Hz (capture jitter and impacts; about 3 % of its vertical
# spectrum), which the 8 Hz COM filter removes at 120 Hz but every-4th-frame thinning folds below 15 Hz,
# where no filter can tell it from the motion: the 30 Hz eq. 1 force is 0.04-0.05 body weights
# RMS off the 120 Hz one (0.10-0.15 at worst), which moves the 0.5 BW events 2-6 ms and the stance spring
# fits 2-10 %. Over the four possible thinnings (frames 0, 1, 2, 3 mod 4) of the nine runs, 11 of 36
# miss K 3 % or θ0 0.5° (K −8.3 to +7.4 %; ``python benchmarks/fit_rates.py`` prints the table). The same
# frames low-passed before the COM is thinned bring all 36 within 2.9 % and 0.30°, and the take written
# through a resampler's anti-alias filter (``rig_variants.resampled``, test below) within 3.5 % and 0.51° (3
# of 36 miss; every run's first take passes).
# Tried in the fit and measured worse or no better: COM cutoff 5/6/7 Hz at 30 Hz (24/16/10 of 36 miss against
# 11 at 8 Hz; a bias towards low K), a ballistic-flight reconstruction of the COM (16-33 of 36: the 120 Hz COM's own
# flights are 0.19-0.21 body weights off ballistic, so the prior is wrong by more than the noise it would
# remove), spring fits weighted to mid-stance (16-23 of 36).
# Where the content comes from (``fit_rates.py --jitter``): the root's translation, which carries 88-96 % of the
# COM's content above 15 Hz (on 09_02 and 09_06 each segment's share follows its mass: the whole body shifts),
# a 0.46-0.75 mm RMS vibration through each stance (0.31-0.47 mm in flight) peaking at 18-35 Hz (mostly 21-26 Hz),
# which the planted foot shares (its ankle height moves with it, correlation 0.5-0.9 on 8 of 9 runs): at 30 Hz
# it folds to 4-12 Hz, the band of the stance force itself. The errors are in every stance, not a few
# (``fit_rates.py --stances``: over 76 stances RMS 2.2 ms at touchdown, 2.6 ms at liftoff, 3.7 ms in duration,
# 3.6 % in a stance's spring; |K| > 5 % on 14), and each clip has two full stances, so no robust aggregation
# over stances is possible. In the four failing takes the cycle's K follows the stance time (the 120 Hz stance
# time alone brings 09_02 to +0.5 %/−0.13°) and the priors K, a, b, c (09_06: the 120 Hz a, b, c alone give
# +3.3 %). Also measured, not adopted: the 0.5 BW events read on a 6 Hz force at both rates (RMS ΔK 3.10 →
# 2.36 %, Δθ0 0.29 → 0.15°; 5 of 36 miss, 09_03 and 09_07 still) moves the 120 Hz fits (09_02 K 13.65 → 14.72) and
# breaks their bars (09_01 COM RMS 19 mm > 16, 09_03 flight residual 0.275 BW > 0.25); the events of a pulse (a
# sum of 1-4 half-sine harmonics over the stance, filtered like the COM) fitted to the force at both rates (6 of
# 36 miss, RMS 2.2-2.4 %/0.14-0.15°) shorten the 120 Hz stances by 3-18 ms (K up to +26 %, COM RMS up to 25 mm);
# a sharper cut of the 30 Hz COM above 12 Hz (9 of 36, RMS 2.9 %/0.32°); the feet's marker events (RMS 8 ms at
# touchdown, 16 ms at liftoff at 30 Hz against 120 Hz).
# Events from the whole COM trajectory (``benchmarks/trajectory_events.py``: ballistic flights, g known, joined to a
# half-sine stance force by least squares on the raw COM at the clip's samples, ~20 per stance at 30 Hz): over 71
# stances RMS 1.5 ms at touchdown, 1.7 at liftoff, 3.1 ms in duration (2.3 ms where the pulse crosses 0.5 BW),
# against the force crossings' 3.7 ms; put in the fit, 5-7 of 36 takes still miss (09_01 K −7.6 %, 09_04 −4.3 %/
# +0.93°, 09_03 −3.2 %, 09_02 θ0 +0.58°, one run's stance dropped at the clip's edge at one rate only: 09_08 +8.3 %
# or, with a looser edge, 02_03 +9.5 %; 09_06 +13.5 % where a 60 ms contact sliver at the take's start pulls the
# contacts' median under SHORT_STANCE_S), and the 120 Hz fits move (θ0 +2.2 to +4.1°, K −9.5 to +8.2 %: the fitted
# pulse begins 18 ms (11-27) before the force's 0.5 BW crossing and ends 7 ms (−2 to 14) after); its own 0.5 BW
# crossings move θ0 −1.3 to −0.45° and K +2 to +20 % (120 Hz COM RMS up to 25 mm against the 16 mm bar; 7 of 36 miss).
# The error sits in both kinds of input of the cycle search (``benchmarks/fit_inputs.py``): the 30 Hz take's stance
# time, flight time and speed swapped for the 120 Hz ones leave 7 of 36 misses (RMS 2.25 %/0.12°), its priors K, a, b,
# c swapped leave 5 (1.82 %/0.29°), U, H, θ0 swapped none fewer (11); so no reweighting of the search closes it: K's
# scale 0.3-3 (11 of 36, RMS ΔK 3.17-3.19 %), a stance time held only within σ = 0.3-5 % (10-15 of 36, 3.08-3.17 %;
# the 120 Hz K moves up to −7 %), a, b, c priors fixed at the runs' mean (8 of 36; the 120 Hz K moves −7 to +6 %).
# The COM's displacement instead of its force fixes the spring worse: each stance's eq. 2 spring fitted to the raw
# COM at the clip's frames (its basis integrated twice, ``--displacement``) differs from the 120 Hz one by 6.3 % RMS
# (force: 3.6 %; with the flights' W_S 0.1 s instead of 0.05: 4.7 %, none: 28 %); the whole machine fitted to the COM's
# displacement through the simulator (``--machine``: 120 Hz K −38 to +4 %, θ0 +0.1 to +1.4°) misses 23-24 of 36
# (RMS ΔK 7.4-7.9 %): the machine misses the 120 Hz COM by 3.3-12.5 mm RMS, far above the 0.5 mm vibration, and the
# spring trades against a, b, c along that misfit.
_RATE_SHORT = {
    ("09_02", "30Hz"): "K +4.4 %, θ0 −0.74° (COM content above 15 Hz aliased by the thinning; events 5 ms apart)",
    ("09_03", "30Hz"): "K −3.1 % (COM content above 15 Hz aliased by the thinning; spring fits 4 % apart)",
    ("09_06", "30Hz"): "K +7.4 % (COM content above 15 Hz aliased by the thinning; one stance's spring 14.1 → 15.6)",
    ("09_07", "30Hz"): "K +4.2 % (COM content above 15 Hz aliased by the thinning; stance 2.7 ms short)",
}


def _rate_fit_cases():
    if MOCAP is None:
        return [pytest.param(None, None, marks=pytest.mark.skip(reason="real clips not found"))]
    return [pytest.param(n, v, marks=pytest.mark.xfail(reason=_RATE_SHORT[(n, v)], strict=True))
            if (n, v) in _RATE_SHORT else pytest.param(n, v)
            for n in RUNNING for v in RATE_VARIANTS]


@pytest.mark.parametrize("name,variant", _rate_fit_cases())
def test_fit_is_the_same_at_60_and_30_hz(name, variant, tmp_root):
    """Every CMU run thinned to 60 and 30 Hz, and written at 30 Hz through an anti-alias filter, fits like its
    120 Hz original (K 3 %, θ0 0.5°)."""
    _assert_same_fit(name, _variant_file(name, variant, tmp_root))


#: Walk variants: another unit, Z-up, a folded rest pose, and (CMU) 60 Hz and 30 Hz through an anti-alias filter.
WALK_VARIANTS = ("metres", "inches", "z_up", "folded", "60Hz", "30Hz_lowpass")
#: Measured misses (``froude fit`` on the variant file), kept as strict xfails. None since a peak must stand 0.01
#: BW above its surroundings (body.com_force.MIN_PEAK_PROMINENCE_BW): 07_01 at 30 Hz through an anti-alias
#: filter missed the push-off by -17.3 % of a step, the machine's landmark on a ripple at 539 ms where the clip's
#: force rises to the liftoff (632 ms); now the machine's is at 612 ms (-3.8 %).
_WALK_SHORT: dict[tuple[str, str], str] = {}


def _walk_variant_cases():
    if MOCAP is None:
        return [pytest.param(None, None, marks=pytest.mark.skip(reason="real clips not found"))]
    names = [n for n in ("02_01", "07_01")] + (list(BANDAI_WALKS) if BANDAI is not None else [])
    return [pytest.param(n, v, marks=pytest.mark.xfail(reason=_WALK_SHORT[(n, v)], strict=True))
            if (n, v) in _WALK_SHORT else pytest.param(n, v)
            for n in names for v in WALK_VARIANTS if v in _variants(n)]


@pytest.mark.parametrize("name,variant", _walk_variant_cases())
def test_walk_fit_meets_issue_17_in_other_conventions(name, variant, tmp_root):
    """A walk in another unit, axis convention, rest pose or frame rate fits the walking machine within
    issue 17's acceptance 1 (force landmarks 0.1 BW and 5 % of a step, stance and double support 5 %, COM
    1.5 cm), as its original does (tests/test_walking.py)."""
    from froude.machine.walk_fit import fit_walking_detailed

    q = fit_walking_detailed(load_bvh(_variant_file(name, variant, tmp_root))).machine.quality
    for key in ("peak1", "trough", "peak2"):
        assert abs(q[key + "_error_bw"]) <= 0.1, (key, q[key + "_error_bw"])
        assert abs(q[key + "_timing_error_step"]) <= 0.05, (key, q[key + "_timing_error_step"])
    assert abs(q["stance_time_error"]) <= 0.05 and abs(q["double_support_error"]) <= 0.05
    assert q["com_rms_m"] <= 0.015


@pytest.mark.parametrize("variant", list(_variants("09_01")))
def test_scaling_to_a_child_meets_the_bars_in_every_convention(variant, tmp_root):
    from froude.flow import pipeline

    path = _variant_file("09_01", variant, tmp_root)
    res = pipeline.scale(pipeline.prepare(path), "child")
    assert res.report.check_bars() == []


# ---- what the loader says ----------------------------------------------------------------------------
@pytest.mark.parametrize("name", clip_params(BANDAI_RUNS))
def test_bandai_rig_reads_in_centimetres_at_human_size(name):
    m = load_bvh(clip(name))
    assert m.meta["length_scale"] == 0.01 and m.meta["units"].startswith("centimetres")
    assert m.skeleton.reference_pose is not None  # the folded bind pose was recognised
    body = BodyModel.from_skeleton(m.skeleton)
    # froude's stature is the joints' (CMU's performers read 1.44-1.51 m): the same proportion here
    assert 1.40 <= body.stature <= 1.60 and 1.75 <= body.stature / body.leg_length <= 1.90
    assert 0.75 <= body.leg_length <= 0.85
    assert m.skeleton.names[body.roles["pelvis"]] == "Hips"  # not the static joint_Root
    # every trunk segment hangs on the spine between the hips and the head, not on joint_Root
    spine = {m.skeleton.index(n) for n in ("Hips", "Spine", "Chest", "Neck", "Head")}
    trunk = [body.seg_joint[i] for i, n in enumerate(body.seg_names) if n.endswith("trunk")]
    assert set(trunk) <= spine


def test_one_rig_reads_one_stature():
    """The Bandai clips share one actor rig (leg 0.80 m); one export writes 10 cm end sites on the joints,
    the others none. The head's end site falling short of its anthropometric extent is no head top: every
    clip reads the same stature (before: dash_normal 1.42 m, the others 1.49 m)."""
    if BANDAI is None:
        pytest.skip("Bandai clips not found")
    statures = {n: BodyModel.from_skeleton(load_bvh(clip(n)).skeleton).stature for n in BANDAI_RUNS + BANDAI_WALKS}
    assert max(statures.values()) < 1.005 * min(statures.values()), statures


def test_cmu_clips_keep_their_rest_pose_and_units():
    m = load_bvh(clip("09_01"))
    assert m.meta["length_scale"] == CMU_SCALE and m.skeleton.reference_pose is None
    assert m.meta["up_axis"] == "Y"


@pytest.mark.parametrize("stature,gravity,expected", [
    (170.0, 981.0, "centimetres"), (50.0, 981.0, "centimetres"), (500.0, 981.0, "centimetres"),
    (170.0 / 2.54, 9.81 / 0.0254, "inches"), (3.0 / CMU_SCALE, 9.81 / CMU_SCALE, "CMU units"),
    (0.6 / CMU_SCALE, 9.81 / CMU_SCALE, "CMU units"), (1.7, 9.81, "metres"), (4.0, 9.81, "metres"),
])
def test_unit_detection_does_not_depend_on_size(stature, gravity, expected):
    s, name, why, ambiguous = conventions.choose_unit(stature, gravity)
    assert name == expected and not ambiguous and "flight gravity" in why


def test_without_flight_the_unit_is_the_most_human_and_flagged():
    s, name, why, ambiguous = conventions.choose_unit(150.0, None)
    assert name == "centimetres" and ambiguous and "inches" in why and "--length-scale" in why
    with pytest.raises(ValueError, match="length-scale"):
        conventions.choose_unit(1e6, None)


@pytest.mark.parametrize("family", rv.FAMILIES)
def test_roles_of_every_naming_family(family):
    b = read_bvh_oracle(clip("09_01"))
    r = rv.renamed(b, family, rv.CMU_PARTS)
    names = r.names
    from froude.core.skeleton import Skeleton

    sk = Skeleton(tuple(names), np.array(r.parents), np.asarray(r.offsets), tuple(tuple(c) for c in r.channels))
    roles = find_roles(sk)
    inverse = {v: k for k, v in rv.CMU_PARTS.items()}
    for role, part in (("left_hip", "hip_L"), ("left_knee", "knee_L"), ("left_ankle", "ankle_L"),
                       ("left_toe", "toe_L"), ("right_shoulder", "shoulder_R"), ("right_elbow", "elbow_R"),
                       ("right_wrist", "wrist_R"), ("head", "head"), ("pelvis", "pelvis")):
        assert b.names[roles[role]] == inverse[part], (family, role, names[roles[role]])


# ---- froude's own outputs read back ------------------------------------------------------------------
@pytest.mark.parametrize("height", [0.5, 0.9, 2.5, 4.0, 5.0])
def test_outputs_read_back_at_their_true_height(height, tmp_path, run_cli):
    out = tmp_path / f"h{height}.bvh"
    # --keep: this is about units (a 5 m runner misses the stricter skate bar by 0.02 mm, measured)
    code, _, err = run_cli("scale", clip("09_01"), "--height", height, "-o", out, "-q", "--keep")
    assert code == 0, err
    report = json.loads(out.with_suffix(".report.json").read_text(),
                        parse_constant=lambda c: pytest.fail(f"{c} in the report JSON"))
    code, text, err = run_cli("info", out, "--json")
    assert code == 0, err
    info = json.loads(text)
    assert info["skeleton"]["height_m"] == pytest.approx(height, rel=0.01)
    assert info["mean_speed_m_s"] == pytest.approx(report["mean_speed_m_s"], rel=0.01)


@pytest.mark.parametrize("preset", ["child", "small", "troll", "giant"])
@pytest.mark.parametrize("name", ["09_01", "dataset-1_dash_old_001"])
def test_every_preset_reads_back_at_its_height(preset, name, tmp_path, run_cli):
    from froude.body.characters import load_character

    out = tmp_path / f"{preset}.bvh"
    code, _, err = run_cli("scale", clip(name), "--character", preset, "-o", out, "-q", "--keep")
    assert code == 0, err
    report = json.loads(out.with_suffix(".report.json").read_text())
    code, text, err = run_cli("info", out, "--json")
    info = json.loads(text)
    assert info["skeleton"]["height_m"] == pytest.approx(load_character(preset).height, rel=0.01)
    assert info["mean_speed_m_s"] == pytest.approx(report["mean_speed_m_s"], rel=0.01)
    assert info["skeleton"]["length_scale_m_per_unit"] == load_bvh(clip(name)).meta["length_scale"]  # its unit


@pytest.mark.parametrize("change", [("--character", "giant"), ("--character", "child"), ("--height", "0.5"),
                                    ("--height", "5.0")])
@pytest.mark.parametrize("name", ["02_01", "dataset-1_walk_normal_001"])
def test_walks_read_back_at_their_true_height(name, change, tmp_path, run_cli):
    """A walk has no flight to weigh its unit: the walking cadence (dimensionless, the same for every size)
    does, so a 3 m giant's or a 0.5 m walker's output is not read as a 1.35 m actor in another unit."""
    from froude.body.characters import load_character

    out = tmp_path / "walk.bvh"
    code, _, err = run_cli("scale", clip(name), *change, "-o", out, "-q", "--keep")  # --keep: units, not bars
    assert code == 0, err
    code, text, err = run_cli("info", out, "--json")
    info = json.loads(text)
    height = load_character(change[1]).height if change[0] == "--character" else float(change[1])
    assert info["skeleton"]["height_m"] == pytest.approx(height, rel=0.01), info["skeleton"]
    assert info["skeleton"]["length_scale_m_per_unit"] == load_bvh(clip(name)).meta["length_scale"]


@pytest.mark.parametrize("name", ["02_01", "07_01", "dataset-1_walk_normal_001"])
def test_real_walks_weigh_their_unit_by_cadence(name):
    m = load_bvh(clip(name))
    assert "walking cadence" in m.meta["units"] and not m.meta["units_ambiguous"], m.meta["units"]
    cadence = float(m.meta["units"].split("walking cadence of ")[1].split()[0])
    assert 0.4 < cadence < 0.7  # human walking's dynamically similar step frequency


def test_cadence_decides_where_stature_cannot():
    # a 3 m walker in CMU units (1.35 m if the file were inches) stepping at a giant's 1.29 steps/s
    leg = 1.70 / conventions.UNITS[4][1]
    s, name, why, ambiguous = conventions.choose_unit(3.0 / conventions.UNITS[4][1], None, step_hz=1.29,
                                                      leg_units=leg)
    assert name == "CMU units" and "walking cadence" in why
    # the same file stepping 2.2x as fast cannot be a 3 m walker: a smaller unit is chosen (inches: the
    # 1.35 m actor, or centimetres: a 0.53 m toddler; both step like that)
    s, name, why, ambiguous = conventions.choose_unit(3.0 / conventions.UNITS[4][1], None, step_hz=1.29 * 2.2,
                                                      leg_units=leg)
    assert s < conventions.UNITS[4][1] and "walking cadence" in why


def _figure_heights_px(png, panels: int) -> list[int]:
    """Drawn height [px] of the figure in each of ``panels`` side-by-side panels of a rendered still: the
    rows holding the figure's bluish-grey capsules (the ground, its shadow and the labels are neutral grey
    or black, and the labels lie in the top 60 px)."""
    import imageio.v3 as iio

    im = iio.imread(png)[..., :3].astype(int)
    width = im.shape[1] // panels
    out = []
    for k in range(panels):
        p = im[60:, k * width + 5:(k + 1) * width - 5]
        body = (p.sum(axis=2) < 600) & (p[..., 2] - p[..., 0] > 8)
        rows = np.flatnonzero(body.any(axis=1))
        out.append(int(rows.max() - rows.min()) if rows.size else 0)
    return out


def test_render_draws_outputs_at_their_true_relative_size(tmp_path, run_cli):
    """Issue 12 acceptance 3: the actor, a 0.5 m and a 5 m character drawn side by side keep their heights'
    proportions (pixels per metre alike within 8 %: the poses differ at one instant)."""
    pytest.importorskip("imageio")
    heights = {"h0.5": 0.5, "h5": 5.0}
    paths = [clip("09_01")]
    for tag, h in heights.items():
        out = tmp_path / f"{tag}.bvh"
        code, _, err = run_cli("scale", clip("09_01"), "--height", h, "-o", out, "-q", "--keep")
        assert code == 0, err
        paths.append(out)
    png = tmp_path / "side.png"
    code, _, err = run_cli("render", *paths, "-o", png, "--at", 0.3, "--width", 1800, "--height", 900, "-q")
    assert code == 0, err
    actor = _info(str(clip("09_01")))["height"]
    px = _figure_heights_px(png, 3)
    per_metre = np.array(px) / np.array([actor, *heights.values()])
    assert per_metre.min() > 0.92 * per_metre.max(), (px, per_metre)


# ---- output conventions ------------------------------------------------------------------------------
def _header(path):
    text = path.read_text()
    return text[: text.index("MOTION")], text[text.index("MOTION"):].splitlines()[:3]


def test_outputs_keep_the_inputs_conventions(tmp_path, run_cli):
    src = clip("dataset-1_dash_old_001")
    out = tmp_path / "child.bvh"
    code, _, err = run_cli("scale", src, "--character", "child", "-o", out, "-q", "--keep")
    assert code == 0, err
    a, b = read_bvh_oracle(src), read_bvh_oracle(out)
    assert b.names == a.names and b.channels == a.channels and b.frame_time == a.frame_time
    m = load_bvh(out)
    assert m.meta["length_scale"] == 0.01 and m.meta["up_axis"] == "Y"


def test_z_up_file_is_written_z_up_and_reads_like_its_y_up_original(tmp_path, run_cli):
    """A file laid out as Blender's BVH exporter writes it: Z up, metres, Blender names, six channels on
    every joint. It reads like its Y-up original and its output is written Z-up, reading back the same."""
    b = read_bvh_oracle(clip("09_01"))
    blender = rv.six_channels(rv.renamed(rv.z_up(rv.units(b, CMU_SCALE, 1.0)), "blender", rv.CMU_PARTS))
    zpath = tmp_path / "blender.bvh"
    zpath.write_text(rv.bvh_text(blender))
    ref, got = _info(str(clip("09_01"))), _info(str(zpath))
    for key in ("speed", "froude", "leg", "step_hz", "height"):
        assert got[key] == pytest.approx(ref[key], rel=0.005), key
    outs = {}
    for tag, path in (("y", clip("09_01")), ("z", zpath)):
        outs[tag] = tmp_path / f"{tag}_child.bvh"
        code, _, err = run_cli("scale", path, "--character", "child", "-o", outs[tag], "-q")
        assert code == 0, err
    assert load_bvh(outs["z"]).meta["up_axis"] == "Z"
    oz = read_bvh_oracle(outs["z"])
    assert oz.names == blender.names and oz.channels == blender.channels
    # the output stands along +Z in the file: its head is above its feet in file Z
    from conftest import oracle_fk
    p, _ = oracle_fk(oz, 1.0)
    head, foot = oz.names.index("head"), oz.names.index("foot.L")
    assert (p[:, head, 2] - p[:, foot, 2]).mean() > 0.5
    iy, iz = _info(str(outs["y"])), _info(str(outs["z"]))
    for key in ("speed", "height", "leg"):
        assert iz[key] == pytest.approx(iy[key], rel=0.01), key


BLENDER_EXPORT = Path(__file__).parent / "fixtures" / "blender" / "09_01_blender_metres.bvh"


def test_a_real_blender_export_reads_and_scales_like_its_original(tmp_path, run_cli):
    """Issue 12 acceptance 4 on a file written by Blender itself (5.0.1, the bpy wheel; made by
    tests/blender_bvh_export.py from the shipped 09_01): Z up, metres, six channels on every joint, frame time
    to 6 decimals. ``info`` and ``scale --character child`` agree with the Y-up original; the output stays
    in Blender's layout (measured: speed, step frequency, height, leg within 0.01 %)."""
    from importlib.resources import files

    original = str(files("froude") / "data" / "09_01.bvh")
    ref, got = _info(original), _info(str(BLENDER_EXPORT))
    for key in ("speed", "froude", "leg", "step_hz", "height"):
        assert got[key] == pytest.approx(ref[key], rel=0.001), key
    assert load_bvh(BLENDER_EXPORT).meta["up_axis"] == "Z"
    reports = {}
    for tag, path in (("y", original), ("blender", BLENDER_EXPORT)):
        out = tmp_path / f"{tag}_child.bvh"
        code, _, err = run_cli("scale", path, "--character", "child", "-o", out, "-q")
        assert code == 0, err
        reports[tag] = json.loads(out.with_suffix(".report.json").read_text(),
                                  parse_constant=lambda c: pytest.fail(f"{c} in the report JSON"))
    for key in ("mean_speed_m_s", "step_frequency_hz", "froude_U", "leg_length_m", "flight_gravity_m_s2",
                "leg_stiffness_K"):
        assert reports["blender"][key] == pytest.approx(reports["y"][key], rel=0.001), key
    back = read_bvh_oracle(tmp_path / "blender_child.bvh")
    assert back.names == read_bvh_oracle(BLENDER_EXPORT).names
    assert load_bvh(tmp_path / "blender_child.bvh").meta["up_axis"] == "Z"


def test_output_unit_rotations_only_and_frame_time(tmp_path, run_cli):
    out = tmp_path / "o.bvh"
    code, _, err = run_cli("scale", clip("dataset-1_dash_old_001"), "--character", "giant", "-o", out, "-q",
                           "--units", "m", "--rotations-only", "--fps", "120", "--keep")
    assert code == 0, err
    b = read_bvh_oracle(out)
    assert all(not any(c.endswith("position") for c in ch) for ch in b.channels[1:])
    assert b.frame_time == pytest.approx(1 / 120, rel=1e-9)
    assert "Frame Time: 0.008333333333" in out.read_text()
    code, text, err = run_cli("info", out, "--json")
    info = json.loads(text)
    assert info["frame_rate_hz"] == 120.0 and info["skeleton"]["length_scale_m_per_unit"] == 1.0
    assert info["skeleton"]["height_m"] == pytest.approx(3.0, rel=0.01)


# ---- the Bandai clips as delivered (issue 12, acceptance 2) ---------------------------------------------
BANDAI_STRIDING = tuple(n for n in BANDAI_RUNS if n != "dataset-1_dash_normal_001")
# The cases that miss a bar, measured 2026-11-26 with the IK's floor hold (tiredtroll, ik.correct._hold_on_floor)
# and the body path meeting the ground path near the floor (switch, synthesis.targets._body_path_correction)
# (`python benchmarks/bars_matrix.py --matrix 12` prints the same table)
# (clip, index in _CHANGES, output rate) -> the bars missed. The stricter skate measure
# (ball and tip near the floor) is a bar since issue 13. None is missed now: run_tired's troll at 30 Hz (5.11 mm:
# its tip at the output's first frame, 0.03 L up and swinging forward after a contact that ended before the clip,
# was measured as resting there) meets it since the measure takes a cut contact's floor from the foot's whole
# stances (metrics._floor_rest_heights; 1.17 mm). Every case meets every bar and must keep doing so; a case
# listed here that starts meeting the bars fails (strict) so that it is taken off the list.
_CHANGES = [("child", 1.0), ("troll", 1.0), ("giant", 1.0), (None, 0.7), (None, 1.2), ("accelerate", 0.5),
            ("accelerate", 1.3)]
_BANDAI_MISSES: dict[tuple[str, int, int | None], str] = {}


def _bandai_cases():
    names = clip_params(BANDAI_STRIDING)
    if not isinstance(names[0], str):
        return names
    cases = []
    for name in names:
        for i, change in enumerate(_CHANGES):
            for fps in (None, 120.0):
                miss = _BANDAI_MISSES.get((name[len("dataset-1_"):-len("_001")], i, None if fps is None else 120))
                marks = () if miss is None else pytest.mark.xfail(strict=True, reason=miss)
                cases.append(pytest.param(name, change, fps, marks=marks, id=f"{name}-change{i}-{fps}"))
    return cases


@functools.cache
def _bandai_prep(name):
    from froude.flow import pipeline

    return pipeline.prepare(load_bvh(clip(name)))


@pytest.mark.parametrize("name,change,fps", _bandai_cases())
def test_bandai_clips_as_delivered_meet_the_bars(name, change, fps):
    """Every striding Bandai run goes through scale and accelerate with no option; the output meets the
    physics bars, measured at its own rate (the input's 30 Hz, or 120 Hz). A refusal is one line."""
    from froude.errors import FroudeError
    from froude.flow import pipeline

    prep = _bandai_prep(name)
    what, factor = change
    try:
        if what == "accelerate":
            res = pipeline.accelerate(prep, to_factor=factor, fps=fps)
        else:
            res = pipeline.scale(prep, what, speed=factor, fps=fps)
    except FroudeError as e:  # a refusal must be one line (an unreachable speed, say)
        assert "\n" not in str(e)
        raise
    assert res.motion.fps == pytest.approx(fps or 30.0, rel=1e-3)
    assert res.report.check_bars() == []


def test_bandai_loop_is_unrolled_and_walk_scaled(run_cli, tmp_path):
    # the one-stride loop is no longer refused: it is unrolled (issue 13; tests/test_take.py); its child meets
    # every bar (since the skate branch: it missed the stricter skate bar by 2.4 mm before)
    code, out, err = run_cli("scale", clip("dataset-1_dash_normal_001"), "--character", "child", "-o",
                             tmp_path / "loop.bvh", "-q")
    assert code == 0 and (tmp_path / "loop.bvh").exists() and "loop" in out and "physics bars: all met" in out
    code, out, err = run_cli("scale", clip("dataset-1_dash_normal_001"), "-o", tmp_path / "same.bvh", "-q")
    assert code == 0 and "physics bars: all met" in out
    # the walk is no longer refused either: it gets the walking machine (issue 17)
    code, out, err = run_cli("scale", clip("dataset-1_walk_normal_001"), "--character", "giant", "-o",
                             tmp_path / "walk.bvh", "-q")
    assert code == 0 and (tmp_path / "walk.bvh").exists() and "double support" in out, err


@pytest.mark.parametrize("name", clip_params(BANDAI_RUNS))
def test_bandai_clips_render_without_a_root_capsule(name, tmp_path):
    from froude.viz.rig import build_rig

    m = load_bvh(clip(name))
    rig = build_rig(BodyModel.from_skeleton(m.skeleton))
    root = m.skeleton.index("joint_Root")
    assert root not in set(rig.point_joint[np.r_[rig.bone_a, rig.bone_b]])  # nothing drawn from the static root
