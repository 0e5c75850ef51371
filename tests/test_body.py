"""The de Leva body model: the table, whole-body COM on real clips, a COM worked out by hand, joint-name
maps (CMU, Mixamo, common names, user YAML) and the error naming unmapped roles, foot markers."""
from __future__ import annotations

import numpy as np
import pytest

from froude import BodyModel, FroudeError, Skeleton, detect_gait, find_roles, load_bvh, load_joint_map
from froude.body.model import DE_LEVA, JointMapError
from froude.core import quat
from froude.core.motion import Motion

from conftest import FIXTURES, RUNNING, clip, clip_params, oracle_fk, read_bvh_oracle

SEGMENTS = ("head", "upper_trunk", "middle_trunk", "lower_trunk") + ("upper_arm", "forearm", "hand", "thigh",
                                                                    "shank", "foot") * 2


# ---- acceptance 3: the table ---------------------------------------------------------------------------
def test_de_leva_male_fractions_sum_to_one():
    assert abs(sum(DE_LEVA[s][0][0] for s in SEGMENTS) - 1.0) <= 2e-4


def test_de_leva_female_fractions_sum_to_0_9999():
    total = sum(DE_LEVA[s][0][1] for s in SEGMENTS)
    assert total == pytest.approx(0.9999, abs=1e-9)
    assert abs(total - 1.0) <= 2e-4


@pytest.mark.parametrize("sex", [0, 1])
def test_de_leva_trunk_parts_add_up_to_the_trunk(sex):
    parts = sum(DE_LEVA[s][0][sex] for s in ("upper_trunk", "middle_trunk", "lower_trunk"))
    assert parts == pytest.approx(DE_LEVA["trunk"][0][sex], abs=1e-9)


@pytest.mark.parametrize("sex", ["male", "female"])
def test_model_masses_add_up_to_the_body_mass(sex):
    body = BodyModel.from_skeleton(load_bvh(clip("09_01")).skeleton, mass=82.5, sex=sex)
    assert len(body.seg_names) == 16
    assert body.seg_mass.sum() == pytest.approx(82.5, rel=1e-12)
    k = 0 if sex == "male" else 1
    thigh = body.seg_mass[body.seg_names.index("left_thigh")]
    assert thigh == pytest.approx(82.5 * DE_LEVA["thigh"][0][k] / (1.0 if k == 0 else 0.9999), rel=1e-9)


def test_default_is_a_70_kg_male():
    body = BodyModel.from_skeleton(load_bvh(clip("09_01")).skeleton)
    assert body.total_mass == 70.0 and body.sex == "male"


def test_female_model_differs():
    sk = load_bvh(clip("09_01")).skeleton
    m, f = BodyModel.from_skeleton(sk), BodyModel.from_skeleton(sk, sex="female")
    assert not np.allclose(m.seg_mass, f.seg_mass)
    assert not np.allclose(m.seg_local, f.seg_local)


def test_per_segment_overrides():
    sk = load_bvh(clip("09_01")).skeleton
    base = BodyModel.from_skeleton(sk)
    body = BodyModel.from_skeleton(sk, overrides={"head": 0.10, "left_foot": 0.02})
    assert body.seg_mass.sum() == pytest.approx(70.0)
    assert body.seg_mass[body.seg_names.index("head")] == pytest.approx(7.0)
    assert body.seg_mass[body.seg_names.index("left_foot")] == pytest.approx(1.4)
    others = [i for i, n in enumerate(body.seg_names) if n not in ("head", "left_foot")]
    ratio = body.seg_mass[others] / base.seg_mass[others]
    assert np.allclose(ratio, ratio[0])  # the rest scaled together
    with pytest.raises(FroudeError, match="unknown segment 'tail'"):
        BodyModel.from_skeleton(sk, overrides={"tail": 0.1})
    with pytest.raises(FroudeError):
        BodyModel.from_skeleton(sk, overrides={"head": 1.5})
    with pytest.raises(FroudeError):
        BodyModel.from_skeleton(sk, mass=-1)
    with pytest.raises(FroudeError):
        BodyModel.from_skeleton(sk, sex="other")


# ---- acceptance 3: COM heights on the real clips ---------------------------------------------------------
def _rest_motion(sk):
    return Motion(sk, np.zeros((1, 3)), quat.identity((1, sk.n_joints)), 1 / 120)


def _standing_com_ratio(sk, body):
    """Height of the rest-pose COM above the rest pose's lowest point, over the stature."""
    com = body.com(_rest_motion(sk))[0]
    pts = np.concatenate([sk.rest_positions(), sk.rest_end_sites()])
    return (com[1] - pts[:, 1].min()) / body.stature


@pytest.mark.parametrize("name", clip_params(RUNNING))
def test_standing_com_is_53_to_60_percent_of_stature(name):
    """'Standing COM' (the lead's interpretation): the COM of the rest pose, measured from the rest pose's
    lowest point, over BodyModel.stature (≈0.585 on every clip)."""
    sk = load_bvh(clip(name)).skeleton
    body = BodyModel.from_skeleton(sk)
    ratio = _standing_com_ratio(sk, body)
    assert 0.53 <= ratio <= 0.60, ratio
    # the stature is a human one and close to the rest pose's extent (legs straightened)
    assert 1.3 < body.stature < 2.0
    assert body.stature == pytest.approx(sk.standing_height(), rel=0.05)


@pytest.mark.parametrize("name", clip_params(RUNNING))
def test_first_clean_frame_com_height_is_plausible(name):
    """Looser sanity check: in the first mocap frame the COM is 0.5-0.7 statures above the ground."""
    motion = load_bvh(clip(name))
    body = BodyModel.from_skeleton(motion.skeleton)
    com, markers = body.com_and_markers(motion)
    ground = detect_gait(motion, body, markers).ground
    ratio = (com[0, 1] - ground) / body.stature
    assert 0.5 <= ratio <= 0.7, ratio


@pytest.mark.parametrize("name,leg_units", [("09_01", 15.26), ("02_03", 14.88), ("07_01", 14.33)])
def test_leg_length_matches_the_data_notes(name, leg_units):
    """SOURCES.md gives thigh + shank per subject to 0.01 unit (one side); the model averages both legs."""
    body = BodyModel.from_skeleton(load_bvh(clip(name)).skeleton)
    assert body.leg_length == pytest.approx(leg_units * 0.056444, abs=0.005)


def test_com_lies_between_the_feet_and_the_head():
    motion = load_bvh(clip("09_01"))
    body = BodyModel.from_skeleton(motion.skeleton)
    com = body.com(motion)
    p, _ = body.world(motion)
    head, lfoot = body.roles["head"], body.roles["left_ankle"]
    assert np.all(com[:, 1] < p[:, head, 1]) and np.all(com[:, 1] > p[:, lfoot, 1].min())
    assert np.all(np.abs(com[:, [0, 2]] - p[:, 0, [0, 2]]) < 0.15)  # near the pelvis horizontally


# ---- acceptance 5: COM of the 3-joint fixture by hand -----------------------------------------------------
# Segments (mass, attached joint, point in that joint's frame): the middle of each bone.
#   "upper" 2 kg on Root at (0, 0.5, 0)   (Root -> Mid)
#   "lower" 1 kg on Mid  at (0.5, 0, 0)   (Mid -> Tip)
#   "tip"   1 kg on Tip  at (0, 0, 0.5)   (Tip -> End Site)
# World bone midpoints follow from the hand FK in test_kinematics (positions per frame):
#   frame 0: upper (1, 2.5, 3), lower (1.5, 3, 3), tip (2, 3, 3.5)  -> COM (5.5, 11, 12.5) / 4
#   frame 1: upper (-0.5, 0, 0), lower (-1, 0.5, 0), tip (-0.5, 1, 0) -> COM (-2.5, 1.5, 0) / 4
#   frame 2: upper (0, 0.5, 0), lower (0, 1, -0.5), tip (0.5, 1, -1)  -> COM (0.5, 3, -1.5) / 4
#   frame 3: upper (0, 0, 0.5), lower (0, 0.5, 1), tip (0.5, 1, 1)    -> COM (0.5, 1.5, 3) / 4
HAND_COM = np.array([[5.5, 11, 12.5], [-2.5, 1.5, 0], [0.5, 3, -1.5], [0.5, 1.5, 3]]) / 4


def _three_joint_body(skeleton):
    return BodyModel(
        skeleton=skeleton, total_mass=4.0, sex="male", seg_names=("upper", "lower", "tip"),
        seg_joint=np.array([0, 1, 2]), seg_local=np.array([[0, 0.5, 0], [0.5, 0, 0], [0, 0, 0.5]]),
        seg_mass=np.array([2.0, 1.0, 1.0]), marker_joint=np.array([[1, 2, 2], [1, 2, 2]]),
        marker_local=np.array([[[0, 0, 0], [0, 0, 0], [0, 0, 1]]] * 2, dtype=float), roles={},
        leg_length=1.0, stature=1.0,
    )


def test_three_joint_fixture_com_by_hand():
    from froude.core.kinematics import com_jacobian

    motion = load_bvh(FIXTURES / "three_joint.bvh", clean=False)
    body = _three_joint_body(motion.skeleton)
    np.testing.assert_allclose(body.com(motion), HAND_COM, atol=1e-12)
    p, R = body.world(motion)
    com, _ = com_jacobian(motion.skeleton, p, R, body.seg_mass, body.seg_joint, body.segment_points(p, R))
    np.testing.assert_allclose(com, HAND_COM, atol=1e-12)
    # the "toe end" marker is the End Site: (2,3,4), (0,1,0), (1,1,-1), (1,1,1)
    markers = body.foot_markers(motion)
    np.testing.assert_allclose(markers[:, 0, 2], [[2, 3, 4], [0, 1, 0], [1, 1, -1], [1, 1, 1]], atol=1e-12)


# ---- joint maps ---------------------------------------------------------------------------------------------
def _humanoid(name_of, toe_end_joint=False, head_top_joint=False) -> Skeleton:
    """A small humanoid (metres) whose joint names come from name_of(side or None, part)."""
    spec = [(name_of(None, "pelvis"), None, (0, 0.95, 0))]
    for side, sx in (("left", 1), ("right", -1)):
        spec += [
            (name_of(side, "thigh"), name_of(None, "pelvis"), (0.1 * sx, -0.05, 0)),
            (name_of(side, "shin"), name_of(side, "thigh"), (0, -0.42, 0)),
            (name_of(side, "foot"), name_of(side, "shin"), (0, -0.42, 0)),
            (name_of(side, "toe"), name_of(side, "foot"), (0, -0.04, 0.1)),
        ]
        if toe_end_joint:
            spec.append((name_of(side, "toe_end"), name_of(side, "toe"), (0, -0.02, 0.04)))
    spec += [(name_of(None, "spine"), name_of(None, "pelvis"), (0, 0.2, 0)),
             (name_of(None, "chest"), name_of(None, "spine"), (0, 0.1, 0))]
    for side, sx in (("left", 1), ("right", -1)):
        spec += [
            (name_of(side, "clavicle"), name_of(None, "chest"), (0.05 * sx, 0.28, 0)),
            (name_of(side, "upper_arm"), name_of(side, "clavicle"), (0.13 * sx, 0.02, 0)),
            (name_of(side, "forearm"), name_of(side, "upper_arm"), (0.3 * sx, 0, 0)),
            (name_of(side, "hand"), name_of(side, "forearm"), (0.26 * sx, 0, 0)),
        ]
    spec += [(name_of(None, "neck"), name_of(None, "chest"), (0, 0.3, 0)),
             (name_of(None, "head"), name_of(None, "neck"), (0, 0.05, 0))]
    if head_top_joint:
        spec.append((name_of(None, "head_top"), name_of(None, "head"), (0, 0.2, 0)))
    names = [s[0] for s in spec]
    parents = [-1 if p is None else names.index(p) for _, p, _ in spec]
    head = names.index(name_of(None, "head_top" if head_top_joint else "head"))
    ends = []
    for j in range(len(names)):
        if j not in parents:  # leaves get an End Site, as BVH exporters write
            ends.append((j, np.array([0, 0.1, 0]) if j == head else np.array([0, 0, 0.05])))
    return Skeleton(tuple(names), np.array(parents), np.array([s[2] for s in spec], float),
                    tuple(("Zrotation", "Xrotation", "Yrotation") for _ in names), tuple(ends))


MIXAMO = {"pelvis": "Hips", "thigh": "UpLeg", "shin": "Leg", "foot": "Foot", "toe": "ToeBase",
          "toe_end": "Toe_End", "spine": "Spine", "chest": "Spine1", "clavicle": "Shoulder", "upper_arm": "Arm",
          "forearm": "ForeArm", "hand": "Hand", "neck": "Neck", "head": "Head", "head_top": "HeadTop_End"}


def mixamo(side, part):
    return "mixamorig:" + ({"left": "Left", "right": "Right"}.get(side, "")) + MIXAMO[part]


COMMON = {"pelvis": "Pelvis", "thigh": "Thigh", "shin": "Shin", "foot": "Foot", "toe": "Toe", "spine": "Spine",
          "chest": "Chest", "clavicle": "Clavicle", "upper_arm": "UpperArm", "forearm": "Forearm", "hand": "Hand",
          "neck": "Neck", "head": "Head"}
UE = {"pelvis": "pelvis", "thigh": "thigh", "shin": "calf", "foot": "foot", "toe": "ball", "spine": "spine_01",
      "chest": "spine_02", "clavicle": "clavicle", "upper_arm": "upperarm", "forearm": "lowerarm", "hand": "hand",
      "neck": "neck_01", "head": "head"}
BLENDER = {"pelvis": "hips", "thigh": "thigh", "shin": "shin", "foot": "foot", "toe": "toe", "spine": "spine",
           "chest": "chest", "clavicle": "shoulder", "upper_arm": "upper_arm", "forearm": "forearm", "hand": "hand",
           "neck": "neck", "head": "head"}

NAMINGS = {
    "common LeftThigh": lambda s, p: (s.capitalize() if s else "") + COMMON[p],
    "common L_Thigh": lambda s, p: (s[0].upper() + "_" if s else "") + COMMON[p],
    "common Thigh_R style": lambda s, p: COMMON[p] + ("_" + s[0].upper() if s else ""),
    "Unreal thigh_l": lambda s, p: UE[p] + ("_" + s[0] if s else ""),
    "Blender thigh.L": lambda s, p: BLENDER[p] + ("." + s[0].upper() if s else ""),
}
EXPECTED_PART = {"left_hip": "thigh", "left_knee": "shin", "left_ankle": "foot", "left_toe": "toe",
                 "left_shoulder": "upper_arm", "left_elbow": "forearm", "left_wrist": "hand", "head": "head",
                 "neck": "neck"}


def _check_roles(sk, name_of):
    roles = find_roles(sk)
    for role, part in EXPECTED_PART.items():
        assert sk.names[roles[role]] == name_of("left" if role.startswith("left") else None, part), role
        if role.startswith("left"):
            right = role.replace("left", "right")
            assert sk.names[roles[right]] == name_of("right", part), right
    assert roles["pelvis"] == 0
    return roles


def test_mixamo_names_map():
    sk = _humanoid(mixamo, toe_end_joint=True, head_top_joint=True)
    roles = _check_roles(sk, mixamo)
    assert sk.names[roles["left_toe_end"]] == "mixamorig:LeftToe_End"
    assert sk.names[roles["head_end"]] == "mixamorig:HeadTop_End"
    body = BodyModel.from_skeleton(sk)
    assert body.stature == pytest.approx(1.80, abs=0.01)
    assert 0.53 <= _standing_com_ratio(sk, body) <= 0.60


@pytest.mark.parametrize("style", list(NAMINGS))
def test_common_names_map(style):
    name_of = NAMINGS[style]
    sk = _humanoid(name_of)
    _check_roles(sk, name_of)
    body = BodyModel.from_skeleton(sk)
    assert body.leg_length == pytest.approx(0.84)


def test_cmu_names_map():
    sk = load_bvh(clip("09_01")).skeleton
    roles = find_roles(sk)
    named = {r: sk.names[j] for r, j in roles.items()}
    assert named["left_hip"] == "LeftUpLeg" and named["left_knee"] == "LeftLeg" and named["left_ankle"] == "LeftFoot"
    assert named["left_toe"] == "LeftToeBase" and named["right_shoulder"] == "RightArm"
    assert named["right_elbow"] == "RightForeArm" and named["right_wrist"] == "RightHand"
    assert named["head"] == "Head" and named["pelvis"] == "Hips"


def test_user_yaml_map(tmp_path):
    """Names no rule knows, mapped by a YAML file."""
    codes = {"pelvis": "J0", "thigh": "A", "shin": "B", "foot": "C", "toe": "D", "spine": "S1", "chest": "S2",
             "clavicle": "K", "upper_arm": "E", "forearm": "F", "hand": "G", "neck": "N", "head": "H"}

    def name_of(side, part):
        return ("P" if side == "left" else "Q" if side == "right" else "") + codes[part]

    sk = _humanoid(name_of)
    with pytest.raises(JointMapError):
        BodyModel.from_skeleton(sk)
    yaml_text = "pelvis: J0\nhead: H\nneck: N\n" + "".join(
        f"{side}_{role}: {'P' if side == 'left' else 'Q'}{codes[part]}\n"
        for side in ("left", "right")
        for role, part in (("hip", "thigh"), ("knee", "shin"), ("ankle", "foot"), ("toe", "toe"),
                           ("shoulder", "upper_arm"), ("elbow", "forearm"), ("wrist", "hand"))
    )
    path = tmp_path / "map.yaml"
    path.write_text(yaml_text)
    joint_map = load_joint_map(path)
    body = BodyModel.from_skeleton(sk, joint_map=joint_map)
    reference = BodyModel.from_skeleton(_humanoid(NAMINGS["common LeftThigh"]))
    np.testing.assert_allclose(body.seg_local, reference.seg_local, atol=1e-12)
    np.testing.assert_allclose(body.seg_mass, reference.seg_mass)
    assert sk.names[body.roles["left_knee"]] == "PB"


def test_unmapped_roles_are_named_in_the_error():
    sk = _humanoid(NAMINGS["common LeftThigh"])
    renamed = tuple({"LeftToe": "Zeh_L", "RightForearm": "Unterarm_R"}.get(n, n) for n in sk.names)
    sk2 = Skeleton(renamed, sk.parents, sk.offsets, sk.channels, sk.end_sites)
    with pytest.raises(JointMapError) as e:
        BodyModel.from_skeleton(sk2)
    msg = str(e.value)
    assert "left_toe" in msg and "right_elbow" in msg
    assert "right_toe" not in msg.split("(")[0] and "left_elbow" not in msg.split("(")[0]
    lines = msg.splitlines()
    assert len(lines) == 3  # what to do, then one line per missing role with its likeliest joints
    assert lines[1].split(",")[0] == "  left_toe: likeliest Zeh_L"
    assert lines[2].split(",")[0] == "  right_elbow: likeliest Unterarm_R"


def test_joint_map_errors(tmp_path):
    sk = _humanoid(NAMINGS["common LeftThigh"])
    with pytest.raises(JointMapError, match="unknown role 'tail'"):
        find_roles(sk, {"tail": "Spine"})
    with pytest.raises(JointMapError, match="'Nope'"):
        find_roles(sk, {"left_hip": "Nope"})
    bad = tmp_path / "bad.yaml"
    bad.write_text("- just\n- a list\n")
    with pytest.raises(JointMapError, match="mapping"):
        load_joint_map(bad)
    with pytest.raises(JointMapError):
        load_joint_map(tmp_path / "missing.yaml")


def test_cli_reports_unmapped_roles_in_a_few_lines(run_cli, tmp_path):
    text = (FIXTURES / "humanoid_metres.bvh").read_text().replace("LeftToe", "Zeh_L")
    p = tmp_path / "h.bvh"
    p.write_text(text)
    code, out, err = run_cli("info", p)
    assert code == 2 and out == ""
    lines = err.splitlines()
    head = next(i for i, l in enumerate(lines) if l.startswith("froude info: error: cannot find the joints"))
    assert "--joint-map" in lines[head]
    assert lines[head + 1:] == ["  left_toe: likeliest Zeh_L, Chest, Spine"]  # one line per missing role
    assert "Traceback" not in err
    # the map the message asks for makes the clip readable
    jm = tmp_path / "map.yaml"
    jm.write_text("left_toe: Zeh_L\n")
    code, out, err = run_cli("info", p, "--joint-map", jm)
    assert code == 0, err


# ---- foot markers ----------------------------------------------------------------------------------------------
def test_three_markers_per_foot_on_a_real_clip():
    path = clip("09_01")
    motion = load_bvh(path, clean=False)
    body = BodyModel.from_skeleton(motion.skeleton)
    markers = body.foot_markers(motion)
    assert markers.shape == (motion.n_frames, 2, 3, 3)
    p, ends = oracle_fk(read_bvh_oracle(path), motion.meta["length_scale"])
    sk = motion.skeleton
    for i, side in enumerate(("Left", "Right")):
        np.testing.assert_allclose(markers[:, i, 0], p[:, sk.index(f"{side}Foot")], atol=1e-9)
        np.testing.assert_allclose(markers[:, i, 1], p[:, sk.index(f"{side}ToeBase")], atol=1e-9)
        e = [k for k, (j, _) in enumerate(sk.end_sites) if j == sk.index(f"{side}ToeBase")][0]
        np.testing.assert_allclose(markers[:, i, 2], ends[:, e], atol=1e-9)
    com, mk = body.com_and_markers(motion)
    np.testing.assert_array_equal(mk, markers)
    np.testing.assert_allclose(com, body.com(motion))
