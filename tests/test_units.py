"""machine.units: the one home of dimensionless ↔ SI and of dynamic similarity (Table 1)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from froude.machine.units import MEASURED, scale_measured, similarity, speed_unit, time_unit

from conftest import clip


def test_units_of_a_one_metre_leg():
    assert time_unit(1.0) == pytest.approx(1.0 / math.sqrt(9.81))
    assert speed_unit(1.0) * time_unit(1.0) == pytest.approx(1.0)  # l0 = √(g l0) · √(l0/g)


def test_similarity_table_1():
    s = similarity(4.0, 8.0)
    assert (s.length, s.time, s.speed, s.mass, s.force, s.stiffness) == (4.0, 2.0, 2.0, 8.0, 8.0, 2.0)
    assert s.factor("setting") == s.factor("label") == s.factor("dimensionless") == 1.0


def test_scaled_measurements_by_dimension_not_by_name():
    d = {"stance_time_s": 0.2, "mean_speed_m_s": 3.0, "apex_height_m": 1.0, "cutoff_hz": 8.0,
         "stride": {"t_events_s": [0.1, 0.3], "kinds": ["TD", "LO"]}, "fit": None}
    out = scale_measured(d, similarity(4.0))
    assert out["stance_time_s"] == pytest.approx(0.4) and out["mean_speed_m_s"] == pytest.approx(6.0)
    assert out["apex_height_m"] == 4.0 and out["cutoff_hz"] == 8.0 and out["fit"] is None
    assert out["stride"] == {"t_events_s": [0.2, 0.6], "kinds": ["TD", "LO"]}
    with pytest.raises(KeyError, match="reference.new_length_m.*MEASURED"):
        scale_measured({"new_length_m": 1.0}, similarity(2.0), "reference")


def test_every_measurement_of_a_fitted_machine_has_a_dimension():
    from froude.flow import pipeline

    m = pipeline.prepare(clip("09_01")).machine
    big = m.scaled(2.25, 3.0)  # raises on a measurement MEASURED does not list
    assert big.reference["mean_speed_m_s"] == pytest.approx(1.5 * m.reference["mean_speed_m_s"])
    assert big.reference["step_time_s"] == pytest.approx(1.5 * m.reference["step_time_s"])
    assert np.allclose(big.stances[0]["contact_m"], 2.25 * np.asarray(m.stances[0]["contact_m"]))
    assert big.time_unit == pytest.approx(1.5 * m.time_unit) and big.speed_unit == pytest.approx(1.5 * m.speed_unit)
    assert set(MEASURED) >= {k for k, v in m.reference.items() if isinstance(v, float)}
