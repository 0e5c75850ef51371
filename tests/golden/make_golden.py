"""Golden outputs of the scale / accelerate test matrices, saved so that a refactor can prove it moves nothing.

Run ``python tests/golden/make_golden.py`` to (re)write ``tests/fixtures/golden/outputs.npz``; the commit it
was made at is stored in the file. ``tests/test_golden.py`` recomputes every output through the public
pipeline and compares joint world positions within ``TOL_M`` (3.5e-5 m; see below).

What is exact and what is not (issue 26). Exact everywhere: every output's frame count, and so every
decision before the arithmetic (which machine, how many strides, accepted or not). Not exact: the last bits
of the positions, which depend on the BLAS kernel and the SIMD path chosen at run time by CPU, and which
accelerate's Newton iterations and shooting carry up to a few 1e-6 m. Measured with
``python tests/golden/make_golden.py --spread`` (every output recomputed under each setting of
``kernels.settings()`` in a fresh process, compared with the default one) on this machine, an AMD EPYC with
AVX-512 (NumPy 2.4.6, SciPy 1.17.1, scipy-openblas 0.3.31), at c3b6cac (accelerate along the human speed
law):

    setting (kernels that ran)                            largest |position - default| [m]
    OPENBLAS_CORETYPE=Haswell  (Haswell)                  1.8e-06   accelerate/09_07/1.3
    OPENBLAS_CORETYPE=SkylakeX (SkylakeX = default)       0
    OPENBLAS_CORETYPE=Zen      (Haswell kernels)          1.8e-06   accelerate/09_07/1.3
    OPENBLAS_CORETYPE=Sandybridge (Sandybridge)           1.8e-06   accelerate/09_07/1.3
    OPENBLAS_CORETYPE=Prescott (Katmai)                   1.8e-06   accelerate/09_07/1.3
    NumPy without AVX-512 (X86_V4 AVX512_ICL AVX512_SPR)  3.3e-06   accelerate/09_02/1.3
    NumPy without AVX2 (X86_V3 as well)                   3.3e-06   accelerate/09_02/1.3
    Prescott + NumPy without AVX-512 (CI's second pass)   2.2e-06   accelerate/09_02/1.3

The spread over all of them (largest max - min of a coordinate) is 3.3e-06 m (before the law, at 26ec188
and 049af6e, it was 2.4e-07 m, with the scale outputs within 1.1e-09 m). So the bar for a platform with the
same libraries (architecture, NumPy, SciPy, BLAS version; any CPU features and kernels) is ``TOL_M`` =
3.5e-5 m, ten times the measured spread and still 0.035 mm, far below a visible difference or any bar
(millimetres). Rerun ``--spread`` after a change to the planner or the fits: a spread above a tenth of
``TOL_M`` means the bar must be measured again. A platform with other libraries (another NumPy, an ARM
Mac's Accelerate, …) was not measured here: there the bar is ``TOL_OTHER_PLATFORM_M`` (0.1 mm: far below
what a physics or synthesis change moves, which is millimetres or frames), and the test says which bar it
used and why.

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
#: Largest spread of the outputs across the kernels and SIMD paths of ``kernels.settings()`` [m] (measured,
#: see the module docstring) and the bar: ten times it, for any platform with the goldens' libraries.
MEASURED_SPREAD_M = 3.3e-6
TOL_M = 3.5e-5  # [m]: 10 x MEASURED_SPREAD_M, rounded up
TOL_OTHER_PLATFORM_M = 1e-4  # [m] with other libraries: not measured (see the module docstring)


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


def run_case(prep, kind: str, kw: dict):
    """One output of the matrix (a ``cases()`` row's kind and kwargs) through the public pipeline."""
    from froude.flow import pipeline

    if kind == "scale":
        kw = dict(kw)
        return pipeline.scale(prep, kw.pop("character"), **kw)
    return pipeline.accelerate(prep, **kw)


def compute(mocap: Path, only=None):
    """{key: summary} for every case (or the keys in ``only``), through the public pipeline."""
    from froude.flow import pipeline

    out, prepared = {}, {}
    for key, c, kind, kw in cases():
        if only is not None and key not in only:
            continue
        if c not in prepared:
            prepared = {c: pipeline.prepare(mocap / f"{c}.bvh")}  # one clip in memory at a time
        out[key] = summarise(run_case(prepared[c], kind, kw).motion)
    return out


def platform_fingerprint() -> str:
    """What decides the last bits of the arithmetic: CPU architecture, NumPy, SciPy and their BLAS, and the
    SIMD features NumPy uses (in brackets)."""
    import platform

    import numpy
    import scipy
    try:
        from numpy._core._multiarray_umath import __cpu_features__ as cpu
    except ImportError:  # NumPy 1.x
        from numpy.core._multiarray_umath import __cpu_features__ as cpu

    blas = numpy.show_config(mode="dicts")["Build Dependencies"]["blas"]
    features = ",".join(sorted(k for k, on in cpu.items() if on))
    return (f"{platform.machine()} numpy {numpy.__version__} scipy {scipy.__version__} "
            f"{blas.get('name')} {blas.get('version')} [{features}]")


def libraries(fingerprint: str) -> str:
    """The part of a :func:`platform_fingerprint` the tolerance depends on: architecture and library
    versions, not the CPU features and kernels (their spread is measured: see the module docstring)."""
    return fingerprint.split(" [")[0]


def tolerance(golden) -> tuple[float, str]:
    """(bar [m], why) for comparing with a loaded golden file."""
    made_on = str(golden["_platform"]) if "_platform" in golden else "an unrecorded platform"
    if libraries(made_on) == libraries(platform_fingerprint()):
        return TOL_M, f"the goldens' libraries ({libraries(made_on)}): 10 x the spread measured across kernels"
    return TOL_OTHER_PLATFORM_M, f"goldens made with other libraries ({made_on}): spread not measured"


def commit() -> str:
    r = subprocess.run(["git", "-C", str(REPO), "rev-parse", "HEAD"], capture_output=True, text=True)
    dirty = subprocess.run(["git", "-C", str(REPO), "status", "--porcelain", "src"], capture_output=True, text=True)
    return r.stdout.strip() + ("+dirty-src" if dirty.stdout.strip() else "")


def spread(tmp: Path) -> int:
    """Recompute every output under each setting of ``kernels.settings()`` (a fresh process each: the
    kernels are chosen at load time) and print each one's largest difference from the default and the
    spread over all (the figures of the module docstring)."""
    import os

    import kernels

    runs = {}
    for name, env in kernels.settings().items():
        out = tmp / f"{len(runs)}.npz"
        r = subprocess.run([sys.executable, __file__, "--dump", str(out)], env={**os.environ, **env},
                           capture_output=True, text=True)
        if r.returncode != 0:
            print(f"make_golden: {name}: {r.stderr.strip().splitlines()[-1]}", file=sys.stderr)
            return 1
        runs[name] = (np.load(out), r.stdout.strip())
    ref = runs["default"][0]
    keys = [k for k in ref.files if k.endswith((":root", ":sparse"))]
    for name, (d, ran) in runs.items():
        frames = all(int(d[k]) == int(ref[k]) for k in ref.files if k.endswith(":n_frames"))
        dev = [(float(np.abs(d[k] - ref[k]).max()), k) for k in keys]
        worst = max(dev)
        print(f"{name:32s} {ran:60s} {worst[0]:8.2g} m at {worst[1].rsplit(':', 1)[0]}"
              f"{'' if frames else '  FRAME COUNTS DIFFER'}")
    total = max(float(np.ptp(np.stack([d[k] for d, _ in runs.values()]), axis=0).max()) for k in keys)
    print(f"spread over all settings: {total:.2g} m (bar TOL_M = {TOL_M:g} m)")
    return 0


def main(argv=None) -> int:
    """``make_golden.py``: rewrite the goldens; ``--spread``: measure the spread across kernels;
    ``--dump FILE``: write this process's outputs to FILE (used by ``--spread``)."""
    import tempfile

    argv = sys.argv[1:] if argv is None else argv
    sys.path.insert(0, str(REPO / "tests"))
    from conftest import MOCAP

    if MOCAP is None:
        print("make_golden: the CMU clips are not found (set FROUDE_MOCAP_DIR)", file=sys.stderr)
        return 2
    if argv[:1] == ["--spread"]:
        with tempfile.TemporaryDirectory() as tmp:
            return spread(Path(tmp))
    data = compute(MOCAP)
    flat = {"_commit": np.array(commit()), "_stride": np.array(STRIDE), "_platform": np.array(platform_fingerprint())}
    for key, d in data.items():
        for name, arr in d.items():
            flat[f"{key}:{name}"] = arr
    if argv[:1] == ["--dump"]:
        np.savez(argv[1], **flat)
        import kernels

        print(kernels.describe())
        return 0
    OUT.parent.mkdir(parents=True, exist_ok=True)
    tmp = OUT.with_name(OUT.name + ".partial.npz")
    np.savez_compressed(tmp, **flat)
    tmp.replace(OUT)
    print(f"make_golden: {len(data)} outputs at {flat['_commit']} -> {OUT} ({OUT.stat().st_size / 1e6:.2f} MB)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
