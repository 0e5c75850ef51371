"""Benchmark of the command line's start-up and end-to-end time (issue 14, acceptance 3).

    python benchmarks/bench_cli.py              # 7 runs of each command, fresh processes
    python benchmarks/bench_cli.py --runs 15

Each figure is wall time of a fresh process (interpreter start, imports, work, exit), as a user waits
for it: best and median of N runs. Bars (docs/architecture.md): ``froude --help`` <= 2 x ``python -c "import numpy"``;
``froude scale`` of 4 strides (CMU 09_01, the embedded sample) <= 0.8 s. Run it on an idle machine: on a
loaded one every figure grows, the start-up ones most. Also prints the import time of the heaviest
modules a ``froude scale`` loads (``python -X importtime``).
"""
from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_v] = "1"

PY = sys.executable
FROUDE = [PY, "-m", "froude"]


def wall(cmd: list[str], runs: int, expect: int = 0) -> list[float]:
    times = []
    for _ in range(runs):
        t = time.perf_counter()
        r = subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        times.append(time.perf_counter() - t)
        if r.returncode != expect:
            sys.exit(f"{' '.join(cmd)}: exit {r.returncode} (expected {expect}): {r.stderr}")
    return times


def show(label: str, times: list[float]) -> float:
    best, med = min(times), statistics.median(times)
    print(f"{label:<48} best {best * 1000:7.0f} ms   median {med * 1000:7.0f} ms")
    return best


def heaviest_imports(cmd: list[str], n: int = 6) -> None:
    r = subprocess.run([PY, "-X", "importtime", *cmd[1:]], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                       text=True)
    rows = []
    for line in r.stderr.splitlines():
        if line.startswith("import time:") and "|" in line:
            _, cum, name = (s.strip() for s in line[len("import time:"):].split("|"))
            if cum.isdigit() and not name.startswith(" "):
                rows.append((int(cum), name))
    top = sorted((c, nm) for c, nm in rows if "." not in nm or nm.startswith("froude"))[-n:][::-1]
    print("  heaviest top-level imports of froude scale: " + ", ".join(f"{nm} {c / 1000:.0f} ms" for c, nm in top))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=7)
    args = ap.parse_args()
    from froude.io.samples import sample_path

    clip = str(sample_path())
    with tempfile.TemporaryDirectory() as d:
        out = str(Path(d) / "o.bvh")
        wall([*FROUDE, "scale", clip, "-o", out, "-q"], 1)  # warm the file cache
        numpy = show('python -c "import numpy"', wall([PY, "-c", "import numpy"], args.runs))
        show('python -c "pass"', wall([PY, "-c", "pass"], args.runs))
        helps = show("froude --help", wall([*FROUDE, "--help"], args.runs))
        show("froude scale --help", wall([*FROUDE, "scale", "--help"], args.runs))
        bad = show("froude scale CLIP --fps 0 (option error)", wall([*FROUDE, "scale", clip, "--fps", "0", "-o", out],
                                                                  args.runs, expect=2))
        guard = show("froude scale CLIP -o CLIP (output guard)", wall([*FROUDE, "scale", clip, "-o", clip],
                                                                    args.runs, expect=2))
        scale = show("froude scale CLIP --strides 4 -o OUT", wall([*FROUDE, "scale", clip, "--strides", "4", "-o", out,
                                                                 "-q"], args.runs))
        heaviest_imports([*FROUDE, "scale", clip, "--strides", "4", "-o", out, "-q"])
    verdict = "met" if helps <= 2 * numpy else "NOT met"
    print(f"\nfroude --help / import numpy = {helps / numpy:.2f} (bar <= 2): {verdict}")
    print(f"option error {bad * 1000:.0f} ms, guard refusal {guard * 1000:.0f} ms (bar: well under 500 ms): "
          f"{'met' if max(bad, guard) < 0.5 else 'NOT met'}")
    print(f"froude scale 4 strides {scale:.3f} s (bar <= 0.8 s): {'met' if scale <= 0.8 else 'NOT met'}")
    print(f"(load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores: figures are only comparable on an "
          "idle machine)")
    if os.environ.get("PYTHONDONTWRITEBYTECODE"):
        # no .pyc is written for the editable source tree, so every process compiles froude's modules again:
        # about 0.1 s of a scale run here (measured with -X pycache_prefix), which an installed froude does not pay
        print("(PYTHONDONTWRITEBYTECODE is set: every command above compiled froude's sources first)")


if __name__ == "__main__":
    main()
