"""§5.3 transition table: agreement with step() and the solve_ivp oracle, lookups, cache."""
import math
import os

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from froude.errors import PlanError
from froude.machine.dynamics import Control, step
from froude.machine.table import (
    TABLE_VERSION,
    TableGrid,
    TransitionTable,
    build_table,
    grid_around,
    load_or_build_table,
    table_key,
)

CTL = Control(K=15.22, a=0.021, b=0.0157, c=-0.0142, T_c=0.6)
CYCLE = (1.15, 1.0, 0.40)


def oracle(U, H, th, K, a, b, c, Tc):
    tf = math.sqrt(2.0 * (H - math.cos(th)))

    def rhs(t, y):
        l = math.hypot(y[0], y[1])
        f = K * (1.0 + a + b * t / Tc + c * (t / Tc) ** 2 - l)
        return [y[2], y[3], f * y[0] / l, f * y[1] / l - 1.0]

    def ev(t, y):
        return 1.0 + a + b * t / Tc + c * (t / Tc) ** 2 - math.hypot(y[0], y[1])

    ev.terminal, ev.direction = True, -1
    s = solve_ivp(rhs, (0, 20 * Tc), [-math.sin(th), math.cos(th), U, -tf], method="DOP853",
                  rtol=1e-11, atol=1e-11, events=ev)
    px, py, vx, vy = s.y_events[0][0]
    return vx, py + 0.5 * vy * vy, s.t_events[0][0], vy


@pytest.fixture(scope="module")
def small():
    grid = grid_around(*CYCLE, n=9, n_H=8, n_theta=7)
    return build_table(CTL, grid)


def test_grid_ranges_around_cycle():
    g = grid_around(*CYCLE)
    assert g.shape == (64, 64, 64)
    assert g.U[:2] == pytest.approx((0.3 * 1.15, 2.0 * 1.15))
    assert g.theta0[:2] == pytest.approx((0.4 - math.radians(15), 0.4 + math.radians(15)))
    assert g.H[0] < 1.0 < g.H[1]


def test_every_cell_matches_direct_step(small):
    t = small
    assert t.U_next.shape == (9, 8, 7)
    assert t.valid.any() and (~t.valid).any()  # the grid reaches infeasible corners
    Ug, Hg, Tg = t.axes()
    UU, HH, TT = np.meshgrid(Ug, Hg, Tg, indexing="ij")
    r = step(UU.ravel(), HH.ravel(), TT.ravel(), CTL, chunk=13)  # different batching
    assert np.array_equal(r.valid.reshape(t.valid.shape), t.valid)
    v = t.valid
    for f in ("U_next", "H_next", "t_stance", "t_rise", "t_fall", "peak_force"):
        a = getattr(t, f)
        assert np.all(np.isfinite(a[v])), f
        assert np.all(np.isnan(a[~v])), f
        assert np.max(np.abs(a[v] - getattr(r, f).reshape(a.shape)[v])) <= 1e-12, f
    # and a few single scalar calls
    rng = np.random.default_rng(0)
    for i in rng.choice(np.flatnonzero(v.ravel()), 5, replace=False):
        iu, ih, it = np.unravel_index(i, v.shape)
        rs = step(Ug[iu], Hg[ih], Tg[it], CTL)
        assert abs(float(rs.U_next) - t.U_next[iu, ih, it]) <= 1e-12
        assert abs(float(rs.H_next) - t.H_next[iu, ih, it]) <= 1e-12


def test_sampled_cells_match_oracle(small):
    t = small
    Ug, Hg, Tg = t.axes()
    rng = np.random.default_rng(1)
    cells = rng.choice(np.flatnonzero(t.valid.ravel()), 10, replace=False)
    for i in cells:
        iu, ih, it = np.unravel_index(i, t.valid.shape)
        Up, Hp, ts, tr = oracle(Ug[iu], Hg[ih], Tg[it], *CTL.as_tuple())
        assert abs(t.U_next[iu, ih, it] - Up) <= 1e-6
        assert abs(t.H_next[iu, ih, it] - Hp) <= 1e-6
        assert abs(t.t_stance[iu, ih, it] - ts) <= 1e-6
        assert abs(t.t_rise[iu, ih, it] - tr) <= 1e-6


def test_lookup_nodes_interpolation_and_feasibility(small):
    t = small
    Ug, Hg, Tg = t.axes()
    iu, ih, it = np.argwhere(t.valid)[len(np.argwhere(t.valid)) // 2]
    L = t.lookup(Ug[iu], Hg[ih], Tg[it])
    # A node is feasible only if its 8-cube is valid; at the node the value is the cell's.
    if L.feasible:
        assert float(L.U_next) == pytest.approx(t.U_next[iu, ih, it], abs=1e-12)
    # Inside a fully valid cube the trilinear value lies between the corner values.
    cubes = t.valid[:-1, :-1, :-1] & t.valid[1:, :-1, :-1] & t.valid[:-1, 1:, :-1] & t.valid[:-1, :-1, 1:] \
        & t.valid[1:, 1:, :-1] & t.valid[1:, :-1, 1:] & t.valid[:-1, 1:, 1:] & t.valid[1:, 1:, 1:]
    cu, ch, ct = np.argwhere(cubes)[0]
    mid = t.lookup(0.5 * (Ug[cu] + Ug[cu + 1]), 0.5 * (Hg[ch] + Hg[ch + 1]), 0.5 * (Tg[ct] + Tg[ct + 1]))
    corners = t.U_next[cu:cu + 2, ch:ch + 2, ct:ct + 2]
    assert mid.feasible and corners.min() <= float(mid.U_next) <= corners.max()
    assert float(mid.U_next) == pytest.approx(corners.mean(), abs=1e-12)
    # Outside the grid and cubes touching invalid cells are infeasible and NaN.
    out = t.lookup([Ug[0] - 0.1, Ug[-1] + 0.1], Hg[3], Tg[3])
    assert not out.feasible.any() and np.all(np.isnan(out.U_next))
    bad = np.argwhere(~t.valid)[0]
    Lb = t.lookup(Ug[bad[0]], Hg[bad[1]], Tg[bad[2]])
    assert not Lb.feasible and np.isnan(Lb.U_next)
    with pytest.raises(PlanError):
        t.lookup(Ug[bad[0]], Hg[bad[1]], Tg[bad[2]], strict=True)
    # Vectorised shape
    assert t.lookup(np.full((2, 3), 1.1), 1.0, 0.4).U_next.shape == (2, 3)


def test_theta_for_speed():
    grid = grid_around(*CYCLE, n=24)
    t = build_table(CTL, grid)
    U, H = 1.15, 1.0
    targets = np.array([1.10, 1.15, 1.20, 50.0])
    th, ok = t.theta_for_speed(U, H, targets)
    assert ok[:3].all() and not ok[3] and np.isnan(th[3])
    L = t.lookup(U, H, th[:3])
    assert np.allclose(L.U_next, targets[:3], atol=1e-9)
    # Slower target → steeper (larger) touchdown angle; true step lands near the target.
    assert th[0] > th[1] > th[2]
    r = step(U, H, th[:3], CTL)
    assert np.allclose(r.U_next, targets[:3], atol=5e-3)


def test_cache_round_trip(tmp_path):
    grid = grid_around(*CYCLE, n=6)
    t1, loaded1 = load_or_build_table(CTL, grid, cache_dir=tmp_path / "c")
    t2, loaded2 = load_or_build_table(CTL, grid, cache_dir=tmp_path / "c")
    assert not loaded1 and loaded2
    files = os.listdir(tmp_path / "c")
    assert files == [f"table_{t1.key}.npz"]  # no temp files left behind
    for f in ("U_next", "H_next", "t_stance", "t_rise", "t_flight", "valid", "reason"):
        assert np.array_equal(getattr(t1, f), getattr(t2, f), equal_nan=f not in ("valid", "reason"))
    assert t2.control == t1.control and t2.grid == t1.grid
    # Key depends on control, grid and version inputs.
    assert table_key(CTL, grid) != table_key(Control(15.23, *CTL.as_tuple()[1:]), grid)
    assert table_key(CTL, grid) != table_key(CTL, grid_around(*CYCLE, n=7))
    # A stale version is rebuilt, not trusted.
    path = tmp_path / "c" / f"table_{t1.key}.npz"
    with np.load(path) as z:
        data = dict(z)
    data["meta"] = np.array(str(data["meta"]).replace(f'"version": {TABLE_VERSION}', '"version": -1'))
    np.savez(path, **data)
    with pytest.raises(ValueError):
        TransitionTable.load(path)
    t3, loaded3 = load_or_build_table(CTL, grid, cache_dir=tmp_path / "c")
    assert not loaded3 and TransitionTable.load(path).grid == grid
    assert isinstance(grid, TableGrid)
