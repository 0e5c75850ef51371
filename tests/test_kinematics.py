"""Forward kinematics against an independent SciPy computation; point and COM Jacobians against central
finite differences; the hand-written 3-joint fixture worked out by hand."""
from __future__ import annotations

import numpy as np
import pytest

from froude import BodyModel, load_bvh
from froude.core import quat
from froude.core.kinematics import (
    ancestor_mask,
    apply_dof_increment,
    com_jacobian,
    fk,
    fk_soa,
    forward_kinematics,
    from_soa,
    point_jacobian,
    points_world,
    to_soa,
)

from conftest import FIXTURES, clip, clip_params, oracle_fk, read_bvh_oracle

FD_STEP = 1e-6  # [m] and [rad]; truncation error ~h^2, round-off ~1e-16/h: both far below the 1e-6 bar


# ---- acceptance 2: FK == SciPy to 1e-9 m -------------------------------------------------------------
@pytest.mark.parametrize("name", clip_params())
def test_fk_matches_scipy_on_real_clips(name):
    path = clip(name)
    motion = load_bvh(path, clean=False)
    ref = read_bvh_oracle(path)
    p_ref, ends_ref = oracle_fk(ref, motion.meta["length_scale"])
    p, R = fk(motion)
    assert np.abs(p - p_ref).max() < 1e-9
    # end sites through the rotations too
    ends = np.stack([p[:, j] + R[:, j] @ off for j, off in motion.skeleton.end_sites], axis=1)
    assert np.abs(ends - ends_ref).max() < 1e-9


@pytest.mark.parametrize("name", ["orders_crlf_tabs_sci", "three_joint", "humanoid_inches"])
def test_fk_matches_scipy_on_fixtures(name):
    """Mixed channel orders, interleaved position/rotation channels, a 6-channel non-root joint and a
    position-only joint."""
    path = FIXTURES / f"{name}.bvh"
    motion = load_bvh(path, clean=False)
    p_ref, _ = oracle_fk(read_bvh_oracle(path), motion.meta["length_scale"])
    p, _ = fk(motion)
    assert np.abs(p - p_ref).max() < 1e-9


def test_soa_and_frame_major_layouts_agree():
    motion = load_bvh(FIXTURES / "orders_crlf_tabs_sci.bvh", clean=False)
    P, R = fk_soa(motion.skeleton.parents, motion.skeleton.offsets,
                  *to_soa(motion.root_positions, motion.rotations, motion.translations))
    p, Rm = from_soa(P, R)
    p2, R2 = forward_kinematics(motion.skeleton, motion.root_positions, motion.rotations, motion.translations)
    np.testing.assert_array_equal(p, p2)
    np.testing.assert_array_equal(Rm, R2)
    np.testing.assert_allclose(Rm, quat.to_matrix(_world_quats(motion)), atol=1e-12)


def _world_quats(motion):
    q = motion.rotations.copy()
    for j in range(1, motion.skeleton.n_joints):
        q[:, j] = quat.mul(q[:, motion.skeleton.parents[j]], motion.rotations[:, j])
    return q


# ---- acceptance 5: the hand-written 3-joint fixture --------------------------------------------------
# Root at the origin of its frame; Mid 1 m above Root; Tip 1 m along Mid's x; End Site 1 m along Tip's z.
# Frame 0: root at (1, 2, 3), no rotation.
# Frame 1: root Zrotation 90 (x -> y, y -> -x), Mid Xrotation 90 (y -> z, z -> -y).
# Frame 2: root Yrotation 90 (z -> x, x -> -z), Tip Zrotation 90.
# Frame 3: root "Zrotation 90, Xrotation 90" in channel order Z Y X: R = Rz(90) Rx(90) (intrinsic).
HAND_POSITIONS = np.array([
    # Root        Mid          Tip           End site
    [[1, 2, 3], [1, 3, 3], [2, 3, 3], [2, 3, 4]],
    [[0, 0, 0], [-1, 0, 0], [-1, 1, 0], [0, 1, 0]],
    [[0, 0, 0], [0, 1, 0], [0, 1, -1], [1, 1, -1]],
    [[0, 0, 0], [0, 0, 1], [0, 1, 1], [1, 1, 1]],
], dtype=float)


def test_three_joint_fixture_fk_by_hand():
    motion = load_bvh(FIXTURES / "three_joint.bvh", clean=False)
    assert motion.meta["length_scale"] == 1.0
    p, R = fk(motion)
    np.testing.assert_allclose(p, HAND_POSITIONS[:, :3], atol=1e-12)
    tip = motion.skeleton.index("Tip")
    (j, off), = motion.skeleton.end_sites
    assert j == tip
    end = p[:, tip] + np.einsum("fab,b->fa", R[:, tip], off)
    np.testing.assert_allclose(end, HAND_POSITIONS[:, 3], atol=1e-12)
    # Frame 3 tells intrinsic file order (Rz Rx) from the extrinsic reading (Rx Rz would put Mid at -x).
    assert p[3, 1] == pytest.approx([0, 0, 1], abs=1e-12)


def test_three_joint_fixture_is_not_cleaned():
    assert load_bvh(FIXTURES / "three_joint.bvh").n_frames == 4


# ---- acceptance 2: Jacobians == central finite differences to 1e-6 relative --------------------------
def _perturbed(root, rot, k, h):
    """The motion with DOF k moved by +h and -h, stacked as extra frames: (2F, 3), (2F, J, 4)."""
    F, J, _ = rot.shape
    dq = np.zeros((F, 3 + 3 * J))
    dq[:, k] = h
    plus = apply_dof_increment(root, rot, dq)
    minus = apply_dof_increment(root, rot, -dq)
    return np.concatenate([plus[0], minus[0]]), np.concatenate([plus[1], minus[1]])


def _fd_jacobian(fun, root, rot, n):
    """Central differences of fun(root (F,3), rot (F,J,4)) -> (F, m) over the n DOFs: (F, m, n)."""
    F = len(root)
    cols = []
    for k in range(n):
        r, q = _perturbed(root, rot, k, FD_STEP)
        y = fun(r, q)
        cols.append((y[:F] - y[F:]) / (2 * FD_STEP))
    return np.stack(cols, axis=-1)


def _assert_jacobian_close(J, J_fd):
    """Max error <= 1e-6 of the largest entry, and every significant column within 1e-6 relative."""
    scale = np.abs(J_fd).max()
    assert np.abs(J - J_fd).max() <= 1e-6 * scale, np.abs(J - J_fd).max() / scale
    col_norm = np.linalg.norm(J_fd, axis=-2)  # (..., n)
    sig = col_norm > 1e-3 * scale
    rel = np.linalg.norm(J - J_fd, axis=-2)[sig] / col_norm[sig]
    assert rel.max() <= 1e-6, rel.max()


def _test_frames():
    """Three real frames of 09_01 plus two seeded random poses (no special configuration)."""
    motion = load_bvh(clip("09_01"))
    frames = motion.cut(0, None)[::50]
    rng = np.random.default_rng(7)
    J = motion.skeleton.n_joints
    rand_rot = quat.normalize(rng.normal(size=(2, J, 4)))
    root = np.concatenate([frames.root_positions, rng.normal(size=(2, 3))])
    rot = np.concatenate([frames.rotations, rand_rot])
    return motion.skeleton, root, rot


def test_point_jacobian_matches_finite_differences():
    skel, root, rot = _test_frames()
    names = ["LeftToeBase", "RightFoot", "LeftHand", "Head", "Hips", "RThumb"]
    joint_index = np.array([skel.index(n) for n in names])
    rng = np.random.default_rng(3)
    p_local = rng.normal(scale=0.1, size=(len(names), 3))

    def points(r, q):
        p, R = forward_kinematics(skel, r, q)
        return points_world(p, R, joint_index, p_local).reshape(len(r), -1)

    p, R = forward_kinematics(skel, root, rot)
    pts = points_world(p, R, joint_index, p_local)
    J = point_jacobian(skel, p, R, joint_index, pts)  # (F, P, 3, n)
    n = 3 + 3 * skel.n_joints
    assert J.shape == (len(root), len(names), 3, n)
    J_fd = _fd_jacobian(points, root, rot, n).reshape(len(root), len(names), 3, n)
    _assert_jacobian_close(J, J_fd)
    # columns of joints that are not ancestors of a point are exactly zero
    anc = ancestor_mask(skel)[joint_index]
    for i in range(len(names)):
        for k in np.flatnonzero(~anc[i]):
            assert not J[:, i, :, 3 + 3 * k : 6 + 3 * k].any()


def test_com_jacobian_matches_finite_differences():
    skel, root, rot = _test_frames()
    body = BodyModel.from_skeleton(skel, mass=70.0)

    def com_of(r, q):
        p, R = forward_kinematics(skel, r, q)
        return com_jacobian(skel, p, R, body.seg_mass, body.seg_joint, body.segment_points(p, R))[0]

    p, R = forward_kinematics(skel, root, rot)
    com, J = com_jacobian(skel, p, R, body.seg_mass, body.seg_joint, body.segment_points(p, R))
    # the COM itself: the mass-weighted segment points, and BodyModel.com's fast path
    seg = body.segment_points(p, R)
    np.testing.assert_allclose(com, np.einsum("s,fsa->fa", body.seg_mass, seg) / 70.0, atol=1e-12)
    from froude.core.motion import Motion

    np.testing.assert_allclose(com, body.com(Motion(skel, root, rot, 1 / 120)), atol=1e-12)
    J_fd = _fd_jacobian(com_of, root, rot, 3 + 3 * skel.n_joints)
    _assert_jacobian_close(J, J_fd)


def test_jacobians_on_a_skeleton_with_translation_channels():
    """The fixture's 6-channel Head and position-only Foot: rotations still act about the moved joints."""
    motion = load_bvh(FIXTURES / "orders_crlf_tabs_sci.bvh", clean=False)
    skel, root, rot, tr = motion.skeleton, motion.root_positions, motion.rotations, motion.translations
    joint_index = np.arange(skel.n_joints)
    p_local = np.full((skel.n_joints, 3), 0.05)

    def points(r, q):
        t = np.concatenate([tr, tr])
        p, R = forward_kinematics(skel, r, q, t)
        return points_world(p, R, joint_index, p_local).reshape(len(r), -1)

    p, R = forward_kinematics(skel, root, rot, tr)
    J = point_jacobian(skel, p, R, joint_index, points_world(p, R, joint_index, p_local))
    n = 3 + 3 * skel.n_joints
    J_fd = _fd_jacobian(points, root, rot, n).reshape(J.shape)
    _assert_jacobian_close(J, J_fd)


def test_apply_dof_increment_rotates_about_local_axes():
    motion = load_bvh(FIXTURES / "three_joint.bvh", clean=False)
    J = motion.skeleton.n_joints
    dq = np.zeros((motion.n_frames, 3 + 3 * J))
    dq[:, 3 + 3 * 1 + 0] = np.pi / 2  # Mid about its own x axis
    dq[:, 0] = 0.5
    root, rot = apply_dof_increment(motion.root_positions, motion.rotations, dq)
    np.testing.assert_allclose(root, motion.root_positions + [0.5, 0, 0])
    expect = quat.mul(motion.rotations[:, 1], quat.from_axis_angle(np.array([1.0, 0, 0]), np.pi / 2))
    np.testing.assert_allclose(np.abs(np.sum(rot[:, 1] * expect, axis=-1)), 1.0, atol=1e-12)


def test_quat_from_matrix_matches_scipy_including_half_turns():
    """quat.from_matrix (NumPy Shepperd, no SciPy import at run time) agrees with SciPy's on random rotations and
    on the 180° turns and axis swaps that unit and up-axis conversions produce; w ≥ 0; shapes broadcast."""
    from scipy.spatial.transform import Rotation

    half_turns = [np.diag([1.0, -1.0, -1.0]), np.diag([-1.0, 1.0, -1.0]), np.diag([-1.0, -1.0, 1.0]),
                  np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]]), np.array([[0.0, 1, 0], [1, 0, 0], [0, 0, -1]])]
    m = np.concatenate([Rotation.random(2000, random_state=3).as_matrix(), np.eye(3)[None], np.array(half_turns)])
    q = quat.from_matrix(m)
    xyzw = Rotation.from_matrix(m).as_quat()
    ref = np.concatenate([xyzw[:, 3:], xyzw[:, :3]], axis=1)
    same_up_to_sign = np.minimum(np.abs(q - ref).max(axis=1), np.abs(q + ref).max(axis=1))
    assert same_up_to_sign.max() < 1e-12
    assert np.all(q[:, 0] >= 0.0)
    assert np.allclose(quat.to_matrix(q), m, atol=1e-12)
    assert quat.from_matrix(m[:6].reshape(2, 3, 3, 3)).shape == (2, 3, 4)
