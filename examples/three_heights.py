"""One run, three body heights: the centre of mass and the ground force of each, plotted.

    python examples/three_heights.py [CLIP.bvh] [-o OUTDIR]

Scales the clip (default: froude's embedded CMU run) to characters 1.2 m, 1.7 m and 2.2 m tall at their
dynamically similar speeds (times x sqrt(L), speeds x sqrt(L): a child takes quicker, shorter steps),
writes each as GLB with its per-frame data (CSV), and plots COM height and vertical ground force
(the simple machine's, in body weights) against time in OUTDIR/three_heights.png.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import froude

HEIGHTS_M = (1.2, 1.7, 2.2)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("clip", nargs="?", default=str(froude.sample_path()), help="a running clip (BVH)")
    ap.add_argument("-o", "--outdir", default="three_heights", help="output folder (default: three_heights)")
    args = ap.parse_args(argv)
    out = Path(args.outdir)

    fitted = froude.fit(args.clip)  # fit the simple machine once, reuse it for every height
    results = {h: froude.scale(fitted, height=h, strides=3) for h in HEIGHTS_M}

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax_com, ax_f) = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
    print(f"{'height':>8} {'speed':>10} {'step freq':>10} {'COM range':>10} {'peak force':>10}")
    for h, r in results.items():
        weight_n = r.body.total_mass * 9.81
        ax_com.plot(r.times, r.com[:, 1], label=f"{h:.1f} m")
        ax_f.plot(r.times, r.ground_force[:, 1] / weight_n, label=f"{h:.1f} m")
        r.save(out / f"h{h:.1f}.glb")
        r.save_data(out / f"h{h:.1f}.csv")
        print(f"{h:>6.1f} m {r.report.mean_speed_m_s:>6.2f} m/s {r.report.step_frequency_hz:>7.2f} Hz "
              f"{100 * (r.com[:, 1].max() - r.com[:, 1].min()):>7.1f} cm "
              f"{r.ground_force[:, 1].max() / weight_n:>7.2f} BW")
    ax_com.set_ylabel("COM height [m]")
    ax_f.set_ylabel("vertical ground force [BW]")
    ax_f.set_xlabel("time [s]")
    ax_com.legend(title="character height")
    ax_com.set_title("One run at three heights (dynamic similarity)")
    fig.tight_layout()
    png = out / "three_heights.png"
    out.mkdir(parents=True, exist_ok=True)
    fig.savefig(png, dpi=100)
    print(f"wrote {png}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
