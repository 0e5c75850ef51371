"""Issue 12 acceptance 2 and issue 13 acceptance 3-4 on the real clips: the parts of the matrices that the other
test files do not already run (tests/test_scale.py: the CMU presets at x0.7-1.2; tests/test_accelerate.py: 0.5x
and 1.3x; tests/test_conventions.py: every Bandai run as delivered at 30 and 120 Hz; tests/test_take.py: the
CMU speed ranges). The whole matrices, with a table of which output misses which bar, are
``python benchmarks/bars_matrix.py`` (a minute or two); figures in the bars helper's note.
"""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from froude.flow import pipeline
from froude.flow.speed_range import reachable_speed_range

from conftest import BANDAI_RUNS, RUNNING, clip, clip_params

PRESETS = ("child", "troll", "giant", "small")
#: Speed factors of acceptance 13.4.
SPEEDS_134 = (0.5, 0.7, 1.5, 1.8, 2.0)
#: x1.5 outputs (acceptance 13.3's fastest column) that miss a bar, measured at 120 Hz (the clips' rate):
#: strict xfail, so that one that starts meeting the bars comes off the list (09_04 child met them with the
#: human speed law: 1.5 x the speed at a 13 % higher cadence, steps 11 % shorter than with the step time kept).
FAST_MISSES = {
    ("09_04", "small"): "joint jump 20.88 deg (<= 1.5 x reference 13.11): a toe at the first touchdown",
}




def _fast_cases():
    names = clip_params(RUNNING)
    if not isinstance(names[0], str):
        return names
    return [pytest.param(n, p, id=f"{n}-{p}",
                         marks=[pytest.mark.xfail(strict=True, reason=FAST_MISSES[(n, p)])] if (n, p) in FAST_MISSES
                         else ())
            for n in names for p in PRESETS]


@pytest.mark.parametrize("name,preset", _fast_cases())
def test_every_preset_at_one_and_a_half_times_the_speed(prepared, name, preset):
    """Acceptance 13.3's x1.5 column: every bar, the stricter skate (ball and tip near the floor) among them."""
    rep = pipeline.scale(prepared[name], preset, speed=1.5, strides=4).report
    assert rep.check_bars() == []


@pytest.mark.parametrize("name", clip_params(BANDAI_RUNS))
def test_bandai_speed_factors_met_or_refused_with_the_range(prepared, name):
    """Acceptance 13.4 on the Bandai runs (the CMU runs: tests/test_take.py): inside the reachable range an
    output meets every bar; its ends were produced and met them."""
    prep = prepared[name]
    rng = reachable_speed_range(prep)
    assert not rng.empty and rng.lo <= 1.0 <= rng.hi and rng.hi >= 1.2
    for s in SPEEDS_134:
        if rng.lo <= s <= rng.hi:
            assert pipeline.scale(prep, speed=s).report.check_bars() == [], s
    assert pipeline.scale(prep, speed=rng.hi).report.check_bars() == []


def test_an_unreachable_speed_is_refused_in_one_line_with_the_range(run_cli, tmp_path):
    """x1.8 of a Bandai run as delivered (a joint jump of 1.6 x the clip's; with the human speed law its x2.0
    meets every bar): not written, one line that gives the range in x and m/s."""
    out = tmp_path / "fast.bvh"
    code, _, err = run_cli("scale", clip("dataset-1_dash_feminine_001"), "--speed", "1.8", "-o", out)
    assert code in (1, 2) and not out.exists()
    lines = [ln for ln in err.strip().splitlines() if "x0." in ln or "x1." in ln]
    assert len(lines) == 1 and "m/s" in lines[0] and "steady speeds are x" in lines[0]


def test_the_measuring_script_runs(tmp_path):
    """benchmarks/bars_matrix.py on one clip of the speed matrix: it prints the table and the counts."""
    script = Path(__file__).resolve().parents[1] / "benchmarks" / "bars_matrix.py"
    clip("09_01")  # skips without the clips
    r = subprocess.run([sys.executable, str(script), "--matrix", "speeds", "--only", "09_01", "--all"],
                       capture_output=True, text=True, timeout=600)
    assert r.returncode in (0, 1), r.stderr
    assert "matrix speeds:" in r.stdout and "09_01" in r.stdout and "reachable x" in r.stdout
