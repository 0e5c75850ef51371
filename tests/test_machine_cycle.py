"""§4 limit-cycle search and step-map stability."""
import math

import numpy as np
import pytest

from froude.core.constants import GRAVITY
from froude.errors import FitError
from froude.machine.cycle import PARAMETERS, find_limit_cycle, step_jacobian, step_map_eigenvalues
from froude.machine.dynamics import Control, step

SEY_K = 20000.0 / (80.0 * GRAVITY)
SEY_U = 5.0 / math.sqrt(GRAVITY)
SEY_TH = math.radians(22.0)
SEY_CTL = Control(SEY_K, 0.0, 0.0, 0.0, math.pi / math.sqrt(SEY_K))
ONLY_H = {"U": 0, "H": 0.05, "theta0": 0, "K": 0, "a": 0, "b": 0, "c": 0, "T_c": 0}
PRIOR = dict(U=1.15, H=1.0, theta0=0.40, control=Control(K=15.0, a=0.02, b=0.01, c=-0.02, T_c=0.6))


def assert_periodic(lc, tol):
    r = step(lc.U, lc.H, lc.theta0, lc.control)
    assert r.valid
    assert abs(float(r.U_next) - lc.U) <= tol
    assert abs(float(r.H_next) - lc.H) <= tol


def test_seyfarth_cycle_only_height_free():
    lc = find_limit_cycle(SEY_U, 1.0, SEY_TH, SEY_CTL, scales=ONLY_H)
    assert lc.residual <= 1e-9
    assert_periodic(lc, 1e-9)
    assert lc.U == SEY_U and lc.theta0 == SEY_TH and lc.control == SEY_CTL
    assert 0.93 < lc.H < 1.1
    # Passive spring-mass: energy conserved ⇒ one eigenvalue 1; this setting is self-stable.
    ev = np.sort(np.abs(lc.eigenvalues))
    assert ev[1] == pytest.approx(1.0, abs=1e-5)
    assert ev[0] < 1.0
    assert lc.step_time == pytest.approx(lc.t_fall + lc.t_stance + lc.t_rise)
    assert lc.t_rise == pytest.approx(lc.t_fall, abs=1e-8)  # symmetric periodic flight


def test_realistic_priors_converge_and_move_little():
    lc = find_limit_cycle(PRIOR["U"], PRIOR["H"], PRIOR["theta0"], PRIOR["control"])
    assert lc.residual <= 1e-9
    assert_periodic(lc, 1e-9)
    # Held by default: U, θ0, T_c.
    assert lc.moved["U"] == 0 and lc.moved["theta0"] == 0 and lc.moved["T_c"] == 0
    assert abs(lc.moved["H"]) < 0.01
    assert abs(lc.moved["K"]) < 0.05 * PRIOR["control"].K
    assert abs(lc.moved["a"]) < 0.01 and abs(lc.moved["b"]) < 0.02 and abs(lc.moved["c"]) < 0.02
    assert set(lc.moved) == set(PARAMETERS)
    assert 0.4 < lc.t_stance < 1.2 and lc.step_length > 1.0 and lc.peak_force > 1.5


def test_solution_is_minimum_norm_in_scaled_variables():
    """KKT check: the scaled displacement from the priors lies in the row space of J_y."""
    scales = {"H": 0.02, "K": 0.1, "a": 0.01, "b": 0.02, "c": 0.02}
    lc = find_limit_cycle(PRIOR["U"], PRIOR["H"], PRIOR["theta0"], PRIOR["control"], scales=scales)
    names = ["H", "K", "a", "b", "c"]
    s = np.array([0.02, 0.1 * PRIOR["control"].K, 0.01, 0.02, 0.02])
    y = np.array([lc.moved[n] for n in names]) / s
    z = lc.as_vector()
    J = np.zeros((2, 5))
    for j, n in enumerate(names):
        i = PARAMETERS.index(n)
        h = 1e-6 * max(abs(z[i]), 1.0)
        zp, zm = z.copy(), z.copy()
        zp[i] += h
        zm[i] -= h
        rp = step(zp[0], zp[1], zp[2], Control(*zp[3:]))
        rm = step(zm[0], zm[1], zm[2], Control(*zm[3:]))
        J[:, j] = [(float(rp.U_next - rm.U_next) - 2 * h * (i == 0)) / (2 * h),
                   (float(rp.H_next - rm.H_next) - 2 * h * (i == 1)) / (2 * h)]
    Jy = J * s
    lam, *_ = np.linalg.lstsq(Jy.T, y, rcond=None)
    assert np.linalg.norm(Jy.T @ lam - y) <= 1e-4 * max(np.linalg.norm(y), 1e-12)
    assert np.linalg.norm(y) > 1e-3  # the priors were not already periodic


def test_recovers_known_cycle_from_perturbed_priors():
    ref = find_limit_cycle(PRIOR["U"], PRIOR["H"], PRIOR["theta0"], PRIOR["control"])
    c = ref.control
    noisy = Control(K=c.K * 1.03, a=c.a + 0.003, b=c.b - 0.004, c=c.c + 0.004, T_c=c.T_c)
    lc = find_limit_cycle(ref.U, ref.H + 0.004, ref.theta0, noisy)
    assert_periodic(lc, 1e-9)
    assert lc.H == pytest.approx(ref.H, abs=0.01)
    assert lc.control.K == pytest.approx(ref.control.K, rel=0.05)


def test_free_speed_and_angle():
    lc = find_limit_cycle(PRIOR["U"], PRIOR["H"], PRIOR["theta0"], PRIOR["control"],
                          scales={"U": 0.02, "theta0": 0.02, "T_c": 0.02})
    assert_periodic(lc, 1e-9)
    assert lc.moved["U"] != 0 and lc.moved["theta0"] != 0


def test_fit_errors_are_clear():
    with pytest.raises(FitError, match="apex below"):
        find_limit_cycle(1.15, 0.8, 0.4, PRIOR["control"])
    with pytest.raises(FitError, match="no free variable"):
        find_limit_cycle(1.15, 1.0, 0.4, PRIOR["control"], scales={"H": 0, "K": 0, "a": 0, "b": 0, "c": 0})
    with pytest.raises(FitError, match="unknown"):
        find_limit_cycle(1.15, 1.0, 0.4, PRIOR["control"], scales={"speed": 1.0})
    # Only H free with a far too soft, preloaded leg: no periodic height exists.
    with pytest.raises(FitError, match="no periodic"):
        find_limit_cycle(1.15, 1.0, 0.3, Control(8.0, 0.15, 0.0, 0.0, 0.6), scales=ONLY_H)


def test_step_jacobian_and_eigenvalues():
    U, H, th, ctl = 1.15, 1.0, 0.4, PRIOR["control"]
    J = step_jacobian(U, H, th, ctl)
    h = 1e-5
    r0 = step(np.array([U - h, U + h, U, U]), np.array([H, H, H - h, H + h]), th, ctl)
    Jref = np.array([[(r0.U_next[1] - r0.U_next[0]) / (2 * h), (r0.U_next[3] - r0.U_next[2]) / (2 * h)],
                     [(r0.H_next[1] - r0.H_next[0]) / (2 * h), (r0.H_next[3] - r0.H_next[2]) / (2 * h)]])
    assert np.allclose(J, Jref, atol=1e-5)
    ev = step_map_eigenvalues(U, H, th, ctl)
    assert np.allclose(np.sort_complex(ev), np.sort_complex(np.linalg.eigvals(Jref)), atol=1e-5)
