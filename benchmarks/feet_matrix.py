"""Issue 30 acceptance 1: does each foot of every output rest in stance where the source's rests, scaled?

    python benchmarks/feet_matrix.py                       # every shared run and walk x 5 changes
    python benchmarks/feet_matrix.py --only 09_01,dataset-2_run_masculine_005 --all
    python benchmarks/feet_matrix.py --json out.json

The matrix: every run and walk of ../shared/data/mocap (CMU), bandai (dataset-1) and
bandai-locomotion/{runs,walks} (dataset-2), each scaled to the child, the troll, the giant and at x0.8 and
x1.2 of its own speed (``pipeline.scale`` with the CLI's defaults). Each clip is prepared once and each output
computed once; its physics report (found from the output alone: contacts, floor, per-foot rest heights) is
judged by ``check_bars`` and the stricter skate. Prints one row per output that misses a bar (every row with
``--all``): the largest rest-height error in % of L with its foot and marker, the stricter skate, the
penetration, the joint-jump ratio, then the counts per bar. Exit status 0 when every output meets every bar.
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
from pathlib import Path  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bars_matrix import judge  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
CMU = ("09_01", "09_02", "09_03", "09_04", "09_05", "09_06", "09_07", "09_08", "02_03", "02_01", "07_01")
#: (verb's character or None, speed factor)
CHANGES = (("child", 1.0), ("troll", 1.0), ("giant", 1.0), (None, 0.8), (None, 1.2))


def _data(kind: str) -> Path | None:
    for c in (REPO.parent / "shared" / "data" / kind, REPO.parent.parent / "shared" / "data" / kind,
              Path("/work/shared/data") / kind):
        if c.is_dir():
            return c
    return None


def clips(cmu=CMU, bandai_glob: str = "*.bvh", loco_subs=("runs", "walks")) -> list[tuple[str, Path]]:
    """(name, path) of every clip of the matrix that is present: the CMU clips named, the Bandai dataset-1
    clips matching bandai_glob, every clip of the bandai-locomotion sub-folders named."""
    out = []
    mocap, bandai, loco = _data("mocap"), _data("bandai"), _data("bandai-locomotion")
    if mocap:
        out += [(n, mocap / f"{n}.bvh") for n in cmu if (mocap / f"{n}.bvh").is_file()]
    if bandai:
        out += [(p.stem, p) for p in sorted(bandai.glob(bandai_glob))]
    if loco:
        for sub in loco_subs:
            out += [(p.stem, p) for p in sorted((loco / sub).glob("*.bvh"))]
    return out


def row_of(name: str, change: str, res) -> dict:
    rep = res.report
    names, texts, figs = judge(rep)
    w = rep.rest_height_worst
    err_pct = 100.0 * rep.rest_height_error_mm / (1000.0 * rep.leg_length_m)
    return {"clip": name, "change": change, "misses": names, "texts": texts, "rest_err_pct_L": err_pct,
            "rest_err_mm": rep.rest_height_error_mm, "worst": f"{w.get('foot', '-')} {w.get('marker', '-')}",
            "rest_mm": rep.rest_height_mm, "source_mm": rep.source_rest_height_mm, **figs}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", default="", help="comma-separated clip names (default: every clip)")
    ap.add_argument("--all", action="store_true", help="print every row, not only the misses")
    ap.add_argument("--json", metavar="OUT.json", help="also write every row as JSON")
    args = ap.parse_args(argv)
    from froude.errors import FroudeError
    from froude.flow import pipeline

    only = {s.strip() for s in args.only.split(",") if s.strip()}
    rows, t0 = [], time.perf_counter()
    print(f"{'clip':<30}{'change':<12}{'rest%L':>7}  {'worst':<12}{'skateF':>7}{'pen':>7}{'jump/r':>7}  misses")
    for name, path in clips():
        if only and name not in only:
            continue
        try:
            prep = pipeline.prepare(path)
        except FroudeError as e:
            rows.append({"clip": name, "change": "prepare", "misses": ["refused"], "texts": [str(e)]})
            print(f"{name:<30}{'prepare':<12} refused: {str(e).splitlines()[0][:80]}", flush=True)
            continue
        for character, factor in CHANGES:
            change = character or f"x{factor:g}"
            try:
                res = pipeline.scale(prep, character, speed=factor)
            except FroudeError as e:
                rows.append({"clip": name, "change": change, "misses": ["refused"], "texts": [str(e)]})
                print(f"{name:<30}{change:<12} refused: {str(e).splitlines()[0][:80]}", flush=True)
                continue
            r = row_of(name, change, res)
            rows.append(r)
            if args.all or r["misses"]:
                print(f"{name:<30}{change:<12}{r['rest_err_pct_L']:7.3f}  {r['worst']:<12}{r['skate_floor']:7.2f}"
                      f"{r['pen']:7.2f}{r['jump_ratio']:7.2f}  {', '.join(m[:40] for m in r['misses'])}",
                      flush=True)
    per_bar = Counter(("rest height" if "foot rests" in m else m[:40]) for r in rows for m in r["misses"])
    bad = sum(bool(r["misses"]) for r in rows)
    errs = sorted(r["rest_err_pct_L"] for r in rows if r.get("rest_err_pct_L") == r.get("rest_err_pct_L")
                  and "rest_err_pct_L" in r)
    print(f"{len(rows) - bad}/{len(rows)} outputs meet every bar; misses per bar: {dict(per_bar) or 'none'}")
    if errs:
        print(f"rest-height error over {len(errs)} outputs: median {errs[len(errs) // 2]:.3f} % L, "
              f"max {errs[-1]:.3f} % L, > 0.3 % L: {sum(e > 0.3 for e in errs)}")
    print(f"{len(rows)} rows in {time.perf_counter() - t0:.0f} s")
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1, default=str))
    return 0 if bad == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
