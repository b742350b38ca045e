"""Quaternion helpers (wxyz, base-frame angular velocity) against scipy, and the Pose type."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from sa_daemon.geometry import (
    Pose,
    integrate_pose,
    matrix_to_quat,
    quat_angle,
    quat_mul,
    quat_to_matrix,
    quat_to_rotvec,
    quat_z_axis,
    rotation_error,
    rotvec_to_quat,
    rpy_to_quat,
)

RNG = np.random.default_rng(1234)


def random_quats(n: int) -> np.ndarray:
    q = RNG.normal(size=(n, 4))
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def same_rotation(q1, q2, tol=1e-9) -> bool:
    """True if the wxyz quaternions describe the same rotation (sign folded)."""
    q1, q2 = np.asarray(q1), np.asarray(q2)
    return min(np.max(np.abs(q1 - q2)), np.max(np.abs(q1 + q2))) < tol


def scipy_rot(q_wxyz) -> Rotation:
    return Rotation.from_quat(q_wxyz, scalar_first=True)


# -- against scipy --------------------------------------------------------------------------------------


def test_quat_mul_matches_scipy_composition():
    a, b = random_quats(20), random_quats(20)
    got = quat_mul(a, b)
    want = (scipy_rot(a) * scipy_rot(b)).as_quat(scalar_first=True)
    for g, w in zip(got, want):
        assert same_rotation(g, w)


@pytest.mark.parametrize("shape_a, shape_b", [
    ((18, 4), (50, 12, 1, 4)),  # a set against many: one matrix product
    ((50, 12, 1, 4), (18, 4)),  # the set on the right: broadcast, component by component (large)
    ((3, 4), (3, 4)),  # small: outer product
    ((200, 18, 4), (18, 4)),  # large, elementwise: component by component
    ((1, 4), (7, 1, 4)),  # a set of one: not the set path
])
def test_quat_mul_and_quat_angle_are_the_same_product_whichever_way_they_compute(shape_a, shape_b):
    """quat_mul picks a matrix product, an outer product or component-wise arithmetic by shape; every
    way equals scipy's composition of the broadcast pairs, and quat_angle its geodesic angle."""
    a = RNG.normal(size=shape_a)
    b = RNG.normal(size=shape_b)
    a /= np.linalg.norm(a, axis=-1, keepdims=True)
    b /= np.linalg.norm(b, axis=-1, keepdims=True)
    got = quat_mul(a, b)
    A, B = np.broadcast_arrays(a, b)
    assert got.shape == A.shape
    want = (scipy_rot(A.reshape(-1, 4)) * scipy_rot(B.reshape(-1, 4))).as_quat(scalar_first=True)
    sign = np.sign(np.sum(got.reshape(-1, 4) * want, axis=-1, keepdims=True))
    np.testing.assert_allclose(got.reshape(-1, 4), sign * want, atol=1e-12)
    angle = (scipy_rot(A.reshape(-1, 4)).inv() * scipy_rot(B.reshape(-1, 4))).magnitude()
    np.testing.assert_allclose(quat_angle(a, b).reshape(-1), angle, atol=1e-6)
    np.testing.assert_allclose(quat_angle(b, a).reshape(-1), angle, atol=1e-6)


def test_quat_to_rotvec_matches_scipy():
    q = random_quats(50)
    got = quat_to_rotvec(q)
    want = scipy_rot(q).as_rotvec()  # scipy also takes the short way (angle <= pi)
    np.testing.assert_allclose(got, want, atol=1e-9)


def test_quat_to_rotvec_takes_the_short_way_for_q_and_minus_q():
    q = random_quats(200)
    np.testing.assert_allclose(quat_to_rotvec(-q), quat_to_rotvec(q), atol=1e-12)
    assert np.all(np.linalg.norm(quat_to_rotvec(q), axis=-1) <= math.pi + 1e-12)


def test_rotvec_to_quat_matches_scipy_and_handles_zero():
    r = RNG.normal(size=(30, 3))
    got = rotvec_to_quat(r)
    want = Rotation.from_rotvec(r).as_quat(scalar_first=True)
    for g, w in zip(got, want):
        assert same_rotation(g, w)
    np.testing.assert_allclose(rotvec_to_quat(np.zeros(3)), [1.0, 0.0, 0.0, 0.0])


def test_quat_to_matrix_matches_scipy():
    q = random_quats(20)
    np.testing.assert_allclose(quat_to_matrix(q), scipy_rot(q).as_matrix(), atol=1e-12)


def test_quat_z_axis_is_the_third_column_of_the_matrix_bit_for_bit():
    """The pre-grasp points use the z axis alone; the planner's recorded numbers need the same bits."""
    q = random_quats(50).reshape(5, 10, 4) * 3.0  # unnormalised, batched
    assert np.array_equal(quat_z_axis(q), quat_to_matrix(q)[..., :, 2])
    np.testing.assert_allclose(quat_z_axis(q[0, 0]), scipy_rot(q[0, 0]).apply([0.0, 0.0, 1.0]), atol=1e-12)


def test_matrix_to_quat_matches_scipy():
    for m in Rotation.random(40, random_state=7).as_matrix():
        want = Rotation.from_matrix(m).as_quat(scalar_first=True)
        assert same_rotation(matrix_to_quat(m), want)


def test_matrix_to_quat_handles_half_turns():
    for rv in ([math.pi, 0, 0], [0, math.pi, 0], [0, 0, math.pi]):
        m = Rotation.from_rotvec(rv).as_matrix()
        assert same_rotation(matrix_to_quat(m), Rotation.from_rotvec(rv).as_quat(scalar_first=True))


def test_rpy_is_extrinsic_xyz_like_scipy():
    for rpy in ([0.3, -0.2, 1.1], [math.pi, 0.0, 0.0], [math.pi, -math.pi / 2, 0.0], [-2.0, 0.7, -3.0]):
        want = Rotation.from_euler("xyz", rpy).as_quat(scalar_first=True)  # lower case = extrinsic
        assert same_rotation(rpy_to_quat(rpy), want)


# -- integration ----------------------------------------------------------------------------------------


def test_integrate_pure_rotation_left_multiplies_in_base_frame():
    p0 = np.array([0.3, -0.1, 0.2])
    q0 = rpy_to_quat([0.4, -0.3, 0.9])
    w = np.array([0.2, -0.5, 1.0])
    p, q = integrate_pose(p0, q0, np.concatenate((np.zeros(3), w)), 0.5)
    np.testing.assert_allclose(p, p0)
    want = (Rotation.from_rotvec(w * 0.5) * scipy_rot(q0)).as_quat(scalar_first=True)
    assert same_rotation(q, want)


def test_integrate_pure_translation_keeps_orientation():
    p0 = np.array([0.3, -0.1, 0.2])
    q0 = rpy_to_quat([0.4, -0.3, 0.9])
    p, q = integrate_pose(p0, q0, [0.1, -0.2, 0.05, 0, 0, 0], 0.3)
    np.testing.assert_allclose(p, p0 + 0.3 * np.array([0.1, -0.2, 0.05]))
    assert same_rotation(q, q0)


def test_rotation_error_as_angular_velocity_reaches_target_in_one_second():
    for q0, target in zip(random_quats(20), random_quats(20)):
        err = rotation_error(target, q0)
        assert np.linalg.norm(err) <= math.pi + 1e-9
        _, q = integrate_pose(np.zeros(3), q0, np.concatenate((np.zeros(3), err)), 1.0)
        assert quat_angle(q, target) < 1e-7


def test_following_rotation_error_proportionally_converges():
    q, target = rpy_to_quat([0.1, 0.2, 0.3]), rpy_to_quat([math.pi, -math.pi / 4, 0.5])
    start = quat_angle(q, target)
    for _ in range(50):
        _, q = integrate_pose(np.zeros(3), q, np.concatenate((np.zeros(3), rotation_error(target, q))), 0.1)
    # geodesic: the angle shrinks by exactly (1 - 0.1) per step
    assert quat_angle(q, target) == pytest.approx(start * 0.9**50, rel=1e-6)


# -- Pose -----------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "position, quat",
    [
        ([np.nan, 0, 0], [1, 0, 0, 0]),
        ([0, np.inf, 0], [1, 0, 0, 0]),
        ([0, 0, 0], [np.nan, 0, 0, 0]),
        ([0, 0, 0], [1, 0, -np.inf, 0]),
        ([0, 0, 0], [0, 0, 0, 0]),
        ([0, 0], [1, 0, 0, 0]),
    ],
)
def test_pose_refuses_non_finite_or_degenerate(position, quat):
    with pytest.raises(ValueError):
        Pose(np.array(position, dtype=float), np.array(quat, dtype=float))


def test_pose_normalises_quaternion_and_is_read_only():
    p = Pose(np.array([1.0, 2.0, 3.0]), np.array([2.0, 0.0, 0.0, 0.0]))
    np.testing.assert_allclose(p.quat_wxyz, [1, 0, 0, 0])
    with pytest.raises(ValueError):
        p.position[0] = 5.0


def test_pose_moved_refuses_nan_twist():
    p = Pose.from_rpy([0.3, 0, 0.2], [math.pi, 0, 0])
    with pytest.raises(ValueError):
        p.moved([0, 0, np.nan, 0, 0, 0], 0.1)


# -- quat_angle properties ------------------------------------------------------------------------------

quat_strategy = (
    st.lists(st.floats(-1.0, 1.0, allow_nan=False), min_size=4, max_size=4)
    .filter(lambda v: np.linalg.norm(v) > 1e-3)
    .map(lambda v: np.asarray(v) / np.linalg.norm(v))
)


@settings(max_examples=200, deadline=None)
@given(quat_strategy, quat_strategy)
def test_quat_angle_symmetric_and_in_range(a, b):
    ab, ba = float(quat_angle(a, b)), float(quat_angle(b, a))
    assert ab == ba
    assert 0.0 <= ab <= math.pi
    want = Rotation.from_quat(a, scalar_first=True).inv() * Rotation.from_quat(b, scalar_first=True)
    assert ab == pytest.approx(want.magnitude(), abs=1e-6)


@settings(max_examples=200, deadline=None)
@given(quat_strategy)
def test_q_and_minus_q_are_the_same_rotation(q):
    assert float(quat_angle(q, -q)) == pytest.approx(0.0, abs=1e-6)
    assert float(quat_angle(q, q)) == pytest.approx(0.0, abs=1e-6)


def test_pose_from_matrix_and_rotation_columns():
    m = Rotation.from_euler("xyz", [0.3, -1.0, 2.0]).as_matrix()
    p = Pose.from_matrix([0.1, 0.2, 0.3], m)
    np.testing.assert_allclose(p.rotation, m, atol=1e-12)
    q = Pose.from_dict(p.as_dict())
    np.testing.assert_allclose(q.position, p.position)
    assert same_rotation(q.quat_wxyz, p.quat_wxyz)
