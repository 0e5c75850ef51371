"""Issue 28 acceptance 1 and 2 on every shared turning clip: scale to child, giant, speed x0.8 and x1.2.

    PYTHONPATH=src python benchmarks/turns_matrix.py                       # every turning clip (35 s here)
    PYTHONPATH=src python benchmarks/turns_matrix.py --only 16_51,left_normal_001 --json out.json

The clips: ../shared/data/bandai-locomotion/turns/dataset-2_walk-turn-* and ../shared/data/cmu-turns (found as
tests/conftest.py finds them). Each output is ``pipeline.scale(prep, X, strides=ceil(clip steps / 2) + 1)``
(the whole turn and a stride on), its figures from its physics report (``extras["path_vs_clip"]``, measured
from the output motion alone). Per output, one row against acceptance 1 (bars in brackets):
- dH: total heading change, output minus intended [deg] (3);
- dH/step: largest difference of a step's heading change from the clip's path over the same stretch
  (the output step's arc length / L on the clip's path) [deg] (3);
- r/L: largest difference of a step's radius in leg lengths from the clip path's over the same stretch, over
  the stretches turning 10 deg or more [%] (5, pure scaling). (The report's figure, the median radius of each
  path's turning steps, compares steps placed differently along the path: the machine's first touchdown is
  not the clip's; it is kept in the JSON as r_median_pct.)
- face: facing vs travel, output minus clip [deg] (5);
- v: speed along the path over the clip's x sqrt(L) x the speed factor - 1 [%] (2);
- f: cadence over the clip's / sqrt(L) - 1 [%] (2, pure scaling; a speed change follows the speed law);
- lean: largest difference of a turning step's lean from the one asked [deg] (2 pure scaling, 3 speed change);
- bars: the physics bars missed (``Report.check_bars``, the path, lean and force bars and the stricter skate
  ``foot_skate_floor_mm`` <= 5 mm among them).
Prints the rows, how many outputs meet every point, and per point how many miss it (and miss it alone).
"""
from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_v] = "1"

import argparse  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "tests"))

CASES = (("child", {"character": "child"}), ("giant", {"character": "giant"}),
         ("x0.8", {"speed": 0.8}), ("x1.2", {"speed": 1.2}))
SKATE_FLOOR_MM = 5.0


def _clips() -> list[str]:
    from conftest import CMU_TURN_CLIPS, LOCO_TURNS

    return [n for n in LOCO_TURNS if "walk-turn" in n] + list(CMU_TURN_CLIPS)


#: Steps whose stretch of the clip's path turns less than this [deg] have no radius per step worth comparing
#: (5 % of the radius of a 10 deg step is 0.5 deg of turn).
RADIUS_STEP_MIN_DEG = 10.0


def _per_step_misses(clip_path, out_path, L: float) -> tuple[float, float | None]:
    """Per output step, against the clip's path over the same stretch (the step's arc length / L; steps past
    the clip's end left out): the largest |heading change difference| [deg] and the largest |radius ratio - 1|
    [%] in leg lengths (clip turn / output turn, the arc lengths being L apart) over the stretches turning
    >= RADIUS_STEP_MIN_DEG (None: none does)."""
    frames_o = np.arange(out_path.arc_length_m.size)
    worst_h, worst_r = 0.0, None
    for st in out_path.steps:
        a0, a1 = (float(np.interp(t / out_path.frame_time, frames_o, out_path.arc_length_m)) / L
                  for t in (st.t0_s, st.t1_s))
        if a1 > clip_path.arc_length_m[-1]:
            continue  # past the clip's end the output runs straight on
        h0, h1 = (float(np.interp(a, clip_path.arc_length_m, clip_path.heading_rad)) for a in (a0, a1))
        worst_h = max(worst_h, abs(math.degrees(st.heading_change_rad - (h1 - h0))))
        if abs(math.degrees(h1 - h0)) >= RADIUS_STEP_MIN_DEG:
            r = 100 * abs((h1 - h0) / st.heading_change_rad - 1)
            worst_r = r if worst_r is None else max(worst_r, r)
    return worst_h, worst_r


def row(prep, label: str, kw: dict) -> dict:
    from froude.body.gait import detect_gait
    from froude.body.path import take_path
    from froude.flow import pipeline

    strides = math.ceil(prep.path.n_steps / 2) + 1
    res = pipeline.scale(prep, strides=strides, **kw)
    L = res.retarget.L
    rep = res.report
    cmp = rep.extras["path_vs_clip"]
    body = res.retarget.body
    com, markers = body.com_and_markers(res.motion)
    out_path = take_path(res.motion, body, com, detect_gait(res.motion, body, markers, com))
    speed = kw.get("speed", 1.0)
    step_h, step_r = _per_step_misses(prep.path, out_path, L)
    h, f, r, v = (cmp[k] for k in ("heading_change_deg", "facing_vs_travel_deg", "radius_per_turning_step_L",
                                   "path_speed_m_s"))
    pure = speed == 1.0
    leans = cmp["lean_per_turning_step"]
    skate = rep.foot_skate_floor_mm
    out = {
        "dH": h["output"] - h["intended"],
        "dH_step": step_h,
        "r_pct": step_r if pure else None,
        "r_median_pct": 100 * (r["output"] / r["clip"] - 1) if r["output"] and r["clip"] else None,
        "face": f["output"] - f["clip"],
        "v_pct": 100 * (v["output"] / (v["clip"] * math.sqrt(L) * speed) - 1),
        "f_pct": 100 * (rep.step_frequency_hz / (prep.summary.step_frequency / math.sqrt(L)) - 1) if pure else None,
        "lean": max((abs(x["lean_deg"] - x["wanted_deg"]) for x in leans), default=None),
        "lean_tol": 2.0 if pure else 3.0,
        "lean_in": cmp["lean_into_turn_deg"],
        "skate_floor_mm": skate,
        "bars": rep.check_bars(),
    }
    out["missed"] = [name for name, met in _points(out).items() if not met]
    out["ok"] = not out["missed"]
    return out


def _points(r: dict) -> dict[str, bool]:
    """Each point of acceptance 1 and 2 (the module's list) for one row: met or not."""
    return {"heading": abs(r["dH"]) <= 3, "heading/step": r["dH_step"] <= 3,
            "radius/step": r["r_pct"] is None or abs(r["r_pct"]) <= 5, "facing": abs(r["face"]) <= 5,
            "speed": abs(r["v_pct"]) <= 2, "cadence": r["f_pct"] is None or abs(r["f_pct"]) <= 2,
            "lean": r["lean"] is None or r["lean"] <= r["lean_tol"], "bars": not r["bars"]}


def _breakdown(rows: dict) -> str:
    """Per point: how many of the outputs made miss it, and how many miss it alone."""
    made = [r for r in rows.values() if "missed" in r]
    lines = [f"per point, of {len(made)} outputs made: missed (missed alone)"]
    for name in _points(made[0]) if made else ():
        n = sum(name in r["missed"] for r in made)
        alone = sum(r["missed"] == [name] for r in made)
        lines.append(f"  {name:13s} {n:3d} ({alone})")
    return "\n".join(lines)


def _fmt(v, spec="+.1f"):
    return "   -" if v is None else format(v, spec)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", help="comma-separated substrings of clip names")
    ap.add_argument("--json", help="write every row here")
    args = ap.parse_args(argv)
    from froude.errors import FroudeError
    from froude.flow import pipeline

    from conftest import clip

    names = _clips()
    if args.only:
        names = [n for n in names if any(s in n for s in args.only.split(","))]
    rows, n_ok, n_out = {}, 0, 0
    t_all = time.time()
    print(f"{'clip':44s} {'out':6s} {'dH':>5s} {'dHst':>5s} {'r/L%':>5s} {'face':>5s} {'v%':>5s} {'f%':>5s} "
          f"{'lean':>5s}  bars missed")
    for name in names:
        t0 = time.time()
        short = name.split("/")[-1].replace("dataset-2_walk-turn-", "")
        try:
            prep = pipeline.prepare(clip(name))
        except FroudeError as e:
            print(f"{short:44s} refused: {str(e).splitlines()[0][:150]}")
            rows[name] = {"refused": str(e)}
            n_out += len(CASES)
            continue
        for label, kw in CASES:
            n_out += 1
            try:
                r = row(prep, label, kw)
            except FroudeError as e:
                print(f"{short:44s} {label:6s} refused: {str(e).splitlines()[0][:150]}")
                rows[f"{name} {label}"] = {"refused": str(e)}
                continue
            n_ok += r["ok"]
            rows[f"{name} {label}"] = r
            bars = "; ".join(b[:90] for b in r["bars"]) or "(a path or lean point)"
            print(f"{short:44s} {label:6s} {_fmt(r['dH']):>5s} {_fmt(r['dH_step'], '.1f'):>5s} "
                  f"{_fmt(r['r_pct']):>5s} {_fmt(r['face']):>5s} {_fmt(r['v_pct']):>5s} {_fmt(r['f_pct']):>5s} "
                  f"{_fmt(r['lean'], '.1f'):>5s}  {'OK' if r['ok'] else bars}", flush=True)
        print(f"   ({time.time() - t0:.0f} s)", flush=True)
    print(f"\n{n_ok} of {n_out} outputs meet every point of acceptance 1 and 2 ({time.time() - t_all:.0f} s)")
    print(_breakdown(rows))
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1, default=str))
    return 0 if n_ok == n_out else 1


if __name__ == "__main__":
    sys.exit(main())
