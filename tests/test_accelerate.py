"""Issue 6: accelerate and decelerate, planned step by step (§5.3), end to end on the real clips."""
from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from froude.errors import PlanError
from froude.flow import pipeline
from froude.machine.table import grid_around, load_or_build_table

from conftest import RUNNING, clip, clip_params, matrix_group

#: (clip, factor) -> the bar missed, measured (benchmarks/bars_matrix.py --matrix 13).
#: (09_04 at 0.5x missed the joint jump, 19.99 deg at a toe lift-off, until the planner's target orbits became
#: the ones nearest the start cycle: 14.3 deg now, ratio 1.09.)
ACCELERATE_MISSES: dict[tuple[str, float], str] = {}


@pytest.mark.parametrize("name", [pytest.param(n, marks=matrix_group(n)) if isinstance(n, str) else n
                                  for n in clip_params(RUNNING)])
@pytest.mark.parametrize("factor", [0.5, 1.3])
def test_reach_goal_in_eight_steps(matrix_outputs, name, factor):
    """Acceptance 2: 0.5x and 1.3x within 8 steps: final speed within 3 %, monotone, physics bars met. The
    outputs are the golden matrix's (``pipeline.accelerate(prepared, to_factor=factor, steps=8)``), computed
    once for this test and test_golden."""
    res = matrix_outputs[f"accelerate/{name}/{factor:g}"]
    plan = res.report.extras["plan"]
    v = np.asarray(plan["apex_speed_m_s"])
    change = [i for i, p in enumerate(plan["phase"]) if p == "change"]
    assert len(change) == 8
    final = v[change[-1] + 1]
    assert final == pytest.approx(factor * plan["start_speed_m_s"], rel=0.03)
    assert np.all(np.diff(v) * np.sign(factor - 1.0) >= -1e-9), v
    miss = ACCELERATE_MISSES.get((name, factor))
    if miss is None:
        assert not res.report.check_bars(), res.report.check_bars()
    else:  # exactly the measured miss (when it goes away this fails, so that it comes off the list)
        assert [f.split(" deg")[0].split(" mm")[0].rsplit(" ", 1)[0] for f in res.report.check_bars()] == [
            miss.split(" deg")[0].split(" mm")[0].rsplit(" ", 1)[0]]
    assert res.finite


def test_same_dimensionless_profile_for_a_child(prepared):
    """Acceptance 3: the plan is dimensionless, so the child's U per step equals the adult's (1 %)."""
    prep = prepared["09_01"]
    adult = pipeline.accelerate(prep, to_factor=0.5, steps=8).report.extras["plan"]
    child = pipeline.accelerate(prep, "child", to_factor=0.5, steps=8).report.extras["plan"]
    assert np.allclose(child["apex_U"], adult["apex_U"], rtol=0.01)
    # while in SI the child is slower by sqrt(L)
    assert child["apex_speed_m_s"][0] < adult["apex_speed_m_s"][0]


def test_paper_figure3_row3(prepared):
    """Fig. 3 row 3: the paper's runner is at 3.3/4.6 = 0.72 of its start speed 1.7 s into slowing to half
    speed; ours is reported the same way and lands in the same neighbourhood."""
    prep = prepared["09_01"]
    plan = pipeline.accelerate(prep, to_factor=0.5, steps=8, lead_steps=0).report.extras["plan"]
    v = np.interp(1.7, plan["apex_time_s"], plan["apex_speed_m_s"]) / plan["start_speed_m_s"]
    assert 0.55 < v < 0.9


@pytest.mark.parametrize("kwargs, needle", [
    (dict(to_factor=10.0, steps=1, unlimited=True, speed_model="planner"), "cannot change speed"),  # §5.3's own
    (dict(to_factor=10.0, steps=1, unlimited=True), "cannot change speed"),  # the law's (no cycle there)
    (dict(to_factor=1.3, steps=1), "cannot change speed"),  # the law's cycles too far apart for one step
    (dict(to_factor=10.0, steps=1), "beyond the human range"),  # issue 30: before any planning
    (dict(to_speed=0.0, steps=8), "must be > 0"),
    (dict(to_factor=-1.0, steps=8), "must be > 0"),
])
def test_impossible_goals_refused(prepared, kwargs, needle):
    """Acceptance 4: impossible goals are refused with a message saying what is reachable."""
    from froude.errors import FroudeError

    with pytest.raises(FroudeError) as e:
        pipeline.accelerate(prepared["09_03"], **kwargs)
    assert needle in str(e.value)
    if "cannot change speed" in needle:
        assert "Traceback" not in str(e.value) and "\n" not in str(e.value)
    if kwargs.get("speed_model") == "planner":
        # said in m/s with the range that is reachable, numbers from the planner's own facts
        prep = prepared["09_03"]
        m = prep.machine.scaled(1.0, 1.0)
        lo, hi = (u * m.speed_unit for u in e.value.__cause__.U_sustainable)
        assert isinstance(e.value, PlanError) and "U =" not in str(e.value)
        assert f"runs steadily only between {lo:.2f} and {hi:.2f} m/s" in str(e.value)
        assert f"from {m.U * m.speed_unit:.2f} to {10 * m.U * m.speed_unit:.2f} m/s (x10.00)" in str(e.value)


def test_table_matches_simulation_and_caches(prepared, tmp_path):
    """Acceptance 1 (also covered on synthetic cycles in test_machine_table): the fitted machine's table
    agrees with direct simulation in every feasible cell of a sample, and loads from the cache."""
    from froude.machine.dynamics import step

    m = prepared["09_01"].machine
    grid = grid_around(m.U, m.H, m.theta0, n=12)
    table, cached = load_or_build_table(m.control, grid, cache_dir=tmp_path)
    assert not cached
    U, H, th = np.meshgrid(*table.axes(), indexing="ij")
    ok = table.valid
    r = step(U[ok], H[ok], th[ok], m.control)
    assert np.allclose(r.U_next, table.U_next[ok], atol=1e-6) and np.allclose(r.H_next, table.H_next[ok], atol=1e-6)
    again, cached = load_or_build_table(m.control, grid, cache_dir=tmp_path)
    assert cached and np.array_equal(again.U_next[ok], table.U_next[ok])


def test_cli_writes_profile_and_refuses_nonsense(tmp_path):
    out = tmp_path / "slow.bvh"
    r = subprocess.run([sys.executable, "-m", "froude", "accelerate", str(clip("09_05")), "--to-speed", "0.5x",
                        "--steps", "8", "-o", str(out), "--plot", str(tmp_path / "slow.png")],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    rep = json.loads(out.with_name("slow.report.json").read_text())
    assert len(rep["extras"]["plan"]["apex_speed_m_s"]) > 8
    assert (tmp_path / "slow.png").stat().st_size > 10_000 and (tmp_path / "slow-table.png").exists()
    bad = subprocess.run([sys.executable, "-m", "froude", "accelerate", str(clip("09_05")), "--to-speed", "10x",
                          "--steps", "1", "-o", str(tmp_path / "x.bvh")], capture_output=True, text=True)
    assert bad.returncode == 2 and "Traceback" not in bad.stderr and not (tmp_path / "x.bvh").exists()
    assert len([line for line in bad.stderr.splitlines() if "error" in line]) == 1
