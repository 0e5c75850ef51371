"""Renders on the real clips: filmstrip geometry (snapshot count, feet on the drawn ground), GIF/MP4 read
back, and the CLI's handling of bad requests (exit 2, one line, no file left behind)."""
from __future__ import annotations

import math

import numpy as np
import pytest

pytest.importorskip("matplotlib")
imageio = pytest.importorskip("imageio")

from froude.apps.cli import main  # noqa: E402
from froude.body.load import load_bvh  # noqa: E402
from froude.body.model import BodyModel  # noqa: E402
from froude.viz.render import LEFT, RIGHT, build_rig, render_filmstrip, render_video  # noqa: E402

from conftest import clip  # noqa: E402


@pytest.fixture(scope="module")
def clips():
    return load_bvh(clip("09_01")), load_bvh(clip("02_03"))


@pytest.fixture(scope="module")
def strip(clips, tmp_path_factory):
    path = tmp_path_factory.mktemp("strip") / "strip.png"
    return path, render_filmstrip(list(clips), path, width=1600)


def test_filmstrip_file_and_rows(strip, clips):
    path, s = strip
    assert path.is_file()
    img = imageio.v3.imread(path)
    assert img.shape[:2] == s.image.shape[:2]
    h, w = img.shape[:2]
    assert w == 1600 and 200 < h < 1600
    assert len(s.row_px) == 2 and s.row_px[-1][1] == h
    for top, bottom in s.row_px:
        band = img[top:bottom, :, :3].astype(int)
        figure = band.max(axis=2) < 130  # far-side and centre capsules (the ground fill is ~240)
        assert figure.mean() > 0.01, "a row has no figures drawn"
    assert s.labels == ("09_01", "02_03")
    assert 3.0 < s.speeds[0] < 4.2 and 2.0 < s.speeds[1] < 3.2


def test_filmstrip_snapshot_count(strip, clips):
    _, s = strip
    for m, n, t in zip(clips, s.n_snapshots, s.times):
        assert n == math.floor(m.duration / 0.066) + 1
        assert len(t) == n and np.allclose(np.diff(t), 0.066)


def test_filmstrip_feet_on_ground(strip, clips):
    """In stance the lowest drawn point touches the ground line; in flight the runner is clearly above it."""
    _, s = strip
    for m, ground, lowest, contact in zip(clips, s.ground_px, s.lowest_px, s.contact):
        leg_px = BodyModel.from_skeleton(m.skeleton).leg_length * s.px_per_m
        gap = (ground - lowest) / s.px_per_m  # [m], > 0: above the drawn ground line
        assert contact.sum() >= 5 and (~contact).sum() >= 2
        # The ground is the lowest foot point of each stance (median over stances), so in stance the feet
        # rest on the line or a little above; 02_03's capture floor slopes by ~5 cm, hence up to +2.5 cm.
        assert -0.01 <= np.median(gap[contact]) <= 0.025
        assert np.all(np.abs(gap[contact]) <= 0.05 * leg_px / s.px_per_m + 0.01)  # contact height threshold
        assert gap[~contact].max() > 0.05 * leg_px / s.px_per_m  # a flight snapshot with both feet well up


def test_rig_sides_and_no_fingers(clips):
    body = BodyModel.from_skeleton(clips[0].skeleton)
    rig = build_rig(body)
    names = clips[0].skeleton.names
    J = len(names)
    side_of = {names[b]: s for b, s in zip(rig.bone_b, rig.bone_side) if b < J}
    assert side_of["LeftLeg"] == LEFT and side_of["RightFoot"] == RIGHT and side_of["LeftForeArm"] == LEFT
    drawn = {names[b] for b in np.concatenate([rig.bone_a, rig.bone_b]) if b < J}
    assert "LThumb" not in drawn and "RThumb" not in drawn and "LeftFingerBase" not in drawn


@pytest.mark.parametrize("ext", [".gif", ".mp4"])
def test_video_read_back(clips, tmp_path, ext):
    short = [clips[0].cut(0, 37), clips[1].cut(0, 50)]  # 0.30 s and 0.41 s at 120 Hz
    path = tmp_path / f"cut{ext}"
    n, h, w = render_video(short, path, fps=20, width=320, height=240)
    expected = math.floor(max(m.duration for m in short) * 20) + 1  # the longer clip sets the length
    assert expected == 9
    assert n == expected and (h, w) == (240, 320)
    assert path.is_file() and [p.name for p in tmp_path.iterdir()] == [path.name]  # no temp file left
    if ext == ".gif":
        frames = imageio.v3.imread(path, index=None)
        got, size = frames.shape[0], frames.shape[1:3]
    else:
        reader = imageio.v2.get_reader(path)
        got, size = reader.count_frames(), reader.get_meta_data()["size"][::-1]
        reader.close()
    assert abs(got - expected) <= 1
    assert tuple(size) == (240, 320)


def _cli(capsys, argv):
    code = main(argv)
    return code, capsys.readouterr().err


def test_cli_unknown_extension(tmp_path, capsys):
    out = tmp_path / "run.avi"
    code, err = _cli(capsys, ["render", str(clip("09_01")), "-o", str(out), "--quiet"])
    assert code == 2
    assert len(err.strip().splitlines()) == 1 and ".avi" in err
    assert list(tmp_path.iterdir()) == []


def test_cli_broken_bvh(tmp_path, capsys):
    bad = tmp_path / "bad.bvh"
    bad.write_text("HIERARCHY\nROOT Hips\n{\n  OFFSET 0 0\n")
    out = tmp_path / "out.mp4"
    code, err = _cli(capsys, ["render", str(bad), "-o", str(out), "--quiet"])
    assert code == 2
    assert len(err.strip().splitlines()) == 1 and "bad.bvh" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.bvh"]


def test_cli_filmstrip(tmp_path, capsys):
    out = tmp_path / "fs.png"
    code, err = _cli(capsys, ["render", str(clip("09_01")), "-o", str(out), "--filmstrip", "--width", "800",
                              "--labels", "runner", "--quiet"])
    assert code == 0 and err == ""
    assert imageio.v3.imread(out).shape[1] == 800


def test_long_clip_name_never_runs_into_the_clock(clips):
    """A clip name wider than its panel is shortened with an ellipsis, and the title, speed and clock of a panel
    do not overlap (the clock once sat on the title's line, under a long Bandai name)."""
    from froude.viz.render import _actors, _VideoScene

    long_name = "dataset-2_walk-turn-left_normal_001_a_long_take_name"
    scene = _VideoScene(_actors(clips[:2], [long_name, "09_01"], "side"), 480, None)
    scene.prepare(np.array([0.5]))
    scene.frame(0)
    renderer = scene.canvas.get_renderer()
    for ax, *_rest in scene.panels:
        texts = [t for t in ax.texts if t.get_text()]
        boxes = [t.get_window_extent(renderer) for t in texts]
        panel = ax.get_window_extent(renderer)
        for i, a in enumerate(boxes):
            assert a.x1 <= panel.x1 + 0.5, f"{texts[i].get_text()!r} runs out of its panel"
            for b in boxes[i + 1:]:
                assert not a.overlaps(b), f"{texts[i].get_text()!r} overlaps another label"
    title = scene.panels[0][0].texts[0].get_text()
    assert title.endswith("…") and long_name.startswith(title[:-1])
    assert scene.panels[1][0].texts[0].get_text() == "09_01"
