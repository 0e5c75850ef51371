"""The fitted simple walking machine: dimensionless core + SI view, versioned JSON (``froude.walking/1``).

The walking counterpart of :class:`froude.machine.model.SimpleMachine`. Canonical content is
dimensionless (l0 = 1, g = 1, m = 1; see :mod:`froude.machine.walking`): the periodic touchdown state
(u, v, d, s), the touchdown geometry (θ0, l_td), the centre-of-pressure roll, the eq. 2 control of both
legs (K, a, b, c, T_c, the cubic term e and the two pulses of ``WalkControl``) and the cycle's times.
The SI view multiplies by l0 [m], m [kg] and g, so :meth:`WalkingMachine.scaled` is dynamic similarity
(Table 1): lengths × L, times × √L, speeds × √L, forces × M; dimensionless numbers, angles and
body-weight forces unchanged (the pulses are dimensionless too: amplitudes in l0, centres and widths in
stance phase, so scaling needs no change for them).

JSON (all keys always present)::

  schema, kind: "walking", source, mass_kg, l0_m, g_m_s2,
  cycle: {u, v, d, s, theta0_rad, l_td, roll, K, a, b, c, e, p, tau_p, w_p, q, tau_q, w_q, T_c, t_stance,
          t_double, t_step, step_length, mean_speed, periodicity, iterations}  # dimensionless
  (e and the pulses p, tau_p, w_p, q, tau_q, w_q may be absent in older files: e = p = q = 0, the control
  they were fitted with)
  cycle_si: {...}                                                               # derived, informative
  frame: {heading, lateral, up, ground_m}
  reference: {...measured on the clip, SI...}, quality: {...}, fit: {...}
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
from .units import speed_unit, time_unit
from .walking import PULSES_OFF, ControlPulses, WalkControl, WalkState, simulate_walk

__all__ = ["WALK_SCHEMA", "WalkingMachine", "load_walking_machine"]

WALK_SCHEMA = "froude.walking/1"
_CYCLE = ("u", "v", "d", "s", "l_td", "roll", "K", "a", "b", "c", "e", "p", "tau_p", "w_p", "q", "tau_q", "w_q", "T_c",
          "t_stance", "t_double", "t_step", "step_length", "mean_speed", "periodicity")
#: Cycle keys that files written before them lack, with the value that keeps their machine (off).
_CYCLE_DEFAULTS = {"e": 0.0, **PULSES_OFF}


@dataclass(frozen=True)
class WalkingMachine(ControlPulses):
    """A periodic walking cycle of the two-leg machine fitted to a reference walk.

    Dimensionless (units l0, √(l0/g), √(g l0), m g): touchdown state u, v (COM velocity), d (COM ahead of
    the trailing touchdown point), s (time since the trailing touchdown); theta0 [rad] and l_td (leg
    length at touchdown) place the landing foot; roll: centre-of-pressure travel per unit τ; K, a, b, c,
    e, T_c: the leg control of both legs (``WalkControl``: eq. 2 with a cubic term e); p, tau_p, w_p and q,
    tau_q, w_q: its push-off and weight-acceptance pulses (amplitude [l0], centre and half-width [stance
    phase]; p = q = 0: off, as in files written before them); t_stance, t_double
    (one double support), t_step; step_length;
    mean_speed (the Froude number U of the gait); periodicity: max |next − state| at the cycle; iterations:
    simulator evaluations of the cycle searches (``machine.orbit.solve_orbit``: points and Jacobians).
    SI: mass [kg], l0 [m] (mean touchdown leg length COM → touchdown point), g [m/s²].
    reference / quality / fit: measured figures, fit-quality figures and the control fit (SI, BW).
    """

    u: float
    v: float
    d: float
    s: float
    theta0: float
    l_td: float
    roll: float
    K: float
    a: float
    b: float
    c: float
    e: float
    T_c: float
    t_stance: float
    t_double: float
    t_step: float
    step_length: float
    mean_speed: float
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
    reference: dict = field(default_factory=dict)
    quality: dict = field(default_factory=dict)
    fit: dict = field(default_factory=dict)

    kind = "walking"

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
    def control(self) -> WalkControl:
        return WalkControl(**{k: getattr(self, k) for k in WalkControl.NAMES})

    @property
    def state(self) -> WalkState:
        return WalkState(self.u, self.v, self.d, self.s)

    @property
    def step_time(self) -> float:
        """Touchdown → next touchdown [√(l0/g)] (the running machine's name for it)."""
        return self.t_step

    @property
    def U(self) -> float:
        """The walk's Froude number U = mean speed / √(g l0) (the running machine's apex speed; a walk's speed
        has no apex to be taken at)."""
        return self.mean_speed

    @property
    def double_support_fraction(self) -> float:
        """Share of the gait cycle with both feet down: 2 t_double / (2 t_step)."""
        return self.t_double / self.t_step

    def si(self) -> dict:
        """The cycle in SI."""
        T, L = self.time_unit, self.l0
        return {"k_N_m": self.K * self.mass * self.g / L, "l0_m": L, "theta0_deg": math.degrees(self.theta0),
                "touchdown_leg_m": self.l_td * L, "roll_m": self.roll * L, "stance_time_s": self.t_stance * T,
                "double_support_s": self.t_double * T, "step_time_s": self.t_step * T,
                "step_frequency_hz": 1.0 / (self.t_step * T), "step_length_m": self.step_length * L,
                "mean_speed_m_s": self.mean_speed_m_s, "double_support_fraction": self.double_support_fraction}

    def path(self, times_s) -> dict:
        """The periodic walk of this machine at times ``times_s`` (N,) [s] ≥ 0, in SI, sagittal.

        Time 0 is a touchdown of foot 0 with its COM at forward position 0; foot 0 leads the even steps,
        foot 1 the odd ones. Returns a dict of arrays:
          p_com (N, 2) COM (forward, up) [m]; v_com (N, 2) [m/s]; force (N, 2) total ground force [N];
          contact (N, 2) bool per foot; cop (N, 2) forward position of each foot's centre of pressure [m]
          (NaN off the ground); step (N,) int, the step each time belongs to.
        This is what synthesis needs of the machine: where the COM goes and which foot is down where.
        """
        T, L = self.time_unit, self.l0
        t = np.asarray(times_s, float) / T
        if t.ndim != 1 or not np.all(np.isfinite(t)) or (t.size and t.min() < 0):
            raise FitError("path times must be a finite, non-negative 1-D array [s]")
        k, ph = np.divmod(t, self.t_step)
        k = k.astype(int)
        tr = simulate_walk(self.state, self.theta0, self.control, ph, roll=self.roll, l_td=self.l_td)
        shift = k * self.step_length
        p = np.stack([tr.pos[:, 0] + shift, tr.pos[:, 1]], axis=1)
        contact = np.zeros((t.size, 2), bool)
        cop = np.full((t.size, 2), np.nan)
        lead, trail = k % 2, (k + 1) % 2
        rows = np.arange(t.size)
        contact[rows, lead] = True
        on_trail = ph <= tr.t_liftoff
        contact[rows[on_trail], trail[on_trail]] = True
        for leg, foot in ((1, lead), (0, trail)):
            x = tr.contact_x[leg] + shift + self.roll * (ph - tr.t_touchdown[leg]) / self.T_c
            sel = contact[rows, foot]
            cop[rows[sel], foot[sel]] = x[sel]
        mg = self.mass * self.g
        return {"p_com": p * L, "v_com": tr.vel * self.speed_unit, "force": tr.total_force * mg,
                "contact": contact, "cop": cop * L, "step": k}

    def scaled(self, L: float, M: float = 1.0) -> WalkingMachine:
        """The dynamically similar machine for a character L times longer and M times heavier."""
        if not (L > 0 and M > 0):
            raise FitError(f"scale factors must be > 0 (L={L}, M={M})")
        return replace(self, mass=self.mass * M, l0=self.l0 * L, ground=self.ground * L,
                       source=self.source + f" (scaled L={L:g}, M={M:g})")

    def to_dict(self) -> dict:
        cyc = {k: getattr(self, k) for k in _CYCLE}
        cyc["theta0_rad"] = self.theta0
        cyc["iterations"] = self.iterations
        return {"schema": WALK_SCHEMA, "kind": "walking", "source": self.source, "mass_kg": self.mass,
                "l0_m": self.l0, "g_m_s2": self.g, "cycle": cyc, "cycle_si": self.si(),
                "frame": {"heading": self.heading, "lateral": self.lateral, "up": self.up, "ground_m": self.ground},
                "reference": self.reference, "quality": self.quality, "fit": self.fit}

    @classmethod
    def from_dict(cls, d: dict, where: str = "machine") -> WalkingMachine:
        if not isinstance(d, dict) or d.get("schema") != WALK_SCHEMA:
            got = d.get("schema") if isinstance(d, dict) else type(d).__name__
            raise FitError(f"{where}: not a froude walking machine file (schema {got!r}, expected {WALK_SCHEMA!r})")
        try:
            c, fr = d["cycle"], d["frame"]
            # files written before the cubic term or the pulses have none: their control is the one they were
            # fitted with (e = 0, pulses off)
            kw = {k: float(c[k] if k not in _CYCLE_DEFAULTS else c.get(k, _CYCLE_DEFAULTS[k])) for k in _CYCLE}
            return cls(**kw, theta0=float(c["theta0_rad"]), iterations=int(c["iterations"]),
                       mass=float(d["mass_kg"]), l0=float(d["l0_m"]), g=float(d["g_m_s2"]), source=str(d["source"]),
                       heading=np.asarray(fr["heading"], float), lateral=np.asarray(fr["lateral"], float),
                       up=np.asarray(fr["up"], float), ground=float(fr["ground_m"]),
                       reference=dict(d["reference"]), quality=dict(d["quality"]), fit=dict(d["fit"]))
        except (KeyError, TypeError, ValueError) as e:
            raise FitError(f"{where}: malformed {WALK_SCHEMA} file ({type(e).__name__}: {e})") from None

    def save(self, path) -> None:
        """Write the machine as JSON, atomically (no NaN: unmeasurable figures are null)."""
        atomic_write_text(path, dumps(self.to_dict(), indent=1) + "\n")


def load_walking_machine(path) -> WalkingMachine:
    """Read a ``froude.walking/1`` JSON file; FitError with the path on any problem."""
    p = Path(path)
    try:
        d = json.loads(p.read_text())
    except OSError as e:
        raise FitError(f"{path}: cannot read ({e.strerror})") from None
    except json.JSONDecodeError as e:
        raise FitError(f"{path}:{e.lineno}: not valid JSON ({e.msg})") from None
    return WalkingMachine.from_dict(d, str(path))
