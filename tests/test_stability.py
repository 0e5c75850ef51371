"""Same answers on every machine (issue 26): decisions that do not hang on the last bit, and no internal error
on a clip that holds too little.

- Perturbation (acceptance 2): every shared clip, perturbed by 1e-9 m noise on the root's position and by
  1e-12 relative noise on every channel, gets the same fit decision (which machine, or refused with the same
  reason), the same bar verdicts of one output (the clip scaled to a child) and an output that moves by less
  than the stated tolerance. CI perturbs every shared clip but the Bandai locomotion walks and turns
  (``WALK_FITS``: 10-20 s a fit); ``FROUDE_EVERY_CLIP=1`` adds them.
- Shortage (acceptance 3): runs and walks trimmed to one contact, or to a single stance cut by both edges,
  are refused by ``fit``, ``scale`` and ``accelerate`` in one line with exit 2 and no output; ``info``
  describes them without an internal error.

The kernel-sensitive selection CI runs a second time under other kernels is ``kernels.SECOND_PASS``
(tests/golden/kernels.py).
"""
from __future__ import annotations

import dataclasses
import os
import re
import sys
from pathlib import Path

import numpy as np
import pytest

from conftest import (
    ALL_CLIPS,
    BANDAI_RUNS,
    BANDAI_WALKS,
    CMU_TURN_CLIPS,
    LOCO_RUNS,
    LOCO_TURNS,
    LOCO_WALKS,
    WALKING,
    clip,
)

sys.path.insert(0, str(Path(__file__).resolve().parent / "golden"))
import make_golden  # noqa: E402  (the goldens' own FK: the check shares no code with the synthesis)

#: Every shared clip (../shared/data/{mocap,bandai,bandai-locomotion,cmu-turns}).
EVERY_CLIP = (*ALL_CLIPS, *BANDAI_RUNS, *BANDAI_WALKS, *LOCO_RUNS, *LOCO_WALKS, *LOCO_TURNS, *CMU_TURN_CLIPS)
#: The clips whose fit is a walk, other than the CMU walks and the Bandai dataset-1 walk (measured: 10-20 s a
#: fit on one core, three fits each here): by CI's budget they are perturbed only with FROUDE_EVERY_CLIP=1.
#: Every other shared clip (all runs, the elderly turns that are refused, walk_active_009 (fitted through the
#: held force trough: walk_fit._start_passes), 02_01, 07_01, dataset-1_walk_normal_001) is in CI.
WALK_FITS = tuple(n for n in (*LOCO_WALKS, *LOCO_TURNS, *LOCO_RUNS)
                  if not n.endswith(("_walk-turn-left_elderly_001", "_walk-turn-right_elderly_001",
                                     "_walk_active_009", "_walk_elderly_001",
                                     "_run_elderly_002", "_run_masculine_001", "_run_masculine_005")))
#: The walks among the rest (and CMU's turns: 16_18 fits as a walk) are marked slow (three fits each): CI's
#: second pass, under other kernels, leaves them out (kernels.SECOND_PASS) and reruns 02_01-folded's walk fit,
#: the one that flipped, instead.
CLIPS = [pytest.param(n, marks=pytest.mark.slow) if n in (*WALK_FITS, *WALKING, *BANDAI_WALKS, *CMU_TURN_CLIPS) else n
         for n in (EVERY_CLIP if os.environ.get("FROUDE_EVERY_CLIP") else
                   tuple(n for n in EVERY_CLIP if n not in WALK_FITS))]
#: How far an output may move under the perturbations [m]: the goldens' bar, ten times the spread of the
#: outputs across BLAS kernels and SIMD paths (make_golden's docstring). Measured here: 1e-10 to 2.4e-8 m on
#: the runs. The walks are held to the same bar since their shape fit converges to its minimum (issue 26,
#: docs/walking.md): 07_01's child output moved 57-69 mm when it stopped where its trust region collapsed.
TOL_M = make_golden.TOL_M
ABS_NOISE_M = 1e-9
REL_NOISE = 1e-12

def _perturbed(motion, kind: str):
    """The motion with seeded noise: ``abs`` 1e-9 m on the root's position, ``rel`` 1e-12 relative on every
    channel (root position, joint rotations, joint translations); ``none``: the motion itself."""
    rng = np.random.default_rng(26)
    if kind == "none":
        return motion
    if kind == "abs":
        noise = ABS_NOISE_M * rng.standard_normal(motion.root_positions.shape)
        return dataclasses.replace(motion, root_positions=motion.root_positions + noise)

    def rel(a):
        return None if a is None else a * (1.0 + REL_NOISE * rng.standard_normal(a.shape))

    return dataclasses.replace(motion, root_positions=rel(motion.root_positions), rotations=rel(motion.rotations),
                               translations=rel(motion.translations))


def _decision(motion):
    """(decision, world joint positions (F, J, 3) [m] of the output or None) of one clip: the machine fitted
    and the bars the child output fails (figures masked: a verdict, not its digits), or the refusal (kind of
    error and its message)."""
    from froude.errors import FroudeError
    from froude.flow import pipeline

    try:
        prep = pipeline.prepare(motion)
        res = pipeline.scale(prep, "child")
    except FroudeError as e:
        return ("refused", type(e).__name__, str(e)), None
    verdicts = tuple(sorted(re.sub(r"\d+(\.\d+)?", "#", s) for s in res.report.check_bars()))
    return (type(prep.machine).__name__, verdicts), make_golden.world_positions(res.motion)


class _Decisions(dict):
    """(decision, output positions) of each (clip, perturbation), computed on first use (once per module)."""

    def __missing__(self, key):
        from froude import load_bvh

        name, kind = key
        if (name, "motion") not in self:
            dict.__setitem__(self, (name, "motion"), load_bvh(clip(name)))
        self[key] = _decision(_perturbed(self[name, "motion"], kind))
        return self[key]


@pytest.fixture(scope="module")
def decisions():
    return _Decisions()


@pytest.mark.parametrize("kind", ["abs", "rel"])
@pytest.mark.parametrize("name", CLIPS)
def test_decisions_do_not_flip_under_noise(name, kind, decisions):
    want, got = decisions[name, "none"][0], decisions[name, kind][0]
    assert got == want, f"{name}: {want} unperturbed, {got} with {kind} noise"


@pytest.mark.parametrize("kind", ["abs", "rel"])
@pytest.mark.parametrize("name", CLIPS)
def test_outputs_move_less_than_the_tolerance_under_noise(name, kind, decisions):
    (_, p_want), (_, p_got) = decisions[name, "none"], decisions[name, kind]
    if p_want is None or p_got is None:
        assert p_want is None and p_got is None, f"{name}: refused with or without {kind} noise only"
        return  # refused: no output (its decision is the other test's)
    moved = float(np.abs(p_got - p_want).max()) if p_got.shape == p_want.shape else np.inf
    assert p_got.shape == p_want.shape, f"{name}: {p_got.shape[0]} frames, unperturbed {p_want.shape[0]}"
    assert moved <= TOL_M, f"{name}: the output moved {moved:.3g} m with {kind} noise (> {TOL_M:g} m)"


#: Rounding of the rotations as Blender and FBX store them (float32 keys: ~1e-6 rad), and how far a run's
#: accelerate output may move for it [m]: far below the add-on's 0.5 mm bar (issue 31). Measured: 0.026 mm
#: on 09_01 (0.60 mm before the IK's unused-joint test took a tolerance; other CMU runs 0.4-0.7 mm then,
#: 0.004-0.085 mm now).
ROUNDING_RAD = 1e-6
ROUNDING_MOVE_M = 1e-4


def test_accelerate_output_barely_moves_with_float32_rounding():
    """froude.accelerate (x1.2 in 8 steps) on 09_01 and on the same clip with every rotation turned by
    1e-6 rad in a random direction: the outputs' joints agree within ROUNDING_MOVE_M."""
    import froude
    from froude.core import quat

    motion = froude.load_bvh(clip("09_01"))
    rng = np.random.default_rng(31)
    axis = rng.standard_normal(motion.rotations.shape[:2] + (3,))
    axis /= np.linalg.norm(axis, axis=-1, keepdims=True)
    rounded = motion.with_(rotations=quat.mul(motion.rotations, quat.from_rotvec(ROUNDING_RAD * axis)))
    a, b = (make_golden.world_positions(froude.accelerate(m, to_factor=1.2, steps=8).motion)
            for m in (motion, rounded))
    assert a.shape == b.shape, f"{a.shape[0]} frames, {b.shape[0]} with rounding"
    moved = float(np.linalg.norm(a - b, axis=-1).max())
    assert moved < ROUNDING_MOVE_M, f"09_01 accelerate moved {1000 * moved:.3f} mm with 1e-6 rad rounding"


# ---- clips without a full stance ----------------------------------------------------------------------
def _trimmed(src: Path, first: int, stop: int, out: Path) -> Path:
    """Frames [first, stop) of a BVH file, written as a BVH file (text surgery: header kept, frame count
    rewritten)."""
    head, motion = src.read_text().split("MOTION", 1)
    lines = motion.strip().splitlines()
    frames = lines[2:][first:stop]
    out.write_text(f"{head}MOTION\nFrames: {len(frames)}\n{lines[1]}\n" + "\n".join(frames) + "\n")
    return out


#: (clip, first frame, stop frame, what is left). Frames from the clips' contacts (gait.detect_gait): 09_01's
#: full stances are frames 41-70 and 85-112; 07_01's left foot is alone on the ground over 80-125 and its
#: complete contact 58-139 overlaps both of the right foot's; the Bandai walk (30 Hz) has contacts 26-46 and
#: 44-63.
SHORT_CLIPS = [
    ("09_01", 30, 80, "a run trimmed to one contact"),
    ("09_01", 45, 65, "a run's single stance cut by both edges"),
    ("09_01", 36, 116, "a run's two contacts, both force events of each at the clip's edges"),
    ("07_01", 50, 150, "a walk trimmed to one full contact"),
    ("07_01", 80, 125, "a walk's single stance cut by both edges"),
    ("dataset-1_walk_normal_001", 24, 48, "a 30 Hz walk trimmed to one full contact"),
    ("dataset-1_walk_normal_001", 31, 43, "a 30 Hz walk's single stance cut by both edges"),
]


@pytest.mark.parametrize("name, first, stop, what", SHORT_CLIPS, ids=[f"{c[0]}-{c[1]}-{c[2]}" for c in SHORT_CLIPS])
def test_no_full_stance_is_refused_in_one_line(name, first, stop, what, tmp_path, run_cli):
    path = _trimmed(clip(name), first, stop, tmp_path / f"{name}_{first}_{stop}.bvh")
    for verb, args in (("fit", ["-o", tmp_path / "out.machine.json"]),
                       ("scale", ["--character", "child", "-o", tmp_path / "out.bvh"]),
                       ("accelerate", ["--to-speed", "0.5x", "-o", tmp_path / "out.bvh"])):
        code, out, err = run_cli(verb, path, *args)
        assert code == 2, f"{what}: froude {verb} exit {code}: {err}"
        assert len(err.strip().splitlines()) == 1 and "internal error" not in err, f"{what}: froude {verb}: {err}"
        assert sorted(p.name for p in tmp_path.iterdir()) == [path.name], f"{what}: froude {verb} wrote output"
    code, out, err = run_cli("info", path)
    assert code in (0, 2) and "internal error" not in err, f"{what}: froude info exit {code}: {err}"
    if code == 2:
        assert len(err.strip().splitlines()) == 1, err
