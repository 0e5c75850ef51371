"""Where a walk's double-support force maxima come from: the legs' own inertia (docs/walking.md, Limitations).

The clip's vertical force (eq. 1) is the whole body's: f = Σ_i m_i (a_i + g) over de Leva's segments. It
splits exactly into the legs' part (thighs, shanks, feet: their weight and their own vertical
acceleration) and the rest's (head, trunk, arms). The machine is a point mass on *massless* spring legs:
it has no force from a leg swinging, landing or lifting. This script measures, over the clip's stance (the
same stances, filter and landmark rule as the fit), the clip's force, the legs' inertial part
Σ_legs m_i a_i / (M g), the force without it (the legs' weight kept), and the fitted machine's; and prints
the landmark times of each, as shares of the clip's step.

Run:  python docs/make_walk_force_parts.py [--plot docs/images/walk_force_parts.png]
(needs the CMU and Bandai walks; FROUDE_MOCAP_DIR / FROUDE_BANDAI_DIR)
"""
from __future__ import annotations

import argparse
import os
from pathlib import Path

import numpy as np

from froude.core.constants import GRAVITY, UP_AXIS
from froude.flow import pipeline
from froude.machine.forces import smooth_com
from froude.machine.walk_fit import force_landmarks

MOCAP = Path(os.environ.get("FROUDE_MOCAP_DIR", "/work/shared/data/mocap"))
BANDAI = Path(os.environ.get("FROUDE_BANDAI_DIR", "/work/shared/data/bandai"))
WALKS = {"CMU 02_01": MOCAP / "02_01.bvh", "CMU 07_01": MOCAP / "07_01.bvh",
         "Bandai walk": BANDAI / "dataset-1_walk_normal_001.bvh"}
LEG_SEGMENTS = ("thigh", "shank", "foot")


def force_parts(prep) -> tuple[np.ndarray, np.ndarray]:
    """(F,) vertical force of the legs' own acceleration and (F,) of the rest's, [BW] (eq. 1's filter).

    Their sum + 1 is the clip's vertical force f / (M g); the legs' weight is in the 1.
    """
    body, motion = prep.body, prep.motion
    seg = body.segment_points(*body.world(motion))  # (F, S, 3) [m]
    legs = np.array([any(k in n for k in LEG_SEGMENTS) for n in body.seg_names])

    def accel_bw(mask):
        part = np.einsum("fsa,s->fa", seg[:, mask], body.seg_mass[mask]) / body.total_mass  # mass-weighted [m]
        return smooth_com(part, motion.frame_time, 8.0)[2][:, UP_AXIS] / GRAVITY

    return accel_bw(legs), accel_bw(~legs)


def stance_profiles(prep, tau):
    """Mean over the fit's complete stances of (total, legs' inertia, without it) at stance phases tau."""
    fit = prep.fit
    f_legs, f_rest = force_parts(prep)
    times = np.arange(prep.motion.n_frames) * prep.motion.frame_time
    full = [sg for sg in fit.stances if not sg.partial]

    def mean_profile(f):
        return np.mean([np.interp(sg.t_touchdown + tau * sg.duration, times, f) for sg in full], axis=0)

    legs = mean_profile(f_legs)
    rest = mean_profile(f_rest)
    return 1.0 + legs + rest, legs, 1.0 + rest


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--plot", help="write the figure here (PNG)")
    args = ap.parse_args()
    tau = np.linspace(0.0, 1.0, 51)
    rows, panels = [], []
    for name, path in WALKS.items():
        prep = pipeline.prepare(path)
        m, fit = prep.machine, prep.fit
        ref = m.reference
        stance, step, ds = ref["stance_time_s"], ref["step_time_s"], ref["double_support_s"]
        total, legs, without = stance_profiles(prep, tau)
        assert np.allclose(total, fit.profile_ref, atol=1e-9), "not the fit's stances or filter"
        lm_m = m.quality["force_bw"]
        t_m = m.t_stance * m.time_unit
        for label, prof in (("clip", total), ("clip without the legs' inertia", without)):
            lm = force_landmarks(tau, prof, ds / stance)
            err = [100 * (lm_m[k] * t_m - lm[k] * stance) / step for k in ("tau_peak1", "tau_trough", "tau_peak2")]
            t_ms = [1000 * lm[k] * stance for k in ("tau_peak1", "tau_trough", "tau_peak2")]
            rows.append(f"| {name} | {label} | {t_ms[0]:.0f} / {t_ms[1]:.0f} / {t_ms[2]:.0f} ms | "
                        f"{lm['peak1']:.2f} / {lm['trough']:.2f} / {lm['peak2']:.2f} BW | "
                        f"{err[0]:+.1f} / {err[1]:+.1f} / {err[2]:+.1f} % |")
        panels.append((name, tau * stance, total, legs, without, fit.profile_model, t_m, ds, step))
    print("| walk | force | peak / trough / peak [ms after touchdown] | heights | machine's timing error "
          "[% of a step] |")
    print("|---|---|---|---|---|")
    print("\n".join(rows))
    if args.plot:
        plot(panels, args.plot)


def plot(panels, out) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from froude.io.atomic import atomic_write

    fig, axes = plt.subplots(1, len(panels), figsize=(4.2 * len(panels), 3.6), sharey=True)
    for ax, (name, t, total, legs, without, model, t_m, ds, step) in zip(axes, panels):
        ms = 1000 * t
        ax.plot(ms, total, "k", lw=2, label="clip (eq. 1)")
        ax.plot(ms, without, color="0.5", ls="--", label="clip without the legs' inertia")
        ax.plot(ms, legs, color="tab:blue", lw=1, label="legs' inertia")
        ax.plot(1000 * np.linspace(0, t_m, model.size), model, color="tab:red", label="machine (same filter)")
        for x in (ds, step):
            ax.axvline(1000 * x, color="0.8", lw=0.8)
        ax.set_title(name)
        ax.set_xlabel("time since touchdown [ms]")
    axes[0].set_ylabel("vertical force [BW]")
    axes[0].legend(fontsize=7, loc="center left")
    fig.tight_layout()
    atomic_write(out, lambda tmp: fig.savefig(tmp, dpi=110, format="png"))
    plt.close(fig)


if __name__ == "__main__":
    main()
