"""The CLI abuse suite (issues 14 and 18): every rough edge and hostile input seen, as a test.

Each case: one line on stderr and exit status 2 (or a correct result), no file changed or left behind
(temporaries included), no traceback, quickly (runaway requests are refused by an estimate, not run).
Most cases run ``froude`` in-process on a copy of the embedded CMU clip; the signal cases run the real
entry point in a subprocess.
"""
from __future__ import annotations

import hashlib
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from froude.io.samples import sample_path

from conftest import clip

FROUDE = [sys.executable, "-m", "froude"]


def snapshot(folder: Path) -> dict:
    """Every file under folder (hidden ones too) -> (size, sha1): what 'nothing changed' compares."""
    out = {}
    for p in sorted(folder.rglob("*")):
        if p.is_file():
            out[str(p.relative_to(folder))] = (p.stat().st_size, hashlib.sha1(p.read_bytes()).hexdigest())
        elif p.is_dir():
            out[str(p.relative_to(folder)) + "/"] = None
    return out


@pytest.fixture
def work(tmp_path, monkeypatch):
    """A folder holding in.bvh (CMU 09_01, the embedded sample); the current directory during the test."""
    shutil.copy(sample_path(), tmp_path / "in.bvh")
    monkeypatch.chdir(tmp_path)
    return tmp_path


def refused(run_cli, folder: Path, *args, needle: str = "", seconds: float = 10.0, after_load: bool = False) -> str:
    """Run froude ARGS; assert exit 2, one error line on stderr (and nothing else there unless the refusal
    needs the clip loaded: then the load's own notes may precede it), nothing changed under folder."""
    before = snapshot(folder)
    t0 = time.perf_counter()
    code, out, err = run_cli(*args)
    elapsed = time.perf_counter() - t0
    lines = err.strip().splitlines()
    if after_load:
        lines = [line for line in lines if "error" in line]
    assert code == 2, (code, err)
    assert len(lines) == 1 and "error" in lines[0], err
    assert "Traceback" not in err and "internal error" not in err
    assert needle.lower() in lines[0].lower(), lines[0]
    assert snapshot(folder) == before, "a file was changed, written or left behind"
    assert elapsed < seconds, f"took {elapsed:.1f} s: the refusal came after work"
    return lines[0]


# ---- issue 14: rough edges -----------------------------------------------------------------------------
@pytest.mark.parametrize("args", [
    ("scale", "in.bvh", "-o", "in.bvh"),
    ("scale", "in.bvh", "-o", "./sub/../in.bvh"),
    ("accelerate", "in.bvh", "--to-speed", "0.8x", "-o", "in.bvh"),
    ("render", "in.bvh", "clip.png", "-o", "clip.png"),  # an input that happens to be named .png
])
def test_output_over_an_input_is_refused(work, run_cli, args):
    (work / "sub").mkdir()
    shutil.copy(work / "in.bvh", work / "clip.png")
    refused(run_cli, work, *args, needle="would overwrite the input")


def test_links_and_character_files_are_inputs(work, run_cli):
    os.symlink(work / "in.bvh", work / "link.bvh")
    os.link(work / "in.bvh", work / "hard.bvh")
    refused(run_cli, work, "scale", "in.bvh", "-o", "link.bvh", needle="would overwrite the input")
    refused(run_cli, work, "scale", "in.bvh", "-o", "hard.bvh", needle="would overwrite the input")
    shutil.copy(work / "in.bvh", work / "target.bvh")
    refused(run_cli, work, "scale", "in.bvh", "--character", "target.bvh", "-o", "target.bvh",
            needle="would overwrite the input 'target.bvh'")
def test_fit_never_replaces_a_clip_or_an_input(work, run_cli):
    refused(run_cli, work, "fit", "in.bvh", "-o", "in.bvh", needle="must be a .json")
    refused(run_cli, work, "fit", "in.bvh", "-o", "m.json", "--plot", "in.bvh", needle="must be a .png")
    refused(run_cli, work, "fit", "in.bvh", "-o", "m.json", "--plot", "plot.txt", needle="must be a .png")
    refused(run_cli, work, "fit", "in.bvh", "-o", "same.json", "--plot", "same.json", needle=".png")


@pytest.mark.parametrize("args, needle", [
    (("--character", "elf"), "unknown character 'elf'"),
    (("--strides", "0"), "--strides: must be from 1"),
    (("--fps", "0"), "--fps: must be from 20 to 1000 Hz"),
    (("--fps", "5"), "--fps: must be from 20 to 1000 Hz"),
    (("--fps", "1"), "--fps: must be from 20 to 1000 Hz"),
    (("--fps", "1e6"), "--fps: must be from 20 to 1000 Hz"),
    (("--strides", "100000"), "--strides: must be from 1 to 10000"),
    (("--duration", "1e9"), "--duration: must be more than 0 and at most 3600 s"),
    (("--speed", "nan"), "outside the supported range"),
    (("--speed", "1_0"), "cannot read"),
    (("--mass", "-70"), "--mass: must be from 20 to 300 kg"),
    (("--length-scale", "inf"), "--length-scale"),
    (("--height", "tall"), "--height: expected a number"),
])
def test_bad_options_are_refused_before_any_work(work, run_cli, args, needle):
    line = refused(run_cli, work, "scale", "in.bvh", *args, "-o", "o.bvh", needle=needle, seconds=5.0)
    assert "fitting" not in line


@pytest.mark.parametrize("text, needle", [
    ("height: tall\n", "height must be a number in metres, got 'tall'"),
    ("name: x\nheigth: 1.5\n", "unknown key(s) heigth"),
    ("name: x\nheight: [1.5\nmass: 3\n", "not valid YAML"),
    ("name: x\n  height: 1.5\n", "c.yaml:2: not valid YAML"),
    ("height: 1.0e+9\n", "height 1e+09 m is outside what froude supports, 0.3-10 m"),
    ("proportions: {legs: .nan}\n", "proportion 'legs' must be > 0"),
])
def test_character_yaml_errors_say_file_line_and_range(work, run_cli, text, needle):
    (work / "c.yaml").write_text(text)
    for cmd in (("scale", "in.bvh"), ("accelerate", "in.bvh", "--to-speed", "0.8x")):
        refused(run_cli, work, *cmd, "--character", "c.yaml", "-o", "o.bvh", needle=needle, seconds=5.0)


@pytest.mark.parametrize("cmd", [
    ("scale", "in.bvh", "-o"), ("accelerate", "in.bvh", "--to-speed", "1.1x", "-o"), ("fit", "in.bvh", "-o"),
    ("render", "in.bvh", "-o"), ("convert", "in.bvh"), ("info", "in.bvh", "--data"),
])
def test_unwritable_outputs_are_one_line(work, run_cli, cmd):
    suffix = {"fit": ".json", "render": ".png", "convert": ".glb", "info": ".csv"}.get(cmd[0], ".bvh")
    (work / "adir").mkdir()
    refused(run_cli, work, *cmd, f"/proc/o{suffix}", needle="cannot write in folder '/proc'")
    refused(run_cli, work, *cmd, f"in.bvh/o{suffix}", needle="'in.bvh' is a file, not a folder")
    refused(run_cli, work, *cmd, f"nodir/sub/o{suffix}", needle="folder 'nodir/sub' does not exist")
    (work / f"afolder{suffix}").mkdir()
    refused(run_cli, work, *cmd, f"afolder{suffix}", needle="is a folder")


def test_read_only_folder(work, run_cli):
    if os.geteuid() == 0:
        pytest.skip("running as root: a read-only permission does not stop root (the /proc cases cover the probe)")
    ro = work / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    try:
        refused(run_cli, work, "scale", "in.bvh", "-o", "ro/o.bvh", needle="cannot write in folder")
        refused(run_cli, work, "demo", "-o", "ro/demo", needle="cannot write in folder")
    finally:
        ro.chmod(0o755)


def test_report_path_taken_by_a_folder_leaves_no_half_result(work, run_cli):
    (work / "o.report.json").mkdir()
    refused(run_cli, work, "scale", "in.bvh", "-o", "o.bvh", needle="o.report.json: is a folder")
    refused(run_cli, work, "accelerate", "in.bvh", "--to-speed", "0.9x", "-o", "o.bvh", needle="is a folder")


def test_plot_folder_and_demo_outputs(work, run_cli):
    (work / "p.png").mkdir()
    refused(run_cli, work, "fit", "in.bvh", "-o", "m.json", "--plot", "p.png", needle="p.png: is a folder")
    refused(run_cli, work, "accelerate", "in.bvh", "--to-speed", "0.9x", "-o", "o.bvh", "--plot", "p.png",
            needle="is a folder")
    refused(run_cli, work, "demo", "-o", "in.bvh", needle="is a file, not a folder")
    refused(run_cli, work, "demo", "-o", "/proc/x", needle="cannot write in folder '/proc'")
    refused(run_cli, work, "demo", "--strides", "0", "-o", "d", needle="--strides: must be from 1 to 20")
    refused(run_cli, work, "demo", "--clip", "nope.bvh", "-o", "d", needle="nope.bvh: no such file")


def test_one_speed_syntax_everywhere():
    from froude.errors import FroudeError
    from froude.flow.speed_goal import SpeedGoal, parse_speed

    assert parse_speed("1.2") == parse_speed("1.2x") == parse_speed(" 1.2X ") == SpeedGoal(factor=1.2)
    assert parse_speed("3.5m/s") == parse_speed("3.5 m/s") == SpeedGoal(m_s=3.5)
    for bad in ("fast", "nan", "inf", "-1x", "0", "1e400", "1_0", "3.5 km/h", "", "x", True):
        with pytest.raises(FroudeError):
            parse_speed(bad)


def test_bare_number_is_a_factor_in_scale_and_accelerate(work, run_cli):
    """scale --speed 0.9 == 0.9x; accelerate --to-speed 0.8 == 0.8x (it used to mean 0.8 m/s)."""
    results = {}
    for cmd, opt, values in (("scale", "--speed", ("0.9", "0.9x")), ("accelerate", "--to-speed", ("0.8", "0.8x"))):
        for v in values:
            out = work / f"{cmd}_{v}.bvh"
            length = ("--strides", "2") if cmd == "scale" else ("--steps", "4")  # the law's change: 4 at x0.8
            code, stdout, err = run_cli(cmd, "in.bvh", opt, v, *length, "-o", out, "-q")
            assert code == 0, err
            assert err == "", "-q prints nothing on stderr"
            results[(cmd, v)] = out.read_text()
    assert results[("scale", "0.9")] == results[("scale", "0.9x")]
    assert results[("accelerate", "0.8")] == results[("accelerate", "0.8x")]
    rep = json.loads((work / "accelerate_0.8.report.json").read_text())
    plan = rep["extras"]["plan"]
    assert plan["target_speed_m_s"] == pytest.approx(0.8 * plan["start_speed_m_s"], rel=1e-9)


def test_no_command_exits_2_with_usage(run_cli):
    code, out, err = run_cli()
    assert code == 2 and err.startswith("usage: froude") and "give a command" in err and out == ""


def test_quiet_is_everywhere_and_quiet(work, run_cli):
    from froude.apps.cli import build_parser

    code, out, err = run_cli("info", "in.bvh", "-q")
    assert code == 0 and err == "" and "Froude number" in out
    code, out, err = run_cli("render", "in.bvh", "-o", "r.png", "-q")
    assert code == 0 and err == "" and (work / "r.png").is_file()

    sub = next(a for a in build_parser()._actions if a.dest == "command")
    for name, p in sub.choices.items():
        if name == "view":
            continue  # the studio's address must print; it has no progress to hide
        opts = {s for a in p._actions for s in a.option_strings}
        assert {"-q", "--quiet"} <= opts, name


def test_runaway_requests_are_refused_by_estimate(work, run_cli):
    """accelerate --steps 100000 (74.5 GiB), scale --duration 1e9 (894 GiB), 1e6 Hz, huge renders."""
    refused(run_cli, work, "accelerate", "in.bvh", "--to-speed", "0.8x", "--steps", "100000", "-o", "o.bvh",
            needle="--steps: must be from 1 to 500")
    refused(run_cli, work, "accelerate", "in.bvh", "--to-speed", "0.8x", "--fps", "0", "-o", "o.bvh",
            needle="--fps: must be from 20 to 1000 Hz")
    # inside every option's range, the product is still bounded by the frame/memory estimate
    refused(run_cli, work, "scale", "in.bvh", "--strides", "10000", "--fps", "1000", "-o", "o.bvh",
            needle="beyond the 200,000-frame", after_load=True)
    refused(run_cli, work, "scale", "in.bvh", "--duration", "3600", "-o", "o.bvh", needle="add --force",
            after_load=True)
    refused(run_cli, work, "accelerate", "in.bvh", "--to-speed", "0.8x", "--steps", "500", "--fps", "1000",
            "--hold-steps", "100", "-o", "o.bvh", needle="beyond the 200,000-frame", after_load=True)
    for args, needle in ((("--at", "nan"), "--at: must be from 0"), (("--at", "-1"), "--at: must be from 0"),
                         (("--spacing", "nan"), "--spacing"), (("--width", "100000"), "--width: must be from 16"),
                         (("--height", "-5"), "--height: must be from 16"), (("--fps", "1e6"), "--fps"),
                         (("--at", "1e9"), "--at")):
        refused(run_cli, work, "render", "in.bvh", *args, "-o", "r.png", needle=needle)
    refused(run_cli, work, "render", "in.bvh", "--at", "100", "-o", "r.png", needle="after the end of the longest clip",
            after_load=True)
    refused(run_cli, work, "render", "in.bvh", "--filmstrip", "--interval", "0.001", "-o", "r.png",
            needle="snapshots", after_load=True)
    refused(run_cli, work, "render", "in.bvh", "--fps", "240", "--width", "8192", "--height", "8192", "-o", "r.gif",
            needle="pixel bound", after_load=True)


def test_short_duration_says_what_it_makes(work, run_cli):
    code, out, err = run_cli("scale", "in.bvh", "--duration", "0.01", "-o", "o.bvh")
    assert code == 0 and "shorter than two steps" in err


# ---- issue 18.12: header values range-checked ------------------------------------------------------------
def _edited(work: Path, old_prefix: str, new_line: str, name: str) -> Path:
    lines = (work / "in.bvh").read_text().splitlines()
    k = next(i for i, line in enumerate(lines) if line.strip().startswith(old_prefix))
    lines[k] = new_line
    p = work / name
    p.write_text("\n".join(lines) + "\n")
    return p


@pytest.mark.parametrize("line, needle", [
    ("Frame Time: 5e-324", ":187: frame time 5e-324 s is outside the supported 0.001-0.1 s (10-1000 Hz)"),
    ("Frame Time: 1e-300", "outside the supported"),
    ("Frame Time: 1_0", "expected a number for the frame time, found '1_0'"),
    ("Frame Time: 10", "outside the supported"),
])
def test_header_frame_time(work, run_cli, line, needle):
    p = _edited(work, "Frame Time:", line, "h.bvh")
    for cmd in (("info", p), ("info", p, "--json"), ("scale", p, "-o", "o.bvh"), ("fit", p, "-o", "m.json")):
        refused(run_cli, work, *cmd, needle=needle)


def test_header_offset(work, run_cli):
    lines = (work / "in.bvh").read_text().splitlines()
    k = next(i for i, line in enumerate(lines) if line.strip().startswith("OFFSET") and i > 3)
    lines[k] = "OFFSET 1e300 0 0"
    (work / "h.bvh").write_text("\n".join(lines) + "\n")
    refused(run_cli, work, "info", "h.bvh", needle=f"h.bvh:{k + 1}: OFFSET of joint")
    lines[k] = "OFFSET 1_0 0 0"
    (work / "h.bvh").write_text("\n".join(lines) + "\n")
    refused(run_cli, work, "info", "h.bvh", needle="expected a number")


@pytest.mark.parametrize("name", ["09_01", "02_01", "dataset-1_dash_normal_001", "dataset-1_walk_normal_001"])
def test_info_json_is_strict_json(run_cli, name):
    code, out, err = run_cli("info", clip(name), "--json")
    assert code == 0

    def no_constants(c):
        raise AssertionError(f"non-finite number {c} in info --json")

    json.loads(out, parse_constant=no_constants)
    assert "Warning" not in err


# ---- issue 18.11: SIGTERM like SIGINT ---------------------------------------------------------------------
def _terminate_mid_run(work: Path, args: list, ready, seconds: float = 60.0):
    """Start froude ARGS, wait until ready(stderr lines so far) (or the time limit), send SIGTERM; returns
    (exit status, stderr)."""
    import threading

    proc = subprocess.Popen(FROUDE + args, cwd=work, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    lines: list[str] = []
    reader = threading.Thread(target=lambda: lines.extend(iter(proc.stderr.readline, "")), daemon=True)
    reader.start()
    t0 = time.perf_counter()
    while proc.poll() is None and not ready(lines) and time.perf_counter() - t0 < seconds:
        time.sleep(0.05)
    assert proc.poll() is None, "finished before it could be stopped: " + "".join(lines)
    proc.send_signal(signal.SIGTERM)
    proc.wait(timeout=90)  # the interrupt lands between NumPy calls: allow a loaded machine
    reader.join(timeout=10)
    return proc.returncode, "".join(lines)


def _encoding(work: Path) -> bool:
    """True once the video's temporary has some frames in it (ffmpeg is running)."""
    return any(p.name.startswith(".v.") and p.stat().st_size > 0 for p in work.iterdir())


def _ffmpeg_children() -> list[str]:
    r = subprocess.run(["ps", "-eo", "pid,ppid,stat,args"], capture_output=True, text=True)
    return [line for line in r.stdout.splitlines() if "ffmpeg" in line and "-f rawvideo" in line
            and " Z" not in line]


def test_sigterm_mid_scale_leaves_nothing(work):
    before = snapshot(work)
    # 300 strides: long enough to say its size ("this takes a while"), then stopped in the middle
    code, err = _terminate_mid_run(work, ["scale", "in.bvh", "--strides", "300", "-o", "o.bvh"],
                                   lambda lines: any("synthesising" in line for line in lines))
    assert code == 143 and err.strip().splitlines()[-1] == "froude scale: terminated", err
    assert "Traceback" not in err
    assert snapshot(work) == before


def test_sigterm_mid_video_kills_ffmpeg_and_leaves_nothing(work):
    pytest.importorskip("imageio_ffmpeg")
    assert not [c for c in _ffmpeg_children() if " .v." in c], "an encoder of another run is still alive"
    # a longer clip: the sample's frames ten times over (about 30 s of video)
    lines = (work / "in.bvh").read_text().splitlines()
    k = next(i for i, line in enumerate(lines) if line.startswith("Frame Time"))
    rows = [r for r in lines[k + 1:] if r.strip()]
    lines[k - 1] = f"Frames: {10 * len(rows)}"
    (work / "long.bvh").write_text("\n".join(lines[:k + 1] + rows * 10) + "\n")
    before = snapshot(work)
    code, err = _terminate_mid_run(work, ["render", "long.bvh", "--fps", "60", "-o", "v.mp4", "-q"],
                                   lambda lines: _encoding(work))
    assert code == 143 and "terminated" in err and "Traceback" not in err, err
    assert snapshot(work) == before, "a partial video or temporary was left"
    # froude kills and reaps its encoder before it exits: none is left, not even for a moment
    assert not [c for c in _ffmpeg_children() if "/.v." in c or " .v." in c], "ffmpeg outlived froude"


# ---- whole results or none; real clips of both rigs --------------------------------------------------------
def test_scale_and_fit_write_whole_results(work, run_cli):
    code, out, err = run_cli("scale", "in.bvh", "--strides", "2", "-o", "o.bvh", "-q")
    assert code == 0 and err == ""
    assert {p.name for p in work.iterdir()} == {"in.bvh", "o.bvh", "o.report.json"}
    code, out, err = run_cli("fit", "in.bvh", "-o", "m.json", "--plot", "f.png", "-q")
    assert code == 0 and err == "" and (work / "m.json").is_file() and (work / "f.png").is_file()
    assert not [p for p in work.iterdir() if p.name.startswith(".")]


def test_bandai_clip_guarded_like_any(tmp_path, run_cli, monkeypatch):
    src = clip("dataset-1_dash_feminine_001")
    shutil.copy(src, tmp_path / "b.bvh")
    monkeypatch.chdir(tmp_path)
    refused(run_cli, tmp_path, "scale", "b.bvh", "-o", "b.bvh", needle="would overwrite the input")
    refused(run_cli, tmp_path, "scale", "b.bvh", "--fps", "5", "-o", "o.bvh", needle="20 to 1000 Hz")
    code, out, err = run_cli("scale", "b.bvh", "--strides", "2", "-o", "o.bvh", "-q")
    assert code in (0, 1) and "Traceback" not in err
    written = {p.name for p in tmp_path.iterdir()} - {"b.bvh"}
    assert written == ({"o.bvh", "o.report.json"} if code == 0 else set())  # a whole result or none
    code, out, err = run_cli("scale", "b.bvh", "--strides", "2", "-o", "o.bvh", "-q", "--keep")
    assert code == 0 and {p.name for p in tmp_path.iterdir()} == {"b.bvh", "o.bvh", "o.report.json"}


def test_os_errors_during_work_are_one_line(work, run_cli, monkeypatch):
    """A write that fails after the checks (disk full) is one line, exit 2, and takes the whole result back."""
    import froude.io.atomic as atomic

    real = atomic.os.replace
    calls = []

    def failing_replace(a, b):
        calls.append(b)
        if len(calls) == 2:
            raise OSError(28, "No space left on device", str(b))
        return real(a, b)

    monkeypatch.setattr(atomic.os, "replace", failing_replace)
    refused(run_cli, work, "scale", "in.bvh", "--strides", "2", "-o", "o.bvh", "-q", needle="No space left on device")
    assert len(calls) == 2  # the BVH had landed: the group took it back


# ---- issue 14.3: start-up (timing is benchmarks/bench_cli.py; this checks what makes it fast) ----------------
@pytest.mark.parametrize("args", [["--help"], ["scale", "--help"], ["scale", "x.bvh", "--fps", "0", "-o", "o.bvh"],
                                  ["batch", "--help"], []])
def test_help_and_option_errors_import_no_numpy(args):
    r = subprocess.run([sys.executable, "-X", "importtime", "-m", "froude", *args], capture_output=True, text=True)
    imported = {line.split("|")[-1].strip() for line in r.stderr.splitlines() if line.startswith("import time:")}
    assert r.returncode in (0, 2)
    assert not {"numpy", "scipy", "froude.apps.batch", "yaml"} & imported or args == ["batch", "--help"], \
        sorted(m for m in imported if m.split(".")[0] in ("numpy", "scipy", "froude", "yaml"))
    if args == ["batch", "--help"]:
        assert "numpy" not in imported



def test_scale_of_a_run_imports_no_scipy_nor_walking_code(tmp_path):
    """A run's ``froude scale`` needs neither SciPy (the BVH's Euler angles are NumPy's, quat.to_euler) nor
    the walking machine: importing them was a third of its time (benchmarks/bench_cli.py)."""
    out = tmp_path / "o.bvh"
    r = subprocess.run([sys.executable, "-X", "importtime", "-m", "froude", "scale", str(sample_path()), "--strides",
                        "2", "-o", str(out), "-q"], capture_output=True, text=True)
    imported = {line.split("|")[-1].strip() for line in r.stderr.splitlines() if line.startswith("import time:")}
    assert r.returncode == 0 and out.is_file(), r.stderr[-2000:]
    assert "froude.flow.pipeline" in imported  # the check sees the work's imports
    unwanted = sorted(m for m in imported if m.split(".")[0] == "scipy" or m.startswith(
        ("froude.machine.walk", "froude.flow.speed_range")))
    assert not unwanted, unwanted

def test_every_command_module_lists_its_help():
    from froude.apps.cli import SUBCOMMANDS, build_parser

    full = build_parser()
    sub = next(a for a in full._actions if a.dest == "command")
    for name in SUBCOMMANDS:
        lean = build_parser([name])
        lean_sub = next(a for a in lean._actions if a.dest == "command")
        assert set(lean_sub.choices) == set(sub.choices)
        assert lean_sub.choices[name].format_help() == sub.choices[name].format_help()


def test_demo_that_fails_midway_leaves_no_folder(work, run_cli):
    """A demo whose clip cannot be fitted (a walk) stops with one error line and creates nothing."""
    shutil.copy(clip("02_01"), work / "walk.bvh")
    refused(run_cli, work, "demo", "--clip", "walk.bvh", "--no-video", "-o", "d", needle="walking, not running",
            after_load=True)
