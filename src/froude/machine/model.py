"""The fitted simple running machine (Pollard 1999 §4): dimensionless core + SI view, versioned JSON.

The canonical content is **dimensionless** (l0 = 1, g = 1, m = 1; see froude.machine.dynamics):
apex state (U, H), touchdown angle θ0, control (K, a, b, c, T_c) and the cycle's phase times. The SI
view multiplies by the character's l0 [m], m [kg] and g. Everything measured on the reference that
synthesis needs (heading, ground, lateral sway, stance measurements, reference stride timing) is kept
in SI next to it, so :meth:`SimpleMachine.scaled` (dynamic similarity, §5.1 Table 1) is trivial:
lengths × L, times × √L, speeds × √L, masses and forces × M, stiffness × M/L; dimensionless numbers,
angles and body-weight forces unchanged.

JSON schema ``froude.machine/1`` (all keys always present; see ``to_dict``)::

  schema, source, mass_kg, l0_m, g_m_s2,
  cycle: {U, H, theta0_rad, K, a, b, c, T_c, t_stance, t_flight, t_fall, t_rise, step_length,
          step_time, mean_speed, peak_force_bw, periodicity, iterations}      # dimensionless
  cycle_si: {...}                                                             # derived, informative only
  frame: {heading, lateral, up, ground_m}
  lateral: {foot_offset_m: [left, right], sway_m: [...], sway_phase: [...]}
  reference: {stance_time_s, flight_time_s, mean_speed_m_s, apex_height_m, frame_time_s,
              stride: {first_event, t_events_s, feet}, flight_residual_bw, shares, filter}
  stances: [{foot, partial, t_touchdown_s, t_liftoff_s, duration_s, l0_m, theta_touchdown_rad,
             theta_liftoff_rad, com_drop_m, peak_vertical_force_bw, contact_m, ground_m,
             lateral_offset_m, fit: {K, a, b, c, r2, rms_bw} | null, fit_free: {...} | null}, ...]
  quality: {com_rms_m, stance_time_error, flight_time_error, mean_speed_error}
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..core.constants import GRAVITY
from ..errors import FitError
from ..io.atomic import atomic_write_text
from ..io.jsonable import dumps
from ..io.jsonable import jsonable as _jsonable
from .dynamics import Control
from .units import scale_measured, similarity, speed_unit, time_unit

__all__ = ["SCHEMA", "SimpleMachine", "load_machine"]

SCHEMA = "froude.machine/1"


@dataclass(frozen=True)
class SimpleMachine:
    """A periodic running cycle of the simple machine fitted to a reference motion.

    Dimensionless (units l0, √(l0/g), √(g l0), m g):
      U: apex horizontal speed (Froude number); H: apex COM height / l0; theta0: touchdown angle from
      vertical [rad]; K = k l0/(m g); a, b, c: desired-length coefficients / l0; T_c: nominal stance
      time; t_stance, t_flight, t_fall (apex → touchdown), t_rise (liftoff → apex); step_length;
      step_time; mean_speed = step_length/step_time; peak_force [m g]; periodicity = max |(U', H') −
      (U, H)| of the step map at the cycle; iterations of the search.
    SI: mass [kg], l0 [m] (mean touchdown leg length contact → COM), g [m/s²].
    frame: heading (3,) travel direction, lateral (3,) = heading × UP (the runner's right, constants.heading_frame),
    up (3,), ground [m] (median).
    lateral_foot_offset: (2,) [m] mean lateral offset of the left/right contact point from the COM line;
    lateral_sway: (N,) [m] mean lateral COM offset from its line over one stride, at lateral_sway_phase (N,)
      in [0, 1) of the reference stride (see reference["stride"]).
    reference: dict of reference measurements in SI (stance/flight time [s], mean speed [m/s], apex
      height [m], stride event times [s] and feet, flight residual [BW], force shares, filter).
    stances: tuple of per-stance dicts (SI; forces in body weights; see module doc).
    quality: dict com_rms_m, stance_time_error, flight_time_error, mean_speed_error (relative errors).
    """

    U: float
    H: float
    theta0: float
    K: float
    a: float
    b: float
    c: float
    T_c: float
    t_stance: float
    t_flight: float
    t_fall: float
    t_rise: float
    step_length: float
    step_time: float
    mean_speed: float
    peak_force: float
    periodicity: float
    iterations: int
    mass: float
    l0: float
    g: float = GRAVITY
    source: str = ""
    heading: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, 1.0]))
    lateral: np.ndarray = field(default_factory=lambda: np.array([1.0, 0.0, 0.0]))
    up: np.ndarray = field(default_factory=lambda: np.array([0.0, 1.0, 0.0]))
    ground: float = 0.0
    lateral_foot_offset: np.ndarray = field(default_factory=lambda: np.zeros(2))
    lateral_sway: np.ndarray = field(default_factory=lambda: np.zeros(0))
    lateral_sway_phase: np.ndarray = field(default_factory=lambda: np.zeros(0))
    reference: dict = field(default_factory=dict)
    stances: tuple = ()
    quality: dict = field(default_factory=dict)

    # ---- dimensionless ↔ SI ------------------------------------------------------------------------
    @property
    def time_unit(self) -> float:
        """√(l0/g) [s]."""
        return time_unit(self.l0, self.g)

    @property
    def speed_unit(self) -> float:
        """√(g l0) [m/s]."""
        return speed_unit(self.l0, self.g)

    @property
    def mean_speed_m_s(self) -> float:
        """The cycle's mean forward speed [m/s] (mean_speed × √(g l0)): for a machine scaled to a character, the
        character's speed at factor 1, the base every speed factor multiplies."""
        return self.mean_speed * self.speed_unit

    @property
    def control(self) -> Control:
        """The dimensionless stance control (K, a, b, c, T_c)."""
        return Control(K=self.K, a=self.a, b=self.b, c=self.c, T_c=self.T_c)

    @property
    def k(self) -> float:
        """Leg stiffness [N/m]."""
        return self.K * self.mass * self.g / self.l0

    def si(self) -> dict:
        """The cycle in SI: k [N/m], a, b, c, step_length, apex_height [m], times [s], speeds [m/s], peak force [N]."""
        T, L, V = self.time_unit, self.l0, self.speed_unit
        return {
            "k_N_m": self.k, "a_m": self.a * L, "b_m": self.b * L, "c_m": self.c * L, "l0_m": L,
            "theta0_deg": math.degrees(self.theta0), "apex_speed_m_s": self.U * V, "apex_height_m": self.H * L,
            "T_c_s": self.T_c * T, "stance_time_s": self.t_stance * T, "flight_time_s": self.t_flight * T,
            "step_time_s": self.step_time * T, "step_length_m": self.step_length * L,
            "mean_speed_m_s": self.mean_speed_m_s, "peak_force_N": self.peak_force * self.mass * self.g,
        }

    # ---- dynamic similarity (§5.1, Table 1) ----------------------------------------------------------
    def scaled(self, L: float, M: float = 1.0) -> SimpleMachine:
        """The dynamically similar machine for a character L times longer and M times heavier.

        Dimensionless fields are unchanged; l0 × L, mass × M; SI measurements: lengths × L, times × √L,
        speeds × √L (forces are stored in body weights, angles in radians: unchanged).
        """
        if not (L > 0 and M > 0):
            raise FitError(f"scale factors must be > 0 (L={L}, M={M})")
        sim = similarity(L, M)
        return replace(
            self, mass=self.mass * M, l0=self.l0 * L, ground=self.ground * L,
            lateral_foot_offset=self.lateral_foot_offset * L, lateral_sway=self.lateral_sway * L,
            reference=scale_measured(self.reference, sim, "reference"),
            stances=tuple(scale_measured(s, sim, "stance") for s in self.stances),
            quality=scale_measured(self.quality, sim, "quality"), source=self.source + f" (scaled L={L:g}, M={M:g})",
        )

    # ---- JSON ----------------------------------------------------------------------------------------
    def to_dict(self) -> dict:
        """JSON-able dict, schema froude.machine/1 (see module doc)."""
        cyc = {"U": self.U, "H": self.H, "theta0_rad": self.theta0, "K": self.K, "a": self.a, "b": self.b,
               "c": self.c, "T_c": self.T_c, "t_stance": self.t_stance, "t_flight": self.t_flight,
               "t_fall": self.t_fall, "t_rise": self.t_rise, "step_length": self.step_length,
               "step_time": self.step_time, "mean_speed": self.mean_speed, "peak_force_bw": self.peak_force,
               "periodicity": self.periodicity, "iterations": self.iterations}
        return _jsonable({
            "schema": SCHEMA, "source": self.source, "mass_kg": self.mass, "l0_m": self.l0, "g_m_s2": self.g,
            "cycle": cyc, "cycle_si": self.si(),
            "frame": {"heading": self.heading, "lateral": self.lateral, "up": self.up, "ground_m": self.ground},
            "lateral": {"foot_offset_m": self.lateral_foot_offset, "sway_m": self.lateral_sway,
                        "sway_phase": self.lateral_sway_phase},
            "reference": self.reference, "stances": list(self.stances), "quality": self.quality,
        })

    @classmethod
    def from_dict(cls, d: dict, where: str = "machine") -> SimpleMachine:
        if not isinstance(d, dict) or d.get("schema") != SCHEMA:
            got = d.get("schema") if isinstance(d, dict) else type(d).__name__
            raise FitError(f"{where}: not a froude machine file (schema {got!r}, expected {SCHEMA!r})")
        try:
            c = d["cycle"]
            fr = d["frame"]
            lat = d["lateral"]
            return cls(
                U=float(c["U"]), H=float(c["H"]), theta0=float(c["theta0_rad"]), K=float(c["K"]),
                a=float(c["a"]), b=float(c["b"]), c=float(c["c"]), T_c=float(c["T_c"]),
                t_stance=float(c["t_stance"]), t_flight=float(c["t_flight"]), t_fall=float(c["t_fall"]),
                t_rise=float(c["t_rise"]), step_length=float(c["step_length"]), step_time=float(c["step_time"]),
                mean_speed=float(c["mean_speed"]), peak_force=float(c["peak_force_bw"]),
                periodicity=float(c["periodicity"]), iterations=int(c["iterations"]),
                mass=float(d["mass_kg"]), l0=float(d["l0_m"]), g=float(d["g_m_s2"]), source=str(d["source"]),
                heading=np.asarray(fr["heading"], float), lateral=np.asarray(fr["lateral"], float),
                up=np.asarray(fr["up"], float), ground=float(fr["ground_m"]),
                lateral_foot_offset=np.asarray(lat["foot_offset_m"], float),
                lateral_sway=np.asarray(lat["sway_m"], float),
                lateral_sway_phase=np.asarray(lat["sway_phase"], float),
                reference=dict(d["reference"]), stances=tuple(d["stances"]), quality=dict(d["quality"]),
            )
        except (KeyError, TypeError, ValueError) as e:
            raise FitError(f"{where}: malformed {SCHEMA} file ({type(e).__name__}: {e})") from None

    def save(self, path) -> None:
        """Write the machine as JSON (atomically: temp file + rename)."""
        atomic_write_text(path, dumps(self.to_dict(), indent=1) + "\n")

    @classmethod
    def load(cls, path) -> SimpleMachine:
        return load_machine(path)


def load_machine(path) -> SimpleMachine:
    """Read a ``froude.machine/1`` JSON file; FitError with the path on any problem."""
    p = Path(path)
    try:
        d = json.loads(p.read_text())
    except OSError as e:
        raise FitError(f"{path}: cannot read ({e.strerror})") from None
    except json.JSONDecodeError as e:
        raise FitError(f"{path}:{e.lineno}: not valid JSON ({e.msg})") from None
    return SimpleMachine.from_dict(d, str(path))


