"""Golden outputs of the scale / accelerate test matrices, saved so that a refactor can prove it moves nothing.

Run ``python tests/golden/make_golden.py`` to (re)write ``tests/fixtures/golden/outputs.npz``; the commit it
was made at is stored in the file. ``tests/test_golden.py`` recomputes every output through the public
pipeline and compares joint world positions within ``TOL_M`` (1e-9 m).

The goldens are exact on the platform that made them (same CPU features, NumPy, SciPy, BLAS: stored in
the file as ``_platform``). Elsewhere the last bits of vectorised arithmetic differ (SIMD kernels chosen at
run time by CPU), and the planner's Newton iterations carry such differences up to about 1e-5 m (measured:
1.4e-5 m on an AVX-512 EPYC against goldens made on another machine; the scale outputs stayed within
1e-9 m). So on another platform the bar is ``TOL_OTHER_PLATFORM_M`` (0.1 mm: far below what a physics or
synthesis change moves, which is millimetres or frames), and the test says which bar it used.

When a change is *meant* to move the physics (a bug fix, a new bar, another synthesis), regenerate the file
with this script at that commit and say in the commit message which change moved the goldens. A refactor
must never need to.

The matrix is the one of tests/test_scale.py and tests/test_accelerate.py:
- scale: every CMU running clip × the presets child, troll, giant, small × speed factors 0.7, 1.0, 1.2,
  4 strides (``pipeline.scale(prep, preset, speed=s, strides=4)``);
- accelerate: every CMU running clip × to_factor 0.5, 1.3, 8 steps (``pipeline.accelerate``).
Per output the file keeps, to stay a few MB: the root's world position at every frame (F, 3) [m] and every
joint's world position at every ``STRIDE``-th frame (F//STRIDE, J, 3) [m], float64, plus the frame count.

The world positions are computed here by a forward kinematics of this file's own (NumPy, no froude code),
so that a change in froude's FK cannot hide a change in the motion.
"""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
REPO = HERE.parents[1]
OUT = REPO / "tests" / "fixtures" / "golden" / "outputs.npz"
RUNNING = ("09_01", "09_02", "09_03", "09_04", "09_05", "09_06", "09_07", "09_08", "02_03")
PRESETS = ("child", "troll", "giant", "small")
SPEEDS = (0.7, 1.0, 1.2)
FACTORS = (0.5, 1.3)
STRIDE = 10  # every STRIDE-th frame keeps all joints
TOL_M = 1e-9  # [m] on the platform the goldens were made on
TOL_OTHER_PLATFORM_M = 1e-4  # [m] elsewhere (see the module docstring)


def cases():
    """[(key, clip, kind, kwargs)] of the whole matrix, in a fixed order."""
    out = []
    for c in RUNNING:
        for p in PRESETS:
            for s in SPEEDS:
                out.append((f"scale/{c}/{p}/{s:g}", c, "scale", dict(character=p, speed=s, strides=4)))
        for f in FACTORS:
            out.append((f"accelerate/{c}/{f:g}", c, "accelerate", dict(to_factor=f, steps=8)))
    return out


def _rotation_matrices(q: np.ndarray) -> np.ndarray:
    """(..., 4) unit quaternions (w, x, y, z) → (..., 3, 3) rotation matrices (Hamilton, active)."""
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = np.moveaxis(q, -1, 0)
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
    ], -2)


def world_positions(motion) -> np.ndarray:
    """(F, J, 3) world joint positions [m] of a froude Motion, by this file's own FK."""
    parents = np.asarray(motion.skeleton.parents)
    R_local = _rotation_matrices(np.asarray(motion.rotations, dtype=float))
    t_local = np.asarray(motion.local_translations(), dtype=float)  # root position at joint 0
    F, J = R_local.shape[:2]
    R = np.empty_like(R_local)
    p = np.empty((F, J, 3))
    for j in range(J):  # parents come before children in a BVH hierarchy
        if parents[j] < 0:
            R[:, j] = R_local[:, j]
            p[:, j] = t_local[:, j]
        else:
            a = parents[j]
            R[:, j] = R[:, a] @ R_local[:, j]
            p[:, j] = p[:, a] + np.einsum("fab,fb->fa", R[:, a], t_local[:, j])
    return p


def summarise(motion) -> dict:
    """What the golden file keeps of one output (see the module docstring)."""
    p = world_positions(motion)
    return {"root": p[:, 0].copy(), "sparse": p[::STRIDE].copy(), "n_frames": np.array(len(p))}


def compute(mocap: Path, only=None):
    """{key: summary} for every case (or the keys in ``only``), through the public pipeline."""
    from froude import pipeline

    out, prepared = {}, {}
    for key, c, kind, kw in cases():
        if only is not None and key not in only:
            continue
        if c not in prepared:
            prepared = {c: pipeline.prepare(mocap / f"{c}.bvh")}  # one clip in memory at a time
        prep = prepared[c]
        if kind == "scale":
            kw = dict(kw)
            res = pipeline.scale(prep, kw.pop("character"), **kw)
        else:
            res = pipeline.accelerate(prep, **kw)
        out[key] = summarise(res.motion)
    return out


def platform_fingerprint() -> str:
    """What decides the last bits of the arithmetic: CPU architecture and the SIMD features NumPy uses,
    NumPy, SciPy and their BLAS."""
    import platform

    import numpy
    import scipy
    from numpy._core._multiarray_umath import __cpu_features__ as cpu

    blas = numpy.show_config(mode="dicts")["Build Dependencies"]["blas"]
    features = ",".join(sorted(k for k, on in cpu.items() if on))
    return (f"{platform.machine()} numpy {numpy.__version__} scipy {scipy.__version__} "
            f"{blas.get('name')} {blas.get('version')} [{features}]")


def tolerance(golden) -> tuple[float, str]:
    """(bar [m], why) for comparing with a loaded golden file: exact where it was made."""
    made_on = str(golden["_platform"]) if "_platform" in golden else "an unrecorded platform"
    if made_on == platform_fingerprint():
        return TOL_M, "this platform made the goldens"
    return TOL_OTHER_PLATFORM_M, f"goldens made on another platform ({made_on})"


def commit() -> str:
    r = subprocess.run(["git", "-C", str(REPO), "rev-parse", "HEAD"], capture_output=True, text=True)
    dirty = subprocess.run(["git", "-C", str(REPO), "status", "--porcelain", "src"], capture_output=True, text=True)
    return r.stdout.strip() + ("+dirty-src" if dirty.stdout.strip() else "")


def main() -> int:
    sys.path.insert(0, str(REPO / "tests"))
    from conftest import MOCAP

    if MOCAP is None:
        print("make_golden: the CMU clips are not found (set FROUDE_MOCAP_DIR)", file=sys.stderr)
        return 2
    data = compute(MOCAP)
    flat = {"_commit": np.array(commit()), "_stride": np.array(STRIDE), "_platform": np.array(platform_fingerprint())}
    for key, d in data.items():
        for name, arr in d.items():
            flat[f"{key}:{name}"] = arr
    OUT.parent.mkdir(parents=True, exist_ok=True)
    tmp = OUT.with_name(OUT.name + ".partial.npz")
    np.savez_compressed(tmp, **flat)
    tmp.replace(OUT)
    print(f"make_golden: {len(data)} outputs at {flat['_commit']} -> {OUT} ({OUT.stat().st_size / 1e6:.2f} MB)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
