"""BVH reading and writing: round trips on every real clip and hand-written fixtures, channel orders,
units, cleaning, and one test per kind of bad input (API and CLI)."""
from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from froude import BvhError, load_bvh, save_bvh
from froude.io.bvh import bvh_text

from conftest import FIXTURES, clip, clip_params, read_bvh_oracle

HAND_FIXTURES = ("three_joint", "orders_crlf_tabs_sci", "humanoid_metres", "humanoid_centimetres",
                 "humanoid_inches")


def _assert_same_file_numbers(original, saved):
    """The saved file has the original's hierarchy exactly and every number within 1e-4."""
    a, b = read_bvh_oracle(original), read_bvh_oracle(saved)
    assert b.names == a.names
    assert b.parents == a.parents
    assert [list(c) for c in b.channels] == [[c[0].upper() + c[1:].lower() for c in ch] for ch in a.channels]
    np.testing.assert_allclose(b.offsets, a.offsets, rtol=0, atol=1e-4)
    assert [j for j, _ in b.end_sites] == [j for j, _ in a.end_sites]
    np.testing.assert_allclose([o for _, o in b.end_sites], [o for _, o in a.end_sites], rtol=0, atol=1e-4)
    assert b.frame_time == pytest.approx(a.frame_time, abs=1e-7)
    assert b.values.shape == a.values.shape
    np.testing.assert_allclose(b.values, a.values, rtol=0, atol=1e-4)


# ---- acceptance 1: load -> save -> load on every real clip ---------------------------------------
@pytest.mark.parametrize("name", clip_params())
def test_real_clip_round_trip(name, tmp_path):
    path = clip(name)
    motion = load_bvh(path, clean=False)
    out = tmp_path / "out.bvh"
    save_bvh(motion, out)
    _assert_same_file_numbers(path, out)
    again = load_bvh(out, clean=False)
    assert again.skeleton.same_topology(motion.skeleton) is None
    assert again.skeleton.channels == motion.skeleton.channels
    np.testing.assert_allclose(again.skeleton.offsets, motion.skeleton.offsets, atol=1e-9)
    np.testing.assert_allclose(again.root_positions, motion.root_positions, atol=1e-4 * motion.meta["length_scale"])
    dots = np.abs(np.sum(again.rotations * motion.rotations, axis=-1))
    assert np.degrees(2 * np.arccos(np.clip(dots, 0, 1))).max() < 1e-4


@pytest.mark.parametrize("name", clip_params(["09_01", "02_01"]))
def test_cleaned_clip_saves_the_motion_without_the_pose_frame(name, tmp_path):
    path = clip(name)
    motion = load_bvh(path)
    out = tmp_path / "clean.bvh"
    save_bvh(motion, out)
    original, saved = read_bvh_oracle(path), read_bvh_oracle(out)
    assert len(saved.values) == len(original.values) - 1
    np.testing.assert_allclose(saved.values, original.values[1:], atol=1e-4)


@pytest.mark.parametrize("name", HAND_FIXTURES)
def test_fixture_round_trip(name, tmp_path):
    path = FIXTURES / f"{name}.bvh"
    motion = load_bvh(path, clean=False)
    out = tmp_path / "out.bvh"
    save_bvh(motion, out)
    _assert_same_file_numbers(path, out)


def test_crlf_tabs_scientific_fixture_is_what_it_claims():
    raw = (FIXTURES / "orders_crlf_tabs_sci.bvh").read_bytes()
    assert raw.count(b"\r\n") == raw.count(b"\n") > 40  # every line ends in CRLF
    assert b"\t" in raw and b"e+01" in raw and b"E1" in raw and b"e-1" in raw


def test_crlf_and_lf_give_the_same_motion(tmp_path):
    raw = (FIXTURES / "orders_crlf_tabs_sci.bvh").read_bytes()
    lf = tmp_path / "lf.bvh"
    lf.write_bytes(raw.replace(b"\r\n", b"\n"))
    cr = tmp_path / "cr.bvh"  # classic Mac line ends
    cr.write_bytes(raw.replace(b"\r\n", b"\r"))
    a = load_bvh(FIXTURES / "orders_crlf_tabs_sci.bvh", clean=False)
    for p in (lf, cr):
        b = load_bvh(p, clean=False)
        np.testing.assert_array_equal(a.rotations, b.rotations)
        np.testing.assert_array_equal(a.translations, b.translations)
        np.testing.assert_array_equal(a.root_positions, b.root_positions)


def test_every_channel_order_and_position_channel_is_read_as_written():
    """Each joint's rotation is the intrinsic composition of its channels in file order (SciPy upper-case
    Euler), position channels replace the rest offset, and the positions/rotations may interleave."""
    path = FIXTURES / "orders_crlf_tabs_sci.bvh"
    m = load_bvh(path, clean=False)
    ref = read_bvh_oracle(path)
    sk = m.skeleton
    assert sk.channels[0] == ("Zposition", "Xrotation", "Xposition", "Yrotation", "Yposition", "Zrotation")
    assert [sk.rotation_order(j) for j in range(sk.n_joints)] == ["xyz", "yxz", "xyz", "zxy", ""]
    assert m.meta["length_scale"] == 0.01
    col = 0
    for j, chans in enumerate(ref.channels):
        rot_cols = [col + k for k, c in enumerate(chans) if c.endswith("rotation")]
        pos_cols = {c[0]: col + k for k, c in enumerate(chans) if c.endswith("position")}
        col += len(chans)
        if rot_cols:
            order = "".join(c[0] for c in chans if c.endswith("rotation"))
            expect = Rotation.from_euler(order.upper(), ref.values[:, rot_cols], degrees=True).as_quat()
            got = np.concatenate([m.rotations[:, j, 1:], m.rotations[:, j, :1]], axis=1)
            assert np.allclose(np.abs(np.sum(expect * got, axis=1)), 1.0, atol=1e-12)
        else:
            np.testing.assert_array_equal(m.rotations[:, j], np.tile([1.0, 0, 0, 0], (m.n_frames, 1)))
        trans = m.local_translations()[:, j]
        for axis, name in enumerate("XYZ"):
            expect = ref.values[:, pos_cols[name]] * 0.01 if name in pos_cols else ref.offsets[j, axis] * 0.01
            np.testing.assert_allclose(trans[:, axis], expect, atol=1e-12)


def test_non_root_six_channel_joint_moves_with_its_position_channels():
    m = load_bvh(FIXTURES / "orders_crlf_tabs_sci.bvh", clean=False)
    head = m.skeleton.index("Head")
    assert m.translations is not None
    np.testing.assert_allclose(m.translations[:, head, 1], [0.30, 0.31, 0.32, 0.33], atol=1e-12)
    np.testing.assert_allclose(m.skeleton.offsets[head], [0, 0.30, 0.001], atol=1e-12)


def test_loaded_rotations_are_a_continuous_unit_quaternion_track():
    m = load_bvh(clip("09_01"))
    assert np.allclose(np.linalg.norm(m.rotations, axis=-1), 1.0, atol=1e-12)
    assert np.all(np.sum(m.rotations[1:] * m.rotations[:-1], axis=-1) >= 0.0)


def test_large_file_loads(tmp_path):
    """A 10 000-frame file made from real frames loads with every frame (speed: benchmarks/bench_core.py)."""
    header, ft, rows = _clip_parts()
    rows = rows[1:]  # without the T-pose
    n = 10_000
    m = load_bvh(_write(tmp_path, header, ft, [rows[i % len(rows)] for i in range(n)]))
    assert m.n_frames == n
    assert m.meta["cleaning"] == ()
    np.testing.assert_array_equal(m.root_positions[len(rows)], m.root_positions[0])
    assert m.root_positions[0, 1] == pytest.approx(float(rows[0].split()[1]) * 0.056444, abs=1e-12)


# ---- units -----------------------------------------------------------------------------------------
@pytest.mark.parametrize("unit,scale", [("metres", 1.0), ("centimetres", 0.01), ("inches", 0.0254)])
def test_units_are_detected_and_converted_to_metres(unit, scale):
    m = load_bvh(FIXTURES / f"humanoid_{unit}.bvh")
    assert m.meta["length_scale"] == scale
    assert m.meta["units"].startswith(unit)
    ref = load_bvh(FIXTURES / "humanoid_metres.bvh")
    np.testing.assert_allclose(m.skeleton.offsets, ref.skeleton.offsets, atol=1e-6)
    np.testing.assert_allclose(m.root_positions, ref.root_positions, atol=1e-6)
    assert m.skeleton.standing_height() == pytest.approx(1.80, abs=1e-6)


def test_cmu_units_are_detected_on_real_clips():
    m = load_bvh(clip("09_01"))
    assert m.meta["length_scale"] == 0.056444
    assert "CMU units" in m.meta["units"]
    # SOURCES.md: the root is at 16.7-17.6 units (0.94-0.99 m) during locomotion
    assert 0.90 < np.median(m.root_positions[:, 1]) < 1.05


def test_given_length_scale_wins_and_is_reported(tmp_path):
    m = load_bvh(FIXTURES / "humanoid_centimetres.bvh", length_scale=0.005)
    assert m.meta["length_scale"] == 0.005
    assert "given" in m.meta["units"]
    assert m.skeleton.standing_height() == pytest.approx(0.9)
    with pytest.raises(BvhError):
        load_bvh(FIXTURES / "humanoid_centimetres.bvh", length_scale=-1.0)
    out = tmp_path / "m.bvh"
    save_bvh(m, out, length_scale=1.0)  # write in metres
    assert load_bvh(out).meta["units"].startswith("metres")


def test_implausible_size_asks_for_a_length_scale(tmp_path):
    text = (FIXTURES / "three_joint.bvh").read_text().replace("OFFSET 0 1 0", "OFFSET 0 100000 0")
    p = tmp_path / "huge.bvh"
    p.write_text(text)
    with pytest.raises(BvhError, match="length_scale") as e:
        load_bvh(p)
    assert e.value.line == 2
    assert load_bvh(p, length_scale=1e-5).skeleton.standing_height() == pytest.approx(1.0, rel=1e-5)


def test_cli_prints_units_and_cleaning(run_cli):
    code, out, err = run_cli("info", clip("09_01"))
    assert code == 0
    assert "units: CMU units (stature 1.51 m" in err and "detected by the flight gravity" in out
    assert "T-pose" in err
    code, out, err = run_cli("info", FIXTURES / "humanoid_inches.bvh")
    assert code == 0
    assert "units: inches (stature 1.80 m), detected as the most human stature" in err


# ---- cleaning --------------------------------------------------------------------------------------
def _clip_parts(name="09_01"):
    text = clip(name).read_text().replace("\r\n", "\n")
    header = text[: text.index("MOTION")]
    lines = text[text.index("MOTION") :].split("\n")
    rows = [r for r in lines[3:] if r.strip()]
    return header, lines[2], rows


def _write(tmp_path, header, frame_time_line, rows, name="x.bvh"):
    p = tmp_path / name
    p.write_text(f"{header}MOTION\nFrames: {len(rows)}\n{frame_time_line}\n" + "\n".join(rows) + "\n")
    return p


def test_tpose_frame_is_dropped_and_reported():
    m = load_bvh(clip("09_01"))
    ref = read_bvh_oracle(clip("09_01"))
    assert m.n_frames == len(ref.values) - 1 == 148
    (note,) = m.meta["cleaning"]
    assert "T-pose" in note and "line 188" in note
    assert m.meta["first_line"] == 189
    np.testing.assert_allclose(m.root_positions[0], ref.values[1, :3] * 0.056444)


@pytest.mark.parametrize("name", clip_params())
def test_every_real_clip_loses_exactly_its_tpose_frame(name):
    m = load_bvh(clip(name))
    assert m.n_frames == len(read_bvh_oracle(clip(name)).values) - 1
    assert len(m.meta["cleaning"]) == 1 and "T-pose" in m.meta["cleaning"][0]


def test_keep_all_frames_keeps_the_tpose(run_cli):
    assert load_bvh(clip("09_01"), clean=False).n_frames == 149
    assert load_bvh(clip("09_01"), clean=False).meta["cleaning"] == ()
    code, out, err = run_cli("info", clip("09_01"), "--json", "--keep-all-frames")
    assert code == 0
    import json

    d = json.loads(out)
    assert d["frames"] == 149 and d["cleaning"] == []
    code, out, _ = run_cli("info", clip("09_01"), "--json")
    d = json.loads(out)
    assert d["frames"] == 148 and len(d["cleaning"]) == 1


@pytest.mark.parametrize("verb", [["scale", "--character", "child"], ["accelerate", "--to-speed", "0.5x"]])
def test_scale_and_accelerate_honour_keep_all_frames(run_cli, tmp_path, verb):
    """--keep-all-frames reaches the fit: the T-pose row stays in the reference the output is measured
    against (its largest joint jump is the T-pose's 108 deg instead of the run's 26.5 deg)."""
    import json

    jumps = []
    for extra in ([], ["--keep-all-frames"]):
        out = tmp_path / f"{verb[0]}{len(extra)}.bvh"
        code, _, err = run_cli(verb[0], clip("09_01"), *verb[1:], "-o", out, "-q", "--keep", *extra)
        assert code == 0, err
        jumps.append(json.loads(out.with_name(out.stem + ".report.json").read_text())["reference_max_joint_jump_deg"])
    assert jumps[0] < 30 < 100 < jumps[1], jumps


def test_leading_invalid_rows_before_the_tpose_are_dropped(tmp_path):
    header, ft, rows = _clip_parts()
    zero = " ".join(["0"] * 96)
    nan = " ".join(["nan"] * 96)
    m = load_bvh(_write(tmp_path, header, ft, [zero, nan, zero] + rows))
    assert m.n_frames == 148
    notes = m.meta["cleaning"]
    assert notes[0].startswith("dropped 3 invalid leading row(s)") and "all-zero" in notes[0] and "NaN" in notes[0]
    assert "lines 188-190" in notes[0]
    assert "T-pose" in notes[1] and "line 191" in notes[1]
    np.testing.assert_array_equal(m.rotations, load_bvh(clip("09_01")).rotations)


def test_invalid_rows_between_the_tpose_and_the_motion_are_dropped(tmp_path):
    """A recording that starts late: T-pose, then all-zero rows, then the motion."""
    header, ft, rows = _clip_parts()
    zero = " ".join(["0.000000"] * 96)
    m = load_bvh(_write(tmp_path, header, ft, rows[:1] + [zero] * 4 + rows[1:]))
    assert m.n_frames == 148
    assert "T-pose" in m.meta["cleaning"][0]
    assert "dropped 4 invalid leading row(s) (all-zero; lines 189-192) after the pose frame" == m.meta["cleaning"][1]
    np.testing.assert_array_equal(m.root_positions, load_bvh(clip("09_01")).root_positions)


def test_trailing_invalid_rows_are_dropped(tmp_path):
    header, ft, rows = _clip_parts()
    m = load_bvh(_write(tmp_path, header, ft, rows + [" ".join(["nan"] * 96), " ".join(["0"] * 96)]))
    assert m.n_frames == 148
    assert m.meta["cleaning"][-1] == "dropped 2 invalid trailing row(s) (all-zero, NaN/inf; lines 337-338)"


def test_keep_all_frames_keeps_zero_rows_but_rejects_nan(tmp_path):
    header, ft, rows = _clip_parts()
    m = load_bvh(_write(tmp_path, header, ft, [" ".join(["0"] * 96)] + rows), clean=False)
    assert m.n_frames == 150 and m.meta["cleaning"] == ()
    with pytest.raises(BvhError) as e:
        load_bvh(_write(tmp_path, header, ft, [" ".join(["nan"] * 96)] + rows), clean=False)
    assert e.value.line == 188


def test_a_clip_without_a_pose_frame_loses_nothing(tmp_path):
    header, ft, rows = _clip_parts()
    m = load_bvh(_write(tmp_path, header, ft, rows[1:]))
    assert m.n_frames == 148 and m.meta["cleaning"] == ()


# ---- bad input: one test per case, API (BvhError with line) and CLI (one line, exit 2) -------------
def _three_joint_lines():
    return (FIXTURES / "three_joint.bvh").read_text().split("\n")


def _edit(line_no, old, new):
    def f(lines):
        assert old in lines[line_no - 1]
        lines[line_no - 1] = lines[line_no - 1].replace(old, new, 1)
        return "\n".join(lines).encode()
    return f


BAD_INPUTS = {
    # name: (make bytes from the fixture's lines, expected line, words expected in the message)
    "truncated in the frame rows": (lambda l: "\n".join(l[:25] + [l[25][:9]]).encode(), 26, "ends early"),
    "truncated in the hierarchy": (lambda l: "\n".join(l[:12]).encode(), 12, "ends early"),
    "extra value in a frame row": (_edit(25, "90 0 0 0", "90 0 0 0 0"), 25, "13 values, expected 12"),
    "missing value in a frame row": (_edit(26, "0 0 0 0 90", "0 0 0 90"), 26, "11 values, expected 12"),
    # the total count is right, so only a per-row check catches it
    "short row then long row": (lambda l: "\n".join(l[:24] + [l[24].rsplit(" ", 1)[0], l[25] + " 7"] + l[26:]).encode(),
                                25, "11 values, expected 12"),
    "non-numeric value": (_edit(26, "90 0 0", "90 abc 0"), 26, "non-numeric value 'abc'"),
    "comma decimal": (_edit(24, "1 2 3", "1,5 2 3"), 24, "non-numeric value '1,5'"),
    "NaN inside the motion": (_edit(25, "90 0 0 0", "nan 0 0 0"), 25, "non-finite"),
    "inf inside the motion": (_edit(26, "90 0 0", "-inf 0 0"), 26, "non-finite"),
    "zero frames": (lambda l: "\n".join(l[:21] + ["Frames: 0", l[22]]).encode(), 22, "0 frames"),
    "frame time zero": (_edit(23, "0.1", "0"), 23, "frame time must be > 0"),
    "frame time negative": (_edit(23, "0.1", "-0.1"), 23, "frame time must be > 0"),
    "duplicate joint names": (_edit(10, "Tip", "Mid"), 10, "duplicate joint name 'Mid'"),
    "missing MOTION section": (lambda l: "\n".join(l[:20]).encode(), 20, "missing MOTION"),
    "empty file": (lambda l: b"", 1, "empty"),
    "blank file": (lambda l: b"  \n\t\r\n \n", 1, "empty"),
    "binary file": (lambda l: b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR" + bytes(range(256)) * 4, 1, "binary"),
    "binary file without NUL bytes": (
        lambda l: b"\x89" + bytes(np.random.default_rng(1).integers(1, 256, 3000, dtype=np.uint8)), 1, "HIERARCHY"),
    "more rows than declared": (lambda l: "\n".join(l[:27] + [l[26]]).encode(), 28, "more frame rows"),
    "unknown channel": (_edit(9, "Yrotation", "Wrotation"), 9, "unknown channel 'Wrotation'"),
    "bad channel count": (_edit(9, "CHANNELS 3", "CHANNELS 7"), 9, "7 channels"),
    "offset not a number": (_edit(8, "0 1 0", "0 one 0"), 8, "expected a number"),
    "two rotation channels": (_edit(13, "CHANNELS 3 Zrotation Yrotation Xrotation", "CHANNELS 2 Zrotation Yrotation"),
                              13, "0 or 3 rotation channels"),
}


@pytest.mark.parametrize("case", list(BAD_INPUTS))
def test_bad_input_raises_bvh_error_with_line(case, tmp_path):
    make, line, words = BAD_INPUTS[case]
    p = tmp_path / "bad.bvh"
    p.write_bytes(make(_three_joint_lines()))
    with pytest.raises(BvhError) as e:
        load_bvh(p)
    assert e.value.line == line, str(e.value)
    assert words in str(e.value)
    assert str(e.value).startswith(f"{p}:{line}: ")
    assert "\n" not in str(e.value) and "\r" not in str(e.value)


@pytest.mark.parametrize("case", list(BAD_INPUTS))
def test_bad_input_cli_says_one_line_and_exits_2(case, tmp_path, run_cli):
    make, line, words = BAD_INPUTS[case]
    p = tmp_path / "bad.bvh"
    p.write_bytes(make(_three_joint_lines()))
    code, out, err = run_cli("info", p)
    assert code == 2
    assert out == ""
    assert err.count("\n") == 1, err
    assert f"{p}:{line}: " in err and words in err


def test_missing_file_is_a_bvh_error(tmp_path, run_cli):
    with pytest.raises(BvhError, match="cannot read"):
        load_bvh(tmp_path / "nope.bvh")
    code, _, err = run_cli("info", tmp_path / "nope.bvh")
    assert code == 2 and err.count("\n") == 1


def test_console_script_exit_status_and_no_traceback(tmp_path):
    """The real entry point (a subprocess), not just main(): exit 2, one line on stderr."""
    p = tmp_path / "bad.bvh"
    p.write_text("HIERARCHY\nROOT Hips\n{\n  OFFSET 0 0 0\n")
    r = subprocess.run([sys.executable, "-m", "froude", "info", str(p)], capture_output=True, text=True,
                       timeout=60)
    assert r.returncode == 2
    assert "Traceback" not in r.stderr
    assert r.stderr.strip().count("\n") == 0 and f"{p}:4:" in r.stderr


def test_messages_do_not_echo_control_characters_or_huge_tokens(tmp_path):
    p = tmp_path / "junk.bvh"
    p.write_bytes(b"\x1b[31m" + b"A" * 5000 + b"\nROOT x\n")
    with pytest.raises(BvhError) as e:
        load_bvh(p)
    msg = str(e.value)
    assert "\x1b" not in msg and len(msg) < 200 + len(str(p))


def test_line_numbers_count_only_real_line_breaks(tmp_path):
    """A form feed or U+0085 inside a line must not shift the reported line numbers."""
    lines = _three_joint_lines()
    lines[1] = "ROOT Root\x0c"
    lines[25] = lines[25].replace("90 0 0", "90 x 0", 1)
    p = tmp_path / "ff.bvh"
    p.write_bytes("\n".join(lines).encode("latin-1") + b"\x85")
    with pytest.raises(BvhError) as e:
        load_bvh(p)
    assert e.value.line == 26


# ---- saving ----------------------------------------------------------------------------------------
def test_save_is_atomic_and_refuses_non_finite(tmp_path):
    m = load_bvh(FIXTURES / "three_joint.bvh", clean=False)
    out = tmp_path / "keep.bvh"
    out.write_text("previous content")
    bad = m.with_(root_positions=np.where(np.arange(4)[:, None] == 2, np.nan, m.root_positions))
    with pytest.raises(BvhError):
        save_bvh(bad, out)
    assert out.read_text() == "previous content"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["keep.bvh"]  # no temporary file left


def test_save_failure_midway_leaves_no_partial_file(tmp_path, monkeypatch):
    import froude.io.bvh as bvh

    m = load_bvh(FIXTURES / "three_joint.bvh", clean=False)
    out = tmp_path / "new.bvh"

    def broken_replace(src, dst):
        raise OSError("disk full")

    monkeypatch.setattr(bvh.os, "replace", broken_replace)
    with pytest.raises(OSError):
        save_bvh(m, out)
    assert list(tmp_path.iterdir()) == []


def test_bvh_text_has_the_declared_frame_count():
    m = load_bvh(clip("09_01"))
    text = bvh_text(m)
    assert f"Frames: {m.n_frames}\n" in text
    assert len([l for l in text.split("MOTION\n")[1].split("\n")[2:] if l.strip()]) == m.n_frames
