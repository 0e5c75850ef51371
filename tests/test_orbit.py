"""Direct unit tests of machine/orbit.py (the one orbit solver) on residuals whose answers are known in closed
form, so that a wrong minimum-norm step, a held unknown that moves, a box that leaks or a failure that
passes silently shows here and not only through the fits that use the solver."""
from __future__ import annotations

import numpy as np
import pytest

from froude.errors import FitError
from froude.machine.dynamics import Control, step
from froude.machine.orbit import Rows, _min_norm_point, rowwise, solve_orbit, step_jacobian


def _batched(residual, valid=lambda z: True):
    """evaluate(Z (m, d), n) -> (R (m, r), Rows) of a one-candidate residual(z) -> (r,)."""
    def evaluate(Z, n):
        ok = np.array([bool(valid(z)) for z in Z])
        R = np.array([residual(z) if v else np.full(len(residual(Z[0])), np.nan) for z, v in zip(Z, ok)])
        return R, Rows(valid=ok, reason=np.where(ok, 0, 1), items=tuple(Z))
    return evaluate


REASONS = ("ok", "outside the test's region")


def test_linear_constraint_lands_on_the_scaled_minimum_norm_point():
    """One linear row over three unknowns: the answer is the prior moved by the pseudo-inverse in the scaled
    coordinates, z* = z0 + S (A S)^+ (b - A z0), not any other point of the plane."""
    A, b = np.array([1.0, 2.0, -1.0]), 3.0
    z0, s = np.array([0.5, -0.2, 0.1]), np.array([1.0, 0.5, 2.0])
    z, rows, calls, R = solve_orbit(_batched(lambda z: np.array([A @ z - b])), z0, s, h=np.full(3, 1e-7),
                                    reasons=REASONS)
    AS = A * s
    want = z0 + s * (AS / (AS @ AS)) * (b - A @ z0)
    assert np.abs(z - want).max() < 1e-6  # the Jacobian is a forward difference: the direction to ~1e-8
    assert abs(float(R[0])) <= 1e-10 and bool(rows.valid[0]) and calls >= 2


def test_held_unknown_stays_at_its_prior_and_the_free_ones_answer():
    """s = 0 holds an unknown: it keeps its prior exactly, the residual is met by the others."""
    z0 = np.array([1.0, 2.0, 3.0])
    z, *_ = solve_orbit(_batched(lambda z: np.array([z.sum() - 9.0])), z0, np.array([1.0, 0.0, 1.0]),
                        h=np.full(3, 1e-7), reasons=REASONS)
    assert z[1] == 2.0
    assert z[0] == pytest.approx(2.5, abs=1e-6) and z[2] == pytest.approx(4.5, abs=1e-6)
    assert abs(z.sum() - 9.0) <= 1e-10


def test_nonlinear_circle_gives_the_nearest_point_to_the_prior():
    """r(z) = |z|² - 1 from z0 = (2, 1): the nearest point of the unit circle is z0 / |z0|."""
    z0 = np.array([2.0, 1.0])
    z, *_ = solve_orbit(_batched(lambda z: np.array([z @ z - 1.0])), z0, np.ones(2), h=np.full(2, 1e-8),
                        reasons=REASONS)
    assert np.abs(z - z0 / np.linalg.norm(z0)).max() < 1e-6
    assert abs(z @ z - 1.0) <= 1e-10


def test_box_bound_holds_and_the_other_unknown_takes_up_the_rest():
    """z0 + z1 = 4 from (0, 0) would land on (2, 2); with z0 <= 1 the bound holds and z1 = 3."""
    z, *_ = solve_orbit(_batched(lambda z: np.array([z[0] + z[1] - 4.0])), np.zeros(2), np.ones(2),
                        h=np.full(2, 1e-7), lo=np.array([-10.0, -10.0]), hi=np.array([1.0, 10.0]),
                        reasons=REASONS)
    assert z[0] <= 1.0 and z == pytest.approx([1.0, 3.0], abs=1e-6)


def test_no_solution_raises_naming_what_was_searched():
    """|z|² + 1 = 0 has no root: the search ends in FitError naming the orbit, never a silent answer."""
    with pytest.raises(FitError, match="no periodic test orbit found"):
        solve_orbit(_batched(lambda z: np.array([z @ z + 1.0])), np.array([0.3, -0.2]), np.ones(2),
                    h=np.full(2, 1e-7), max_iter=12, what="test orbit", reasons=REASONS)


def test_start_outside_the_valid_region_raises_with_the_evaluators_reason():
    with pytest.raises(FitError, match="outside the test's region"):
        solve_orbit(_batched(lambda z: np.array([z[0] - 1.0]), valid=lambda z: z[0] < 0), np.array([0.5]),
                    np.ones(1), h=np.full(1, 1e-7), reasons=REASONS)


def test_rowwise_batches_a_one_candidate_evaluator_and_blanks_invalid_rows():
    class Rec:
        def __init__(self, ok):
            self.valid, self.reason = ok, 0 if ok else 3

    ev = rowwise(lambda z, n: (np.array([z[0] * n, z[1]]), Rec(z[0] >= 0)), n_rows=2)
    R, rows = ev(np.array([[1.0, 2.0], [-1.0, 5.0]]), 10)
    assert R[0].tolist() == [10.0, 2.0] and np.isnan(R[1]).all()
    assert rows.valid.tolist() == [True, False] and rows.reason.tolist() == [0, 3] and len(rows.items) == 2


def test_min_norm_point_active_set_keeps_the_constraint():
    """Clipping the free minimum-norm point would leave the constraint; the active set does not."""
    Js, rhs = np.array([[1.0, 1.0]]), np.array([4.0])
    y = _min_norm_point(Js, rhs, (np.array([-5.0, -5.0]), np.array([1.0, 5.0])))
    assert y == pytest.approx([1.0, 3.0], abs=1e-12)
    assert _min_norm_point(Js, rhs, None) == pytest.approx([2.0, 2.0], abs=1e-12)


def test_step_jacobian_agrees_with_a_wider_central_difference():
    """The step map's (U, H) Jacobian at a running apex: the default step and one 100x wider agree, and
    the columns are the response of the simulator itself (a column of one-sided differences)."""
    U, H, th = 1.15, 1.0, 0.40
    ctl = Control(K=15.0, a=0.02, b=0.01, c=-0.02, T_c=0.6)
    J = step_jacobian(U, H, th, ctl)
    J_wide = step_jacobian(U, H, th, ctl, eps=1e-4)
    assert np.isfinite(J).all() and np.abs(J - J_wide).max() < 1e-4 * max(1.0, np.abs(J).max())
    d = 1e-6
    r0, r1 = step(U, H, th, ctl), step(U + d, H, th, ctl)
    one_sided = np.array([float(r1.U_next - r0.U_next), float(r1.H_next - r0.H_next)]) / d
    assert np.abs(J[:, 0] - one_sided).max() < 1e-3
