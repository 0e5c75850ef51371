"""The dimensionless simple running machine (Pollard 1999, Fig. 1 right; §4 eq. 2; §5.3 eq. 5).

A point mass on a massless, actuated spring leg, in the sagittal plane: x forward, y up, ground
at y = 0. Everything here is **dimensionless**: touchdown leg length l0 = 1, g = 1, m = 1.

=============  ==========================  =====================================
quantity       dimensionless unit          to SI
=============  ==========================  =====================================
length         l0                          × l0 [m]
time           √(l0/g)                     × √(l0/g) [s]
velocity       √(g l0)  (U is the Froude)  × √(g l0) [m/s]
acceleration   g                           × g [m/s²]
force          m g  (body weights)         × m g [N]
stiffness      m g / l0   (K)              × m g / l0 [N/m]
=============  ==========================  =====================================

Phases of one *step* (apex → apex):

* fall: ballistic from the apex (x = 0, y = H, ẋ = U, ẏ = 0) until the COM height is cos θ0 while
  descending; the foot lands at x_c = x_td + sin θ0 (ahead of the COM), y = 0, and stays put;
* stance: force along the leg (contact → COM) of magnitude f = K (l_d(τ) − l), l = |COM − contact|,
  l_d(τ) = 1 + a + b τ + c τ², τ = (t − t_td)/T_c. τ may exceed 1 (the polynomial is extrapolated).
  If a < 0 the leg is slack at touchdown: the force is clamped at 0 until it first becomes
  positive ("armed"); after that the model force is used unclamped;
* liftoff: the first time (after arming) the force would pull, f = 0 crossing from > 0 to ≤ 0,
  i.e. l = l_d(τ). Located to ~1e-13 in time by Newton iterations on partial integration steps;
* rise: ballistic to the next apex (U', H').

Stance is integrated by classical RK4 (in its exact Runge–Kutta–Nyström form, since the
acceleration depends on position and time only) with a fixed step per row
h = 1 / (n √(1/T_c² + K/π²)) — i.e. ≈ n steps per nominal stance or per half spring period,
whichever is shorter. h is a smooth function of (K, T_c) so finite-difference Jacobians of the
step map are clean.

Everything is vectorised over broadcast arrays of states, angles and control parameters: the
same code serves a single step, a batch of finite-difference perturbations and a transition
table of 10⁵–10⁶ points. Invalid rows are flagged (``valid`` False, ``reason`` code) and their
outputs set to NaN, so a NaN never hides behind ``valid`` True.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import ClassVar

import numpy as np

from froude.core.constants import GRAVITY
from froude.errors import PlanError
from froude.machine.units import time_unit

__all__ = [
    "Control", "StepResult", "Trajectory", "step", "simulate", "fall_time", "energy",
    "REASONS", "OK", "BAD_INPUT", "APEX_BELOW_TOUCHDOWN", "COLLAPSE", "STALL", "NO_LIFTOFF",
    "LIFTOFF_DESCENDING", "N_PER_STANCE", "MIN_COM_HEIGHT", "MAX_STANCE_FACTOR",
]

# --- invalid-reason codes (StepResult.reason) -------------------------------------------------
OK = 0
BAD_INPUT = 1             #: non-finite input, U ≤ 0, K ≤ 0 or T_c ≤ 0
APEX_BELOW_TOUCHDOWN = 2  #: H < cos θ0: the leg cannot reach the ground from this apex
COLLAPSE = 3              #: COM height ≤ MIN_COM_HEIGHT during stance (or cos θ0 that low)
STALL = 4                 #: horizontal velocity ≤ 0 during stance
NO_LIFTOFF = 5            #: stance longer than MAX_STANCE_FACTOR · T_c
LIFTOFF_DESCENDING = 6    #: liftoff with vertical velocity ≤ 0: there is no next apex
REASONS = {
    OK: "ok", BAD_INPUT: "bad input (non-finite, U <= 0, K <= 0 or T_c <= 0)",
    APEX_BELOW_TOUCHDOWN: "apex below touchdown height (H < cos theta0)",
    COLLAPSE: "COM collapsed (height <= 0.2 l0) in stance",
    STALL: "horizontal velocity <= 0 in stance (stall)",
    NO_LIFTOFF: "no liftoff within the stance time limit",
    LIFTOFF_DESCENDING: "liftoff with downward velocity (no next apex)",
}

#: Default RK4 steps per nominal stance (or per half spring period, whichever is shorter).
N_PER_STANCE = 48
#: Up to this many rows, step() integrates each row with the scalar twin instead of the NumPy batch.
SMALL_BATCH = 16
#: COM height [l0] at or below which stance is declared a collapse.
MIN_COM_HEIGHT = 0.2
#: Longest allowed stance, in units of the nominal stance duration T_c.
MAX_STANCE_FACTOR = 5.0
#: Rows integrated together; keeps the ~40 work arrays inside L2 cache.
CHUNK = 16384


# --- data ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Control:
    """Dimensionless stance control of eq. 2: f = K (l_d(τ) − l), l_d = 1 + a + b τ + c τ².

    K:   leg stiffness k l0/(m g) [-]
    a:   desired-length offset at touchdown [l0]
    b:   linear coefficient [l0 per unit τ]
    c:   quadratic coefficient [l0 per unit τ²]
    T_c: nominal stance duration [√(l0/g)]; τ = (t − t_touchdown)/T_c

    Fields are floats, or arrays that broadcast against the state arrays (batch evaluation).
    """

    K: float
    a: float = 0.0
    b: float = 0.0
    c: float = 0.0
    T_c: float = 1.0

    NAMES: ClassVar[tuple[str, ...]] = ("K", "a", "b", "c", "T_c")

    def as_tuple(self):
        """(K, a, b, c, T_c)."""
        return (self.K, self.a, self.b, self.c, self.T_c)

    def to_si(self, m_kg, l0_m, g=GRAVITY):
        """dict of SI values: k [N/m], a, b, c [m], T_c [s], l0 [m], m [kg]."""
        return {"k": float(self.K) * m_kg * g / l0_m, "a": float(self.a) * l0_m,
                "b": float(self.b) * l0_m, "c": float(self.c) * l0_m,
                "T_c": float(self.T_c) * time_unit(l0_m, g), "l0": float(l0_m), "m": float(m_kg)}

    @classmethod
    def from_si(cls, k_N_per_m, a_m, b_m, c_m, T_c_s, m_kg, l0_m, g=GRAVITY):
        """Dimensionless Control from SI: k [N/m], a, b, c [m], T_c [s], m [kg], l0 [m]."""
        return cls(K=k_N_per_m * l0_m / (m_kg * g), a=a_m / l0_m, b=b_m / l0_m, c=c_m / l0_m,
                   T_c=T_c_s / time_unit(l0_m, g))


@dataclass(frozen=True)
class StepResult:
    """Result of :func:`step`, every field an array of the broadcast input shape S.

    Positions are relative to the starting apex (x = 0); all dimensionless (see module doc).

    U_next, H_next:  next apex state [√(g l0)], [l0]
    t_fall:          apex → touchdown [√(l0/g)]
    t_stance:        touchdown → liftoff
    t_rise:          liftoff → next apex
    t_flight:        liftoff → next touchdown = t_rise + fall_time(H_next, θ0), assuming the next
                     step uses the same θ0; NaN where H_next < cos θ0 even if ``valid``
    x_touchdown:     COM x at touchdown [l0]
    vy_touchdown:    COM vertical velocity at touchdown (≤ 0)
    x_contact:       foot (contact point) x during stance [l0]
    x_liftoff, y_liftoff, vx_liftoff, vy_liftoff: COM state at liftoff
    apex_dx:         next apex x − this apex x [l0]
    step_length:     next contact x − this contact x with the same θ0 next step (NaN like t_flight)
    peak_force:      largest leg force in stance [m g] (parabolic refinement on the RK4 nodes)
    valid:           bool, the apex → apex step is physically valid
    reason:          int8 code, see REASONS (0 = ok)
    """

    U_next: np.ndarray
    H_next: np.ndarray
    t_fall: np.ndarray
    t_stance: np.ndarray
    t_rise: np.ndarray
    t_flight: np.ndarray
    x_touchdown: np.ndarray
    vy_touchdown: np.ndarray
    x_contact: np.ndarray
    x_liftoff: np.ndarray
    y_liftoff: np.ndarray
    vx_liftoff: np.ndarray
    vy_liftoff: np.ndarray
    apex_dx: np.ndarray
    step_length: np.ndarray
    peak_force: np.ndarray
    valid: np.ndarray
    reason: np.ndarray


def fall_time(H, theta0):
    """Apex → touchdown time √(2 (H − cos θ0)) [√(l0/g)]; NaN where H < cos θ0."""
    drop = np.asarray(H, float) - np.cos(theta0)
    with np.errstate(invalid="ignore"):
        return np.where(drop >= 0.0, np.sqrt(np.maximum(drop, 0.0) * 2.0), np.nan)


def energy(pos, vel, contact=None, stance=None, control=None, tau=None):
    """Mechanical energy [m g l0] = ½|v|² + y (+ spring ½ K (l_d − l)² in stance).

    pos, vel: (..., 2) COM position and velocity; contact: (..., 2) contact point; stance: (...)
    bool; tau: (...) stance phase (for l_d). The spring term is only the potential of a passive
    spring, i.e. energy is conserved only for a = b = c = 0 (then l_d ≡ 1).
    """
    pos = np.asarray(pos, float)
    vel = np.asarray(vel, float)
    e = 0.5 * np.sum(vel * vel, axis=-1) + pos[..., 1]
    if control is not None and contact is not None and stance is not None:
        l = np.linalg.norm(pos - np.nan_to_num(np.asarray(contact, float)), axis=-1)
        tau = np.zeros_like(l) if tau is None else np.nan_to_num(np.asarray(tau, float))
        ld = 1.0 + control.a + tau * (control.b + control.c * tau)
        e = e + np.where(stance, 0.5 * control.K * (ld - l) ** 2, 0.0)
    return e


# --- stance integration -------------------------------------------------------------------------
def _desired_length(tau, a1, b, c):
    """l_d(τ) = 1 + a + b τ + c τ² with a1 = 1 + a."""
    ld = c * tau
    ld += b
    ld *= tau
    ld += a1
    return ld


def _accel(px, py, ld, K, armed):
    """Leg acceleration at COM position (px, py) relative to the contact, desired length ld.

    Returns (ax, ay, g) with g = l_d − l (force = K g). ``armed`` None means all rows armed;
    otherwise unarmed rows have the force clamped at ≥ 0 (slack leg before first push).
    """
    l = px * px
    l += py * py
    np.sqrt(l, out=l)
    g = ld - l
    if armed is not None:
        g = np.where(armed, g, np.maximum(g, 0.0))
    fl = K * g
    fl /= l
    ax = fl * px
    fl *= py
    fl -= 1.0
    return ax, fl, g


def _partial_step(px, py, vx, vy, ax1, ay1, s, tau0, invTc, K, a1, b, c):
    """One RK4 (Nyström form) step of per-row size s from a node; all rows armed.

    Returns the end state (px, py, vx, vy), g = l_d − l there and dg/dt there.
    """
    hs = 0.5 * s
    s2 = s * s
    tm = tau0 + hs * invTc
    te = tau0 + s * invTc
    x2 = px + hs * vx
    y2 = py + hs * vy
    ldm = _desired_length(tm, a1, b, c)
    lde = _desired_length(te, a1, b, c)
    ax2, ay2, _ = _accel(x2, y2, ldm, K, None)
    ax3, ay3, _ = _accel(x2 + 0.25 * s2 * ax1, y2 + 0.25 * s2 * ay1, ldm, K, None)
    xe = px + s * vx
    ye = py + s * vy
    ax4, ay4, _ = _accel(xe + 0.5 * s2 * ax2, ye + 0.5 * s2 * ay2, lde, K, None)
    s6 = s / 6.0
    pxn = xe + s * s6 * (ax1 + ax2 + ax3)
    pyn = ye + s * s6 * (ay1 + ay2 + ay3)
    vxn = vx + s6 * (ax1 + 2.0 * (ax2 + ax3) + ax4)
    vyn = vy + s6 * (ay1 + 2.0 * (ay2 + ay3) + ay4)
    l = np.sqrt(pxn * pxn + pyn * pyn)
    g = lde - l
    gdot = (b + 2.0 * c * te) * invTc - (pxn * vxn + pyn * vyn) / l
    return pxn, pyn, vxn, vyn, g, gdot


def _rk4_node(px, py, vx, vy, ax1, ay1, h, tau0, htau, K, a1, b, c, arm):
    """One classical RK4 step of size h (N,) [√(l0/g)] from the node (px, py, vx, vy) (N,) [l0], [√(g l0)] with
    its acceleration (ax1, ay1) [g], written for x'' = f(t, x) (identical result, fewer operations); tau0 (N,)
    the node's time / T_c, htau = h / T_c; arm: None (all armed) or (N,) bool. Returns the new node
    (pxn, pyn, vxn, vyn) and l_d there (lde) [l0]."""
    hh = 0.5 * h
    h2 = h * h
    tm = tau0 + 0.5 * htau
    te = tau0 + htau
    ldm = _desired_length(tm, a1, b, c)
    lde = _desired_length(te, a1, b, c)
    x2 = hh * vx
    x2 += px
    y2 = hh * vy
    y2 += py
    ax2, ay2, _ = _accel(x2, y2, ldm, K, arm)
    q = 0.25 * h2
    t3 = q * ax1
    t3 += x2
    u3 = q * ay1
    u3 += y2
    ax3, ay3, _ = _accel(t3, u3, ldm, K, arm)
    xe = h * vx
    xe += px
    ye = h * vy
    ye += py
    q = 0.5 * h2
    t4 = q * ax2
    t4 += xe
    u4 = q * ay2
    u4 += ye
    ax4, ay4, _ = _accel(t4, u4, lde, K, arm)
    q = h2 * (1.0 / 6.0)
    sx = ax1 + ax2
    sx += ax3
    pxn = q * sx
    pxn += xe
    sy = ay1 + ay2
    sy += ay3
    pyn = q * sy
    pyn += ye
    sx += ax2
    sx += ax3
    sx += ax4
    sx *= h * (1.0 / 6.0)
    vxn = sx
    vxn += vx
    sy += ay2
    sy += ay3
    sy += ay4
    sy *= h * (1.0 / 6.0)
    vyn = sy
    vyn += vy
    return pxn, pyn, vxn, vyn, lde


def _liftoff(L, g1, gn, h, node, ctl, k: int):
    """Liftoff of the rows L (N,) bool whose leg force ends within the step from node k: Newton on the partial
    step size s ∈ (0, h]: g(node + s) = 0. g1, gn (N,) l_d − l at the step's ends; node = (px, py, vx, vy,
    ax1, ay1) (N,) each; ctl = (tau0, invTc, K, a1, b, c) (N,) each. Returns (t (n_L,) the stance time
    [√(l0/g)], px, py, vx, vy (n_L,) at liftoff)."""
    g0 = np.maximum(g1[L], 0.0)
    hL = h[L]
    den = g0 - gn[L]
    s = np.where(den > 0.0, hL * g0 / np.where(den > 0.0, den, 1.0), hL)
    px, py, vx, vy, ax1, ay1 = (x[L] for x in node)
    tau0, invTc, K, a1, b, c = (x[L] for x in ctl)
    for _ in range(8):
        qx, qy, wx, wy, gs, gd = _partial_step(px, py, vx, vy, ax1, ay1, s, tau0, invTc, K, a1, b, c)
        ds = np.where(gd < 0.0, gs / gd, 0.0)
        s = np.clip(s - ds, 0.0, hL)
        if np.all(np.abs(ds) <= 1e-13):
            break
    qx, qy, wx, wy, gs, gd = _partial_step(px, py, vx, vy, ax1, ay1, s, tau0, invTc, K, a1, b, c)
    return k * hL + s, qx, qy, wx, wy


def _refined_peak(fm, fb, fa):
    """Peak force [m g] per row: the vertex of the parabola through three equally spaced nodes (fb, fm, fa),
    only where both neighbours exist and the max is a strict interior one; else the node's fm."""
    den = fb - 2.0 * fm + fa
    with np.errstate(invalid="ignore", divide="ignore"):
        d = np.where(den < 0.0, 0.5 * (fb - fa) / den, 0.0)
        refined = fm - 0.25 * (fb - fa) * d
    return np.where(np.isfinite(refined) & (np.abs(d) <= 1.0), refined, fm)


def _finish(out: dict, rows, t, qx, qy, wx, wy, reason, peak) -> None:
    """Write the liftoff (or failure) of rows into the (N,) arrays of out."""
    out["t"][rows] = t
    out["px"][rows] = qx
    out["py"][rows] = qy
    out["vx"][rows] = wx
    out["vy"][rows] = wy
    out["reason"][rows] = reason
    out["fmax"][rows] = peak


def _end_failed(finish, alive, pyn, vxn) -> None:
    """End the rows still in stance (alive (N,) bool) whose new node has collapsed (COM height pyn ≤
    MIN_COM_HEIGHT [l0]) or stalled (vxn ≤ 0), by finish(rows, t, px, py, vx, vy, reason) with NaN states;
    the stalls after the collapses, so that a row ends once."""
    b1 = alive & (pyn <= MIN_COM_HEIGHT)
    if b1.any():
        finish(b1, np.nan, np.nan, np.nan, np.nan, np.nan, COLLAPSE)
    b1 = alive & (vxn <= 0.0)
    if b1.any():
        finish(b1, np.nan, np.nan, np.nan, np.nan, np.nan, STALL)


def _stance_steps(K, Tc, n_per_stance, max_stance):
    """(h [√(l0/g)], 1/T_c, h/T_c, the most steps before NO_LIFTOFF), each (N,): n_per_stance RK4 steps per
    1/√(1/T_c² + K/π²), a time below both the nominal stance T_c and the spring's half period π/√K."""
    h = 1.0 / (n_per_stance * np.sqrt(1.0 / (Tc * Tc) + K * (1.0 / math.pi ** 2)))
    invTc = 1.0 / Tc
    htau = h * invTc
    return h, invTc, htau, np.ceil(max_stance * Tc / h)


def _touchdown_accel(px, py, a1, K):
    """(ax, ay) [g], g = max(l_d − l, 0) [l0] and armed (N,) bool at touchdown: a leg already compressed is
    armed; the others push only once compressed (their force clamped at ≥ 0 until then)."""
    ax1, ay1, g1 = _accel(px, py, a1, K, None)
    armed = g1 > 0.0
    g1 = np.maximum(g1, 0.0)
    if not armed.all():
        ax1, ay1, _ = _accel(px, py, a1, K, armed)
    return ax1, ay1, g1, armed


def _integrate_stance(px, py, vx, vy, K, a, b, c, Tc, n_per_stance, max_stance):
    """Integrate stance for N rows from touchdown to liftoff (or failure).

    px, py: (N,) COM position relative to the contact [l0]; vx, vy: (N,) velocity; K, a, b, c,
    Tc: (N,) control. Returns dict of (N,) arrays: t [√(l0/g)] stance duration, px, py, vx, vy at
    liftoff, fmax [m g], reason (int8; OK / COLLAPSE / STALL / NO_LIFTOFF). The loop is the twin of
    _integrate_stance_scalar's (the two must agree to 1e-12).
    """
    N = px.shape[0]
    h, invTc, htau, kmax = _stance_steps(K, Tc, n_per_stance, max_stance)
    a1 = 1.0 + a
    out = {key: np.full(N, np.nan) for key in ("t", "px", "py", "vx", "vy", "fmax")}
    out["reason"] = np.full(N, NO_LIFTOFF, dtype=np.int8)
    idx = np.arange(N)
    ax1, ay1, g1, armed = _touchdown_accel(px, py, a1, K)
    alive = np.ones(N, bool)
    # Peak-force tracking: value at the max node and its two neighbours (parabolic refinement).
    f_prev = K * g1
    fmax, f_before, f_after, just_max = f_prev.copy(), np.full(N, np.nan), np.full(N, np.nan), np.ones(N, bool)

    def finish(sel, t, qx, qy, wx, wy, reason):
        _finish(out, idx[sel], t, qx, qy, wx, wy, reason, _refined_peak(fmax[sel], f_before[sel], f_after[sel]))
        alive[sel] = False

    kmin_max = kmax.min() if N else 0.0
    k = 0
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        while idx.size:
            all_armed = bool(armed.all())
            tau0 = k * htau
            pxn, pyn, vxn, vyn, lde = _rk4_node(px, py, vx, vy, ax1, ay1, h, tau0, htau, K, a1, b, c,
                                                None if all_armed else armed)
            # Acceleration at the new node: stage 1 of the next step, and the event function.
            ax1n, ay1n, gn = _accel(pxn, pyn, lde, K, None)

            lift = gn <= 0.0
            lift &= armed
            lift &= alive
            if lift.any():
                t_lo, qx, qy, wx, wy = _liftoff(lift, g1, gn, h, (px, py, vx, vy, ax1, ay1),
                                                (tau0, invTc, K, a1, b, c), k)
                finish(lift, t_lo, qx, qy, wx, wy, OK)
            armed |= gn > 0.0
            # Failures (only rows still in stance); one combined test first, it rarely fires.
            bad = pyn <= MIN_COM_HEIGHT
            bad |= vxn <= 0.0
            if bad.any():
                _end_failed(finish, alive, pyn, vxn)
            if k + 1 >= kmin_max:
                b1 = alive & (k + 1 >= kmax)
                if b1.any():
                    finish(b1, np.nan, np.nan, np.nan, np.nan, np.nan, NO_LIFTOFF)

            # Peak force bookkeeping at the new node (in place: no new arrays per step).
            fn = np.maximum(gn, 0.0)
            fn *= K
            np.copyto(f_after, fn, where=just_max)
            np.greater(fn, fmax, out=just_max)
            np.copyto(f_before, f_prev, where=just_max)
            np.copyto(fmax, fn, where=just_max)
            f_prev = fn

            px, py, vx, vy = pxn, pyn, vxn, vyn
            if not all_armed:
                ax1n, ay1n, _ = _accel(px, py, lde, K, armed)
            ax1, ay1, g1 = ax1n, ay1n, gn
            k += 1
            n_alive = int(np.count_nonzero(alive))
            if n_alive == 0:
                break
            if n_alive < 0.75 * idx.size:
                # Compact: drop finished rows so later steps only pay for live ones.
                (idx, px, py, vx, vy, ax1, ay1, g1, K, a1, b, c, h, htau, invTc, kmax, armed, f_prev, fmax,
                 f_before, f_after, just_max) = (x[alive] for x in (
                    idx, px, py, vx, vy, ax1, ay1, g1, K, a1, b, c, h, htau, invTc, kmax, armed, f_prev, fmax,
                    f_before, f_after, just_max))
                alive = np.ones(idx.size, bool)
                kmin_max = kmax.min()
    return out


def _stance_steps_scalar(K, Tc, n_per_stance, max_stance):
    """Plain-float twin of :func:`_stance_steps`: (h [√(l0/g)], 1/T_c, h/T_c, the most steps (int))."""
    h = 1.0 / (n_per_stance * math.sqrt(1.0 / (Tc * Tc) + K * (1.0 / math.pi ** 2)))
    invTc = 1.0 / Tc
    return h, invTc, h * invTc, math.ceil(max_stance * Tc / h)


def _partial_step_scalar(acc, px, py, vx, vy, ax1, ay1, s, tau0, invTc, a1, b, c):
    """Plain-float twin of :func:`_partial_step` (one RK4 step of size s, armed), acc the row's
    acceleration (x, y, l_d, armed) -> (ax, ay, g). Returns (px, py, vx, vy, g, dg/dt) at its end."""
    hs = 0.5 * s
    s2 = s * s
    tm = tau0 + hs * invTc
    te = tau0 + s * invTc
    ldm = a1 + tm * (b + c * tm)
    lde = a1 + te * (b + c * te)
    x2 = px + hs * vx
    y2 = py + hs * vy
    ax2, ay2, _ = acc(x2, y2, ldm, True)
    ax3, ay3, _ = acc(x2 + 0.25 * s2 * ax1, y2 + 0.25 * s2 * ay1, ldm, True)
    xe = px + s * vx
    ye = py + s * vy
    ax4, ay4, _ = acc(xe + 0.5 * s2 * ax2, ye + 0.5 * s2 * ay2, lde, True)
    s6 = s / 6.0
    pxn = xe + s * s6 * (ax1 + ax2 + ax3)
    pyn = ye + s * s6 * (ay1 + ay2 + ay3)
    vxn = vx + s6 * (ax1 + 2.0 * (ax2 + ax3) + ax4)
    vyn = vy + s6 * (ay1 + 2.0 * (ay2 + ay3) + ay4)
    l = math.sqrt(pxn * pxn + pyn * pyn)
    return pxn, pyn, vxn, vyn, lde - l, (b + 2.0 * c * te) * invTc - (pxn * vxn + pyn * vyn) / l


def _liftoff_scalar(acc, node, g1, gn, h, k, tau0, invTc, a1, b, c):
    """Plain-float twin of :func:`_liftoff` for one row: Newton on the partial step size s ∈ (0, h] from node
    k = (px, py, vx, vy, ax1, ay1). Returns (t [√(l0/g)], px, py, vx, vy at liftoff, its node (t, px, py,
    vx, vy, ax, ay))."""
    px, py, vx, vy, ax1, ay1 = node
    g0 = max(g1, 0.0)
    s = h * g0 / (g0 - gn) if g0 - gn > 0.0 else h
    for _ in range(8):
        qx, qy, wx, wy, gs, gd = _partial_step_scalar(acc, px, py, vx, vy, ax1, ay1, s, tau0, invTc, a1, b, c)
        ds = gs / gd if gd < 0.0 else 0.0
        s = min(max(s - ds, 0.0), h)
        if abs(ds) <= 1e-13:
            break
    qx, qy, wx, wy, gs, gd = _partial_step_scalar(acc, px, py, vx, vy, ax1, ay1, s, tau0, invTc, a1, b, c)
    t_lo = k * h + s
    tl = t_lo * invTc
    axl, ayl, _ = acc(qx, qy, a1 + tl * (b + c * tl), True)
    return t_lo, qx, qy, wx, wy, (t_lo, qx, qy, wx, wy, axl, ayl)


def _refined_peak_scalar(fmax, f_before, f_after):
    """Plain-float twin of :func:`_refined_peak` for one row [m g]."""
    den = f_before - 2.0 * fmax + f_after
    if den < 0.0:
        d = 0.5 * (f_before - f_after) / den
        if abs(d) <= 1.0:
            return fmax - 0.25 * (f_before - f_after) * d
    return fmax


def _integrate_stance_scalar(px, py, vx, vy, K, a, b, c, Tc, n_per_stance, max_stance,
                             record=False):
    """Single-row twin of :func:`_integrate_stance` in plain floats (no NumPy per-call overhead:
    ~10× faster for one step, used by :func:`simulate` and by :func:`step` on one row).

    Same scheme, step size, arming, events and failure rules. Returns a dict of floats (t, px,
    py, vx, vy, fmax, reason) and, with ``record``, 'nodes': list of (t, px, py, vx, vy, ax, ay)
    tuples from touchdown to the liftoff node inclusive.
    """
    sqrt = math.sqrt
    h, invTc, htau, kmax = _stance_steps_scalar(K, Tc, n_per_stance, max_stance)
    a1 = 1.0 + a

    def acc(x, y, ld, armed):
        l = sqrt(x * x + y * y)
        g = ld - l
        if not armed and g < 0.0:
            g = 0.0
        fl = K * g / l
        return fl * x, fl * y - 1.0, g

    ax1, ay1, g1 = acc(px, py, a1, True)
    armed = g1 > 0.0
    if not armed:
        g1 = 0.0
        ax1, ay1, _ = acc(px, py, a1, False)
    fmax = f_prev = K * g1
    f_before, f_after, just_max = math.nan, math.nan, True
    nodes = [(0.0, px, py, vx, vy, ax1, ay1)]  # kept only with ``record``
    out = dict.fromkeys(("t", "px", "py", "vx", "vy", "fmax"), math.nan) | {"reason": NO_LIFTOFF}
    k = 0
    q4, q2, q6, h6 = 0.25 * h * h, 0.5 * h * h, h * h / 6.0, h / 6.0
    while True:
        tau0 = k * htau
        tm = tau0 + 0.5 * htau
        te = tau0 + htau
        ldm = a1 + tm * (b + c * tm)
        lde = a1 + te * (b + c * te)
        x2 = px + 0.5 * h * vx
        y2 = py + 0.5 * h * vy
        ax2, ay2, _ = acc(x2, y2, ldm, armed)
        ax3, ay3, _ = acc(x2 + q4 * ax1, y2 + q4 * ay1, ldm, armed)
        xe = px + h * vx
        ye = py + h * vy
        ax4, ay4, _ = acc(xe + q2 * ax2, ye + q2 * ay2, lde, armed)
        pxn = xe + q6 * (ax1 + ax2 + ax3)
        pyn = ye + q6 * (ay1 + ay2 + ay3)
        vxn = vx + h6 * (ax1 + 2.0 * (ax2 + ax3) + ax4)
        vyn = vy + h6 * (ay1 + 2.0 * (ay2 + ay3) + ay4)
        ax1n, ay1n, gn = acc(pxn, pyn, lde, True)
        if armed and gn <= 0.0:
            t_lo, qx, qy, wx, wy, node = _liftoff_scalar(acc, (px, py, vx, vy, ax1, ay1), g1, gn, h, k, tau0,
                                                         invTc, a1, b, c)
            out.update(t=t_lo, px=qx, py=qy, vx=wx, vy=wy, fmax=_refined_peak_scalar(fmax, f_before, f_after),
                       reason=OK)
            if record:
                nodes.append(node)
            break
        armed = armed or gn > 0.0
        if pyn <= MIN_COM_HEIGHT or vxn <= 0.0 or k + 1 >= kmax:
            out["reason"] = COLLAPSE if pyn <= MIN_COM_HEIGHT else STALL if vxn <= 0.0 else NO_LIFTOFF
            break
        fn = K * max(gn, 0.0)
        if just_max:
            f_after = fn
        just_max = fn > fmax
        if just_max:
            f_before = f_prev
            fmax = fn
        f_prev = fn
        px, py, vx, vy = pxn, pyn, vxn, vyn
        if not armed:
            ax1n, ay1n, _ = acc(px, py, lde, False)
        ax1, ay1, g1 = ax1n, ay1n, gn
        k += 1
        if record:
            nodes.append((k * h, px, py, vx, vy, ax1, ay1))
    if record:
        out["nodes"] = nodes  # type: ignore[assignment]  # the one list-valued entry
    return out


# --- the step map -------------------------------------------------------------------------------
_STEP_FIELDS = [f.name for f in fields(StepResult)]


def _step_flat(U, H, th, K, a, b, c, Tc, n_per_stance, max_stance, chunk):
    """step() on 1-D arrays of equal length N; returns dict of (N,) arrays."""
    N = U.shape[0]
    reason = np.zeros(N, np.int8)
    finite = np.isfinite(U) & np.isfinite(H) & np.isfinite(th) & np.isfinite(K) & np.isfinite(a) \
        & np.isfinite(b) & np.isfinite(c) & np.isfinite(Tc)
    with np.errstate(invalid="ignore"):
        bad = ~finite | ~(U > 0.0) | ~(K > 0.0) | ~(Tc > 0.0)
        ctd = np.cos(th)
        std = np.sin(th)
        drop = H - ctd
        reason[~bad & (ctd <= MIN_COM_HEIGHT)] = COLLAPSE
        reason[~bad & ~(drop >= 0.0)] = APEX_BELOW_TOUCHDOWN
        reason[bad] = BAD_INPUT
    t_fall = np.sqrt(np.where(reason == OK, 2.0 * drop, np.nan))
    x_td = U * t_fall
    x_c = x_td + std

    t_st = np.full(N, np.nan)
    px = np.full(N, np.nan)
    py = np.full(N, np.nan)
    vx = np.full(N, np.nan)
    vy = np.full(N, np.nan)
    fpk = np.full(N, np.nan)
    rows = np.flatnonzero(reason == OK)
    if 0 < rows.size <= SMALL_BATCH:
        # A few rows (a finite-difference Jacobian, a line search): the plain-float twin per row is
        # faster than NumPy on short arrays (measured: 8 rows 10 ms batched, 8 x 0.5 ms per row).
        for row in rows:
            i = int(row)
            res = _integrate_stance_scalar(-float(std[i]), float(ctd[i]), float(U[i]), -float(t_fall[i]),
                                           float(K[i]), float(a[i]), float(b[i]), float(c[i]),
                                           float(Tc[i]), n_per_stance, max_stance)
            t_st[i], px[i], py[i], vx[i], vy[i], fpk[i] = (res["t"], res["px"], res["py"], res["vx"],
                                                           res["vy"], res["fmax"])
            reason[i] = res["reason"]
        rows = rows[:0]
    for s in range(0, rows.size, chunk):
        r = rows[s:s + chunk]
        res = _integrate_stance(-std[r], ctd[r], U[r].copy(), -t_fall[r], K[r], a[r], b[r], c[r],
                                Tc[r], n_per_stance, max_stance)
        t_st[r], px[r], py[r], vx[r], vy[r], fpk[r] = (res["t"], res["px"], res["py"], res["vx"],
                                                       res["vy"], res["fmax"])
        reason[r] = res["reason"]
    with np.errstate(invalid="ignore"):
        reason[(reason == OK) & ~(vy > 0.0)] = LIFTOFF_DESCENDING
    ok = reason == OK
    nan = np.where(ok, 0.0, np.nan)  # adds NaN to every output of an invalid row
    x_lo = x_c + px + nan
    y_lo = py + nan
    vx_lo = vx + nan
    vy_lo = vy + nan
    t_rise = vy_lo
    H_next = y_lo + 0.5 * vy_lo * vy_lo
    with np.errstate(invalid="ignore"):
        t_fall_next = fall_time(H_next, th)
    apex_dx = x_lo + vx_lo * t_rise
    return {
        "U_next": vx_lo, "H_next": H_next, "t_fall": t_fall + nan, "t_stance": t_st + nan,
        "t_rise": t_rise, "t_flight": t_rise + t_fall_next, "x_touchdown": x_td + nan,
        "vy_touchdown": -t_fall + nan, "x_contact": x_c + nan, "x_liftoff": x_lo,
        "y_liftoff": y_lo, "vx_liftoff": vx_lo, "vy_liftoff": vy_lo, "apex_dx": apex_dx,
        "step_length": apex_dx + vx_lo * t_fall_next + np.sin(th) - x_c,
        "peak_force": fpk + nan, "valid": ok, "reason": reason,
    }


def step(U, H, theta0, control, *, n_per_stance=N_PER_STANCE, max_stance=MAX_STANCE_FACTOR,
         chunk=CHUNK):
    """One step of the running machine, apex → next apex (eq. 5), vectorised.

    U:       apex horizontal velocity [√(g l0)] (Froude number), array-like, broadcastable
    H:       apex COM height [l0]
    theta0:  touchdown leg angle from vertical [rad], foot ahead of the COM
    control: :class:`Control` (fields broadcast against U, H, theta0)
    n_per_stance: RK4 steps per nominal stance (default 48: next apex U', H' within 2e-8 of 2048 steps
                  on the fitted 09_01, 09_05, 02_03 machines, 0.7-1.3 × U, θ0 ± 0.1 rad)
    max_stance:   stance longer than max_stance · T_c is invalid (NO_LIFTOFF)
    chunk:        rows integrated together (memory/cache; results do not depend on it)

    Returns a :class:`StepResult` whose fields have the broadcast shape S of all inputs.
    """
    arrs = np.broadcast_arrays(*(np.asarray(v, dtype=float) for v in
                                 (U, H, theta0, *control.as_tuple())))
    shape = arrs[0].shape
    u, h, th, K, a, b, c, Tc = (np.ascontiguousarray(x).reshape(-1) for x in arrs)
    out = _step_flat(u, h, th, K, a, b, c, Tc, n_per_stance, max_stance, max(int(chunk), 1))
    return StepResult(**{k: out[k].reshape(shape) for k in _STEP_FIELDS})


# --- dense trajectory ---------------------------------------------------------------------------
@dataclass(frozen=True)
class Trajectory:
    """Dense machine trajectory over n steps, starting at an apex at x = 0 (dimensionless).

    Samples (S = number of samples, t = 0, dt, 2 dt, … ≤ t_apex[-1]):
      t:        (S,) time [√(l0/g)]
      pos:      (S, 2) COM (x, y) [l0]
      vel:      (S, 2) COM velocity [√(g l0)]
      force:    (S, 2) ground/leg force on the COM [m g] (zero in flight)
      stance:   (S,) bool
      contact:  (S, 2) contact point during stance, NaN in flight [l0]
      step_index: (S,) int, the step (apex i → apex i+1) each sample belongs to
    Events / per-step (n = number of steps):
      t_apex: (n+1,), U_apex: (n+1,), H_apex: (n+1,), x_apex: (n+1,)
      t_touchdown, t_liftoff: (n,); contact_x: (n,); theta0: (n,); peak_force: (n,)
      controls: tuple of the n per-step Controls
    """

    t: np.ndarray
    pos: np.ndarray
    vel: np.ndarray
    force: np.ndarray
    stance: np.ndarray
    contact: np.ndarray
    step_index: np.ndarray
    t_apex: np.ndarray
    U_apex: np.ndarray
    H_apex: np.ndarray
    x_apex: np.ndarray
    t_touchdown: np.ndarray
    t_liftoff: np.ndarray
    contact_x: np.ndarray
    theta0: np.ndarray
    peak_force: np.ndarray
    controls: tuple

    @property
    def dt(self):
        return float(self.t[1] - self.t[0]) if self.t.size > 1 else float("nan")


def _hermite(t0, t1, y0, d0, y1, d1, t):
    """Cubic Hermite interpolation between nodes t0 < t1 (arrays broadcast)."""
    hh = t1 - t0
    s = (t - t0) / hh
    s2 = s * s
    s3 = s2 * s
    return ((2 * s3 - 3 * s2 + 1) * y0 + (s3 - 2 * s2 + s) * hh * d0
            + (-2 * s3 + 3 * s2) * y1 + (s3 - s2) * hh * d1)


@dataclass(frozen=True)
class _StepEvents:
    """The events of n simulated steps (dimensionless): apexes (n+1,) t [√(l0/g)], U [√(g l0)], H, x [l0];
    per step (n,) touchdown and liftoff times, contact x, peak force [m g], and its stance's RK4 nodes
    (M, 7): t, px, py, vx, vy, ax, ay in the run's frame (x from the start)."""

    t_apex: np.ndarray
    U_apex: np.ndarray
    H_apex: np.ndarray
    x_apex: np.ndarray
    t_touchdown: np.ndarray
    t_liftoff: np.ndarray
    contact_x: np.ndarray
    peak_force: np.ndarray
    stance_nodes: list


def _step_events(U, H, th, controls, n_per_stance, max_stance) -> _StepEvents:
    """The steps from apex (U, H) at x = 0, t = 0 with touchdown angles th (n,) [rad] and controls (n
    Controls), through the plain-float integrator (the nodes :func:`step` uses). Raises PlanError naming the
    step and reason if a step is invalid."""
    n = th.size
    t_apex = np.zeros(n + 1)
    U_ap = np.zeros(n + 1)
    H_ap = np.zeros(n + 1)
    x_ap = np.zeros(n + 1)
    U_ap[0], H_ap[0] = float(U), float(H)
    t_td = np.zeros(n)
    t_lo = np.zeros(n)
    xc = np.zeros(n)
    fpk = np.zeros(n)
    stance_nodes = []
    for i in range(n):
        ctl = controls[i]
        Ui, Hi, thi = U_ap[i], H_ap[i], th[i]
        drop = Hi - math.cos(thi)
        if not (Ui > 0 and drop >= 0 and math.cos(thi) > MIN_COM_HEIGHT):
            code = BAD_INPUT if not Ui > 0 else (APEX_BELOW_TOUCHDOWN if drop < 0 else COLLAPSE)
            raise PlanError(f"step {i}: {REASONS[code]} (U={Ui:.6g}, H={Hi:.6g}, theta0={thi:.6g})")
        tf = math.sqrt(2.0 * drop)
        t_td[i] = t_apex[i] + tf
        xc[i] = x_ap[i] + Ui * tf + math.sin(thi)
        res = _integrate_stance_scalar(-math.sin(thi), math.cos(thi), Ui, -tf, float(ctl.K),
                                       float(ctl.a), float(ctl.b), float(ctl.c), float(ctl.T_c),
                                       n_per_stance, max_stance, record=True)
        code = int(res["reason"])
        if code == OK and not res["vy"] > 0:
            code = LIFTOFF_DESCENDING
        if code != OK:
            raise PlanError(f"step {i}: {REASONS[code]} (U={Ui:.6g}, H={Hi:.6g}, theta0={thi:.6g})")
        ts = float(res["t"])
        arr = np.array(res["nodes"])  # (M, 7): t, px, py, vx, vy, ax, ay
        arr[:, 0] += t_td[i]
        arr[:, 1] += xc[i]
        stance_nodes.append(arr)
        t_lo[i] = t_td[i] + ts
        fpk[i] = res["fmax"]
        vy = float(res["vy"])
        U_ap[i + 1] = float(res["vx"])
        H_ap[i + 1] = float(res["py"]) + 0.5 * vy * vy
        t_apex[i + 1] = t_lo[i] + vy
        x_ap[i + 1] = xc[i] + float(res["px"]) + U_ap[i + 1] * vy
    return _StepEvents(t_apex, U_ap, H_ap, x_ap, t_td, t_lo, xc, fpk, stance_nodes)


def _flight_samples(ev: _StepEvents, t, sidx, pos, vel):
    """Fill pos, vel (S, 2) [l0], [√(g l0)] at the flight samples (exact parabolas): before touchdown of
    step i (from apex i) and after its liftoff (to apex i+1); t (S,) [√(l0/g)], sidx (S,) each sample's
    step. Returns the stance samples (S,) bool."""
    pre = t < ev.t_touchdown[sidx]
    post = t > ev.t_liftoff[sidx]
    for mask, which in ((pre, 0), (post, 1)):
        j = sidx[mask]
        ta = ev.t_apex[j + which]
        dtt = t[mask] - ta
        pos[mask, 0] = ev.x_apex[j + which] + ev.U_apex[j + which] * dtt
        pos[mask, 1] = ev.H_apex[j + which] - 0.5 * dtt * dtt
        vel[mask, 0] = ev.U_apex[j + which]
        vel[mask, 1] = -dtt
    return ~pre & ~post


def _stance_samples(ev: _StepEvents, controls, t, sidx, st, pos, vel, force, contact) -> None:
    """Fill pos, vel, force (S, 2) and contact (S, 2) at the stance samples st (S,) bool: cubic Hermite
    interpolation of each step's RK4 nodes, and the force evaluated from the model at the interpolated
    position (exact eq. 2), not interpolated: f = K (l_d − l) along the leg [m g]."""
    for i in np.unique(sidx[st]):
        m = st & (sidx == i)
        arr = ev.stance_nodes[i]
        tq = t[m]
        k = np.clip(np.searchsorted(arr[:, 0], tq, side="right") - 1, 0, arr.shape[0] - 2)
        n0, n1 = arr[k], arr[k + 1]
        for d in range(2):
            pos[m, d] = _hermite(n0[:, 0], n1[:, 0], n0[:, 1 + d], n0[:, 3 + d], n1[:, 1 + d],
                                 n1[:, 3 + d], tq)
            vel[m, d] = _hermite(n0[:, 0], n1[:, 0], n0[:, 3 + d], n0[:, 5 + d], n1[:, 3 + d],
                                 n1[:, 5 + d], tq)
        ctl = controls[i]
        xc = ev.contact_x[i]
        rel = pos[m] - np.array([xc, 0.0])
        l = np.linalg.norm(rel, axis=1)
        tau = (tq - ev.t_touchdown[i]) / ctl.T_c
        g = 1.0 + ctl.a + tau * (ctl.b + ctl.c * tau) - l
        f = ctl.K * np.maximum(g, 0.0)
        force[m] = (f / l)[:, None] * rel
        contact[m] = (xc, 0.0)


def simulate(U, H, theta0, control, dt, *, n_steps=None, n_per_stance=N_PER_STANCE,
             max_stance=MAX_STANCE_FACTOR, times=None):
    """Dense trajectory of the machine over a sequence of steps, for synthesis.

    U, H:     starting apex state (scalars) [√(g l0)], [l0]; the run starts at x = 0, t = 0
    theta0:   touchdown angle [rad], a scalar (then ``n_steps`` is required) or a sequence (n,)
    control:  a :class:`Control` (all steps) or a sequence of n Controls (per step)
    dt:       sample spacing [√(l0/g)]
    times:    optional explicit sample times (S,) in [0, t_apex[-1]] [√(l0/g)] instead of k·dt
              (e.g. one stride sampled at output frame times modulo the stride, to tile a periodic gait)

    Returns a :class:`Trajectory`. Stance samples use cubic Hermite interpolation of the same RK4
    nodes that :func:`step` uses (so apex states agree with :func:`step` exactly); flight
    samples are exact parabolas. Raises PlanError naming the step and reason if a step is invalid.
    """
    th = np.atleast_1d(np.asarray(theta0, float))
    if th.size == 1 and n_steps is not None:
        th = np.full(int(n_steps), th[0])
    n = th.size
    if isinstance(control, Control):
        controls = (control,) * n
    else:
        controls = tuple(control)
        if len(controls) != n:
            raise PlanError(f"got {len(controls)} controls for {n} steps")
    if not dt > 0:
        raise PlanError(f"dt must be > 0, got {dt}")
    ev = _step_events(U, H, th, controls, n_per_stance, max_stance)
    if times is None:
        S = int(math.floor(ev.t_apex[-1] / dt + 1e-9)) + 1
        t = np.arange(S) * dt
    else:
        t = np.clip(np.asarray(times, float), 0.0, ev.t_apex[-1])
        S = t.size
    pos = np.zeros((S, 2))
    vel = np.zeros((S, 2))
    force = np.zeros((S, 2))
    contact = np.full((S, 2), np.nan)
    stance = np.zeros(S, bool)
    sidx = np.clip(np.searchsorted(ev.t_apex, t, side="right") - 1, 0, n - 1)
    st = _flight_samples(ev, t, sidx, pos, vel)
    stance[st] = True
    _stance_samples(ev, controls, t, sidx, st, pos, vel, force, contact)
    return Trajectory(t=t, pos=pos, vel=vel, force=force, stance=stance, contact=contact,
                      step_index=sidx, t_apex=ev.t_apex, U_apex=ev.U_apex, H_apex=ev.H_apex, x_apex=ev.x_apex,
                      t_touchdown=ev.t_touchdown, t_liftoff=ev.t_liftoff, contact_x=ev.contact_x, theta0=th,
                      peak_force=ev.peak_force, controls=controls)
