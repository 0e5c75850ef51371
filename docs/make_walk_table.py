"""Print the tables of docs/walking.md "Scaling walks" and "Walking at another speed", measured now.

Run:  python docs/make_walk_table.py   (needs the CMU and Bandai walks; FROUDE_MOCAP_DIR / FROUDE_BANDAI_DIR)
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from froude.flow import pipeline

MOCAP = Path(os.environ.get("FROUDE_MOCAP_DIR", "/work/shared/data/mocap"))
BANDAI = Path(os.environ.get("FROUDE_BANDAI_DIR", "/work/shared/data/bandai"))
WALKS = {"02_01": MOCAP / "02_01.bvh", "07_01": MOCAP / "07_01.bvh",
         "Bandai walk": BANDAI / "dataset-1_walk_normal_001.bvh"}


def scale_row(name: str, prep, character: str) -> str:
    r = pipeline.scale(prep, character).report
    c, w = r.extras["cadence"], r.extras["walking"]
    f, fe = r.step_frequency_hz, c["expected_step_frequency_hz"]
    u, uc = r.froude_U, prep.summary.froude
    fails = r.check_bars()
    return (f"| {name} | {character} | {f:.3f} / {fe:.3f} Hz ({100 * (f / fe - 1):+.1f} %) | "
            f"{u:.3f} / {uc:.3f} ({100 * (u / uc - 1):+.1f} %) | {100 * w['double_support_fraction']:.1f} / "
            f"{100 * w['clip']['double_support_fraction']:.1f} % | {r.foot_skate_mm:.1f} | {r.penetration_mm:.1f} | "
            f"{r.max_joint_jump_deg:.1f} / {1.5 * r.reference_max_joint_jump_deg:.1f} | "
            f"{c['naive_step_frequency_hz']:.3f} Hz ({100 * c['naive_error']:+.0f} %) | "
            f"{'all met' if not fails else '; '.join(fails)} |")


def main() -> None:
    for name, path in WALKS.items():
        prep = pipeline.prepare(path)
        for character in ("child", "troll", "giant"):
            print(scale_row(name, prep, character), flush=True)
        if name != "02_01":
            continue
        for s in (0.8, 1.2):
            r = pipeline.scale(prep, None, speed=s).report
            print(f"scale x{s}: {r.mean_speed_m_s:.3f} m/s, {r.step_frequency_hz:.3f} Hz, skate {r.foot_skate_mm:.2f} "
                  f"mm, penetration {r.penetration_mm:.2f} mm, bars: {r.check_bars() or 'all met'}", flush=True)
        for goal in (0.6, 1.3):
            r = pipeline.accelerate(prep, None, to_factor=goal, steps=8).report
            v = np.round(r.extras["plan"]["apex_speed_m_s"], 2).tolist()
            print(f"accelerate to x{goal}: step speeds {v} m/s, skate {r.foot_skate_mm:.2f} mm, bars: "
                  f"{r.check_bars() or 'all met'}", flush=True)


if __name__ == "__main__":
    main()
