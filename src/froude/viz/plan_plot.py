"""Plots for ``froude accelerate --plot``: the speed profile and the transition table (paper §5.3)."""
from __future__ import annotations

from pathlib import Path

from ..machine.table import grid_around, load_or_build_table
from .table_plot import plot_speed_profile, plot_table


def plan_plot_paths(path) -> list[Path]:
    """The files ``plot_plan(result, path)`` writes: PATH and PATH-table.png."""
    path = Path(path)
    return [path, path.with_name(path.stem + "-table.png")]


def plot_plan(result, path) -> list[Path]:
    """Write PATH (the per-step speed profile) and PATH-table.png (U′ over (U, θ0) at the cycle's H).

    result: a pipeline Output from ``accelerate`` (its ``plan`` and the prepared machine's control).
    """
    path = Path(path)
    plan = result.plan
    plot_speed_profile(plan, path, title=f"{result.retarget.character.name}: apex speed per step "
                       f"(U = u / sqrt(g l0)), {plan.mode} mode")
    # the table of the start cycle's control around its fixed point
    U0, H0, th0 = float(plan.U[0]), float(plan.H[0]), float(plan.theta0[0])
    grid = grid_around(U0, H0, th0, n=48)
    table, _ = load_or_build_table(plan.controls[0], grid)
    table_path = plan_plot_paths(path)[1]
    plot_table(table, H0, table_path, cycle=_Point(U0, H0, th0),
               title="transition table: next apex speed U' over (U, touchdown angle)")
    return [path, table_path]


class _Point:
    def __init__(self, U, H, theta0):
        self.U, self.H, self.theta0 = U, H, theta0
