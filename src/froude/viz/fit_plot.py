"""Figure 2 of Pollard 1999 for a fitted clip (matplotlib, Agg; imported lazily by the CLI).

Panels: (left) desired leg length l_d(τ) vs actual leg length over one stance; (middle) COM height of the
simple machine vs the reference over one stride (phase-matched, above the ground under the stance);
(right) measured leg force vs the eq. 2 model over the same stance.
"""
from __future__ import annotations

import numpy as np

from ..io.atomic import atomic_write


def plot_fit(res, path, title: str = "") -> None:
    """Write the three-panel figure of a FitResult (froude.machine.fit) to a PNG, atomically."""

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    m = res.machine
    mg = m.mass * m.g
    T = m.time_unit
    # The stance shown: the first fitted stance of the stride used for the cycle comparison, else the first
    # fitted one; a stance that is no spring has no fit of its own, and where no stance has one (the pooled fit
    # can hold where each alone does not) the first full stance is drawn with the pooled fit.
    fitted = [k for k, ft in enumerate(res.stance_fits) if ft is not None] or \
        [k for k, s in enumerate(res.stances) if not s.partial]
    i = next((k for k in fitted if res.stances[k].t_touchdown >= res.stride_events[0] - 1e-9), fitted[0])
    sg, ft = res.stances[i], res.stance_fits[i] or res.pooled
    tau = sg.tau
    t_ms = tau * sg.duration * 1e3
    taus = np.linspace(0.0, 1.0, 101)

    # Machine stance from the dense one-step trajectory (dimensionless → SI).
    tr = res.traj
    st = tr.stance
    t_m = (tr.t[st] - tr.t_touchdown[0]) * T
    rel = tr.pos[st] - np.array([tr.contact_x[0], 0.0])
    l_m = np.linalg.norm(rel, axis=1) * m.l0
    f_m = np.linalg.norm(tr.force[st], axis=1)

    fig, ax = plt.subplots(1, 3, figsize=(15, 4.6), constrained_layout=True)
    a0 = ax[0]
    a0.plot(t_ms, sg.l, "k-", lw=2, label="actual leg length l (reference)")
    a0.plot(taus * sg.duration * 1e3, ft.desired_length(taus) * sg.l0, "k:", lw=2,
            label="desired leg length l_d (stance fit, eq. 2)")
    a0.plot(t_m * 1e3, l_m, "C0-", lw=1.2, alpha=0.8, label="machine cycle: l")
    a0.plot(taus * m.T_c * T * 1e3, (1 + m.a + taus * (m.b + m.c * taus)) * m.l0, "C0:", lw=1.2,
            label="machine cycle: l_d")
    a0.set_xlabel("time since touchdown [ms]")
    a0.set_ylabel("leg length [m]")
    a0.set_title(f"one stance ({('left', 'right')[sg.foot]} foot)")
    a0.legend(fontsize=8)

    a1 = ax[1]
    tt = res.t_ref - res.t_ref[0]
    a1.plot(tt, res.h_ref, "k-", lw=2, label="reference COM height")
    a1.plot(tt, res.h_machine, "k:", lw=2, label="simple machine COM height")
    for e, k in zip(res.stride_events - res.t_ref[0], res.stride_kinds):
        a1.axvline(e, color="0.8", lw=0.8, zorder=0)
        a1.text(e, np.max(res.h_ref), k, fontsize=7, ha="center", va="bottom")
    a1.set_xlabel("time in stride [s]")
    a1.set_ylabel("COM height above ground [m]")
    a1.set_title(f"one stride (RMS {100 * m.quality['com_rms_m']:.2f} cm)")
    a1.legend(fontsize=8, loc="lower right")

    a2 = ax[2]
    a2.plot(t_ms, sg.f_leg / mg, "k-", lw=2, label="measured leg force (eq. 1, along the leg)")
    a2.plot(t_ms, ft.force(tau, sg.l / sg.l0), "k:", lw=2, label="model k (l_d − l) (stance fit)")
    a2.plot(t_m * 1e3, f_m, "C0-", lw=1.2, alpha=0.8, label="machine cycle")
    a2.set_xlabel("time since touchdown [ms]")
    a2.set_ylabel("leg force [body weights]")
    a2.set_title(f"leg force (stance fit r² = {ft.r2:.3f})")
    a2.legend(fontsize=8)
    fig.suptitle(f"{title or m.source}: simple machine fit  (K = {m.K:.1f}, θ0 = {np.degrees(m.theta0):.1f}°, "
                 f"{m.mean_speed_m_s:.2f} m/s)")

    try:
        atomic_write(path, lambda tmp: fig.savefig(tmp, dpi=110, format="png"))
    finally:
        plt.close(fig)
