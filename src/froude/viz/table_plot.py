"""Plots of the §5.3 transition table and of speed plans (matplotlib, imported lazily, Agg).

Both functions write a PNG atomically (temp file in the same directory + os.replace) and return
the path. Everything plotted is dimensionless: speeds in √(g l0) (the Froude number U), heights in
l0, times in √(l0/g), angles in degrees.
"""
from __future__ import annotations

import numpy as np

from ..io.atomic import atomic_write

__all__ = ["plot_table", "plot_speed_profile"]


def _pyplot():
    import matplotlib
    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt
    return plt


def _save(fig, path):
    return atomic_write(path, lambda tmp: fig.savefig(tmp, dpi=120))


def plot_table(table, H, path, *, cycle=None, title=None):
    """Heat map of the next apex speed U′ over (U, θ0) at apex height H (the table's nearest H
    node), invalid cells grey, the contour U′ = U (steady speed) drawn, and the cycle's fixed point
    (U, θ0) marked when ``cycle`` (anything with U, H, theta0) is given.

    table: TransitionTable; H: apex height [l0]; path: PNG file. Returns the path.
    """
    plt = _pyplot()
    Ug, Hg, Tg = table.axes()
    ih = int(np.argmin(np.abs(Hg - H)))
    Up = np.ma.masked_invalid(np.where(table.valid[:, ih, :], table.U_next[:, ih, :], np.nan))
    th_deg = np.degrees(Tg)
    fig, ax = plt.subplots(figsize=(7.2, 5.0), layout="constrained")
    ax.set_facecolor("0.82")  # invalid cells show the background
    cmap = plt.get_cmap("viridis").with_extremes(bad="0.82")
    mesh = ax.pcolormesh(Ug, th_deg, Up.T, shading="nearest", cmap=cmap)
    fig.colorbar(mesh, ax=ax, label="next apex speed U′  [√(g l0)]")
    UU, TT = np.meshgrid(Ug, th_deg, indexing="ij")
    diff = np.where(table.valid[:, ih, :], table.U_next[:, ih, :] - UU, np.nan)
    if np.any(np.isfinite(diff)) and np.nanmin(diff) < 0 < np.nanmax(diff):
        cs = ax.contour(Ug, th_deg, np.ma.masked_invalid(diff).T, levels=[0.0], colors="white",
                        linewidths=1.6)
        ax.clabel(cs, fmt={0.0: "U′ = U"}, fontsize=8)
    if cycle is not None:
        ax.plot([cycle.U], [np.degrees(cycle.theta0)], marker="*", ms=15, color="#d62728",
                markeredgecolor="white", ls="none", label=f"cycle (U = {cycle.U:.3f}, H = {cycle.H:.3f})")
        ax.legend(loc="upper left", fontsize=8, framealpha=0.85)
    ax.set_xlabel("apex speed U  [√(g l0)]")
    ax.set_ylabel("touchdown angle θ0  [deg from vertical]")
    ax.set_title(title or f"Transition table: U′(U, θ0) at H = {Hg[ih]:.3f} l0 "
                          f"(grey: no valid step)", fontsize=10)
    try:
        return _save(fig, path)
    finally:
        plt.close(fig)


def plot_speed_profile(plan, path, *, title=None):
    """Apex speed per step against time (steps on the lower panel: touchdown angle and b), with
    the reference speeds and the change phase shaded. Dimensionless. Returns the path."""
    plt = _pyplot()
    fig, (ax, ax2) = plt.subplots(2, 1, figsize=(7.2, 5.6), sharex=True, layout="constrained",
                                  gridspec_kw={"height_ratios": [2.2, 1.0]})
    t = plan.t_apex
    idx = plan.change_steps
    if idx.size:
        ax.axvspan(t[idx[0]], t[idx[-1] + 1], color="0.92", zorder=0, label="change")
        ax2.axvspan(t[idx[0]], t[idx[-1] + 1], color="0.92", zorder=0)
    ax.plot(t, plan.U_ref, ls="--", color="0.45", lw=1.2, label="reference U_ref")
    ax.plot(t, plan.U, marker="o", ms=4, color="#1f77b4", lw=1.6, label="apex speed U (simulated)")
    ax.axhline(plan.U_target, color="#d62728", lw=0.8, ls=":", label=f"target U = {plan.U_target:.3f}")
    ax.set_ylabel("apex speed U  [√(g l0)]")
    ax.legend(fontsize=8, loc="best")
    ax.set_title(title or f"Speed plan: U {plan.U_start:.3f} → {plan.U_target:.3f} "
                          f"({idx.size} change steps, mode {plan.mode}, policy {plan.policy})",
                 fontsize=10)
    tm = 0.5 * (t[:-1] + t[1:])
    ax2.step(tm, np.degrees(plan.theta0), where="mid", color="#2ca02c", label="θ0 [deg]")
    ax2.set_ylabel("θ0  [deg]", color="#2ca02c")
    ax2.set_xlabel("time  [√(l0/g)]")
    ax3 = ax2.twinx()
    ax3.step(tm, plan.b, where="mid", color="#9467bd", label="b [l0]")
    ax3.set_ylabel("control b  [l0]", color="#9467bd")
    try:
        return _save(fig, path)
    finally:
        plt.close(fig)
