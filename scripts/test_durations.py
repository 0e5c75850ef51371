"""Measure every test's time and write tests/durations.tsv, which tests/conftest.py reads to mark the tests
slower than its ``SLOW_S`` as ``slow`` (the fast tier, ``./scripts/test -m "not slow"``, leaves them out).

    python scripts/test_durations.py                 # every tests/test_*.py, one file at a time, one process
    python scripts/test_durations.py tests/test_ik.py tests/test_bvh.py   # re-measure some files (merged in)
    python scripts/test_durations.py --from-junit DIR   # rebuild from junit XML files already written
    python scripts/test_durations.py --merge-run OUT    # add the --durations lines of a pytest run's output
                                                        # (e.g. of the fast tier), keeping each test's larger time

One file at a time, in one process each (``-n 0``, under ``nice``): the whole suite in one run with
``--durations=0`` takes 12+ minutes and a crash there loses every number. A test's time is its setup, call and
teardown (junit's "total"), so the first test of a module pays for a module fixture it builds; a fast test
that shares such a fixture with slow ones then pays for it in the fast tier too, and is measured there.
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
import xml.etree.ElementTree as ET
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
OUT = REPO / "tests" / "durations.tsv"


def junit_times(xml_path: Path) -> dict[str, float]:
    """{node id: seconds} of one junit XML file written by pytest (classname "tests.test_x" → tests/test_x.py)."""
    out = {}
    for case in ET.parse(xml_path).getroot().iter("testcase"):
        module = case.get("classname", "").split(".")
        # classname is the module path, then a class name for tests in a class (none in this suite)
        node = "/".join(module) + ".py::" + case.get("name", "")
        out[node] = float(case.get("time", "0"))
    return out


def measure(files: list[Path], python: str) -> dict[str, float]:
    """{node id: seconds} of the given test files, each in its own pytest process."""
    out: dict[str, float] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for f in files:
            xml = Path(tmp) / (f.stem + ".xml")
            t0 = time.monotonic()
            subprocess.run(["nice", python, "-m", "pytest", str(f.relative_to(REPO)), "-q", "-n", "0",
                            "-p", "no:cacheprovider", f"--junitxml={xml}"], cwd=REPO, check=False,
                           stdout=subprocess.DEVNULL)
            print(f"{f.name}: {time.monotonic() - t0:.0f} s", file=sys.stderr)
            if xml.is_file():
                out.update(junit_times(xml))
    return out


def durations_lines(text: str) -> dict[str, float]:
    """{node id: seconds} from pytest's ``--durations`` lines ("12.34s call     tests/test_x.py::name"),
    setup, call and teardown summed."""
    out: dict[str, float] = {}
    for line in text.splitlines():
        parts = line.split(None, 2)
        if len(parts) == 3 and parts[0].endswith("s") and parts[1] in ("setup", "call", "teardown"):
            try:
                sec = float(parts[0][:-1])
            except ValueError:
                continue
            out[parts[2].strip()] = out.get(parts[2].strip(), 0.0) + sec
    return out


def read(path: Path = OUT) -> dict[str, float]:
    """{node id: seconds} of tests/durations.tsv ({} when absent)."""
    if not path.is_file():
        return {}
    rows = (line.split("\t", 1) for line in path.read_text().splitlines() if line and not line.startswith("#"))
    return {node.strip(): float(sec) for sec, node in rows}


def write(times: dict[str, float], note: str, path: Path = OUT) -> None:
    head = ["# seconds\tnode id: each test's setup + call + teardown, one process, file by file (written by",
            "# scripts/test_durations.py; tests/conftest.py marks those over SLOW_S as slow). " + note]
    body = [f"{sec:.2f}\t{node}" for node, sec in sorted(times.items(), key=lambda kv: (-kv[1], kv[0]))]
    path.write_text("\n".join(head + body) + "\n")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("files", nargs="*", type=Path, help="test files to (re)measure (default: all)")
    ap.add_argument("--from-junit", type=Path, help="a folder of junit XML files to read instead of running")
    ap.add_argument("--merge-run", type=Path, help="a pytest output with --durations lines to merge in (max)")
    ap.add_argument("--python", default=sys.executable)
    args = ap.parse_args()
    if args.merge_run:
        # a test that shares a module fixture or a cache with slow ones pays for it when they are left out
        # (the fast tier): such a run's times count too, the larger one kept
        old = read()
        new = durations_lines(args.merge_run.read_text())
        times = {**old, **{n: max(s, old.get(n, 0.0)) for n, s in new.items()}}
        head = OUT.read_text().splitlines()[1] if OUT.is_file() else ""
        write(times, head.split("). ", 1)[-1] + f" Merged: {len(new)} times of {args.merge_run.name}.")
        print(f"{len(new)} times merged -> {OUT.relative_to(REPO)}", file=sys.stderr)
        return 0
    if args.from_junit:
        times = {}
        for xml in sorted(args.from_junit.glob("*.xml")):
            times.update(junit_times(xml))
    else:
        files = [f.resolve() for f in args.files] or sorted((REPO / "tests").glob("test_*.py"))
        times = measure(files, args.python)
    if args.files:  # a partial run: keep the other files' numbers
        measured = {f.name for f in args.files}
        times = {**{n: s for n, s in read().items() if n.split("::")[0].rsplit("/", 1)[-1] not in measured},
                 **times}
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    write(times, f"Load average at the end: {load:.1f} on {os.cpu_count()} cores.")
    print(f"{len(times)} tests, {sum(times.values()):.0f} s in total -> {OUT.relative_to(REPO)}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
