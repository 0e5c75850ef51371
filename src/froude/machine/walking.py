"""The dimensionless simple walking machine: a bipedal spring-mass model with controlled legs.

The walking counterpart of :mod:`froude.machine.dynamics` (Geyer, Seyfarth & Blickhan 2006, Proc. R.
Soc. B 273:2861: a point mass on two massless compliant legs, with double support, which reproduces
the M-shaped vertical force and the vaulting COM path of human walking). Each leg is controlled as in
Pollard's eq. 2, with the same control for both legs (a symmetric gait)::

    f_i = K (l_d(τ_i) − l_i),   l_d(τ) = 1 + a + b τ + c τ² + e τ³ + two pulses,
    τ_i = (t − t_touchdown,i) / T_c

(``WalkControl``: the running machine's ``Control`` and a cubic term e, which lets the weight-acceptance
half of a stance differ from the push-off half: with e = 0 the fitted l_d came out symmetric about
mid-stance, b ≈ −c, and so did the force's peaks. The two pulses, short smooth extensions of the leg
just past the other foot's touchdown (push-off, p) and in weight acceptance (q), give each double
support two force maxima, the trailing leg's push-off and the leading leg's loading, as a walk's
COM-derived force has; amplitude 0 is off.)

along the leg from its contact point to the COM, in the sagittal plane: x forward, y up, ground y = 0.
Units are those of the running machine (touchdown leg length l0 = 1, g = 1, m = 1; see the table in
:mod:`froude.machine.dynamics`; ``froude.machine.units`` converts).

One *step* runs from a touchdown to the next (the Poincaré section of the gait):

* touchdown: the swinging leg lands at angle θ0 from vertical, ahead of the COM, when the COM height
  falls to cos θ0 (Geyer's landing rule, dimensionless). The state there is ``WalkState``:
  (u, v) the COM velocity, d the COM's distance ahead of the trailing foot, s the time since the
  trailing leg touched down;
* double support: both legs push (a leg is clamped at ≥ 0 force until it first pushes, "armed", as in
  the running machine); it ends when the trailing leg's force falls to zero (its liftoff);
* single support on the leading leg until the next touchdown. A leg force falling to zero here would
  be a flight phase (running, not walking): the step is invalid.

A periodic gait is a fixed point of the step map (u', v', d', s') = (u, v, d, s); its stance time is
s + t_double and its double-support time t_double. Integration is classical RK4 with a fixed step
``T_c / N_PER_STANCE``; events are located inside a step by secant iterations on partial RK4 steps
(≈1e-13), so the step map is smooth in its inputs for finite-difference Jacobians. Rows are integrated
one at a time with plain floats: a cycle search needs ~10 rows per call, where scalar code beats
NumPy (as in the running machine's small-batch path).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import ClassVar

import numpy as np

from ..body.com_force import parabola_vertex
from ..errors import PlanError
from .dynamics import Control, _hermite

__all__ = ["WalkControl", "ControlPulses", "PULSES_OFF", "WalkState", "desired_leg_length", "WalkStep",
           "WalkTrajectory", "RecordedStep", "walk_step", "record_step", "simulate_walk", "N_PER_STANCE",
           "REASONS", "OK"]

#: RK4 steps per nominal stance T_c.
N_PER_STANCE = 240
#: COM height [l0] at or below which the machine has collapsed.
MIN_COM_HEIGHT = 0.2
#: Longest allowed phase, in units of T_c.
MAX_PHASE_FACTOR = 3.0

OK = 0
BAD_INPUT = 1        #: non-finite input, K ≤ 0, T_c ≤ 0, s < 0, θ0 outside (0, π/2) or a pulse of width ≤ 0
NO_DOUBLE_SUPPORT = 2  #: the trailing leg pushes no more at touchdown (a flight phase came before)
COLLAPSE = 3         #: COM height ≤ MIN_COM_HEIGHT
STALL = 4            #: forward velocity ≤ 0
NO_EVENT = 5         #: a phase longer than MAX_PHASE_FACTOR · T_c
FLIGHT = 6           #: the stance leg's force fell to zero in single support: running, not walking
LOW_VAULT = 7        #: the COM fell below the landing height before passing over the stance foot
REASONS = {
    OK: "ok", BAD_INPUT: "bad input (non-finite, K <= 0, T_c <= 0, s < 0, theta0 outside (0, 90) deg or a pulse "
                         "of width <= 0)",
    NO_DOUBLE_SUPPORT: "the trailing leg is already unloaded at touchdown (no double support)",
    COLLAPSE: "COM collapsed (height <= 0.2 l0)", STALL: "forward velocity <= 0 (stall)",
    NO_EVENT: "no liftoff or touchdown within the phase time limit",
    FLIGHT: "the machine's stance leg unloaded in single support (the machine would take off where a walk "
            "keeps its foot down)",
    LOW_VAULT: "the COM fell below the landing height before vaulting over the stance foot",
}


@dataclass(frozen=True, kw_only=True)
class ControlPulses:
    """The walking control's two pulses (``WalkControl``), keyword fields shared by the control and the
    fitted machine (``walk_model.WalkingMachine``, which stores them in its JSON): amplitudes p, q [l0],
    centres tau_p, tau_q and half-widths w_p, w_q [stance phase]. The defaults are off (amplitudes 0;
    centres and widths then do nothing), as in files written before the pulses."""

    p: float = 0.0
    tau_p: float = 0.85
    w_p: float = 0.04
    q: float = 0.0
    tau_q: float = 0.15
    w_q: float = 0.075


#: The pulse fields with their off values (the defaults of ``ControlPulses``).
PULSES_OFF: dict[str, float] = {f.name: float(getattr(ControlPulses, f.name)) for f in fields(ControlPulses)}


@dataclass(frozen=True)
class WalkControl(Control, ControlPulses):
    """The walking leg control: eq. 2's (K, a, b, c, T_c), a cubic coefficient e [l0 per unit τ³] and two
    pulses (scalar fields)::

        l_d = 1 + a + b τ + c τ² + e τ³ + p B((τ − tau_p) / w_p) + q B((τ − tau_q) / w_q),
        B(x) = cos²(π x / 2) for |x| < 1, else 0                         (a smooth bump, C¹, compact)

    p [l0]: the push-off pulse, centred at tau_p just past the other foot's touchdown (an extension of the
    trailing leg there, as an ankle's push-off); q [l0]: the weight-acceptance pulse of the leading leg,
    centred at tau_q; w_p, w_q: half-widths in stance phase. In a machine with massless legs they also
    stand in for the legs' own inertia, which puts force into a clip's COM at those instants
    (docs/walking.md, Limitations). A plain ``Control`` is a WalkControl with
    e = p = q = 0 (``desired_leg_length``)."""

    e: float = 0.0

    NAMES: ClassVar[tuple[str, ...]] = ("K", "a", "b", "c", "T_c", "e", "p", "tau_p", "w_p", "q", "tau_q", "w_q")

    def as_tuple(self):
        """(K, a, b, c, T_c, e, p, tau_p, w_p, q, tau_q, w_q)."""
        return (self.K, self.a, self.b, self.c, self.T_c, self.e, self.p, self.tau_p, self.w_p, self.q, self.tau_q,
                self.w_q)


@dataclass(frozen=True)
class WalkState:
    """The state at a touchdown (dimensionless): COM velocity (u forward, v up) [√(g l0)], the COM's
    horizontal distance d ahead of the trailing contact [l0], the time s since the trailing leg's
    touchdown [√(l0/g)]. The COM height there is cos θ0 and the new contact is sin θ0 ahead of it."""

    u: float
    v: float
    d: float
    s: float

    def as_tuple(self):
        return (self.u, self.v, self.d, self.s)


@dataclass(frozen=True)
class WalkStep:
    """One step touchdown → touchdown (dimensionless; x from the COM at the first touchdown).

    next: the WalkState at the next touchdown; t_double: double support (touchdown → trailing liftoff);
    t_step: touchdown → next touchdown; t_stance = s + t_double: the trailing leg's whole stance;
    step_length: contact → next contact [l0]; y_min: lowest COM height (in double support) [l0];
    y_max: highest [l0]; valid, reason (see REASONS).
    """

    next: WalkState | None
    t_double: float
    t_step: float
    t_stance: float
    step_length: float
    y_min: float
    y_max: float
    valid: bool
    reason: int


def _ld(tau, a1, b, c, e):
    return a1 + tau * (b + tau * (c + e * tau))


def desired_leg_length(control: Control, tau) -> np.ndarray:
    """l_d(τ) [l0] of a walking leg control (``WalkControl``; a running ``Control`` has no cubic term and
    no pulses) at stance phases tau (N,)."""
    tau = np.asarray(tau, float)
    ld = _ld(tau, 1.0 + control.a, control.b, control.c, getattr(control, "e", 0.0))
    for amp, centre, width in _pulses(control):
        x = (tau - centre) / width
        ld = ld + amp * np.where(np.abs(x) < 1.0, np.cos(0.5 * np.pi * np.clip(x, -1.0, 1.0)) ** 2, 0.0)
    return ld


def _pulses(control) -> list[tuple[float, float, float]]:
    """[(amplitude, centre, half-width)] of the control's pulses that are on (amplitude ≠ 0)."""
    out = [(float(getattr(control, amp, 0.0)), float(getattr(control, "tau_" + amp, 0.0)),
            float(getattr(control, "w_" + amp, 1.0))) for amp in ("p", "q")]
    return [pl for pl in out if pl[0] != 0.0]


class _Machine:
    """Scalar RK4 of the two-leg machine for one control; legs given as (contact x, touchdown time)."""

    def __init__(self, ctl: Control, n_per_stance: int, roll: float = 0.0):
        self.roll = float(roll)
        self.K = float(ctl.K)
        self.a1 = 1.0 + float(ctl.a)
        self.b = float(ctl.b)
        self.c = float(ctl.c)
        self.e = float(getattr(ctl, "e", 0.0))  # a running Control has no cubic term
        self.pulses = _pulses(ctl)
        self.ctl = ctl
        self.Tc = float(ctl.T_c)
        self.h = self.Tc / n_per_stance

    def ld(self, tau):
        """l_d(τ) (scalar, as ``desired_leg_length``; the bump B of ``WalkControl`` written out, as in ``accel``)."""
        v = self.a1 + tau * (self.b + tau * (self.c + self.e * tau))
        for amp, centre, width in self.pulses:
            xb = (tau - centre) / width
            if -1.0 < xb < 1.0:
                cx = math.cos(0.5 * math.pi * xb)
                v += amp * (cx * cx)
        return v

    def leg(self, x, y, t, xc, t0, armed):
        """(force along the leg [m g], unclamped g = l_d − l, ux, uy) of one leg.

        The centre of pressure rolls forward from the touchdown point xc at ``roll`` l0 per unit τ.
        """
        tau = (t - t0) / self.Tc
        dx = x - xc - self.roll * tau
        l = math.sqrt(dx * dx + y * y)
        g = self.ld(tau) - l
        f = self.K * (g if armed else max(g, 0.0))
        return f, g, dx / l, y / l

    def accel(self, x, y, t, legs, armed):
        """(ax, ay) of the COM [g]: gravity and the legs' forces (``accel_fn``'s, for one point)."""
        return self.accel_fn(legs, armed)(x, y, t)

    def accel_fn(self, legs, armed):
        """acc(x, y, t) → (ax, ay) of the COM [g] with these legs [(contact x, touchdown time)] and arming
        flags: gravity and the legs' forces (``leg`` written out, with ``ld``, and the control's constants
        bound once: this is the simulator's inner loop, where calls and attribute look-ups cost more than
        the arithmetic; the same operations in the same order, so the result is the same to the bit)."""
        K, Tc, roll, a1, b, c, e = self.K, self.Tc, self.roll, self.a1, self.b, self.c, self.e
        pulses = tuple(self.pulses)
        legs_armed = tuple((float(xc), float(t0), bool(arm)) for (xc, t0), arm in zip(legs, armed))
        sqrt, cos, half_pi = math.sqrt, math.cos, 0.5 * math.pi
        if len(pulses) == 2 and all(armed):
            return _accel_two_pulses(self, legs_armed)

        def acc(x, y, t):
            ax, ay = 0.0, -1.0
            for xc, t0, arm in legs_armed:
                tau = (t - t0) / Tc
                dx = x - xc - roll * tau
                l = sqrt(dx * dx + y * y)
                v = a1 + tau * (b + tau * (c + e * tau))
                for amp, centre, width in pulses:
                    xb = (tau - centre) / width
                    if -1.0 < xb < 1.0:
                        cx = cos(half_pi * xb)
                        v += amp * (cx * cx)
                g = v - l
                f = K * (g if arm else max(g, 0.0))
                ax += f * (dx / l)
                ay += f * (y / l)
            return ax, ay

        return acc

    def slack_fn(self, xc, t0):
        """g(x, y, t) = l_d − l of one leg (``leg``'s g, with the control's constants bound once)."""
        Tc, roll, a1, b, c, e = self.Tc, self.roll, self.a1, self.b, self.c, self.e
        pulses = tuple(self.pulses)
        sqrt, cos, half_pi = math.sqrt, math.cos, 0.5 * math.pi

        def g(x, y, t):
            tau = (t - t0) / Tc
            dx = x - xc - roll * tau
            l = sqrt(dx * dx + y * y)
            v = a1 + tau * (b + tau * (c + e * tau))
            for amp, centre, width in pulses:
                xb = (tau - centre) / width
                if -1.0 < xb < 1.0:
                    cx = cos(half_pi * xb)
                    v += amp * (cx * cx)
            return v - l

        return g

    def rk4(self, s, t, h, legs, armed):
        """One RK4 step of size h from state s = (x, y, vx, vy) at time t."""
        return _rk4(self.accel_fn(legs, armed), s, t, h)

    @staticmethod
    def _crossing(acc, s, t, h, fn, e0, e1):
        """(σ, state at t + σ): the partial step σ ∈ (0, h] where fn(state, time) falls from e0 > 0 to ≤ 0
        (regula falsi, Illinois); acc: the phase's ``accel_fn``."""
        lo, hi, flo, fhi = 0.0, h, e0, e1
        sig = h * e0 / (e0 - e1)
        side = 0  # which end the last iterate replaced (+1 lo, −1 hi)
        for _ in range(60):
            q = _rk4(acc, s, t, sig)
            em = fn(q, t + sig)
            if abs(em) <= 1e-14 or hi - lo <= 1e-15:
                return sig, q
            # Illinois: the kept end's value is halved only when the same end was replaced twice in a row
            # (halving it every time made the iterates alternate sides and the bracket merely halve: ~30
            # iterations an event where this takes 4-8).
            if em > 0.0:
                lo, flo = sig, em
                if side == 1:
                    fhi *= 0.5
                side = 1
            else:
                hi, fhi = sig, em
                if side == -1:
                    flo *= 0.5
                side = -1
            sig = lo + (hi - lo) * flo / (flo - fhi)
        return sig, _rk4(acc, s, t, sig)

    def run_phase(self, s, t, legs, armed, event, t_max, nodes=None):
        """Integrate until event(state, t) crosses from > 0 to ≤ 0; returns (state, t, armed, reason).

        armed: list of bools; a slack leg is armed at the exact time it starts to push (located like the
        event, and the integration restarts there), so the step map has no kink from the force clamp.
        nodes: optional list to which (t, x, y, vx, vy) of every node is appended (event points included).
        """
        armed = list(armed)
        acc = self.accel_fn(legs, armed)
        slack = {i: self.slack_fn(xc, t0) for i, (xc, t0) in enumerate(legs) if not armed[i]}
        e0 = event(s, t)
        h = self.h
        while True:
            if t > t_max:
                return s, t, armed, NO_EVENT
            s1 = _rk4(acc, s, t, h)
            e1 = event(s1, t + h)
            if e0 > 0.0 and e1 <= 0.0:
                sig, s_end = self._crossing(acc, s, t, h, event, e0, e1)
                if nodes is not None:
                    nodes.append((t + sig, *s_end))
                return s_end, t + sig, armed, OK
            h_taken = h
            for i, gi in slack.items():
                if gi(s1[0], s1[1], t + h) > 0.0:
                    def neg_slack(q, tq, gi=gi):
                        return -gi(q[0], q[1], tq)

                    g0 = neg_slack(s, t)
                    if g0 > 0.0:
                        h_taken, s1 = self._crossing(acc, s, t, h, neg_slack, g0, neg_slack(s1, t + h))
                    armed[i] = True
                    del slack[i]
                    acc = self.accel_fn(legs, armed)
                    break
            # The event at the new node is e1 unless a leg was armed inside the step (which moves the node):
            # evaluating it again cost a sixth of the walking fit (issue 29).
            same_node = h_taken == h
            s, t = s1, t + h_taken
            e0 = e1 if same_node else event(s, t)
            if nodes is not None:
                nodes.append((t, *s))
            if s[1] <= MIN_COM_HEIGHT:
                return s, t, armed, COLLAPSE
            if s[2] <= 0.0:
                return s, t, armed, STALL


def _accel_two_pulses(mc: _Machine, legs_armed):
    """``_Machine.accel_fn`` of one or two armed legs under a control with both pulses on (the shape fit's
    usual case), its loops over the legs and pulses unrolled: a third less time per call in the simulator's
    inner loop, the same operations in the same order (the same result to the bit)."""
    K, Tc, roll, a1, b, c, e = mc.K, mc.Tc, mc.roll, mc.a1, mc.b, mc.c, mc.e
    (ap, cp, wp), (aq, cq, wq) = mc.pulses
    sqrt, cos, half_pi = math.sqrt, math.cos, 0.5 * math.pi
    (xc1, t1, _) = legs_armed[-1]

    if len(legs_armed) == 1:
        def one(x, y, t):
            tau = (t - t1) / Tc
            dx = x - xc1 - roll * tau
            l = sqrt(dx * dx + y * y)
            v = a1 + tau * (b + tau * (c + e * tau))
            xb = (tau - cp) / wp
            if -1.0 < xb < 1.0:
                cx = cos(half_pi * xb)
                v += ap * (cx * cx)
            xb = (tau - cq) / wq
            if -1.0 < xb < 1.0:
                cx = cos(half_pi * xb)
                v += aq * (cx * cx)
            f = K * (v - l)
            return 0.0 + f * (dx / l), -1.0 + f * (y / l)

        return one
    (xc0, t0, _) = legs_armed[0]

    def two(x, y, t):
        tau = (t - t0) / Tc
        dx = x - xc0 - roll * tau
        l = sqrt(dx * dx + y * y)
        v = a1 + tau * (b + tau * (c + e * tau))
        xb = (tau - cp) / wp
        if -1.0 < xb < 1.0:
            cx = cos(half_pi * xb)
            v += ap * (cx * cx)
        xb = (tau - cq) / wq
        if -1.0 < xb < 1.0:
            cx = cos(half_pi * xb)
            v += aq * (cx * cx)
        f = K * (v - l)
        ax, ay = 0.0 + f * (dx / l), -1.0 + f * (y / l)
        tau = (t - t1) / Tc
        dx = x - xc1 - roll * tau
        l = sqrt(dx * dx + y * y)
        v = a1 + tau * (b + tau * (c + e * tau))
        xb = (tau - cp) / wp
        if -1.0 < xb < 1.0:
            cx = cos(half_pi * xb)
            v += ap * (cx * cx)
        xb = (tau - cq) / wq
        if -1.0 < xb < 1.0:
            cx = cos(half_pi * xb)
            v += aq * (cx * cx)
        f = K * (v - l)
        return ax + f * (dx / l), ay + f * (y / l)

    return two


def _rk4(acc, s, t, h):
    """One RK4 step of size h from state s = (x, y, vx, vy) at time t; acc(x, y, t) → (ax, ay)."""
    x, y, vx, vy = s
    k1x, k1y = acc(x, y, t)
    hh = 0.5 * h
    x2, y2, vx2, vy2 = x + hh * vx, y + hh * vy, vx + hh * k1x, vy + hh * k1y
    k2x, k2y = acc(x2, y2, t + hh)
    x3, y3, vx3, vy3 = x + hh * vx2, y + hh * vy2, vx + hh * k2x, vy + hh * k2y
    k3x, k3y = acc(x3, y3, t + hh)
    x4, y4, vx4, vy4 = x + h * vx3, y + h * vy3, vx + h * k3x, vy + h * k3y
    k4x, k4y = acc(x4, y4, t + h)
    h6 = h / 6.0
    return (x + h6 * (vx + 2 * vx2 + 2 * vx3 + vx4), y + h6 * (vy + 2 * vy2 + 2 * vy3 + vy4),
            vx + h6 * (k1x + 2 * k2x + 2 * k3x + k4x), vy + h6 * (k1y + 2 * k2y + 2 * k3y + k4y))


def _valid_inputs(state: WalkState, theta0: float, ctl: Control) -> bool:
    vals = (*state.as_tuple(), theta0, *map(float, ctl.as_tuple()))
    return (all(math.isfinite(v) for v in vals) and ctl.K > 0 and ctl.T_c > 0 and state.s >= 0
            and 0.0 < theta0 < 0.5 * math.pi and all(w > 0 for _, _, w in _pulses(ctl)))


def _one_step(state: WalkState, theta0: float, ctl: Control, n_per_stance: int, record: bool, roll: float = 0.0,
              l_td: float = 1.0):
    """The step map with optional node recording; returns (WalkStep, nodes, t_liftoff, legs)."""
    bad = WalkStep(None, math.nan, math.nan, math.nan, math.nan, math.nan, math.nan, False, BAD_INPUT)
    if not (_valid_inputs(state, theta0, ctl) and l_td > 0 and math.isfinite(roll)):
        return bad, None, math.nan, None
    mc = _Machine(ctl, n_per_stance, roll)
    y_td = l_td * math.cos(theta0)
    x_lead = l_td * math.sin(theta0)
    legs = [(-state.d, -state.s), (x_lead, 0.0)]  # trailing, leading
    s0 = (0.0, y_td, state.u, state.v)
    f_trail, g_trail, _, _ = mc.leg(0.0, y_td, 0.0, -state.d, -state.s, True)
    if not g_trail > 0.0:
        return replace_reason(bad, NO_DOUBLE_SUPPORT), None, math.nan, None
    nodes = [(0.0, *s0)] if record else None
    t_max = MAX_PHASE_FACTOR * mc.Tc
    lead_armed = mc.leg(0.0, y_td, 0.0, x_lead, 0.0, True)[1] > 0.0

    trail_slack = mc.slack_fn(-state.d, -state.s)

    def trail_event(s, t):
        return trail_slack(s[0], s[1], t)

    s1, t_lo, armed, code = mc.run_phase(s0, 0.0, legs, [True, lead_armed], trail_event, t_max, nodes)
    if code != OK:
        return replace_reason(bad, code), nodes, math.nan, legs
    y_min = min(n[2] for n in nodes) if nodes else math.nan
    stance_leg = [legs[1]]

    def td_event(s, t):
        # Next touchdown: the COM descends through cos θ0 after vaulting over the stance foot. Until
        # then the stance leg must push (the second event below): a flight phase is not a walk.
        return s[1] - y_td if (s[3] < 0.0 and s[0] > x_lead) else 1.0

    # Single support: watch for the leg unloading as well as for the touchdown.
    lead_slack = mc.slack_fn(x_lead, 0.0)
    lead_pushes = armed[1]

    def both(s, t):  # td_event written out (called at every node)
        td = s[1] - y_td if (s[3] < 0.0 and s[0] > x_lead) else 1.0
        return min(td, lead_slack(s[0], s[1], t) if lead_pushes else 1.0)

    s2, t_td, _, code = mc.run_phase(s1, t_lo, stance_leg, [armed[1]], both, t_lo + t_max, nodes)
    if code != OK:
        return replace_reason(bad, code), nodes, t_lo, legs
    if abs(s2[1] - y_td) > 1e-9:
        unloaded = mc.leg(s2[0], s2[1], t_td, x_lead, 0.0, True)[1] <= 1e-9
        return replace_reason(bad, FLIGHT if unloaded else LOW_VAULT), nodes, t_lo, legs
    ys = [n[2] for n in nodes] if nodes else [s1[1], s2[1]]
    nxt = WalkState(u=s2[2], v=s2[3], d=s2[0] - x_lead, s=t_td)
    ws = WalkStep(next=nxt, t_double=t_lo, t_step=t_td, t_stance=state.s + t_lo, step_length=s2[0],
                  y_min=min(y_min, min(ys)) if record else math.nan,
                  y_max=max(ys) if record else math.nan, valid=True, reason=OK)
    return ws, nodes, t_lo, legs


def replace_reason(w: WalkStep, code: int) -> WalkStep:
    return WalkStep(None, math.nan, math.nan, math.nan, math.nan, math.nan, math.nan, False, code)


def walk_step(state: WalkState, theta0: float, control: Control, *, roll: float = 0.0, l_td: float = 1.0,
              n_per_stance: int = N_PER_STANCE) -> WalkStep:
    """One step of the walking machine, touchdown → next touchdown (see module doc).

    state: the touchdown state; theta0: touchdown angle from vertical [rad]; control: the eq. 2 control
    of both legs (a WalkControl, or a Control for e = 0; scalar fields). Returns a WalkStep (``valid``
    False with a ``reason`` code, never raises).
    """
    return _one_step(state, float(theta0), control, n_per_stance, False, roll, l_td)[0]


@dataclass(frozen=True)
class WalkTrajectory:
    """Dense machine trajectory of one step (dimensionless), starting at a touchdown at x = 0, t = 0.

    t: (S,) [√(l0/g)]; pos, vel: (S, 2) COM; force: (S, 2, 2) per leg (0 trailing, 1 leading) force on
    the COM [m g], zero when the leg is off the ground; contact_x: (2,) trailing, leading contact x [l0];
    t_touchdown: (2,) their touchdown times (trailing < 0); t_liftoff: trailing leg's liftoff;
    t_step: time of the next touchdown.
    """

    t: np.ndarray
    pos: np.ndarray
    vel: np.ndarray
    force: np.ndarray
    contact_x: np.ndarray
    t_touchdown: np.ndarray
    t_liftoff: float
    t_step: float

    @property
    def total_force(self) -> np.ndarray:
        """(S, 2) ground force on the COM from both legs [m g]."""
        return self.force.sum(axis=1)


class RecordedStep:
    """One step integrated once, sampled at any times after (:func:`record_step`).

    step: the WalkStep (``valid`` False: :meth:`sample` raises PlanError naming the reason).
    """

    def __init__(self, state, theta0, control, n_per_stance, roll, l_td):
        self.step, nodes, self._t_lo, self._legs = _one_step(state, float(theta0), control, n_per_stance, True,
                                                             roll, l_td)
        self._why = (f"walking step invalid: {REASONS[self.step.reason]} (u={state.u:.4g}, v={state.v:.4g}, "
                     f"d={state.d:.4g}, s={state.s:.4g}, theta0={theta0:.4g})")
        if not self.step.valid:
            return
        self._mc = mc = _Machine(control, n_per_stance, roll)
        arr = np.array(nodes)  # (M, 5): t, x, y, vx, vy
        # drop duplicate times (an event node can coincide with the next regular node)
        self._nodes = arr = arr[np.concatenate([[True], np.diff(arr[:, 0]) > 1e-12])]
        # accelerations at the nodes (Hermite velocities); a leg's force is never a pull (clamped)
        tk, x, y = arr[:, 0], arr[:, 1], arr[:, 2]
        ax, ay = np.zeros(tk.size), np.full(tk.size, -1.0)
        for i, (xc, t0) in enumerate(self._legs):  # the trailing leg until its liftoff, then the leading
            on = tk <= self._t_lo if i == 0 else np.ones(tk.size, bool)
            f, ux, uy = _leg_force(mc, x[on], y[on], tk[on], xc, t0)
            ax[on] += f * ux
            ay[on] += f * uy
        self._acc = np.stack([ax, ay], axis=1)

    def positions(self, times) -> tuple[np.ndarray, np.ndarray]:
        """(pos (S, 2), vel (S, 2)) of the COM at ``times`` (S,) in [0, t_step] [√(l0/g)] (clipped): cubic
        Hermite positions and velocities between the RK4 nodes (``sample`` without the legs' forces)."""
        if not self.step.valid:
            raise PlanError(self._why)
        arr, acc = self._nodes, self._acc
        t = np.clip(np.asarray(times, float), 0.0, self.step.t_step)
        k = np.clip(np.searchsorted(arr[:, 0], t, side="right") - 1, 0, arr.shape[0] - 2)
        n0, n1 = arr[k], arr[k + 1]
        pos = np.empty((t.size, 2))
        vel = np.empty((t.size, 2))
        for d in range(2):
            pos[:, d] = _hermite(n0[:, 0], n1[:, 0], n0[:, 1 + d], n0[:, 3 + d], n1[:, 1 + d], n1[:, 3 + d], t)
            vel[:, d] = _hermite(n0[:, 0], n1[:, 0], n0[:, 3 + d], acc[k, d], n1[:, 3 + d], acc[k + 1, d], t)
        return pos, vel

    def sample(self, times) -> WalkTrajectory:
        """Dense samples at ``times`` (S,) in [0, t_step] [√(l0/g)] (clipped): cubic Hermite positions and
        velocities between the RK4 nodes, leg forces from the model (eq. 2) at those positions."""
        if not self.step.valid:
            raise PlanError(self._why)
        mc, legs, t_lo = self._mc, self._legs, self._t_lo
        t = np.clip(np.asarray(times, float), 0.0, self.step.t_step)
        pos, vel = self.positions(t)
        force = np.zeros((t.size, 2, 2))
        for i, (xc, t0) in enumerate(legs):
            on = t <= t_lo if i == 0 else np.ones(t.size, bool)
            tau = (t - t0) / mc.Tc
            rel = pos - np.stack([xc + mc.roll * tau, np.zeros_like(tau)], axis=1)
            l = np.linalg.norm(rel, axis=1)
            f = mc.K * np.maximum(desired_leg_length(mc.ctl, tau) - l, 0.0)
            force[:, i] = np.where(on[:, None], (f / l)[:, None] * rel, 0.0)
        return WalkTrajectory(t=t, pos=pos, vel=vel, force=force, contact_x=np.array([legs[0][0], legs[1][0]]),
                              t_touchdown=np.array([legs[0][1], legs[1][1]]), t_liftoff=float(t_lo),
                              t_step=float(self.step.t_step))


def _leg_force(mc: _Machine, x, y, t, xc: float, t0: float):
    """(f (N,) force along the leg [m g], clamped ≥ 0; ux, uy (N,) its unit vector contact → COM) of one leg
    (contact xc, touchdown t0) at COM positions x, y and times t (N,) each: ``_Machine.accel_fn``'s leg over
    arrays, the same operations in the same order (to the cosine's last bit)."""
    tau = (t - t0) / mc.Tc
    dx = x - xc - mc.roll * tau
    l = np.sqrt(dx * dx + y * y)
    f = mc.K * np.maximum(desired_leg_length(mc.ctl, tau) - l, 0.0)
    return f, dx / l, y / l


def record_step(state: WalkState, theta0: float, control: Control, *, roll: float = 0.0, l_td: float = 1.0,
                n_per_stance: int = N_PER_STANCE) -> RecordedStep:
    """Integrate one step once (like :func:`walk_step`) and keep its nodes for :meth:`RecordedStep.sample`."""
    return RecordedStep(state, theta0, control, n_per_stance, roll, l_td)


#: Samples of the single-support phase at which :func:`single_support_trough` looks for the force minimum.
TROUGH_SAMPLES = 400


def single_support_trough(rec: RecordedStep) -> float:
    """The lowest total vertical ground force [m g] in the single support of a recorded step (trailing
    liftoff → next touchdown); nan where the step is invalid.

    The minimum of TROUGH_SAMPLES samples refined by the parabola through it and its neighbours
    (``body.com_force.parabola_vertex``): a bare sample minimum jumps as the trough moves between samples,
    and the cycle search differentiates this value by finite differences."""
    w = rec.step
    if not w.valid:
        return math.nan
    t = np.linspace(w.t_double, w.t_step, TROUGH_SAMPLES)
    f = rec.sample(t).total_force[:, 1]
    return parabola_vertex(t, f, int(np.argmin(f)))[0]


def simulate_walk(state: WalkState, theta0: float, control: Control, times, *, roll: float = 0.0,
                  l_td: float = 1.0, n_per_stance: int = N_PER_STANCE) -> WalkTrajectory:
    """Dense samples of one step at ``times`` (S,) in [0, t_step] [√(l0/g)] (clipped).

    Positions and velocities are cubic Hermite interpolations of the RK4 nodes; leg forces are
    evaluated from the model (eq. 2) at the interpolated positions. Raises PlanError if the step is
    invalid.
    """
    return record_step(state, theta0, control, roll=roll, l_td=l_td, n_per_stance=n_per_stance).sample(times)
