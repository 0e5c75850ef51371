"""Dimensionless ↔ SI, and dynamic similarity (§5.1, Table 1): the one place √(l0/g), √(g l0) and √L are
written.

The machine lives in units of its leg: lengths in l0, times in √(l0/g), speeds in √(g l0) (so the apex
speed U is the Froude number), forces in body weights m g, leg stiffness as K = k l0/(m g). A character L
times longer and M times heavier runs the same dimensionless motion; in SI its lengths are × L, times and
speeds × √L, masses and forces × M, stiffness × M/L (``Similarity``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..core.constants import GRAVITY

__all__ = ["time_unit", "speed_unit", "froude_number", "to_si_time", "to_si_length", "to_si_velocity",
           "to_si_force", "to_si_stiffness", "Similarity", "similarity", "MEASURED", "scale_measured"]


def time_unit(l0_m: float, g: float = GRAVITY) -> float:
    """√(l0/g) [s]: the machine's unit of time for a leg of l0 [m]."""
    return math.sqrt(l0_m / g)


def speed_unit(l0_m: float, g: float = GRAVITY) -> float:
    """√(g l0) [m/s]: the machine's unit of speed for a leg of l0 [m]."""
    return math.sqrt(g * l0_m)


def froude_number(u_mps, l0_m, g=GRAVITY):
    """U = u/√(g l0): horizontal speed [m/s] → dimensionless (arrays broadcast)."""
    return np.asarray(u_mps) / np.sqrt(g * np.asarray(l0_m, float))


def to_si_time(t, l0_m, g=GRAVITY):
    """Dimensionless time → [s] (arrays broadcast)."""
    return np.asarray(t) * np.sqrt(np.asarray(l0_m, float) / g)


def to_si_length(x, l0_m):
    """Dimensionless length (units of l0) → [m]."""
    return np.asarray(x) * l0_m


def to_si_velocity(v, l0_m, g=GRAVITY):
    """Dimensionless velocity (units of √(g l0)) → [m/s]."""
    return np.asarray(v) * np.sqrt(g * np.asarray(l0_m, float))


def to_si_force(f, m_kg, g=GRAVITY):
    """Dimensionless force (body weights) → [N]."""
    return np.asarray(f) * m_kg * g


def to_si_stiffness(K, m_kg, l0_m, g=GRAVITY):
    """Dimensionless stiffness K = k l0/(m g) → k [N/m]."""
    return np.asarray(K) * m_kg * g / l0_m


@dataclass(frozen=True)
class Similarity:
    """The factors by which SI quantities change between dynamically similar bodies (Table 1)."""

    length: float
    time: float
    speed: float
    mass: float
    force: float
    stiffness: float

    def factor(self, dimension: str) -> float:
        """The factor of one dimension ("length", "time", "speed", "mass", "force", "stiffness"; anything
        dimensionless, an angle, a setting or a label: 1)."""
        return getattr(self, dimension) if dimension in _SCALED else 1.0


_SCALED = ("length", "time", "speed", "mass", "force", "stiffness")


def similarity(L: float, M: float = 1.0) -> Similarity:
    """Factors for a body L times longer and M times heavier: lengths L, times and speeds √L, masses and
    forces M, stiffness M/L."""
    root_L = math.sqrt(L)
    return Similarity(length=L, time=root_L, speed=root_L, mass=M, force=M, stiffness=M / L)


#: Every SI quantity a fitted SimpleMachine records (reference, stances, quality), by name, with its
#: dimension; ``SimpleMachine.scaled`` scales each by ``Similarity.factor``. "setting": a processing
#: choice (the COM filter's cutoff), kept; "label": words, flags and frame indices of the clip, kept.
MEASURED = {
    # times [s]
    "stance_time_s": "time", "flight_time_s": "time", "flight_time_contacts_s": "time", "step_time_s": "time",
    "frame_time_s": "time", "t_events_s": "time", "t_touchdown_s": "time", "t_liftoff_s": "time",
    "duration_s": "time",
    # speeds [m/s]
    "apex_speed_m_s": "speed", "mean_speed_m_s": "speed", "stride_speed_m_s": "speed",
    # lengths [m]
    "apex_height_m": "length", "com_drop_m": "length", "contact_m": "length", "ground_m": "length",
    "l0_m": "length", "lateral_offset_m": "length", "com_rms_m": "length",
    # dimensionless: body weights, fractions, fitted control (units of l0, √(l0/g)), angles, errors
    "flight_residual_bw": "dimensionless", "peak_vertical_force_bw": "dimensionless", "rms_bw": "dimensionless",
    "event_threshold_bw": "dimensionless", "K": "dimensionless", "a": "dimensionless", "b": "dimensionless",
    "c": "dimensionless", "r2": "dimensionless", "leg": "dimensionless", "leg_sq": "dimensionless",
    "vertical": "dimensionless", "vertical_sq": "dimensionless", "theta_touchdown_rad": "dimensionless",
    "theta_liftoff_rad": "dimensionless", "stance_time_error": "dimensionless",
    "flight_time_error": "dimensionless", "mean_speed_error": "dimensionless",
    "cutoff_hz": "setting",
    "frames": "label", "feet": "label", "kinds": "label", "first_event": "label", "kind": "label",
    "foot": "label", "partial": "label",
}


def scale_measured(d: dict, sim: Similarity, where: str = "machine") -> dict:
    """A copy of a (nested) dict of measurements with every value scaled by its dimension (``MEASURED``);
    None, words and flags are kept. Raises KeyError naming a numeric quantity ``MEASURED`` does not list
    (a new measurement must say how it scales)."""
    out: dict = {}
    for key, v in d.items():
        if isinstance(v, dict):
            out[key] = scale_measured(v, sim, f"{where}.{key}")
            continue
        dim = MEASURED.get(key)
        if dim is None:
            if v is None or isinstance(v, (str, bool)):
                out[key] = v
                continue
            raise KeyError(f"{where}.{key}: no dimension for this measurement: add it to machine.units.MEASURED")
        f = sim.factor(dim)
        out[key] = _mul(v, f) if f != 1.0 else v
    return out


def _mul(v, f: float):
    """v × f for a number, an array or a (nested) list of them; None, flags and words are kept."""
    if isinstance(v, (list, tuple)):
        return [_mul(x, f) for x in v]
    if v is None or isinstance(v, (bool, str)):
        return v
    return v * f
