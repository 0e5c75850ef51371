"""Shared test helpers: where the real clips are, an independent BVH reader + SciPy FK oracle, the CLI.

The oracle deliberately shares no code with ``froude``: its own tokenizer, SciPy ``Rotation`` for the
Euler angles (intrinsic, file order) and for composing joint transforms.
"""
from __future__ import annotations

import os
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from froude.apps.cli import main as cli_main

REPO = Path(__file__).resolve().parents[1]
FIXTURES = Path(__file__).resolve().parent / "fixtures"


def _find_data(kind: str, probe: str) -> Path | None:
    """The folder of real clips of one kind ("mocap": CMU, "bandai", "bandai-locomotion", "cmu-turns"), or None.

    Looked for in $FROUDE_<KIND>_DIR, then ../shared/data/<kind> beside the repository (a worktree one
    level deeper is covered too), then /work/shared/data/<kind>.
    """
    env = f"FROUDE_{kind.upper().replace('-', '_')}_DIR"
    candidates = [os.environ.get(env), REPO.parent / "shared" / "data" / kind,
                  REPO.parent.parent / "shared" / "data" / kind, Path("/work/shared/data") / kind]
    for c in candidates:
        if c and Path(c, probe).is_file():
            return Path(c)
    return None


MOCAP = _find_data("mocap", "09_01.bvh")
BANDAI = _find_data("bandai", "dataset-1_dash_normal_001.bvh")
RUNNING = ("09_01", "09_02", "09_03", "09_04", "09_05", "09_06", "09_07", "09_08", "02_03")
WALKING = ("02_01", "07_01")
ALL_CLIPS = tuple(sorted(p.stem for p in MOCAP.glob("*.bvh"))) if MOCAP else ()
# Bandai Namco Research Motion Dataset 1 (CC BY-NC 4.0: tests only, never shipped): 30 Hz, centimetres,
# folded bind-pose rest pose, six channels per joint, a static joint_Root. dash_normal is a one-stride loop.
BANDAI_RUNS = ("dataset-1_dash_active_001", "dataset-1_dash_feminine_001", "dataset-1_dash_normal_001",
               "dataset-1_dash_old_001", "dataset-1_run_tired_001")
BANDAI_WALKS = ("dataset-1_walk_normal_001",)
NO_DATA = "real clips not found: set FROUDE_MOCAP_DIR to the folder holding 09_01.bvh"
NO_BANDAI = ("Bandai clips not found: set FROUDE_BANDAI_DIR to the folder holding "
             "dataset-1_dash_normal_001.bvh")
# The locomotion sample of the same Bandai rig (walks of seven styles, 90-degree walk-turns, a backward walk,
# grounded runs; CC BY-NC 4.0, tests only) and CMU's turning walk and run. Their clips are named by folder:
# clip("bandai-locomotion/turns/dataset-2_walk-turn-left_normal_001"), clip("cmu-turns/16_51").
BANDAI_LOCO = _find_data("bandai-locomotion", "walks/dataset-2_walk_normal_002.bvh")
CMU_TURNS = _find_data("cmu-turns", "16_18.bvh")
_FOLDERS = {"bandai-locomotion": BANDAI_LOCO, "cmu-turns": CMU_TURNS}


def _folder_clips(kind: str, sub: str = "") -> tuple[str, ...]:
    """Names (``kind/sub/stem``) of the clips in one of the folders above; () when it is absent."""
    root = _FOLDERS[kind]
    if root is None:
        return ()
    return tuple(sorted(f"{kind}/{p.relative_to(root).with_suffix('').as_posix()}"
                        for p in (root / sub).glob("*.bvh")))


LOCO_WALKS = _folder_clips("bandai-locomotion", "walks")
LOCO_RUNS = _folder_clips("bandai-locomotion", "runs")
LOCO_TURNS = _folder_clips("bandai-locomotion", "turns")
CMU_TURN_CLIPS = _folder_clips("cmu-turns")


def clip(name: str) -> Path:
    """Path of a real clip (CMU "09_01", Bandai "dataset-1_…", or "bandai-locomotion/…", "cmu-turns/…"),
    skipping the test with the reason when its data folder is absent."""
    kind, _, rest = name.partition("/")
    if rest:
        if _FOLDERS.get(kind) is None:
            pytest.skip(f"{kind} clips not found: set FROUDE_{kind.upper().replace('-', '_')}_DIR")
        return _FOLDERS[kind] / f"{rest}.bvh"
    if name.startswith("dataset-"):
        if BANDAI is None:
            pytest.skip(NO_BANDAI)
        return BANDAI / f"{name}.bvh"
    if MOCAP is None:
        pytest.skip(NO_DATA)
    return MOCAP / f"{name}.bvh"


class _Prepared(dict):
    """Running clips prepared (loaded, fitted) on first use; a missing clip skips the test that asks."""

    def __missing__(self, name: str):
        from froude.flow import pipeline

        self[name] = pipeline.prepare(clip(name))
        return self[name]


@pytest.fixture(scope="module")
def prepared():
    """Each clip's ``pipeline.prepare`` once per test module: ``prepared["09_01"]``."""
    return _Prepared()


@dataclass(frozen=True)
class MatrixOutput:
    """What the tests keep of one output of the scale / accelerate matrix (tests/golden/make_golden.cases):
    the golden summary (root and sparse joint world positions, frame count), the physics report, and
    whether the motion is finite everywhere. Small, so the whole matrix stays in memory."""

    summary: dict
    report: object
    finite: bool


class _MatrixOutputs(dict):
    """Outputs of the matrix by make_golden key ("scale/09_01/child/0.7", "accelerate/09_01/1.3"), each
    computed once per test process and shared by test_golden, test_scale and test_accelerate (their cases
    of one clip share an xdist group, so under scripts/test's ``--dist loadgroup`` they meet in one worker).
    The clips are prepared once each (the last two kept)."""

    def __init__(self):
        super().__init__()
        self._prepared: dict = {}

    def __missing__(self, key: str) -> MatrixOutput:
        import make_golden

        from froude.flow import pipeline

        row = next((r for r in make_golden.cases() if r[0] == key), None)
        assert row is not None, f"{key}: not a case of tests/golden/make_golden.py"
        _, name, kind, kw = row
        if name not in self._prepared:
            if len(self._prepared) >= 2:
                self._prepared.pop(next(iter(self._prepared)))
            self._prepared[name] = pipeline.prepare(clip(name))
        res = make_golden.run_case(self._prepared[name], kind, kw)
        m = res.motion
        self[key] = MatrixOutput(make_golden.summarise(m), res.report,
                                 bool(np.all(np.isfinite(m.rotations)) and np.all(np.isfinite(m.root_positions))))
        return self[key]


@pytest.fixture(scope="session")
def matrix_outputs():
    """The scale / accelerate matrix's outputs, each computed once per test process: ``matrix_outputs[key]``."""
    sys.path.insert(0, str(Path(__file__).resolve().parent / "golden"))
    return _MatrixOutputs()


def matrix_group(name: str):
    """The xdist group of one clip's matrix outputs (its golden, scale and accelerate cases)."""
    return pytest.mark.xdist_group(f"matrix-{name}")


def clip_params(names=None):
    """pytest parameters over real clips; a single skipping parameter when the data is absent."""
    names = list(names or ALL_CLIPS)
    if not names:
        return [pytest.param(None, marks=pytest.mark.skip(reason="that folder of real clips is absent"))]
    if all("/" in n for n in names):  # folder-named clips: clip() skips each one whose folder is absent
        return names
    bandai = any(n.startswith("dataset-") for n in names)
    if (MOCAP is None and not bandai) or (bandai and BANDAI is None) or not names:
        return [pytest.param(None, marks=pytest.mark.skip(reason=NO_BANDAI if bandai else NO_DATA))]
    return names


# ---- test tiers --------------------------------------------------------------------------------------
#: A test measured slower than this [s] (tests/durations.tsv: one process, file by file, written by
#: scripts/test_durations.py) is marked ``slow``: ``./scripts/test -m "not slow"`` is the fast tier run
#: before every commit; CI (.ci/run) runs every test. A test not in the file (a new one) counts as fast:
#: measure it with the script when it is not cheap.
SLOW_S = 1.0
DURATIONS = Path(__file__).with_name("durations.tsv")


def _measured_slow() -> set[str]:
    """Node ids ("tests/test_x.py::name[param]") measured over SLOW_S."""
    if not DURATIONS.is_file():
        return set()
    rows = (line.split("\t", 1) for line in DURATIONS.read_text().splitlines() if line and line[0] != "#")
    return {node for sec, node in rows if float(sec) > SLOW_S}


#: Module fixtures whose first user pays for a fit (tens of seconds here): every test using one is slow, or
#: leaving the measured slow ones out would only move the fit onto the next test of the module.
SLOW_FIXTURES = {"tests/test_walk_scale.py": "walks"}


def pytest_collection_modifyitems(config, items):
    slow = _measured_slow()
    for item in items:
        heavy_fixture = SLOW_FIXTURES.get(item.nodeid.split("::")[0]) in getattr(item, "fixturenames", ())
        # a browser test starts Chromium and a studio: minutes on this machine, measured or not
        if item.nodeid in slow or heavy_fixture or item.get_closest_marker("browser") is not None:
            item.add_marker(pytest.mark.slow)


# ---- an independent BVH reader and FK (the oracle) -----------------------------------------------
@dataclass
class OracleBvh:
    names: list
    parents: list
    offsets: np.ndarray  # (J, 3) file units
    channels: list  # per joint, channel names as written
    end_sites: list  # (joint, (3,) offset file units)
    frame_time: float
    values: np.ndarray  # (F, C) file numbers


def read_bvh_oracle(path) -> OracleBvh:
    text = Path(path).read_text()
    head, motion = text.split("MOTION", 1)
    words = head.split()
    names, parents, offsets, channels, end_sites = [], [], [], [], []
    stack = []  # joint index per open brace; -1 for End Site braces
    i = 0
    pending = None
    while i < len(words):
        w = words[i]
        if w in ("ROOT", "JOINT"):
            pending = ("joint", words[i + 1])
            i += 2
        elif w == "End":
            pending = ("end", None)
            i += 2
        elif w == "{":
            if pending[0] == "joint":
                names.append(pending[1])
                parents.append(next((s for s in reversed(stack) if s >= 0), -1))
                offsets.append(None)
                channels.append([])
                stack.append(len(names) - 1)
            else:
                stack.append(-1)
            i += 1
        elif w == "}":
            stack.pop()
            i += 1
        elif w == "OFFSET":
            off = [float(x) for x in words[i + 1 : i + 4]]
            if stack[-1] >= 0:
                offsets[stack[-1]] = off
            else:
                end_sites.append((next(s for s in reversed(stack) if s >= 0), np.array(off)))
            i += 4
        elif w == "CHANNELS":
            n = int(words[i + 1])
            channels[stack[-1]] = words[i + 2 : i + 2 + n]
            i += 2 + n
        else:
            i += 1
    lines = [l for l in motion.splitlines() if l.strip()]
    frame_time = float(lines[1].split(":")[1])
    values = np.array([[float(x) for x in l.split()] for l in lines[2:]])
    return OracleBvh(names, parents, np.array(offsets, float), channels, end_sites, frame_time, values)


def oracle_fk(b: OracleBvh, length_scale: float, rows=slice(None)):
    """World joint positions (F, J, 3) [m] and end-site positions (F, E, 3) [m] with SciPy Rotation."""
    from scipy.spatial.transform import Rotation

    values = b.values[rows]
    F, J = len(values), len(b.names)
    p_world = np.zeros((F, J, 3))
    R_world = [None] * J
    col = 0
    for j in range(J):
        t_local = np.broadcast_to(b.offsets[j] * length_scale, (F, 3)).copy()
        order, angles = "", []
        for c in b.channels[j]:
            if c.endswith("position"):
                t_local[:, "XYZ".index(c[0])] = values[:, col] * length_scale
            else:
                order += c[0].upper()  # upper case = intrinsic rotations in SciPy
                angles.append(values[:, col])
            col += 1
        R_local = (Rotation.from_euler(order, np.stack(angles, axis=1), degrees=True) if order
                   else Rotation.identity(F))
        if b.parents[j] < 0:
            p_world[:, j] = t_local
            R_world[j] = R_local
        else:
            pj = b.parents[j]
            p_world[:, j] = p_world[:, pj] + R_world[pj].apply(t_local)
            R_world[j] = R_world[pj] * R_local
    ends = np.stack([p_world[:, j] + R_world[j].apply(off * length_scale) for j, off in b.end_sites], axis=1) \
        if b.end_sites else np.zeros((F, 0, 3))
    return p_world, ends


# ---- the command line ----------------------------------------------------------------------------
@pytest.fixture
def run_cli(capsys):
    """Run ``froude ARGS`` in-process: returns (exit status, stdout, stderr)."""

    def run(*args):
        try:
            code = cli_main([str(a) for a in args])
        except SystemExit as e:  # argparse errors
            code = e.code
        out, err = capsys.readouterr()
        return code, out, err

    return run


def bpy_python() -> str:
    """A Python that imports ``bpy`` (Blender as a module): $FROUDE_BPY_PYTHON, the one scripts/test installs
    (.tools/bpy-venv: bpy 5.0 needs NumPy < 2, so it has its own venv), or this one. Skips the test saying so
    when there is none, except in CI (scripts/test installs it), where that is a failure."""
    import subprocess
    import sys

    for py in (os.environ.get("FROUDE_BPY_PYTHON"), str(REPO / ".tools" / "bpy-venv" / "bin" / "python"),
               sys.executable):
        if py and Path(py).exists() and subprocess.run([py, "-c", "import bpy"], capture_output=True,
                                                       timeout=120).returncode == 0:
            return py
    msg = ("bpy (Blender as a Python module) is not installed: scripts/test installs it into .tools/bpy-venv, "
           "or set FROUDE_BPY_PYTHON to a Python that has it")
    if os.environ.get("CI"):
        pytest.fail(msg)
    pytest.skip(msg)
