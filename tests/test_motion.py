"""Motion operations (cut, slicing, resample, time-warp, continuity) and the quaternion helpers they rely on,
checked against SciPy on real data."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation, Slerp

from froude import Motion, load_bvh
from froude.core import quat

from conftest import FIXTURES, clip


@pytest.fixture(scope="module")
def run120():
    """09_01 with its frame time made exactly 1/120 s (the file says .0083333, 4 ppm off)."""
    m = load_bvh(clip("09_01"))
    return m.with_(frame_time=1 / 120)


def _xyzw(q):
    return np.concatenate([q[..., 1:], q[..., :1]], axis=-1)


def _same_rotation(a, b, atol=1e-12):
    return np.allclose(np.abs(np.sum(a * b, axis=-1)), 1.0, atol=atol)


# ---- cut and slicing --------------------------------------------------------------------------------------
def test_cut_and_slicing(run120):
    c = run120.cut(10, 40)
    assert c.n_frames == 30 and c.frame_time == run120.frame_time
    np.testing.assert_array_equal(c.rotations, run120.rotations[10:40])
    np.testing.assert_array_equal(c.root_positions, run120.root_positions[10:40])
    s = run120[10:40]
    np.testing.assert_array_equal(s.rotations, c.rotations)
    every2 = run120[::2]
    assert every2.frame_time == pytest.approx(2 / 120)
    np.testing.assert_array_equal(every2.root_positions, run120.root_positions[::2])
    one = run120[5]
    assert one.n_frames == 1 and np.array_equal(one.rotations[0], run120.rotations[5])
    assert run120[-1].n_frames == 1
    assert len(run120) == run120.n_frames == 148
    assert c.skeleton is run120.skeleton and c.meta == run120.meta
    with pytest.raises(TypeError):
        run120["a"]


def test_operations_do_not_touch_their_input(run120):
    before = (run120.root_positions.copy(), run120.rotations.copy())
    run120.cut(3, 9)
    run120.resample(60)
    run120.time_warp(np.linspace(0, 0.5, 30))
    run120.continuous()
    np.testing.assert_array_equal(run120.root_positions, before[0])
    np.testing.assert_array_equal(run120.rotations, before[1])


def test_timing_properties(run120):
    assert run120.fps == pytest.approx(120)
    assert run120.duration == pytest.approx(147 / 120)
    np.testing.assert_allclose(run120.times, np.arange(148) / 120)


# ---- resample -----------------------------------------------------------------------------------------------
def test_resample_to_60_hz_takes_every_other_frame(run120):
    r = run120.resample(60)
    assert r.frame_time == pytest.approx(1 / 60) and r.n_frames == 74
    np.testing.assert_array_equal(r.rotations, run120.rotations[::2])
    np.testing.assert_allclose(r.root_positions, run120.root_positions[::2], atol=1e-15)


def test_resample_to_240_hz_keeps_frames_and_slerps_between(run120):
    r = run120.resample(240)
    assert r.n_frames == 2 * 147 + 1 and r.duration == pytest.approx(run120.duration)
    np.testing.assert_array_equal(r.rotations[::2], run120.rotations)
    # in-between frames: SciPy's Slerp per joint, and the linear mean of the root positions
    mid_times = np.arange(147) + 0.5
    for j in (0, 3, 18):  # Hips, LeftLeg, LeftArm
        ref = Slerp(np.arange(148), Rotation.from_quat(_xyzw(run120.rotations[:, j])))(mid_times).as_quat()
        assert _same_rotation(_xyzw(r.rotations[1::2, j]), ref)
    np.testing.assert_allclose(r.root_positions[1::2], 0.5 * (run120.root_positions[:-1] + run120.root_positions[1:]))


def test_resample_then_back_is_close(run120):
    there = run120.resample(240).resample(120)
    np.testing.assert_allclose(there.root_positions, run120.root_positions, atol=1e-12)
    assert _same_rotation(there.rotations, run120.rotations, atol=1e-12)


def test_resample_rejects_bad_rates(run120):
    for bad in (0, -30, float("nan")):
        with pytest.raises(ValueError):
            run120.resample(bad)


def test_resample_of_the_file_frame_time_covers_the_same_duration():
    m = load_bvh(clip("09_01"))  # frame time .0083333 as written
    r = m.resample(60)
    assert abs(r.duration - m.duration) < 1 / 60
    assert r.duration <= m.duration + 1e-12


# ---- time warp ------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("exact_rate", [True, False])
def test_identity_time_warp_is_exact(run120, exact_rate):
    m = run120 if exact_rate else load_bvh(clip("09_01"))
    w = m.time_warp(m.times)
    np.testing.assert_array_equal(w.rotations, m.rotations)
    np.testing.assert_array_equal(w.root_positions, m.root_positions)
    assert w.frame_time == m.frame_time


def test_time_warp_linear_map_is_a_resample(run120):
    t = np.arange(295) / 240
    w = run120.time_warp(t, frame_time=1 / 240)
    r = run120.resample(240)
    np.testing.assert_array_equal(w.rotations, r.rotations)
    assert w.frame_time == pytest.approx(1 / 240)


def test_time_warp_slow_motion_and_clamping(run120):
    # half speed over the first 0.5 s, then held at the last frame (times past the end clamp)
    t = np.concatenate([np.arange(121) / 240, [10.0, 20.0]])
    w = run120.time_warp(t)
    assert w.n_frames == 123
    np.testing.assert_array_equal(w.rotations[0:121:2], run120.rotations[:61])
    np.testing.assert_array_equal(w.rotations[-1], run120.rotations[-1])
    with pytest.raises(ValueError):
        run120.time_warp(np.array([0.0, 0.2, 0.1]))


def test_time_warp_translations_are_interpolated():
    m = load_bvh(FIXTURES / "orders_crlf_tabs_sci.bvh", clean=False)
    w = m.time_warp(np.array([0.5, 1.5]) * m.frame_time)
    np.testing.assert_allclose(w.translations, 0.5 * (m.translations[0:2] + m.translations[1:3]))


# ---- quaternion track -----------------------------------------------------------------------------------------
def test_slerp_matches_scipy():
    rng = np.random.default_rng(11)
    q0 = quat.normalize(rng.normal(size=(200, 4)))
    q1 = quat.normalize(rng.normal(size=(200, 4)))
    t = rng.uniform(size=200)
    got = quat.slerp(q0, q1, t)
    for i in range(0, 200, 7):
        ref = Slerp([0, 1], Rotation.from_quat(_xyzw(np.stack([q0[i], q1[i]]))))([t[i]]).as_quat()[0]
        assert _same_rotation(_xyzw(got[i]), ref)
    # endpoints and the shorter arc across the sign ambiguity
    assert _same_rotation(quat.slerp(q0, q1, 0.0), q0) and _same_rotation(quat.slerp(q0, q1, 1.0), q1)
    half = quat.slerp(q0, -q1, 0.5)
    assert _same_rotation(half, quat.slerp(q0, q1, 0.5))
    # nearly equal quaternions do not divide by zero
    near = quat.slerp(q0, q0 + 1e-9, 0.3)
    assert np.all(np.isfinite(near)) and _same_rotation(near, q0)


def test_make_continuous_removes_sign_flips_only(run120):
    rng = np.random.default_rng(5)
    signs = rng.choice([-1.0, 1.0], size=run120.rotations.shape[:2])[..., None]
    flipped = run120.rotations * signs
    fixed = quat.make_continuous(flipped)
    assert np.all(np.sum(fixed[1:] * fixed[:-1], axis=-1) >= 0)
    assert _same_rotation(fixed, run120.rotations)
    np.testing.assert_allclose(np.abs(fixed), np.abs(run120.rotations))
    m = run120.with_(rotations=flipped).continuous()
    assert np.all(np.sum(m.rotations[1:] * m.rotations[:-1], axis=-1) >= 0)


def test_sampling_a_sign_flipped_track_takes_the_short_way(run120):
    """Interpolation across a sign flip must not swing through the long way round."""
    rng = np.random.default_rng(6)
    signs = rng.choice([-1.0, 1.0], size=run120.rotations.shape[:2])[..., None]
    m = run120.with_(rotations=run120.rotations * signs)
    r = m.resample(240)
    ref = run120.resample(240)
    assert _same_rotation(r.rotations, ref.rotations, atol=1e-12)


def test_euler_round_trip_for_every_order():
    rng = np.random.default_rng(2)
    angles = rng.uniform(-np.pi, np.pi, size=(500, 3))
    angles[:, 1] = rng.uniform(-1.5, 1.5, size=500)
    for order in ("xyz", "xzy", "yxz", "yzx", "zxy", "zyx"):
        q = quat.from_euler(angles, order)
        ref = Rotation.from_euler(order.upper(), angles).as_quat()
        assert _same_rotation(_xyzw(q), ref)
        np.testing.assert_allclose(quat.to_euler(q, order), angles, atol=1e-9)



@pytest.mark.parametrize("order", ["xyz", "xzy", "yxz", "yzx", "zxy", "zyx", "xyx", "zxz", "yzy"])
def test_to_euler_matches_scipy(order):
    """quat.to_euler (NumPy, so that writing a BVH does not import SciPy) against SciPy's as_euler as the
    oracle: random rotations of both signs, the identity, and the middle angle at and near gimbal lock (the
    third angle 0, the first carrying the whole turn; a joint bent exactly 90 degrees is ordinary)."""
    import warnings

    rng = np.random.default_rng(7)
    q = rng.normal(size=(4000, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    angles = rng.uniform(-np.pi, np.pi, size=(600, 3))
    singular = [-np.pi / 2, np.pi / 2] if order[0] != order[2] else [0.0, np.pi]
    angles[:, 1] = np.resize(singular + [s + 5e-8 * (1 if s < 1 else -1) for s in singular], 600)
    locked = quat.from_euler(angles, order)
    q = np.concatenate([q, -q, quat.identity((1,)), locked, -locked])
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="Gimbal lock detected")
        ref = Rotation.from_quat(_xyzw(q)).as_euler(order.upper())
    got = quat.to_euler(q, order)
    assert got.shape == ref.shape
    assert np.abs(got - ref).max() < 1e-14  # the same method: only NumPy's and libm's atan2 round differently
    assert np.all(got[-1200:, 2] == 0.0)  # at gimbal lock the third angle is 0, as SciPy sets it

def test_motion_validates_shapes():
    m = load_bvh(FIXTURES / "three_joint.bvh", clean=False)
    with pytest.raises(ValueError):
        Motion(m.skeleton, m.root_positions, m.rotations[:, :2], m.frame_time)
    with pytest.raises(ValueError):
        Motion(m.skeleton, m.root_positions, m.rotations, 0.0)
