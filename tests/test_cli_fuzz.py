"""Issue 18, acceptance 2: a hypothesis-driven fuzz of every command's option values.

For every command, hypothesis draws a handful of its options with hostile or ordinary values (NaN,
infinities, huge and tiny numbers, negatives, '1_0', hex, words, units, the ends of each supported range
and just beyond) and runs ``froude`` in-process on the embedded CMU clip. Whatever it draws, froude must
end with exit status 0/1 (a result) or 2 (one error line), never a traceback or an internal error, never
leave a temporary behind, and never exit 0 with a non-finite number in what it printed or wrote.

CI runs ``FUZZ_EXAMPLES`` (40) examples per command, derandomized; a longer run with fresh random cases:

    FROUDE_FUZZ_EXAMPLES=1000 FROUDE_FUZZ_RANDOM=1 python -m pytest -q -p no:cacheprovider tests/test_cli_fuzz.py

To keep each accepted case small, the work bound is lowered to 3,000 output frames here (a larger
request is refused by the same estimate that refuses 200,000 frames in normal use).
"""
from __future__ import annotations

import os
import re
import shutil
import tempfile
from pathlib import Path

import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from froude.apps.cli import common
from froude.io.samples import sample_path

FUZZ_EXAMPLES = int(os.environ.get("FROUDE_FUZZ_EXAMPLES", "40"))
SETTINGS = settings(max_examples=FUZZ_EXAMPLES, deadline=None, derandomize=not os.environ.get("FROUDE_FUZZ_RANDOM"),
                    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
                    database=None)
NON_FINITE = re.compile(r"(?<![A-Za-z_])(nan|inf|infinity)(?![A-Za-z_])", re.IGNORECASE)

_WORDS = ["", " ", "0", "-0", "1", "2", "1_0", "0x10", "1e400", "-1e400", "1e-400", "abc", "nan", "-nan", "inf",
          "-inf", "Infinity", "1.2x", "0.8x", "3.5m/s", "3.5 m/s", "nanx", "infm/s", "-1x", "0x", " 2 ", "1e3m/s",
          "4.5", "0.5", "1e308", "5e-324", "٣", "1,5", "--", "../x", "true"]


def _number_text(lo: float, hi: float):
    """Numbers as a user could type them: anywhere, at and just beyond the range's ends, and odd words."""
    edges = [lo, hi, lo - 1e-9 * max(1, abs(lo)), hi * (1 + 1e-9) + 1e-9, (lo + hi) / 2, -hi, 10 * hi]
    return st.one_of(
        st.floats(allow_nan=True, allow_infinity=True).map(repr),
        st.integers(-10**9, 10**9).map(str),
        st.sampled_from(edges).map(lambda v: f"{v:.12g}"),
        st.floats(min_value=lo, max_value=hi).map(lambda v: f"{v:.6g}"),
        st.sampled_from(_WORDS),
    )


def _speed_text():
    return st.one_of(
        st.floats(allow_nan=True, allow_infinity=True).map(lambda v: f"{v!r}x"),
        st.floats(min_value=0.3, max_value=1.6).map(lambda v: f"{v:.3g}x"),
        st.floats(min_value=0.5, max_value=8.0).map(lambda v: f"{v:.3g}m/s"),
        st.floats(min_value=0.3, max_value=1.6).map(lambda v: f"{v:.3g}"),
        st.sampled_from(_WORDS),
    )


#: Every command's options and what values they take: ("number", lo, hi) | ("speed",) | ("choice", ...)
#: | ("word", ...) | ("flag",). The ranges only steer the drawing toward the interesting ends.
CHARACTER = {"--character": ("word", "child", "troll", "giant", "small", "elf", "", "c.yaml", "in.bvh", "none.yaml"),
             "--height": ("number", 0.3, 10), "--char-mass": ("number", 1, 5000), "--leg-scale": ("number", 0.2, 5),
             "--arm-scale": ("number", 0.2, 5), "--head-scale": ("number", 0.2, 5), "--trunk-scale": ("number", 0.2, 5)}
LOAD = {"--length-scale": ("number", 1e-6, 100), "--keep-all-frames": ("flag",),
        "--up": ("choice", "Y", "Z", "y", "X"), "--joint-map": ("word", "map.yaml", "c.yaml", "none.yaml")}
RANGE = ("word", "0.2:2.5", "1:", ":2", "2:1", "nan:1", "1e400:", "-1:3", "1_0:2", ":", "0:0", "0.5:0.6")
OUTPUT = {"--units": ("choice", "m", "cm", "mm", "in", "cmu", "km"), "--rotations-only": ("flag",),
          "--in-place": ("flag",), "--travel": ("flag",), "--keep": ("flag",), "--range": RANGE,
          "--data": ("word", "d.csv", "d.npz", "in.bvh", "o.bvh", "o.report.json", "d.txt")}
OPTIONS = {
    "info": {"--mass": ("number", 20, 300), "--json": ("flag",), **LOAD},
    "fit": {"--mass": ("number", 20, 300), "--plot": ("word", "f.png", "f.txt", "in.bvh", "o.json", "nodir/f.png"),
            "--range": RANGE, **LOAD},
    "scale": {"--speed": ("speed",), **OUTPUT, "--strides": ("number", 1, 6), "--duration": ("number", 0, 4),
              "--fps": ("number", 20, 240), "--method": ("choice", "physical", "naive", "magic"),
              "--mass": ("number", 20, 300), **CHARACTER, **LOAD},
    "accelerate": {"--to-speed": ("speed",), "--steps": ("number", 1, 6), "--within": ("number", 0, 3),
                   "--lead-steps": ("number", 0, 3), "--hold-steps": ("number", 0, 3),
                   "--policy": ("choice", "ease", "even", "fast"), "--fps": ("number", 20, 240),
                   "--mass": ("number", 20, 300), **CHARACTER, **LOAD, **OUTPUT},
    "render": {"--interval": ("number", 0.001, 10), "--spacing": ("number", 0, 100), "--fps": ("number", 1, 240),
               "--width": ("number", 16, 400), "--height": ("number", 16, 300), "--at": ("number", 0, 3),
               "--camera": ("choice", "side", "front", "three-quarter", "top"), "--labels": ("word", "a", "a,b", ""),
               "--filmstrip": ("flag",), **LOAD},
    "view": {"--port": ("number", 0, 65535), "--mass": ("number", 20, 300), "--speed": ("speed",),
             "--strides": ("number", 1, 12), "--character": ("word", "same", "child", "elf"), **LOAD},
    "demo": {"--strides": ("number", 1, 20)},
    "convert": {"--fps": ("number", 1, 1000), "--no-mesh": ("flag",),
                "--data": ("word", "d.csv", "d.npz", "d.txt", "in.bvh", "o.glb", "nodir/d.csv"), **LOAD},
    "batch": {"--workers": ("number", 1, 256), "--redo": ("flag",)},
}
#: Fixed arguments of each command (an output in the temporary folder).
BASE = {
    "info": ["info", "in.bvh"],
    "fit": ["fit", "in.bvh", "-o", "o.json"],
    "scale": ["scale", "in.bvh", "-o", "o.bvh"],
    "accelerate": ["accelerate", "in.bvh", "-o", "o.bvh"],
    "render": ["render", "in.bvh", "-o", "o.png"],
    "view": ["view", "in.bvh"],
    "demo": ["demo", "--no-video", "-o", "d"],
    "batch": ["batch", "in.bvh", "--plan", "plan.yaml", "-o", "out", "--dry-run"],
    "convert": ["convert", "in.bvh", "o.glb"],
}


def _value(spec):
    kind = spec[0]
    if kind == "number":
        return _number_text(spec[1], spec[2])
    if kind == "speed":
        return _speed_text()
    if kind in ("choice", "word"):
        return st.one_of(st.sampled_from(spec[1:]), st.sampled_from(_WORDS))
    return st.none()  # a flag


@st.composite
def invocation(draw, command: str):
    opts = OPTIONS[command]
    names = draw(st.lists(st.sampled_from(sorted(opts)), max_size=4, unique=True))
    args = list(BASE[command])
    if command == "accelerate" and "--to-speed" not in names:
        names.append("--to-speed")  # required
    for name in names:
        v = draw(_value(opts[name]))
        args += [name] if v is None else [f"{name}={v}"]  # '=' keeps values starting with '-' values
    return args


def _check(run_cli, args, folder: Path) -> int:
    code, out, err = run_cli(*args)
    event(f"exit {code}")
    assert "Traceback" not in err and "internal error" not in err, (args, err)
    assert code in (0, 1, 2), (args, code, err)
    if code == 2:
        errors = [line for line in err.splitlines() if "error" in line]
        assert len(errors) == 1, (args, err)
    leftovers = [p.name for p in folder.rglob(".*") if p.is_file()]
    assert not leftovers, (args, leftovers)
    if code == 0:
        texts = [out] + [p.read_text(errors="replace") for p in folder.rglob("*")
                         if p.is_file() and p.suffix in (".bvh", ".json", ".md", ".csv", ".gltf")
                         and p.name != "in.bvh"]
        for t in texts:
            m = NON_FINITE.search(t)
            assert m is None, (args, t[max(0, m.start() - 80):m.end() + 80])
    return code


def _folder() -> tempfile.TemporaryDirectory:
    d = tempfile.TemporaryDirectory(prefix="froude-fuzz-")
    shutil.copy(sample_path(), Path(d.name) / "in.bvh")
    (Path(d.name) / "c.yaml").write_text("name: c\nheight: 1.4\nmass: 40\n")
    (Path(d.name) / "map.yaml").write_text("left_foot: LeftFoot\nright_foot: RightFoot\n")
    (Path(d.name) / "plan.yaml").write_text("characters: [child]\nspeeds: [1.0]\nstrides: [1]\n")
    return d


@pytest.fixture
def small_work(monkeypatch):
    """Accepted cases stay small: the work bound at 3,000 frames; the studio never really starts."""
    monkeypatch.setattr(common, "MAX_FRAMES", 3000)
    import froude.apps.studio

    monkeypatch.setattr(froude.apps.studio, "serve", lambda *a, **k: 0, raising=True)


@pytest.mark.parametrize("command", ["info", "fit", "scale", "accelerate", "render", "view", "batch", "convert"])
def test_fuzz_options(command, run_cli, small_work, monkeypatch, capsys):
    codes = []

    @SETTINGS
    @given(args=invocation(command))
    def run(args):
        with _folder() as d:
            monkeypatch.chdir(d)
            codes.append(_check(run_cli, args, Path(d)))

    run()
    # the fuzz must reach both sides: refusals and real runs (else it tests nothing but the parser)
    assert 2 in codes and ({0, 1} & set(codes)), codes
    with capsys.disabled():
        print(f"\n  {command}: {len(codes)} cases, exit status counts "
              f"{ {c: codes.count(c) for c in sorted(set(codes))} }", end="")


def test_fuzz_demo_options(run_cli, small_work, monkeypatch):
    """The demo is long when it runs (every Figure 3 row): a few examples, mostly refusals."""
    @settings(SETTINGS, max_examples=max(4, FUZZ_EXAMPLES // 8))
    @given(args=invocation("demo"))
    def run(args):
        with _folder() as d:
            monkeypatch.chdir(d)
            _check(run_cli, args, Path(d))

    run()
