"""Which outputs of the issue 12/13 test matrices meet which physics bars (measured on the real clips).

    python benchmarks/bars_matrix.py                 # all three matrices (a few minutes on one core)
    python benchmarks/bars_matrix.py --matrix 12     # issue 12 acceptance 2 only
    python benchmarks/bars_matrix.py --matrix 13 --only 09_01,dataset-1_run_tired_001
    python benchmarks/bars_matrix.py --matrix speeds --json out.json
    python benchmarks/bars_matrix.py --matrix 12 --render /tmp/renders   # also `froude render` each output

The matrices (the clips come from ../shared/data, found as tests/conftest.py finds them):
- ``12``: issue 12 acceptance 2: every Bandai run as delivered (30 Hz, centimetres, folded rest pose):
  scale child / troll / giant / speed 0.7 / speed 1.2, accelerate 0.5x / 1.3x, each at the output's own
  rate (the input's 30 Hz) and at --fps 120; the walk too, through the walking machine (issue 17; issue 12
  had it refused in one line).
- ``13``: issue 13 acceptance 3: 9 CMU runs x 4 presets (child, troll, giant, small) x speeds 0.7 / 1.0 /
  1.2 / 1.5, the Bandai runs x 3 presets (child, troll, giant), and 0.5x / 1.3x accelerations of every
  run, all at 120 Hz; every physics bar, the stricter skate (``foot_skate_floor_mm`` <= 5 mm) among them.
- ``speeds``: issue 13 acceptance 4: --speed 0.5 / 0.7 / 1.5 / 1.8 / 2.0 on every shared run: the output
  must meet every bar (joint jump <= 1.5 x the reference's) or be refused in one line with the reachable
  range (``speed_range.reachable_speed_range``), which is what ``froude scale`` does.

Each output goes through the same API the CLI calls (``pipeline.prepare`` once per clip, then ``scale`` /
``accelerate`` with the CLI's defaults: 4 strides, 8 steps). Prints one row per output that misses a bar
(or every row with ``--all``), the counts per matrix and, per bar, how many outputs miss it.
Exit status 0 when every output meets every bar (or is refused with its range, for ``speeds``), else 1.
"""
from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_v] = "1"

import argparse  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from collections import Counter  # noqa: E402
from dataclasses import dataclass, field  # noqa: E402
from pathlib import Path  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
CMU_RUNS = ("09_01", "09_02", "09_03", "09_04", "09_05", "09_06", "09_07", "09_08", "02_03")
BANDAI_RUNS = ("dataset-1_dash_active_001", "dataset-1_dash_feminine_001", "dataset-1_dash_normal_001",
               "dataset-1_dash_old_001", "dataset-1_run_tired_001")
BANDAI_WALK = "dataset-1_walk_normal_001"
#: issue 12 acceptance 2's changes: (verb, character or None, factor)
CHANGES_12 = (("scale", "child", 1.0), ("scale", "troll", 1.0), ("scale", "giant", 1.0), ("scale", None, 0.7),
              ("scale", None, 1.2), ("accelerate", None, 0.5), ("accelerate", None, 1.3))
PRESETS_13 = ("child", "troll", "giant", "small")
SPEEDS_13 = (0.7, 1.0, 1.2, 1.5)
SPEEDS_134 = (0.5, 0.7, 1.5, 1.8, 2.0)
#: the stricter skate bar [mm] (issue 13 acceptance 3), applied here whether or not the report's own
#: check_bars has it yet, so that before/after figures are comparable
SKATE_FLOOR_MM = 5.0


def _data_dir(kind: str, probe: str) -> Path | None:
    for c in (os.environ.get(f"FROUDE_{kind.upper()}_DIR"), REPO.parent / "shared" / "data" / kind,
              REPO.parent.parent / "shared" / "data" / kind, Path("/work/shared/data") / kind):
        if c and Path(c, probe).is_file():
            return Path(c)
    return None


def clip_path(name: str) -> Path:
    kind, probe = ("bandai", "dataset-1_dash_normal_001.bvh") if name.startswith("dataset-") else ("mocap", "09_01.bvh")
    d = _data_dir(kind, probe)
    if d is None:
        sys.exit(f"bars_matrix: {kind} clips not found: set FROUDE_{kind.upper()}_DIR")
    return d / f"{name}.bvh"


@dataclass
class Row:
    matrix: str
    clip: str
    change: str
    fps: str
    status: str  # "ok", "misses", "refused", "error"
    misses: list = field(default_factory=list)  # short bar names
    detail: str = ""
    figures: dict = field(default_factory=dict)

    @property
    def good(self) -> bool:
        return self.status == "ok" or (self.status == "refused" and self.matrix == "speeds")


#: short names of the bars, by the start of check_bars' text (the longest match wins)
BAR_NAMES = {"flight gravity": "gravity", "COM tracking RMS": "COM rms", "COM tracking max": "COM max",
             "foot skate": "skate", "foot skate (ball and tip": "skate floor", "ground penetration": "penetration",
             "joint jump": "joint jump", "left foot rests": "rest height", "right foot rests": "rest height",
             "step of": "step length"}


def bar_name(text: str) -> str:
    """'foot skate 5.20 mm (<= 5)' -> 'skate' (BAR_NAMES; the text itself when no name fits)."""
    hits = [k for k in BAR_NAMES if text.startswith(k)]
    return BAR_NAMES[max(hits, key=len)] if hits else text


def judge(rep) -> tuple[list[str], list[str], dict]:
    """(short names of the bars missed, their texts, the figures) of one report, the stricter skate included."""
    texts = list(rep.check_bars())
    stricter_shown = any(t.startswith("foot skate (ball and tip") for t in texts)
    if not stricter_shown and not rep.foot_skate_floor_mm <= SKATE_FLOOR_MM:
        texts.append(f"foot skate (ball and tip near the floor) {rep.foot_skate_floor_mm:.2f} mm (<= 5)")
    names = [bar_name(t) for t in texts]
    jr = rep.max_joint_jump_deg / rep.reference_max_joint_jump_deg if rep.reference_max_joint_jump_deg else float("nan")
    figs = {"skate": rep.foot_skate_mm, "skate_floor": rep.foot_skate_floor_mm, "pen": rep.penetration_mm,
            "jump_ratio": jr, "g": rep.flight_gravity_m_s2, "com_max": rep.com_tracking_max_mm,
            "speed": rep.mean_speed_m_s}
    return names, texts, figs


class Clips:
    """Each clip prepared once (fit + cycle), or the one-line reason it was refused."""

    def __init__(self):
        self._prep = {}

    def get(self, name: str):
        if name not in self._prep:
            from froude.errors import FroudeError
            from froude.flow import pipeline

            try:
                self._prep[name] = pipeline.prepare(clip_path(name))
            except FroudeError as e:
                self._prep[name] = e
        return self._prep[name]


def run_one(clips: Clips, matrix: str, name: str, verb: str, character, factor: float, fps, render_dir=None) -> Row:
    from froude.errors import FroudeError
    from froude.flow import pipeline

    change = (f"{verb} {factor:g}x" if verb == "accelerate" else f"{character or 'same'} x{factor:g}")
    row = Row(matrix, name, change, "own" if fps is None else f"{fps:g}", "error")
    prep = clips.get(name)
    if isinstance(prep, Exception):  # the clip refused before any output (one line) or a failure
        row.status = "refused" if "\n" not in str(prep) else "error"
        row.detail = f"prepare: {prep}"
        return row
    try:
        if verb == "accelerate":
            res = pipeline.accelerate(prep, character, to_factor=factor, fps=fps)
        else:
            res = pipeline.scale(prep, character, speed=factor, fps=fps)
    except FroudeError as e:
        row.status, row.detail = "refused", str(e).splitlines()[0]
        return row
    names, texts, row.figures = judge(res.report)
    row.status = "misses" if names else "ok"
    row.misses, row.detail = names, "; ".join(texts)
    if render_dir is not None:
        _render(res, Path(render_dir) / f"{name}_{change.replace(' ', '_')}_{row.fps}")
    return row


def _render(res, stem: Path) -> None:
    """Write the output and ``froude render`` it (a filmstrip PNG), as a user would."""
    import subprocess

    from froude.flow import pipeline

    stem.parent.mkdir(parents=True, exist_ok=True)
    bvh = stem.with_suffix(".bvh")
    pipeline.write_result(res, bvh)
    subprocess.run([sys.executable, "-m", "froude", "render", str(bvh), "-o", str(stem.with_suffix(".png")), "-q"],
                   check=True)


def matrix_12(clips: Clips, only, render_dir=None) -> list[Row]:
    rows = []
    for name in BANDAI_RUNS:
        if only and name not in only:
            continue
        prep = clips.get(name)
        if isinstance(prep, Exception):  # refused before any output
            one_line = "\n" not in str(prep)
            rows.append(Row("12", name, "every change", "-", "refused" if one_line else "error",
                            [] if one_line else ["refusal not one line"], str(prep)))
            continue
        for verb, character, factor in CHANGES_12:
            for fps in (None, 120.0):
                rows.append(run_one(clips, "12", name, verb, character, factor, fps, render_dir))
    if not only or BANDAI_WALK in only:
        # Issue 12 had the walk refused in one line; since issue 17 it goes through the walking machine, so
        # it gets the runs' changes and bars, and a row that misses if another machine (or none) took it.
        walk = clips.get(BANDAI_WALK)
        order = getattr(getattr(walk, "cycle", None), "order", None)
        if order != "walking":
            rows.append(Row("12", BANDAI_WALK, "walking machine", "-", "misses", ["walk not walking machine"],
                            str(walk)[:120] if isinstance(walk, Exception) else f"cycle order {order}"))
        else:
            for verb, character, factor in CHANGES_12:
                for fps in (None, 120.0):
                    rows.append(run_one(clips, "12", BANDAI_WALK, verb, character, factor, fps, render_dir))
    return rows


def matrix_13(clips: Clips, only) -> list[Row]:
    rows = []
    for name in CMU_RUNS + BANDAI_RUNS:
        if only and name not in only:
            continue
        bandai = name.startswith("dataset-")
        for character in (PRESETS_13[:3] if bandai else PRESETS_13):
            for s in ((1.0,) if bandai else SPEEDS_13):
                rows.append(run_one(clips, "13", name, "scale", character, s, 120.0))
        for f in (0.5, 1.3):
            rows.append(run_one(clips, "13", name, "accelerate", None, f, 120.0))
    return rows


def matrix_speeds(clips: Clips, only) -> list[Row]:
    """Acceptance 13.4 as ``froude scale --speed S`` behaves: an output inside the reachable range must meet
    every bar; outside it the CLI refuses with the range (a refusal inside the range is a miss)."""
    rows = []
    for name in CMU_RUNS + BANDAI_RUNS:
        if only and name not in only:
            continue
        prep = clips.get(name)
        if isinstance(prep, Exception):  # refused in one line before any output: no speed is offered
            one_line = "\n" not in str(prep)
            rows.append(Row("speeds", name, "every speed", "own", "refused" if one_line else "error",
                            [] if one_line else ["refusal not one line"], str(prep)))
            continue
        from froude.flow.speed_range import reachable_speed_range

        rng = reachable_speed_range(prep)
        for s in SPEEDS_134:
            row = run_one(clips, "speeds", name, "scale", None, s, None)
            inside = not rng.empty and rng.lo - 1e-9 <= s <= rng.hi + 1e-9
            row.figures["range"] = rng.describe()
            if row.status in ("misses", "refused") and not inside:
                row.status, row.misses = "refused", []  # the CLI refuses: exit 1/2, with the range
                row.detail = f"refused with the reachable range {rng.describe()} ({row.detail})"
            elif row.status == "refused" and inside:
                row.status, row.misses = "misses", ["refused inside the reachable range"]
            elif row.status == "ok" and not inside:
                row.detail = f"meets every bar outside the reported range {rng.describe()}"
            rows.append(row)
    return rows


def _fmt(v) -> str:
    return "   -  " if v is None or v != v else f"{v:6.2f}"


def print_table(rows: list[Row], every: bool) -> None:
    print(f"{'matrix':<7}{'clip':<28}{'change':<22}{'fps':<5}{'status':<9}{'skateF':>7}{'skate':>7}{'pen':>7}"
          f"{'jump/r':>7}{'g':>7}  misses")
    for r in rows:
        if every or not r.good:
            f = r.figures
            print(f"{r.matrix:<7}{r.clip:<28}{r.change:<22}{r.fps:<5}{r.status:<9}{_fmt(f.get('skate_floor'))} "
                  f"{_fmt(f.get('skate'))} {_fmt(f.get('pen'))} {_fmt(f.get('jump_ratio'))} {_fmt(f.get('g'))}  "
                  f"{', '.join(r.misses) or r.detail[:90]}")


def print_counts(rows: list[Row]) -> None:
    for m in sorted({r.matrix for r in rows}):
        rs = [r for r in rows if r.matrix == m]
        status = Counter(r.status for r in rs)
        per_bar = Counter(b for r in rs for b in r.misses)
        good = sum(r.good for r in rs)
        print(f"matrix {m}: {good}/{len(rs)} good ({dict(status)}); misses per bar: {dict(per_bar) or 'none'}")
        if m == "13":
            sk = [r.figures["skate_floor"] for r in rs if "skate_floor" in r.figures]
            if sk:
                import numpy as np

                print(f"   stricter skate over {len(sk)} outputs: median {np.median(sk):.2f} mm, max {max(sk):.2f} mm, "
                      f"<= 5 mm: {sum(s <= SKATE_FLOOR_MM for s in sk)}")
        if m == "speeds":
            ranges = {r.clip: r.figures.get("range") for r in rs if r.figures.get("range")}
            for c, d in ranges.items():
                print(f"   {c:<28} reachable {d}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--matrix", choices=("12", "13", "speeds", "all"), default="all")
    ap.add_argument("--only", default="", help="comma-separated clip names (default: every clip of the matrix)")
    ap.add_argument("--all", action="store_true", help="print every row, not only the misses")
    ap.add_argument("--json", metavar="OUT.json", help="also write every row as JSON")
    ap.add_argument("--render", metavar="DIR", help="matrix 12: write each output and `froude render` it into DIR")
    args = ap.parse_args(argv)
    only = {s.strip() for s in args.only.split(",") if s.strip()}
    clips = Clips()
    t0 = time.perf_counter()
    rows = []
    if args.matrix in ("12", "all"):
        rows += matrix_12(clips, only, args.render)
    if args.matrix in ("13", "all"):
        rows += matrix_13(clips, only)
    if args.matrix in ("speeds", "all"):
        rows += matrix_speeds(clips, only)
    print_table(rows, args.all)
    print_counts(rows)
    print(f"{len(rows)} rows in {time.perf_counter() - t0:.0f} s")
    if args.json:
        Path(args.json).write_text(json.dumps([r.__dict__ for r in rows], indent=1, default=str))
    return 0 if all(r.good for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
