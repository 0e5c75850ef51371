"""The simple machine placed in the world and the time warp of the reference cycle onto its steps (§6).

``machine_path`` simulates the (scaled) machine for any number of steps, places it in the world along the
reference's heading frame and maps every output time to a reference stride phase ψ, stance→stance and
flight→flight (piecewise linear, knots at every touchdown, liftoff and marker contact).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..core.constants import GRAVITY, UP_AXIS
from ..machine.dynamics import simulate
from .cycle import ReferenceCycle, sample_cycle


@dataclass(frozen=True, eq=False)
class MachinePath:
    """The simple machine's motion in world coordinates at the output frame rate (SI).

    times: (T,) [s]; com: (T, 3) [m]; force: (T, 3) ground force on the COM [N]; psi: (T,) unwrapped stride
    phase (0 at the first touchdown of foot A); stance: (T, 2) bool (the machine's force-based stance);
    contact: (T, 2) bool, the foot on the ground (the reference's marker contact through the time warp,
    a little wider than the stance); foot_of_step: (n,) 0/1; t_touchdown, t_liftoff: (n,) [s];
    contact_on, contact_off: (n,) [s]; contacts: (n, 3) contact points [m]; apex_speed: (n+1,) [m/s];
    U: (n+1,) dimensionless apex speeds; frame: (3, 3) heading frame rows; l0 [m]; mass [kg].
    """

    times: np.ndarray
    com: np.ndarray
    force: np.ndarray
    psi: np.ndarray
    stance: np.ndarray
    contact: np.ndarray
    foot_of_step: np.ndarray
    t_touchdown: np.ndarray
    t_liftoff: np.ndarray
    contact_on: np.ndarray
    contact_off: np.ndarray
    contacts: np.ndarray
    apex_speed: np.ndarray
    U: np.ndarray
    frame: np.ndarray
    l0: float
    mass: float

    @property
    def frame_time(self) -> float:
        return float(self.times[1] - self.times[0]) if len(self.times) > 1 else 0.0


def machine_path(
    cycle: ReferenceCycle,
    m,
    L: float,
    origin: np.ndarray,
    *,
    stretch: float = 1.0,
    n_steps: int,
    fps: float,
    theta0=None,
    controls=None,
    start_state: tuple[float, float] | None = None,
) -> MachinePath:
    """Simulate a machine for n_steps steps and place it in the world.

    cycle: the reference cycle (heading frame, foot order, phase events, lateral offsets);
    m: the SimpleMachine already scaled to the character (``machine.scaled(L, M)``); L: the character's
    length ratio [-] (scales the cycle's lateral sway); origin: (3,) [m] the reference COM's start, put
    on the floor; stretch: §5.2 horizontal stretch factor s (vertical motion and timing unchanged);
    fps: output frame rate [Hz].
    theta0: per-step touchdown angles (n_steps,) [rad] (default: the cycle's); controls: per-step Controls;
    start_state: apex (U, H) to start from (default: the periodic cycle's).
    """
    T_unit = m.time_unit
    dt = 1.0 / fps / T_unit
    if theta0 is None and controls is None and start_state is None:
        tr = _periodic_trajectory(m, n_steps, dt)
    else:
        th = np.full(n_steps, m.theta0) if theta0 is None else np.asarray(theta0, float)
        U0, H0 = (m.U, m.H) if start_state is None else start_state
        tr = simulate(U0, H0, th, m.control if controls is None else controls, dt)
    cyc = cycle
    Rh = cyc.frame
    fwd, up, lat = Rh
    l0 = m.l0
    t = tr.t * T_unit
    A = cyc.first_foot
    feet = np.where(np.arange(n_steps) % 2 == 0, A, 1 - A)
    t_td = tr.t_touchdown * T_unit
    t_lo = tr.t_liftoff * T_unit
    psi, _, _, contact_on, contact_off = _stride_phase(t, t_td, t_lo, feet, A, cyc.phase_events,
                                                       cyc.contact_phase, tr, T_unit)
    phi = np.mod(psi, 1.0)
    _, data = sample_cycle(cyc, phi, rotations=False)
    origin = np.array(origin, dtype=float)
    origin[UP_AXIS] = 0.0
    com = (origin + np.outer(stretch * tr.pos[:, 0] * l0, fwd) + np.outer(tr.pos[:, 1] * l0, up)
           + np.outer(L * data["com_lateral"], lat))
    contacts = (origin + np.outer(stretch * tr.contact_x * l0, fwd)
                + np.outer(L * cyc.contact_lateral[feet], lat))
    force = (np.outer(stretch * tr.force[:, 0], fwd) + np.outer(tr.force[:, 1], up)) * m.mass * GRAVITY
    stance = np.zeros((len(t), 2), bool)
    contact = np.zeros((len(t), 2), bool)
    for i, f in enumerate(feet):
        stance[(t >= t_td[i]) & (t < t_lo[i]), f] = True
        contact[(t >= contact_on[i]) & (t < contact_off[i]), f] = True
    return MachinePath(
        times=t, com=com, force=force, psi=psi, stance=stance, contact=contact, foot_of_step=feet,
        t_touchdown=t_td, t_liftoff=t_lo, contact_on=contact_on, contact_off=contact_off, contacts=contacts,
        apex_speed=stretch * tr.U_apex * m.speed_unit, U=tr.U_apex,
        frame=Rh, l0=l0, mass=m.mass,
    )


@dataclass(frozen=True)
class _Tiled:
    """The fields of machine.dynamics.Trajectory that machine_path uses (dimensionless)."""

    t: np.ndarray
    pos: np.ndarray
    force: np.ndarray
    t_touchdown: np.ndarray
    t_liftoff: np.ndarray
    contact_x: np.ndarray
    U_apex: np.ndarray
    t_apex: np.ndarray


def _periodic_trajectory(m, n_steps: int, dt: float) -> _Tiled:
    """n_steps of the periodic cycle: one stride simulated at the output times modulo the stride, tiled.

    The cycle is periodic to 1e-9, so this equals simulating every step while costing one stride.
    """
    T2, dx = 2.0 * m.step_time, 2.0 * m.step_length
    n_frames = int(math.floor(n_steps * m.step_time / dt + 1e-9)) + 1
    t = np.arange(n_frames) * dt
    k = np.floor(t / T2 + 1e-12)
    tau = t - k * T2
    one = simulate(m.U, m.H, np.full(2, m.theta0), m.control, dt, times=tau)
    pos = one.pos.copy()
    pos[:, 0] += k * dx
    i = np.arange(n_steps)
    shift = (i // 2) * T2
    return _Tiled(
        t=t, pos=pos, force=one.force, t_touchdown=one.t_touchdown[i % 2] + shift,
        t_liftoff=one.t_liftoff[i % 2] + shift, contact_x=one.contact_x[i % 2] + (i // 2) * dx,
        U_apex=np.full(n_steps + 1, m.U), t_apex=np.arange(n_steps + 1) * m.step_time,
    )


def _stride_phase(t, t_td, t_lo, feet, A, phase_events, contact_phase, tr, T_unit):
    """Unwrapped reference stride phase of each output time, and each step's ground contact [s].

    The time warp is piecewise linear with knots at every touchdown and liftoff (stance→stance,
    flight→flight, paper §6), plus knots where the foot reaches and leaves the ground as the reference's
    markers see it (contact_phase, a little outside the force-based stance): those stretches are played at
    the stance's rate, so the body travels as far over the planted foot as in the reference whatever the
    flight time is. Returns (psi (T,), knot times, knot phases, contact_on (n,), contact_off (n,)).
    """
    p = {(A, "td"): 0.0, (A, "lo"): phase_events[1], (1 - A, "td"): phase_events[2], (1 - A, "lo"): phase_events[3]}
    n = len(feet)
    k = np.arange(n) // 2
    psi_td = k + np.array([p[(f, "td")] for f in feet])
    psi_lo = k + np.array([p[(f, "lo")] for f in feet])
    ext_before = np.array([p[(f, "td")] - contact_phase[f, 0] for f in feet])  # [phase] before touchdown
    ext_after = np.array([contact_phase[f, 1] - p[(f, "lo")] for f in feet])  # [phase] after liftoff
    rate = (t_lo - t_td) / (psi_lo - psi_td)  # [s per phase] in each stance
    # the flights around each step, in time (the first and last from the machine's own flight time)
    flight_time = (t_td[1:] - t_lo[:-1]) if n > 1 else np.array([(tr.t_apex[-1] * T_unit - t_lo[-1]) * 2])
    fl_before = np.concatenate([[flight_time[0]], flight_time])[:n]
    fl_after = np.concatenate([flight_time, [flight_time[-1]]])[:n]
    on_t = t_td - ext_before * rate
    off_t = t_lo + ext_after * rate
    # never let the extensions eat a flight: keep at least 20 % of each flight as true flight
    room_before = 0.4 * fl_before
    room_after = 0.4 * fl_after
    on_t = np.maximum(on_t, t_td - room_before)
    off_t = np.minimum(off_t, t_lo + room_after)
    knots_t: list[float] = []
    knots_psi: list[float] = []
    for i in range(n):
        knots_t += [on_t[i], t_td[i], t_lo[i], off_t[i]]
        knots_psi += [psi_td[i] - ext_before[i], psi_td[i], psi_lo[i], psi_lo[i] + ext_after[i]]
    last_f = feet[-1]
    next_td_psi = k[-1] + (1.0 if last_f == 1 - A else phase_events[2])
    times = np.array([t_td[0] - fl_before[0]] + knots_t + [t_lo[-1] + fl_after[-1]])
    psis = np.array([p[(1 - A, "lo")] - 1.0] + knots_psi + [next_td_psi])
    return np.interp(t, times, psis), times, psis, on_t, off_t
