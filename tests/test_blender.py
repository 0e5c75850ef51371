"""froude inside Blender (issue 31): the add-on's operators headless with the ``bpy`` wheel, on clips as a
Blender user gets them, against froude's own commands on the same BVH; glTF in from froude and from Blender;
the armature <-> Motion adapter without Blender.

Blender runs in a subprocess (tests/blender_addon_run.py, with ``conftest.bpy_python``: bpy 5.0 needs NumPy
< 2, so scripts/test gives it its own venv); the references are froude's commands run here. A CMU clip is
imported with Blender's BVH importer at 0.056444 (CMU units -> metres) and a Bandai clip at 0.01 (cm ->
metres), each exported to FBX with a mesh skinned to it (its bind pose carries the rest pose) and imported
again (the FBX importer's Ignore Leaf Bones turns the exporter's end bones back into bone tails).
"""
from __future__ import annotations

import json
import subprocess
from pathlib import Path

import numpy as np
import pytest

import froude
from froude.apps.blender.adapter import Armature, armature_basis, armature_motion, pose_from_basis
from froude.core import quat
from froude.core.kinematics import fk
from froude.core.rig import Z_UP_TO_Y_UP

from conftest import bpy_python, cli_main, clip

HERE = Path(__file__).resolve().parent
CMU, BANDAI = "09_01", "dataset-1_run_tired_001"
#: Blender importer scales that make one Blender unit a metre (the scene's unit).
IMPORT_SCALE = {CMU: 0.056444, BANDAI: 0.01}
#: Acceptance 1-2: the add-on's new action against froude's command on the same BVH [m].
JOINT_TOLERANCE_M = 0.5e-3
#: Acceptance 3 and the Analyse button: froude info figures agree within this (relative).
INFO_TOLERANCE = 0.01
CHILD = {"character": "child", "speed_factor": 1.2}
ACCELERATE = {"character": "SAME", "to_factor": 1.2, "steps": 8}  # the law's change needs 8 at x1.2


@pytest.fixture(scope="module")
def blender(tmp_path_factory):
    """Run the add-on in Blender once for every test here: (output folder, {case: log})."""
    py = bpy_python()
    out = tmp_path_factory.mktemp("blender")
    addons = out / "addons"
    assert cli_main(["blender", "--install-addon", "--addons-dir", str(addons), "-q"]) == 0
    cases = [
        {"name": "cmu", "bvh": str(clip(CMU)), "import_scale": IMPORT_SCALE[CMU], "fbx": True, "glb": True,
         "ops": [["scale", {"character": "child", "speed_factor": 4.0}],  # beyond the human range: refused
                 ["scale", {"unlimited": True}],  # allowed, but it misses a bar: refused
                 ["panel", {"unlimited": False}],
                 ["scale", {"speed_factor": 1.2, "joint_map": str(out / "no_such_map.yaml")}],  # no file
                 ["info", {"joint_map": "", "length_unit": "DETECT"}],
                 ["info", {"length_unit": "SCENE"}],
                 ["panel", {}],
                 ["scale", CHILD],
                 ["panel", {}],
                 ["accelerate", ACCELERATE]]},
        {"name": "bandai", "bvh": str(clip(BANDAI)), "import_scale": IMPORT_SCALE[BANDAI], "fbx": True, "glb": True,
         "ops": [["scale", CHILD],  # the FBX importer connected the travelling hips: refused, says how to fix
                 ["disconnect", {"bones": ["Hips"]}],
                 ["info", {}],
                 ["scale", CHILD]]},
    ]
    spec = out / "spec.json"
    spec.write_text(json.dumps({"addons_dir": str(addons), "cases": cases}))
    run = subprocess.run([py, str(HERE / "blender_addon_run.py"), str(spec), str(out)], capture_output=True,
                         text=True, timeout=900)
    assert run.returncode == 0, run.stderr[-3000:]
    return out, {c["name"]: json.loads((out / f"{c['name']}.json").read_text()) for c in cases}


def _done(log: dict, op: str) -> int:
    """The index of the one operator ``op`` that finished."""
    done = [k for k, e in enumerate(log["ops"]) if e["op"] == op and e.get("result") == ["FINISHED"]]
    assert len(done) == 1, [(e["op"], e.get("result")) for e in log["ops"]]
    return done[0]


def _joint_error_mm(out: Path, case: str, k: int, reference) -> float:
    """Largest distance [mm] between the joints of operator k's new action and froude's result."""
    data = np.load(out / f"{case}_{k}.npz")
    names = list(reference.motion.skeleton.names)
    heads = data["heads"][:, [list(data["names"]).index(n) for n in names]]
    ref = fk(reference.motion)[0]
    assert heads.shape == ref.shape, f"{case}: {heads.shape[0]} frames in Blender, {ref.shape[0]} from froude"
    return float(1000 * np.linalg.norm(heads - ref, axis=-1).max())


# ---- acceptance 1 and 2 ------------------------------------------------------------------------------------
@pytest.mark.parametrize("case,name", [("cmu", CMU), ("bandai", BANDAI)])
def test_scale_operator_matches_froude_scale(blender, case, name):
    """BVH -> Blender -> FBX -> Blender, the Scale button (child, x1.2): the new action's world joint positions
    are froude.scale's on the BVH within 0.5 mm."""
    out, logs = blender
    err = _joint_error_mm(out, case, _done(logs[case], "scale"), froude.scale(clip(name), "child", speed=1.2))
    print(f"{case}: Scale button vs froude.scale, largest joint distance {err:.4f} mm")
    assert err < 1000 * JOINT_TOLERANCE_M


def test_accelerate_operator_matches_froude_accelerate(blender):
    """The Accelerate button (x1.2 in 8 steps) on the CMU run through FBX: the new action's world joint positions
    are froude.accelerate's on the BVH within 0.5 mm (the float32 keys Blender and FBX store, ~1e-6 rad, once
    unfroze CMU's LHipJoint/RHipJoint in the IK and moved this by 0.56 mm: ik.solver.UNUSED_JOINT_TOL)."""
    out, logs = blender
    ref = froude.accelerate(clip(CMU), to_factor=1.2, steps=8)
    err = _joint_error_mm(out, "cmu", _done(logs["cmu"], "accelerate"), ref)
    print(f"cmu: Accelerate button vs froude.accelerate, largest joint distance {err:.4f} mm")
    assert err < 1000 * JOINT_TOLERANCE_M


def test_original_action_is_untouched(blender):
    """Every operator, done or refused, leaves the original action's keys as they were, and it stays in the
    file; each done operator added one action and made it the active one."""
    _, logs = blender
    for case, log in logs.items():
        for e in log["ops"]:
            if "original_untouched" not in e:
                continue
            assert e["original_untouched"], (case, e["op"])
            if e["op"] != "info" and e["result"] == ["FINISHED"]:
                assert len(e["actions"]) == e["actions_before"] + 1 and e["active"] != log["original"]


def test_errors_are_one_line_in_the_panel_and_change_nothing(blender):
    """A refusal is one line in the user's terms, in the panel and Blender's report; no action is added, the
    original stays active, the timeline's markers are as they were."""
    _, logs = blender
    refused = [(case, e) for case, log in logs.items() for e in log["ops"]
               if e.get("result") and e["result"] != ["FINISHED"]]
    assert len(refused) == 4, refused
    for case, e in refused:
        assert e["error"] and "\n" not in e["error"] and len(e["error"]) < 400, e["error"]
        assert "Traceback" not in e["result"][0] and e["error"] in e["result"][0]
        assert len(e["actions"]) == e["actions_before"] and e["active"] == logs[case]["original"]
        assert not e["markers_changed"]
    errors = [e["error"] for _, e in refused]
    assert "beyond the human range" in errors[0] and "m/s" in errors[0] and "tick Unlimited" in errors[0]
    assert "physics bars" in errors[1] and "Keep" in errors[1]
    assert "no_such_map.yaml" in errors[2]
    assert "'Hips'" in errors[3] and "Disconnect" in errors[3]


@pytest.mark.parametrize("case,name", [("cmu", CMU), ("bandai", BANDAI)])
def test_analyse_says_what_froude_info_says(blender, case, name):
    """The Analyse button on the armature gives froude info's kind, frames and figures of the BVH within 1 %,
    in the scene's unit and with the unit detected from the motion."""
    _, logs = blender
    ref = froude.info(clip(name))
    infos = [json.loads(e["info"]) for e in logs[case]["ops"] if e["op"] == "info" and e["result"] == ["FINISHED"]]
    assert infos
    for d in infos:
        assert d["kind"] == ref["kind"] and d["frames"] == ref["frames"]
        for k in ("mean_speed_m_s", "froude_U", "step_frequency_hz", "duration_s"):
            assert d[k] == pytest.approx(ref[k], rel=INFO_TOLERANCE), k
        for k in ("height_m", "leg_length_m"):
            assert d["skeleton"][k] == pytest.approx(ref["skeleton"][k], rel=INFO_TOLERANCE), k
        assert [c["foot"] for c in d["contacts"]] == [c["foot"] for c in ref["contacts"]]
    units = [d["skeleton"]["units"] for d in infos]
    if case == "cmu":  # Detect, then Scene
        assert "detected" in units[0] and units[1].startswith("the scene's unit")


def test_panel_draws_every_control(blender):
    """The panel (drawn headless into a recording layout) shows every setting and the three buttons, the
    Analyse figures, and after Scale the physics report."""
    _, logs = blender
    panels = [e for e in logs["cmu"]["ops"] if e["op"] == "panel"]
    assert len(panels) == 3
    for p in panels:
        assert p["unknown_props"] == []
        props = {n for kind, n in p["controls"] if kind == "prop"}
        assert props == {"length_unit", "joint_map", "mass_kg", "mark_contacts", "character", "height_m",
                         "character_mass_kg", "keep", "unlimited", "speed_factor", "strides", "to_factor", "steps"}
        assert [n for kind, n in p["controls"] if kind == "operator"] == ["froude.info", "froude.scale",
                                                                           "froude.accelerate"]
    labels = [[t for kind, t in p["controls"] if kind == "label"] for p in panels]
    assert any("physics bars" in t for t in labels[0])  # the last refusal, as the panel's error line
    assert any(t.startswith("speed: ") and "U = " in t for t in labels[1])
    assert any(t.startswith("physics bars: all met") for t in labels[2])
    assert any(t.startswith("new action: ") for t in labels[2])


def test_installed_addon_registers_in_blender(blender):
    """``froude blender --install-addon`` writes an add-on Blender enables (settings, three operators, the
    panel) and disables cleanly."""
    out, _ = blender
    d = json.loads((out / "addon.json").read_text())
    assert d == {"bl_info": "froude", "settings": True, "operators": ["accelerate", "info", "scale"],
                 "panel": True, "unregistered": True}


# ---- acceptance 3: glTF in -----------------------------------------------------------------------------------
INFO_FIGURES = ("mean_speed_m_s", "froude_U", "step_frequency_hz", "duration_s", "com_vertical_excursion_m")


def _same_info(got: dict, ref: dict) -> None:
    assert got["kind"] == ref["kind"] and got["frames"] == ref["frames"]
    for k in INFO_FIGURES:
        assert got[k] == pytest.approx(ref[k], rel=INFO_TOLERANCE), (k, got[k], ref[k])
    for k in ("height_m", "leg_length_m"):
        assert got["skeleton"][k] == pytest.approx(ref["skeleton"][k], rel=INFO_TOLERANCE), k
    assert [c["foot"] for c in got["contacts"]] == [c["foot"] for c in ref["contacts"]]


@pytest.mark.parametrize("case,name", [("cmu", CMU), ("bandai", BANDAI)])
def test_blender_glb_gives_the_info_of_its_bvh(blender, case, name):
    """A GLB Blender's glTF exporter wrote from the imported BVH: froude info within 1 % of the BVH's."""
    out, _ = blender
    _same_info(froude.info(out / f"{case}.glb"), froude.info(clip(name)))


def test_froude_glb_gives_the_info_of_its_bvh(tmp_path, capsys):
    """``froude scale -o x.glb`` and ``-o x.bvh``: ``froude info`` of the two within 1 %."""
    for suffix in (".glb", ".bvh"):
        assert cli_main(["scale", str(clip(CMU)), "--character", "child", "-o", str(tmp_path / f"x{suffix}"),
                         "-q"]) == 0
    infos = {}
    for suffix in (".glb", ".bvh"):
        capsys.readouterr()
        assert cli_main(["info", "--json", str(tmp_path / f"x{suffix}")]) == 0
        infos[suffix] = json.loads(capsys.readouterr().out)
    _same_info(infos[".glb"], infos[".bvh"])


# ---- the adapter without Blender ------------------------------------------------------------------------------
def _synthetic_armature(motion, rng):
    """An armature as Blender would hold ``motion`` (Z-up, 1 BU = 1 cm, an object rotated and scaled by
    0.01, every bone with its own rest orientation): (Armature, pose_world (F, B, 4, 4))."""
    C = Z_UP_TO_Y_UP
    unit = 0.01
    p, R = fk(motion)
    rest_p = motion.skeleton.rest_positions()
    B = motion.skeleton.n_joints
    R_obj = quat.to_matrix(quat.from_rotvec(np.array([0.0, 0.0, 0.7])))
    obj = np.eye(4)
    obj[:3, :3] = 0.01 * R_obj
    obj[:3, 3] = [1.0, -2.0, 0.5]
    roll = quat.to_matrix(quat.normalize(rng.standard_normal((B, 4))))  # bones' own axes
    rest = np.zeros((B, 4, 4))
    rest[:, 3, 3] = 1.0
    rest[:, :3, :3] = 0.01 * R_obj @ roll
    rest[:, :3, 3] = rest_p @ C / unit  # world heads [BU]: x = Cᵀ x'
    tails = rest[:, :3, 3] + np.einsum("bij,j->bi", rest[:, :3, :3], np.array([0.0, 10.0, 0.0]))
    for j, off in motion.skeleton.end_sites:  # leaf tails at the end sites
        tails[j] = rest[j, :3, 3] + off @ C / unit
    D = np.swapaxes(C, 0, 1) @ R @ C  # world rotations from the rest, Blender axes
    pose = np.broadcast_to(rest, (motion.n_frames, B, 4, 4)).copy()
    pose[..., :3, :3] = D @ rest[None, :, :3, :3]
    pose[..., :3, 3] = p @ C / unit
    connected = np.zeros(B, bool)
    return Armature(motion.skeleton.names, motion.skeleton.parents, rest, tails, connected, obj), pose


def test_adapter_reads_and_writes_an_armature_exactly():
    """An armature made from a clip (Z-up, centimetre units, a rotated and scaled object, random bone axes) is
    read back as the clip's world joints, and the pose-bone bases written for a clip on another skeleton
    (legs x0.8, head x1.4) put the armature's joints exactly where that clip has them."""
    rng = np.random.default_rng(7)
    motion = froude.load(clip(CMU))[:40]
    arm, pose = _synthetic_armature(motion, rng)
    read = armature_motion(arm, pose, motion.frame_time, metres_per_unit=0.01)
    assert read.skeleton.names == motion.skeleton.names and read.n_frames == motion.n_frames
    assert np.abs(fk(read)[0] - fk(motion)[0]).max() < 1e-9
    assert len(read.skeleton.end_sites) == len(motion.skeleton.end_sites)
    # another skeleton: every offset below the knees and the head scaled, the pose turned a little
    factors = np.ones(motion.skeleton.n_joints)
    for j, n in enumerate(motion.skeleton.names):
        factors[j] = 0.8 if ("Leg" in n or "Foot" in n or "Toe" in n) else 1.4 if n == "Head" else 1.0
    other = read.skeleton.with_offsets(read.skeleton.offsets * factors[:, None])
    turned = quat.mul(read.rotations, quat.from_rotvec(0.05 * rng.standard_normal(read.rotations.shape[:2] + (3,))))
    target = read.with_(skeleton=other, rotations=quat.normalize(turned))
    basis = armature_basis(arm, read, target)
    heads_arm = pose_from_basis(arm, basis)[..., :3, 3]
    heads_world = heads_arm @ arm.object_world[:3, :3].T + arm.object_world[:3, 3]
    assert np.abs(heads_world * 0.01 @ Z_UP_TO_Y_UP.T - fk(target)[0]).max() < 1e-9
