"""Direct unit tests of synthesis/ helpers on synthetic inputs with answers in closed form: the bend onto a
clip's path (synthesis/bend.py) and the time warp and periodic tiling of the machine (synthesis/timewarp.py).

The expected values are written out here (circle arcs, rotations about +Y by explicit cos/sin, piecewise
linear knots), sharing no code with the synthesis.
"""
from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from froude.machine.cycle import find_limit_cycle
from froude.machine.dynamics import Control, simulate
from froude.synthesis.bend import Centreline, bend_points
from froude.synthesis.timewarp import _periodic_trajectory, _stride_phase

FWD = np.array([1.0, 0.0, 0.0])
# +Y is up; a turn to the left (seen from above, + heading) takes +X towards -Z (right hand about +Y)
LEFT = np.array([0.0, 0.0, -1.0])
ORIGIN = np.array([0.3, 0.9, -0.2])  # [m]; its height is not part of the path (the path lies on the floor)


def _arc(radius_m: float, turn_rad: float, n: int = 4001):
    """A clip's path as Centreline.of reads it: arc length (n,) [m] and heading (n,) [rad] of a steady turn
    of radius radius_m (inf: straight) through turn_rad (heading starts at 0.7 rad: only changes count); its
    travel line is the path itself (a track without sway)."""
    length = abs(turn_rad) * radius_m if math.isfinite(radius_m) else 6.0
    s = np.linspace(0.0, length, n)
    heading = 0.7 + (s / radius_m * np.sign(turn_rad) if math.isfinite(radius_m) else 0.0 * s)
    return SimpleNamespace(arc_length_m=s, heading_rad=heading, travel_line=lambda: (heading, s))


def _on_circle(a_m, radius_m):
    """Closed form: the floor point at arc length a_m along a left turn of radius radius_m from ORIGIN."""
    ang = a_m / radius_m
    base = ORIGIN * np.array([1.0, 0.0, 1.0])
    return base + radius_m * (np.sin(ang)[..., None] * FWD + (1 - np.cos(ang))[..., None] * LEFT)


def test_straight_path_leaves_points_where_they_are():
    line = Centreline.of(_arc(math.inf, 0.0), 1.0, ORIGIN, FWD)
    rng = np.random.default_rng(0)
    x = ORIGIN + rng.uniform(-3, 8, (50, 3))
    assert np.abs(bend_points(x, line, ORIGIN) - x).max() < 1e-12


def test_points_on_the_line_land_on_the_turned_circle():
    R, turn = 4.0, math.pi / 2
    line = Centreline.of(_arc(R, turn), 1.0, ORIGIN, FWD)
    a = np.linspace(0.0, R * turn, 9)
    x = ORIGIN * np.array([1.0, 0.0, 1.0]) + a[:, None] * FWD
    x[:, 1] = 1.1  # a COM height: kept as it is
    got = bend_points(x, line, ORIGIN)
    want = _on_circle(a, R)
    assert np.abs(got[:, [0, 2]] - want[:, [0, 2]]).max() < 1e-5  # the trapezoid's error on 4,001 samples
    assert np.all(got[:, 1] == 1.1)


def test_sideways_offsets_turn_with_the_path_and_keep_their_length():
    """A point r to the runner's left at arc length a goes to C(a) + Rot(a / R) r: still |r| from the
    centreline point, now along the turned left direction (a sway stays a sway)."""
    R = 4.0
    line = Centreline.of(_arc(R, math.pi), 1.0, ORIGIN, FWD)
    a, r = 5.0, 0.12
    x = ORIGIN * np.array([1.0, 0.0, 1.0]) + a * FWD + r * LEFT
    got = bend_points(x[None], line, ORIGIN)[0]
    ang = a / R
    turned_left = np.cos(ang) * LEFT - np.sin(ang) * FWD
    assert np.abs(got - (_on_circle(np.array(a), R) + r * turned_left)).max() < 1e-5


def test_past_the_clips_end_the_path_runs_straight_on_and_L_scales_the_turn():
    R, turn, L = 3.0, math.pi / 2, 2.0
    line = Centreline.of(_arc(R, turn), L, ORIGIN, FWD)
    end = L * R * turn  # the path scaled by L about its start
    end_point = _on_circle(np.array(end), L * R)
    got_end = bend_points((ORIGIN * [1, 0, 1] + end * FWD)[None], line, ORIGIN)[0]
    assert np.abs(got_end - end_point).max() < 1e-4
    beyond = bend_points((ORIGIN * [1, 0, 1] + (end + 2.0) * FWD)[None], line, ORIGIN)[0]
    assert np.abs(beyond - (end_point + 2.0 * LEFT)).max() < 1e-4  # heading +90 deg: travel along LEFT


def test_nan_points_stay_nan_and_the_rest_move():
    line = Centreline.of(_arc(4.0, 1.0), 1.0, ORIGIN, FWD)
    x = np.array([[np.nan, np.nan, np.nan], [1.0, 0.0, 0.0]])
    got = bend_points(x, line, ORIGIN)
    assert np.isnan(got[0]).all() and np.isfinite(got[1]).all()


# ---- the time warp ----------------------------------------------------------------------------------
PHASE_EVENTS = (0.0, 0.3, 0.5, 0.8)  # touchdown A, liftoff A, touchdown B, liftoff B [stride phase]
CONTACT_PHASE = np.array([[-0.02, 0.33], [0.47, 0.84]])  # each foot's marker contact [phase]


def _steps(n=6, stance_s=0.24, step_s=0.4, first_foot=0):
    feet = np.where(np.arange(n) % 2 == 0, first_foot, 1 - first_foot)
    t_td = 0.1 + step_s * np.arange(n)
    return feet, t_td, t_td + stance_s


def test_stride_phase_hits_the_events_and_plays_each_stance_at_one_rate():
    feet, t_td, t_lo = _steps()
    t = np.linspace(0.0, 2.6, 2601)
    psi, knots_t, knots_psi, on, off = _stride_phase(t, t_td, t_lo, feet, 0, PHASE_EVENTS, CONTACT_PHASE,
                                                     None, 1.0)
    k = np.arange(len(feet)) // 2
    want_td = k + np.where(feet == 0, 0.0, 0.5)
    want_lo = k + np.where(feet == 0, 0.3, 0.8)
    assert np.interp(t_td, knots_t, knots_psi) == pytest.approx(want_td, abs=1e-12)
    assert np.interp(t_lo, knots_t, knots_psi) == pytest.approx(want_lo, abs=1e-12)
    assert np.all(np.diff(knots_t) > 0) and np.all(np.diff(knots_psi) > 0) and np.all(np.diff(psi) >= 0)
    # inside a stance psi advances at 0.3 phase per 0.24 s
    inside = (t > t_td[2] + 0.01) & (t < t_lo[2] - 0.01)
    assert np.diff(psi[inside]) / np.diff(t[inside]) == pytest.approx(0.3 / 0.24, rel=1e-9)


def test_contact_widens_the_stance_but_keeps_a_fifth_of_each_flight():
    feet, t_td, t_lo = _steps()
    t = np.linspace(0.0, 2.6, 261)
    _, _, _, on, off = _stride_phase(t, t_td, t_lo, feet, 0, PHASE_EVENTS, CONTACT_PHASE, None, 1.0)
    assert np.all(on <= t_td) and np.all(off >= t_lo) and np.any(on < t_td) and np.any(off > t_lo)
    flight = t_td[1:] - t_lo[:-1]
    assert np.all(on[1:] - off[:-1] >= 0.2 * flight - 1e-12)
    # wide marker contacts (a third of each flight per side) are capped at 40 % of the flight
    wide = np.array([[-0.2, 0.5], [0.3, 1.0]])
    _, _, _, on_w, off_w = _stride_phase(t, t_td, t_lo, feet, 0, PHASE_EVENTS, wide, None, 1.0)
    assert np.all(on_w[1:] - off_w[:-1] >= 0.2 * flight - 1e-12)
    assert np.all(t_td[1:] - on_w[1:] <= 0.4 * flight + 1e-12)


def test_periodic_trajectory_tiles_one_stride_as_simulating_every_step_would():
    lc = find_limit_cycle(1.15, 1.0, 0.40, Control(K=15.0, a=0.02, b=0.01, c=-0.02, T_c=0.6))
    m = SimpleNamespace(U=lc.U, H=lc.H, theta0=lc.theta0, control=lc.control, step_time=lc.step_time,
                        step_length=lc.step_length)
    n_steps, dt = 6, 0.02
    tiled = _periodic_trajectory(m, n_steps, dt)
    full = simulate(lc.U, lc.H, np.full(n_steps, lc.theta0), lc.control, dt)
    n = min(len(tiled.t), len(full.t))
    assert abs(len(tiled.t) - len(full.t)) <= 1
    assert np.abs(tiled.t[:n] - full.t[:n]).max() < 1e-12
    assert np.abs(tiled.pos[:n] - full.pos[:n]).max() < 1e-6
    assert np.abs(tiled.t_touchdown - full.t_touchdown).max() < 1e-6
    assert np.abs(tiled.contact_x - full.contact_x).max() < 1e-6
