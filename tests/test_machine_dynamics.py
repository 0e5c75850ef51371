"""Dimensionless simple running machine: step map, dense trajectory, eq. 2 control fit."""
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

from froude.core.constants import GRAVITY
from froude.errors import FitError, PlanError
from froude.machine.control_fit import control_from_si, fit_leg_control
from froude.machine.dynamics import APEX_BELOW_TOUCHDOWN, BAD_INPUT, OK, Control, energy, simulate, step
from froude.machine.units import time_unit

# Seyfarth et al. 2002 standard setting: m = 80 kg, l0 = 1 m, k = 20 kN/m, 22° from vertical, 5 m/s.
SEY_K = 20000.0 * 1.0 / (80.0 * GRAVITY)
SEY_U = 5.0 / math.sqrt(GRAVITY * 1.0)
SEY_TH = math.radians(22.0)
SEY_CTL = Control(K=SEY_K, a=0.0, b=0.0, c=0.0, T_c=math.pi / math.sqrt(SEY_K))


def oracle_step(U, H, th, K, a, b, c, Tc):
    """Independent reference: solve_ivp (DOP853, rtol = atol = 1e-11) with a terminal event."""
    tf = math.sqrt(2.0 * (H - math.cos(th)))
    xc = U * tf + math.sin(th)

    def rhs(t, y):
        px, py, vx, vy = y
        l = math.hypot(px, py)
        tau = t / Tc
        f = K * (1.0 + a + b * tau + c * tau * tau - l)
        return [vx, vy, f * px / l, f * py / l - 1.0]

    def liftoff(t, y):
        tau = t / Tc
        return 1.0 + a + b * tau + c * tau * tau - math.hypot(y[0], y[1])

    liftoff.terminal = True
    liftoff.direction = -1
    sol = solve_ivp(rhs, (0.0, 20.0 * Tc), [-math.sin(th), math.cos(th), U, -tf], method="DOP853",
                    rtol=1e-11, atol=1e-11, events=liftoff, dense_output=True)
    t = sol.t_events[0][0]
    px, py, vx, vy = sol.y_events[0][0]
    ts = np.linspace(0.0, t, 4001)
    Y = sol.sol(ts)
    tau = ts / Tc
    fpk = np.max(K * (1.0 + a + b * tau + c * tau * tau - np.hypot(Y[0], Y[1])))
    return {"U_next": vx, "H_next": py + 0.5 * vy * vy, "t_stance": t, "t_fall": tf,
            "t_rise": vy, "x_contact": xc, "x_liftoff": xc + px, "y_liftoff": py,
            "vx_liftoff": vx, "vy_liftoff": vy, "apex_dx": xc + px + vx * vy,
            "peak": fpk}


def random_points(n, seed):
    rng = np.random.default_rng(seed)
    pts = []
    while len(pts) < n:
        th = rng.uniform(0.25, 0.5)
        p = dict(U=rng.uniform(0.8, 2.0), H=math.cos(th) + rng.uniform(0.01, 0.2), th=th,
                 K=rng.uniform(10.0, 30.0), a=rng.uniform(0.0, 0.06), b=rng.uniform(-0.05, 0.05),
                 c=rng.uniform(-0.05, 0.05), Tc=rng.uniform(0.4, 0.8))
        r = step(p["U"], p["H"], p["th"], Control(p["K"], p["a"], p["b"], p["c"], p["Tc"]))
        if r.valid:
            pts.append(p)
    return pts


def seyfarth_periodic_H():
    """Apex height making the passive spring-mass step periodic at U and θ0 (root of U' − U)."""
    Hs = np.linspace(math.cos(SEY_TH) + 1e-3, 1.3, 300)
    r = step(SEY_U, Hs, SEY_TH, SEY_CTL)
    d = np.where(r.valid, r.U_next - SEY_U, np.nan)
    i = np.flatnonzero(np.isfinite(d[:-1]) & np.isfinite(d[1:]) & (np.sign(d[:-1]) != np.sign(d[1:])))
    assert i.size >= 1, "no periodic apex height found in the scan"

    def f(H):
        return float(step(SEY_U, H, SEY_TH, SEY_CTL).U_next) - SEY_U

    return brentq(f, Hs[i[0]], Hs[i[0] + 1], xtol=1e-15, rtol=1e-15)


def test_seyfarth_periodic_gait():
    H = seyfarth_periodic_H()
    r = step(SEY_U, H, SEY_TH, SEY_CTL)
    assert r.valid
    assert abs(float(r.U_next) - SEY_U) <= 1e-6
    assert abs(float(r.H_next) - H) <= 1e-6
    # Symmetric stance of a periodic passive gait: liftoff height equals touchdown height.
    assert abs(float(r.y_liftoff) - math.cos(SEY_TH)) <= 1e-6
    # Sanity against the published setting: plausible apex height (m) and stance time (s).
    assert 0.93 < H < 1.1
    assert 0.1 < float(r.t_stance) * time_unit(1.0) < 0.3


def test_energy_conserved_over_ten_strides():
    H = seyfarth_periodic_H()
    traj = simulate(SEY_U, H, SEY_TH, SEY_CTL, dt=0.004, n_steps=20)
    E0 = SEY_U ** 2 / 2 + H
    # Apex energies of every step (kinetic + potential).
    E_apex = 0.5 * traj.U_apex ** 2 + traj.H_apex
    assert np.max(np.abs(E_apex - E0)) / E0 <= 1e-6
    # Along the whole dense trajectory, spring energy included.
    E = energy(traj.pos, traj.vel, traj.contact, traj.stance, SEY_CTL)
    assert np.all(np.isfinite(E))
    assert np.max(np.abs(E - E0)) / E0 <= 1e-6
    assert traj.stance.any() and (~traj.stance).any()
    # The gait stays periodic over the 10 strides.
    assert np.max(np.abs(traj.U_apex - SEY_U)) <= 1e-6
    assert np.max(np.abs(traj.H_apex - H)) <= 1e-6


def test_energy_check_fails_when_control_is_active():
    # The energy bookkeeping is not trivially constant: a pushing leg (b > 0) adds energy.
    ctl = Control(SEY_K, 0.0, 0.05, 0.0, SEY_CTL.T_c)
    r = step(SEY_U, 1.0, SEY_TH, ctl)
    assert r.valid
    assert 0.5 * float(r.U_next) ** 2 + float(r.H_next) > 0.5 * SEY_U ** 2 + 1.0 + 1e-3


def test_step_matches_solve_ivp_oracle():
    for p in random_points(8, seed=1):
        r = step(p["U"], p["H"], p["th"], Control(p["K"], p["a"], p["b"], p["c"], p["Tc"]))
        o = oracle_step(p["U"], p["H"], p["th"], p["K"], p["a"], p["b"], p["c"], p["Tc"])
        for k in ("U_next", "H_next", "t_stance", "t_fall", "t_rise", "x_contact", "x_liftoff",
                  "y_liftoff", "vx_liftoff", "vy_liftoff", "apex_dx"):
            assert abs(float(getattr(r, k)) - o[k]) <= 1e-6, (k, p)
        assert abs(float(r.peak_force) - o["peak"]) <= 1e-4 * o["peak"]


def test_liftoff_located_exactly():
    pts = random_points(6, seed=2)
    arr = {k: np.array([p[k] for p in pts]) for k in pts[0]}
    ctl = Control(arr["K"], arr["a"], arr["b"], arr["c"], arr["Tc"])
    r = step(arr["U"], arr["H"], arr["th"], ctl)
    assert r.valid.all()
    tau = r.t_stance / arr["Tc"]
    ld = 1 + arr["a"] + arr["b"] * tau + arr["c"] * tau ** 2
    l = np.hypot(r.x_liftoff - r.x_contact, r.y_liftoff)
    assert np.max(np.abs(ld - l)) <= 1e-10


def test_batch_equals_single_calls_and_broadcasts():
    pts = random_points(5, seed=3)
    arr = {k: np.array([p[k] for p in pts]) for k in pts[0]}
    ctl = Control(arr["K"], arr["a"], arr["b"], arr["c"], arr["Tc"])
    rb = step(arr["U"], arr["H"], arr["th"], ctl, chunk=2)
    for i, p in enumerate(pts):
        rs = step(p["U"], p["H"], p["th"], Control(p["K"], p["a"], p["b"], p["c"], p["Tc"]))
        assert rs.U_next.shape == ()
        for k in ("U_next", "H_next", "t_stance", "apex_dx", "peak_force"):
            assert abs(float(getattr(rs, k)) - getattr(rb, k)[i]) <= 1e-12
    # Broadcasting: (3,1) × (4,) → (3,4).
    r = step(np.array([[1.0], [1.2], [1.4]]), 1.0, np.linspace(0.3, 0.45, 4), Control(15, 0.02, 0, 0, 0.6))
    assert r.U_next.shape == (3, 4) and r.valid.shape == (3, 4)


def test_invalid_steps_are_flagged_not_silent():
    ctl = Control(15.0, 0.02, 0.0, 0.0, 0.6)
    U = np.array([1.2, 1.2, -1.0, np.nan, 0.3, 1.2])
    H = np.array([1.0, 0.80, 1.0, 1.0, 1.0, 1.0])
    th = np.array([0.4, 0.4, 0.4, 0.4, 0.75, 0.4])
    r = step(U, H, th, Control(np.array([15, 15, 15, 15, 15, 0.3]), 0.02, 0.0, 0.0, 0.6))
    assert r.valid[0] and r.reason[0] == OK
    assert r.reason[1] == APEX_BELOW_TOUCHDOWN
    assert r.reason[2] == BAD_INPUT and r.reason[3] == BAD_INPUT
    assert not r.valid[4] and r.reason[4] != OK  # slow and steep: stalls or falls
    assert not r.valid[5]  # far too soft: collapses
    for k in ("U_next", "H_next", "t_stance", "peak_force", "step_length"):
        v = getattr(r, k)
        assert np.all(np.isnan(v[~r.valid]))
    assert np.all(np.isfinite(r.U_next[r.valid]))
    del ctl


def test_slack_leg_with_negative_offset_still_steps():
    # a < 0: the leg is slack at touchdown; the force is clamped at 0 until it first pushes.
    r = step(1.2, 1.0, 0.4, Control(18.0, -0.01, 0.0, 0.0, 0.6))
    assert r.valid
    assert float(r.peak_force) > 0


def test_dense_trajectory_consistent_with_step():
    ctl = Control(15.0, 0.02, 0.01, -0.02, 0.6)
    ths = [0.40, 0.38, 0.42]
    tr = simulate(1.15, 1.0, ths, ctl, dt=0.01)
    U, H = 1.15, 1.0
    x = 0.0
    for i, th in enumerate(ths):
        r = step(U, H, th, ctl)
        assert r.valid
        assert abs(tr.contact_x[i] - (x + float(r.x_contact))) <= 1e-12
        assert abs(tr.t_liftoff[i] - tr.t_touchdown[i] - float(r.t_stance)) <= 1e-12
        x += float(r.apex_dx)
        U, H = float(r.U_next), float(r.H_next)
        assert abs(tr.U_apex[i + 1] - U) <= 1e-12 and abs(tr.H_apex[i + 1] - H) <= 1e-12
    # Samples: shapes, stance flags between events, contact only in stance, force zero in flight.
    S = tr.t.size
    assert tr.pos.shape == (S, 2) and tr.force.shape == (S, 2) and tr.contact.shape == (S, 2)
    in_st = np.zeros(S, bool)
    for td, lo in zip(tr.t_touchdown, tr.t_liftoff):
        in_st |= (tr.t >= td) & (tr.t <= lo)
    assert np.array_equal(in_st, tr.stance)
    assert np.all(np.isnan(tr.contact[~tr.stance])) and np.all(np.isfinite(tr.contact[tr.stance]))
    assert np.all(tr.force[~tr.stance] == 0)
    # Velocity is the derivative of position (Hermite samples are smooth): central differences.
    v_fd = (tr.pos[2:] - tr.pos[:-2]) / (2 * 0.01)
    assert np.max(np.abs(v_fd - tr.vel[1:-1])) < 5e-3
    # Flight acceleration is exactly -g.
    fl = ~tr.stance[:-2] & ~tr.stance[1:-1] & ~tr.stance[2:]
    acc = (tr.pos[2:, 1] - 2 * tr.pos[1:-1, 1] + tr.pos[:-2, 1]) / 0.01 ** 2
    assert np.allclose(acc[fl], -1.0, atol=1e-8)
    with pytest.raises(PlanError):
        simulate(1.15, 0.5, 0.4, ctl, dt=0.01, n_steps=2)


def test_fit_exact_on_model_data():
    rng = np.random.default_rng(4)
    k, a, b, c, l0 = 12000.0, 0.02, 0.03, -0.04, 0.95
    tau = np.linspace(0, 1, 30)
    l = l0 - 0.08 * np.sin(np.pi * tau) + 0.002 * rng.standard_normal(30)
    f = k * (l0 + a + b * tau + c * tau ** 2 - l)
    fit = fit_leg_control(tau, l, f, l0)
    assert fit.k == pytest.approx(k, rel=1e-10)
    assert (fit.a, fit.b, fit.c) == pytest.approx((a, b, c), abs=1e-12)
    assert fit.r2 == pytest.approx(1.0, abs=1e-12) and fit.rms < 1e-6
    # Weights: a wild outlier with zero weight does not matter.
    f2 = f.copy()
    f2[5] += 500.0
    w = np.ones(30)
    w[5] = 0.0
    fit2 = fit_leg_control(tau, l, f2, l0, weights=w)
    assert fit2.k == pytest.approx(k, rel=1e-9)
    assert fit_leg_control(tau, l, f2, l0).k != pytest.approx(k, rel=1e-3)
    ctl = fit.to_control(70.0, 0.2)
    assert ctl.K == pytest.approx(k * l0 / (70 * GRAVITY))
    assert ctl.T_c == pytest.approx(0.2 / math.sqrt(l0 / GRAVITY))
    assert np.allclose(control_from_si(k, a, b, c, 0.2, 70.0, l0).as_tuple(), ctl.as_tuple(), rtol=1e-9)
    with pytest.raises(FitError):
        fit_leg_control(tau[:3], l[:3], f[:3], l0)


def test_synthetic_mocap_recovery():
    """Simulate a stance, sample it like 120 Hz mocap, extract forces like the data path, fit."""
    l0, m, fps = 0.95, 70.0, 120.0
    true = Control(K=12.0, a=0.03, b=0.04, c=-0.03, T_c=0.65)
    U, th = 1.2, 0.38
    H = math.cos(th) + 0.06
    assert step(U, H, th, true).valid
    T = time_unit(l0)
    dt = (1.0 / fps) / T
    tr = simulate(U, H, th, true, dt=dt, n_steps=1)
    t_s = tr.t * T
    p = tr.pos * l0
    foot = np.array([tr.contact_x[0] * l0, 0.0])
    # Acceleration by central second differences of the sampled COM (what the data path does),
    # only where the whole stencil is in stance (the force jumps at touchdown and liftoff).
    acc = (p[2:] - 2 * p[1:-1] + p[:-2]) / (1.0 / fps) ** 2
    inner = tr.stance[:-2] & tr.stance[1:-1] & tr.stance[2:]
    f = m * (acc + np.array([0.0, GRAVITY]))  # f = m (a − g), g = (0, −9.81)
    rel = p[1:-1] - foot
    l = np.linalg.norm(rel, axis=1)
    f_leg = np.sum(f * rel, axis=1) / l
    # Touchdown from the samples: extrapolate the last flight samples (ballistic) to |COM − foot| = l0.
    first = int(np.flatnonzero(tr.stance)[0])
    fl = slice(first - 6, first)
    cy = np.polyfit(t_s[fl], p[fl, 1], 2)
    cx = np.polyfit(t_s[fl], p[fl, 0], 1)

    def dist(t):
        return math.hypot(np.polyval(cx, t) - foot[0], np.polyval(cy, t)) - l0

    t_td = brentq(dist, t_s[first - 1], t_s[first], xtol=1e-14)
    theta_est = math.atan2(foot[0] - np.polyval(cx, t_td), np.polyval(cy, t_td))
    assert theta_est == pytest.approx(th, abs=1e-6)
    T_c_s = true.T_c * T
    tau = (t_s[1:-1] - t_td) / T_c_s
    fit = fit_leg_control(tau[inner], l[inner], f_leg[inner], l0)
    got = fit.to_control(m, T_c_s)
    assert got.K == pytest.approx(true.K, rel=0.02)
    for name in ("a", "b", "c"):
        assert getattr(got, name) == pytest.approx(getattr(true, name), rel=0.02), name
    assert fit.r2 > 0.999


def test_scalar_and_vector_integrators_agree_including_failures():
    """step() on one row uses a plain-float twin of the vectorised integrator: same numbers."""
    rng = np.random.default_rng(5)
    n = 150
    th = rng.uniform(0.2, 0.6, n)
    U = rng.uniform(0.3, 2.2, n)
    H = np.cos(th) + rng.uniform(-0.02, 0.2, n)
    ctl = Control(rng.uniform(4, 30, n), rng.uniform(-0.02, 0.08, n), rng.uniform(-0.1, 0.1, n),
                  rng.uniform(-0.1, 0.1, n), rng.uniform(0.3, 0.9, n))
    rb = step(U, H, th, ctl)
    assert rb.valid.sum() > 20 and (~rb.valid).sum() > 20
    for i in range(n):
        rs = step(U[i], H[i], th[i], Control(*(float(v[i]) for v in ctl.as_tuple())))
        assert int(rs.reason) == int(rb.reason[i])
        for k in ("U_next", "H_next", "t_stance", "peak_force", "x_liftoff"):
            a, b = float(getattr(rs, k)), float(getattr(rb, k)[i])
            assert (np.isnan(a) and np.isnan(b)) or abs(a - b) <= 1e-11, (i, k, a, b)
