"""Figure 2 of Pollard 1999, for walking: the fitted walking machine against its clip (matplotlib, Agg).

Panels: (left) leg length and desired leg length l_d(τ) over one stance, clip and machine; (middle) COM
height of the machine vs the clip over every complete step, phase-matched; (right) the total vertical
ground force over one stance: the clip's (eq. 1, mean of its stances), the machine's measured through the
same filter, and the machine's exact force, with the two peaks and the trough marked.
"""
from __future__ import annotations

import numpy as np

from ..io.atomic import atomic_write
from ..machine.walk_fit import stance_leg_length


def plot_walk_fit(res, path, title: str = "") -> None:
    """Write the three-panel figure of a WalkFitResult (froude.machine.walk_fit) to a PNG, atomically."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    m = res.machine
    T = m.time_unit
    stance_s = m.t_stance * T
    taus = np.linspace(0.0, 1.0, 101)
    l_m, ld_m = stance_leg_length(m, taus)

    fig, ax = plt.subplots(1, 3, figsize=(15, 4.6), constrained_layout=True)
    a0 = ax[0]
    a0.plot(res.t_leg * 1e3, res.l_leg, "k-", lw=2, label="clip: leg length l (COM → centre of pressure)")
    a0.plot(taus * stance_s * 1e3, l_m * m.l0, "C0-", lw=1.2, label="machine: l")
    a0.plot(taus * stance_s * 1e3, ld_m * m.l0, "C0:", lw=1.5, label="machine: desired length l_d (eq. 2)")
    for t in (m.t_double * T, m.t_step * T):
        a0.axvline(t * 1e3, color="0.8", lw=0.8, zorder=0)
    a0.set_xlabel("time since touchdown [ms]")
    a0.set_ylabel("leg length [m]")
    a0.set_title("one stance (grey: other foot lifts off, lands)")
    a0.legend(fontsize=8)

    a1 = ax[1]
    a1.plot(res.t_ref, res.h_ref, "k.", ms=3, label="clip COM height")
    a1.plot(res.t_ref, res.h_model, "C0.", ms=3, label="machine COM height")
    for td, lo, _ in res.steps:
        a1.axvline(td, color="0.8", lw=0.8, zorder=0)
        a1.axvline(lo, color="0.9", lw=0.8, ls="--", zorder=0)
    a1.set_xlabel("clip time [s] (complete steps)")
    a1.set_ylabel("COM height above ground [m]")
    a1.set_title(f"COM height (RMS {100 * m.quality['com_rms_m']:.2f} cm)")
    a1.legend(fontsize=8, loc="lower right")

    a2 = ax[2]
    t_ms = res.profile_tau * stance_s * 1e3
    a2.plot(t_ms, res.profile_ref, "k-", lw=2, label="clip (eq. 1, mean of its stances)")
    a2.plot(t_ms, res.profile_model, "C0-", lw=1.5, label="machine, through the clip's filter")
    a2.plot(t_ms, res.profile_unfiltered, "C0:", lw=1.2, label="machine, exact")
    for lm, style in ((m.reference["force_bw"], "ko"), (m.quality["force_bw"], "C0s")):
        for key in ("peak1", "trough", "peak2"):
            a2.plot(lm["tau_" + key] * stance_s * 1e3, lm[key], style, ms=6, mfc="none")
    a2.set_xlabel("time since touchdown [ms]")
    a2.set_ylabel("total vertical ground force [body weights]")
    a2.set_title("vertical force over a stance (marks: peaks, trough)")
    a2.legend(fontsize=8)
    fig.suptitle(f"{title or m.source}: walking machine fit  (K = {m.K:.1f}, θ0 = {np.degrees(m.theta0):.1f}°, "
                 f"{m.mean_speed_m_s:.2f} m/s, double support {100 * m.double_support_fraction:.0f}%)")

    try:
        atomic_write(path, lambda tmp: fig.savefig(tmp, dpi=110, format="png"))
    finally:
        plt.close(fig)
