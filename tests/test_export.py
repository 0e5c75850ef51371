"""Exports and the Python API (issue 14): glTF/GLB (Khronos validator, Blender's importer), per-frame data,
``froude.fit/scale/accelerate`` and the example script, on real CMU and Bandai clips.

The validator is the npm package gltf-validator, installed by scripts/test into .tools/ (or found through
$FROUDE_GLTF_VALIDATOR); Blender is the ``bpy`` wheel (``conftest.bpy_python``: scripts/test installs it into
.tools/bpy-venv; in CI its absence is a failure).
"""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import froude
from froude.core.kinematics import fk
from froude.io.framedata import peak_vertical_force_bw, read_frame_data

from conftest import bpy_python, clip

pytest.importorskip("pygltflib")

REPO = Path(__file__).resolve().parents[1]
HERE = Path(__file__).resolve().parent


def _validator_dir() -> Path | None:
    for c in (os.environ.get("FROUDE_GLTF_VALIDATOR"), REPO / ".tools" / "node_modules" / "gltf-validator"):
        if c and (Path(c) / "package.json").is_file():
            return Path(c)
    return None


def validate(*files) -> list[dict]:
    """The Khronos validator's verdict on each file (skips when node or the validator is missing, except in
    CI, where scripts/test installs it and its absence is a failure)."""
    vdir = _validator_dir()
    node = shutil.which("node")
    if vdir is None or node is None:
        msg = "gltf-validator not installed (scripts/test installs it with npm into .tools/) or node missing"
        if os.environ.get("CI"):
            pytest.fail(msg)
        pytest.skip(msg)
    out = subprocess.run([node, str(HERE / "gltf_validate.js"), str(vdir), *map(str, files)], capture_output=True,
                         text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    return [json.loads(line) for line in out.stdout.splitlines()]


@pytest.fixture(scope="module")
def outputs():
    """Three outputs through the API: a CMU run scaled to a child, a Bandai run at another height, and an
    acceleration of a CMU run."""
    cmu = froude.fit(clip("09_01"))
    return {
        "cmu_child": froude.scale(cmu, "child", strides=2),
        "bandai": froude.scale(clip("dataset-1_dash_feminine_001"), height=1.5, strides=2),
        "accelerate": froude.accelerate(cmu, to_factor=1.2, steps=8),
    }


# ---- glTF -------------------------------------------------------------------------------------------------
def test_glb_outputs_pass_the_khronos_validator(outputs, tmp_path):
    files = []
    for name, res in outputs.items():
        files += [res.save(tmp_path / f"{name}.glb")[0],
                  froude.save(res.motion, tmp_path / f"{name}_bones.gltf", mesh=False)]
    for name in ("09_01", "dataset-1_run_tired_001"):  # input clips converted as they are (6-channel Bandai joints)
        files.append(froude.save(froude.load(clip(name)), tmp_path / f"{name}.glb"))
    verdicts = validate(*files)
    assert len(verdicts) == len(files)
    for v in verdicts:
        assert v["errors"] == 0, v
        assert v["warnings"] == 0, v  # not required, but these files are clean: keep them so


@pytest.mark.parametrize("suffix", [".glb", ".gltf"])
def test_gltf_round_trip_keeps_the_pose(outputs, tmp_path, suffix):
    """froude's own glTF reader gives back the same joints, channel layout and world joint positions."""
    for name, res in outputs.items():
        path = res.save(tmp_path / f"{name}{suffix}", report=False)[0]
        back = froude.load(path)
        m = res.motion
        assert back.skeleton.names == m.skeleton.names and back.skeleton.channels == m.skeleton.channels
        assert back.n_frames == m.n_frames and back.frame_time == pytest.approx(m.frame_time)
        err = np.abs(fk(back)[0] - fk(m)[0]).max()
        assert err < 1e-5, f"{name}: joint positions differ by {err * 1000:.4f} mm"  # float32 in the file


def test_blender_imports_the_glb_with_froude_joint_positions(outputs, tmp_path):
    """Blender's own glTF importer (bpy wheel): every joint of every frame within 1 mm of froude's FK."""
    py = bpy_python()
    for name, res in outputs.items():
        glb = res.save(tmp_path / f"{name}.glb", report=False)[0]
        out = tmp_path / f"{name}.json"
        run = subprocess.run([py, str(HERE / "blender_joints.py"), str(glb), str(res.motion.fps), str(out)],
                             capture_output=True, text=True, timeout=600)
        assert run.returncode == 0, run.stderr[-2000:]
        data = json.loads(out.read_text())
        names = res.motion.skeleton.names
        blender = np.array([[frame[n] for n in names] for frame in data["frames"]])
        assert data["first"] == 0 and blender.shape == (res.motion.n_frames, len(names), 3)
        err_mm = 1000 * np.abs(blender - fk(res.motion)[0]).max()
        print(f"{name}: Blender vs froude FK, largest joint difference {err_mm:.4f} mm")
        assert err_mm < 1.0


def test_convert_gltf_back_to_bvh_and_bad_files(tmp_path):
    m = froude.load(clip("dataset-1_dash_normal_001"))
    glb = froude.save(m, tmp_path / "dash.glb")
    back = froude.load(glb)
    bvh = froude.save(back, tmp_path / "dash.bvh")
    again = froude.load(bvh)
    assert np.abs(fk(again)[0] - fk(m)[0]).max() < 1e-4
    (tmp_path / "junk.glb").write_bytes(b"glTF not really")
    with pytest.raises(froude.FroudeError, match="junk.glb"):
        froude.load(tmp_path / "junk.glb")
    with pytest.raises(froude.FroudeError, match=r"\.bvh, \.glb, \.gltf"):
        froude.save(m, tmp_path / "x.fbx")
    assert not (tmp_path / "x.fbx").exists()


# ---- per-frame data -----------------------------------------------------------------------------------------
@pytest.mark.parametrize("suffix", [".csv", ".parquet", ".npz"])
def test_frame_data_matches_report_and_machine(outputs, tmp_path, suffix):
    """Acceptance 14.2: the file's COM is the body's, its force the machine's; the COM tracking and peak
    force the report states are what the file's columns give."""
    if suffix == ".parquet":
        pytest.importorskip("pyarrow")
    tol = 2e-6 if suffix == ".csv" else 0.0  # CSV keeps 9 significant digits
    for name, res in outputs.items():
        d = read_frame_data(res.save_data(tmp_path / f"{name}{suffix}"))
        m = res.motion
        assert len(d["time_s"]) == m.n_frames
        np.testing.assert_allclose(d["time_s"], m.times, atol=tol + 1e-12)
        com = np.stack([d[f"com_{a}_m"] for a in "xyz"], axis=1)
        np.testing.assert_allclose(com, res.body.com(m), atol=tol + 1e-9)  # an independent FK of the output
        force = np.stack([d[f"machine_force_{a}_N"] for a in "xyz"], axis=1)
        np.testing.assert_allclose(force, res.machine_path.force, atol=1e-4 if tol else 0.0, rtol=tol)
        mcom = np.stack([d[f"machine_com_{a}_m"] for a in "xyz"], axis=1)
        np.testing.assert_allclose(mcom, res.machine_path.com, atol=tol)
        track_max_mm = 1000 * np.linalg.norm(com - mcom, axis=1).max()
        assert track_max_mm == pytest.approx(res.report.com_tracking_max_mm, abs=0.01)
        peak = peak_vertical_force_bw({"com_force_y_N": d["com_force_y_N"]}, res.body.total_mass)
        assert peak == pytest.approx(res.report.peak_vertical_force_bw, rel=1e-6)
        # stance/flight phase and contacts agree with the report's flights
        phase = np.asarray(d["phase"]).astype(str)
        assert set(phase) <= {"flight", "left", "right", "double"} and (phase == "flight").any()
        assert ((phase == "flight") == ((d["contact_left"] == 0) & (d["contact_right"] == 0))).all()
        for col in d.values():
            if np.asarray(col).dtype.kind == "f":
                assert np.isfinite(col).all()


def test_frame_data_of_an_input_clip_matches_the_fit(tmp_path):
    """For an input clip the force column is the one the machine was fitted to (eq. 1 from the COM)."""
    fitted = froude.fit(clip("09_03"))
    d = read_frame_data(fitted.save_data(tmp_path / "in.npz"))
    fit = fitted.prepared.fit
    np.testing.assert_allclose(np.stack([d[f"com_force_{a}_N"] for a in "xyz"], axis=1), fit.f_world, rtol=1e-9,
                               atol=1e-6)
    np.testing.assert_allclose(fitted.ground_force, fit.f_world, rtol=1e-9, atol=1e-6)
    assert peak_vertical_force_bw(d, fitted.body.total_mass) == pytest.approx(fitted.report.peak_vertical_force_bw,
                                                                               rel=1e-9)
    assert "machine_force_x_N" not in d


# ---- the Python API -----------------------------------------------------------------------------------------
def test_api_takes_paths_motions_and_fits_alike(tmp_path):
    path = clip("09_02")
    motion = froude.load(path)
    fitted = froude.fit(path)
    a = froude.scale(motion, height=1.2, strides=1)  # was: AttributeError: 'Motion' object has no attribute 'retarget'
    b = froude.scale(fitted, height=1.2, strides=1)
    c = froude.scale(str(path), height=1.2, strides=1)
    for r in (b, c):
        np.testing.assert_allclose(r.motion.root_positions, a.motion.root_positions, atol=1e-9)
    assert a.body.stature == pytest.approx(1.2, rel=1e-6)
    assert a.com.shape == (a.motion.n_frames, 3) and a.ground_force.shape == (a.motion.n_frames, 3)
    assert a.contacts.shape == (a.motion.n_frames, 2) and a.contacts.dtype == bool
    np.testing.assert_allclose(froude.ground_reaction_force(fitted.motion, fitted.body), fitted.ground_force)
    written = a.save(tmp_path / "a.bvh")
    assert [p.name for p in written] == ["a.bvh", "a.report.json"]
    assert json.loads(written[1].read_text())["n_frames"] == a.motion.n_frames
    assert froude.load(written[0]).n_frames == a.motion.n_frames


def test_api_keyword_typo_names_the_valid_arguments():
    with pytest.raises(TypeError) as e:
        froude.scale("run.bvh", heigth=1.2)
    msg = str(e.value)
    assert "'heigth'" in msg and "did you mean 'height'" in msg and "character_mass" in msg and "strides" in msg
    with pytest.raises(TypeError, match="valid arguments: clip, character, to_speed, to_factor"):
        froude.accelerate("run.bvh", to_sped=3.0)
    with pytest.raises(TypeError, match="clip must be a path"):
        froude.fit(42)
    assert set(froude.__all__) >= {"load", "fit", "scale", "accelerate", "ground_reaction_force", "Result", "save"}


def test_example_three_heights(tmp_path):
    out = tmp_path / "out"
    run = subprocess.run([sys.executable, str(REPO / "examples" / "three_heights.py"), "-o", str(out)],
                         capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr[-2000:]
    assert (out / "three_heights.png").stat().st_size > 10_000
    rows = [l.split() for l in run.stdout.splitlines() if l.strip().endswith("BW")]
    assert [r[0] for r in rows] == ["1.2", "1.7", "2.2"]
    speeds = [float(r[2]) for r in rows]
    assert speeds[0] < speeds[1] < speeds[2]  # dynamic similarity: speed grows as sqrt(L)
    for h in ("1.2", "1.7", "2.2"):
        d = read_frame_data(out / f"h{h}.csv")
        assert abs((d["com_y_m"].max()) / float(h) - 0.65) < 0.1  # the COM sits near 0.55-0.65 of stature
        assert (out / f"h{h}.glb").is_file()


# ---- the CLI ----------------------------------------------------------------------------------------------
def test_cli_glb_and_data_outputs(tmp_path, run_cli):
    """-o OUT.glb and --data on scale and accelerate: the validator passes them, the data matches the report."""
    out = tmp_path / "child.glb"
    code, stdout, err = run_cli("scale", clip("09_01"), "--character", "child", "--strides", 2, "-o", out,
                                "--data", tmp_path / "child.csv", "-q")
    assert code == 0, err
    rep = json.loads((tmp_path / "child.report.json").read_text())
    d = read_frame_data(tmp_path / "child.csv")
    assert len(d["time_s"]) == rep["n_frames"]
    com = np.stack([d[f"com_{a}_m"] for a in "xyz"], axis=1)
    mcom = np.stack([d[f"machine_com_{a}_m"] for a in "xyz"], axis=1)
    assert 1000 * np.linalg.norm(com - mcom, axis=1).max() == pytest.approx(rep["com_tracking_max_mm"], abs=0.01)
    assert peak_vertical_force_bw(d, rep["mass_kg"]) == pytest.approx(rep["peak_vertical_force_bw"], rel=1e-6)
    code, _, err = run_cli("accelerate", clip("09_01"), "--to-speed", "1.2x", "--steps", 8, "-o",
                           tmp_path / "fast.gltf", "--data", tmp_path / "fast.parquet", "-q")
    assert code == 0, err
    assert {p.name for p in tmp_path.iterdir()} == {"child.glb", "child.report.json", "child.csv", "fast.gltf",
                                                     "fast.report.json", "fast.parquet"}
    assert all(v["errors"] == 0 for v in validate(out, tmp_path / "fast.gltf"))
    # a bad --data suffix is refused before any work, nothing written
    code, _, err = run_cli("scale", clip("09_01"), "-o", tmp_path / "x.glb", "--data", tmp_path / "x.xlsx")
    assert code == 2 and "--data output must be a .csv or .parquet or .npz" in err
    assert len(err.strip().splitlines()) == 1
    assert not (tmp_path / "x.glb").exists()


def test_cli_convert_both_ways_and_info_data(tmp_path, run_cli):
    src = clip("dataset-1_run_tired_001")
    glb = tmp_path / "tired.glb"
    code, _, err = run_cli("convert", src, glb, "-q")
    assert code == 0, err
    code, _, err = run_cli("convert", glb, tmp_path / "tired.bvh", "--data", tmp_path / "tired.npz", "-q")
    assert code == 0, err
    a, b = froude.load(src), froude.load(tmp_path / "tired.bvh")
    assert b.skeleton.names == a.skeleton.names and b.skeleton.channels == a.skeleton.channels
    assert np.abs(fk(a)[0] - fk(b)[0]).max() < 1e-4
    assert len(read_frame_data(tmp_path / "tired.npz")["time_s"]) == a.n_frames
    code, _, err = run_cli("convert", glb, glb)
    assert code == 2 and "would overwrite the input" in err
    code, _, err = run_cli("convert", src, tmp_path / "x.fbx")
    assert code == 2 and len(err.strip().splitlines()) == 1 and not (tmp_path / "x.fbx").exists()
    code, _, err = run_cli("info", clip("09_03"), "--data", tmp_path / "in.csv")
    assert code == 0, err
    d = read_frame_data(tmp_path / "in.csv")
    fitted = froude.fit(clip("09_03"))
    np.testing.assert_allclose(d["com_force_y_N"], fitted.ground_force[:, 1], rtol=1e-6, atol=1e-3)


def test_api_speed_syntax_and_all_or_none_saves(tmp_path):
    fitted = froude.fit(clip("09_02"))
    a = froude.scale(fitted, speed="0.9x", strides=1)
    b = froude.scale(fitted, speed=0.9, strides=1)
    np.testing.assert_array_equal(a.motion.root_positions, b.motion.root_positions)
    c = froude.scale(fitted, speed="3.4m/s", strides=1)
    assert c.report.mean_speed_m_s == pytest.approx(3.4, rel=0.03)
    with pytest.raises(froude.FroudeError, match="speed: cannot read 'fast'"):
        froude.scale(fitted, speed="fast")
    # the report cannot be written (a folder holds its name): neither file stays (issue 18, point 6)
    (tmp_path / "o.report.json").mkdir()
    with pytest.raises(OSError):
        a.save(tmp_path / "o.glb")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["o.report.json"]
