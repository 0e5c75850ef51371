"""The arithmetic settings this machine can run: OpenBLAS kernels and NumPy SIMD paths (issue 26).

One list, used by ``make_golden.py --spread`` (the goldens' tolerance is measured across it) and by CI's
second pass (``.ci/run``: the tests of ``SECOND_PASS`` under ``ci_environment()``).

- ``OPENBLAS_CORETYPE`` picks the kernels of a DYNAMIC_ARCH OpenBLAS (NumPy's and SciPy's scipy-openblas).
  What really ran is read back from the library (:func:`openblas_cores`): on this EPYC, Zen runs the
  Haswell kernels and Prescott the Katmai ones (scipy-openblas 0.3.31).
- ``NPY_DISABLE_CPU_FEATURES`` switches off NumPy's run-time dispatched SIMD targets. Only dispatched
  targets may be named (NumPy refuses a baseline one, and NumPy 2.4 refuses names outside its dispatch
  list: X86_V3 = AVX2, X86_V4 / AVX512_ICL / AVX512_SPR = AVX-512), so the names are taken from the
  installed NumPy's own list (:func:`numpy_targets`), not written here.
"""
from __future__ import annotations

import ctypes
import glob
import os
import shlex
import sys

#: CPU-feature families, by the words in NumPy's dispatch-target names (2.x: X86_V4, AVX512_ICL, …;
#: 1.26: AVX512F, AVX512_SKX, …).
AVX512 = ("AVX512", "X86_V4")
AVX2 = AVX512 + ("AVX2", "X86_V3", "FMA3")


def numpy_targets(families) -> str:
    """The installed NumPy's dispatched SIMD targets whose names contain one of ``families``, space-separated
    (the value of NPY_DISABLE_CPU_FEATURES that switches them off); '' when it has none."""
    try:
        from numpy._core._multiarray_umath import __cpu_dispatch__ as dispatch
    except ImportError:  # NumPy 1.x
        from numpy.core._multiarray_umath import __cpu_dispatch__ as dispatch
    return " ".join(t for t in dispatch if any(f in t for f in families))


def settings() -> dict[str, dict[str, str]]:
    """{name: environment} of every setting of the spread measurement (issue 26, point 2)."""
    out: dict[str, dict[str, str]] = {"default": {}}
    for core in ("Haswell", "SkylakeX", "Zen", "Sandybridge", "Prescott"):
        out[f"OPENBLAS_CORETYPE={core}"] = {"OPENBLAS_CORETYPE": core}
    out["NumPy without AVX-512"] = {"NPY_DISABLE_CPU_FEATURES": numpy_targets(AVX512)}
    out["NumPy without AVX2"] = {"NPY_DISABLE_CPU_FEATURES": numpy_targets(AVX2)}
    out["ci"] = ci_environment()
    return out


#: CI's second pass (``.ci/run``; pytest arguments): the tests whose results hang on the arithmetic's last
#: bits, rerun under ``ci_environment()``: the goldens, the perturbation and shortage tests but their walks
#: (marked slow: three 10-20 s fits each, over CI's 20 minutes), and the walk fit that flipped under
#: OpenBLAS's Haswell kernels (issue 26). Measured: 106 tests, 39 s (ead0b02, load 1.5).
SECOND_PASS = (
    "-m", "not slow",
    "tests/test_golden.py",
    "tests/test_stability.py",
    "tests/test_conventions.py::test_walk_fit_meets_issue_17_in_other_conventions[02_01-folded]",
)


def ci_environment() -> dict[str, str]:
    """CI's second pass (issue 26, point 3): OpenBLAS's oldest x86-64 kernels and NumPy without AVX-512."""
    return {"OPENBLAS_CORETYPE": "Prescott", "NPY_DISABLE_CPU_FEATURES": numpy_targets(AVX512)}


def openblas_cores() -> dict[str, str]:
    """{library file: OpenBLAS core name} of the OpenBLAS libraries NumPy and SciPy loaded (the kernels
    that really run); {} where there is none (another BLAS)."""
    import numpy
    import scipy.linalg  # noqa: F401  (loads SciPy's OpenBLAS)

    out = {}
    for pkg in ("numpy", "scipy"):
        base = os.path.dirname(os.path.dirname(sys.modules[pkg].__file__ or ""))
        for lib in glob.glob(os.path.join(base, f"{pkg}.libs", "*openblas*")):
            handle = ctypes.CDLL(lib)
            for sym in ("scipy_openblas_get_corename64_", "scipy_openblas_get_corename", "openblas_get_corename64_",
                        "openblas_get_corename"):
                fn = getattr(handle, sym, None)
                if fn is not None:
                    fn.restype = ctypes.c_char_p
                    out[os.path.basename(lib)] = fn().decode()
                    break
    del numpy
    return out


def describe() -> str:
    """One line: the OpenBLAS cores and NumPy's SIMD targets switched off in this process."""
    cores = sorted(set(openblas_cores().values())) or ["(no OpenBLAS)"]
    off = os.environ.get("NPY_DISABLE_CPU_FEATURES", "").split()
    return f"OpenBLAS core {'/'.join(cores)}; NumPy SIMD off: {' '.join(off) or 'none'}"


if __name__ == "__main__":
    # ``python kernels.py NAME`` prints the setting as shell exports (``ci``: CI's second pass);
    # ``python kernels.py second-pass`` the tests of that pass, one a line; ``python kernels.py`` says
    # what this process runs.
    if sys.argv[1:] == ["second-pass"]:
        print("\n".join(SECOND_PASS))
    elif len(sys.argv) > 1:
        env = ci_environment() if sys.argv[1] == "ci" else settings()[sys.argv[1]]
        print("\n".join(f"export {k}={shlex.quote(v)}" for k, v in env.items()))
    else:
        print(describe())
