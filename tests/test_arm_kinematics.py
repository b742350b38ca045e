"""xArm-6 kinematics (Pinocchio from xarm6.xml) against the published joint table, computed independently."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from sa_daemon.arm.base import Kinematics
from sa_daemon.arm.kinematics import (
    VELOCITY_LIMIT_RADPS,
    ArmKinematics,
    IKError,
    start_configuration,
)
from sa_daemon.geometry import Pose
from sa_daemon.world.scene import load_scene

# The published table (docs/arm.md): joint origin xyz (m) and rpy (rad) in the parent link, every joint
# about its local z; the TCP 0.172 m along the flange z.
TABLE_XYZ = [(0, 0, 0.267), (0, 0, 0), (0.0535, -0.2845, 0), (0.0775, 0.3425, 0), (0, 0, 0), (0.076, 0.097, 0)]
TABLE_RPY = [(0, 0, 0), (-1.5708, 0, 0), (0, 0, 0), (-1.5708, 0, 0), (1.5708, 0, 0), (-1.5708, 0, 0)]
TCP_M = 0.172
LOWER = [-2 * math.pi, -2.059, -3.927, -2 * math.pi, -1.69297, -2 * math.pi]
UPPER = [2 * math.pi, 2.0944, 0.19198, 2 * math.pi, math.pi, 2 * math.pi]


def table_fk(q) -> tuple[np.ndarray, np.ndarray]:
    """TCP (position, rotation) by chaining the table's homogeneous transforms (scipy, not Pinocchio)."""
    t = np.eye(4)
    for xyz, rpy, qi in zip(TABLE_XYZ, TABLE_RPY, q):
        origin = np.eye(4)
        origin[:3, :3] = Rotation.from_euler("xyz", rpy).as_matrix()  # URDF rpy: extrinsic x, y, z
        origin[:3, 3] = xyz
        joint = np.eye(4)
        joint[:3, :3] = Rotation.from_rotvec([0.0, 0.0, qi]).as_matrix()
        t = t @ origin @ joint
    tcp = np.eye(4)
    tcp[2, 3] = TCP_M
    t = t @ tcp
    return t[:3, 3], t[:3, :3]


@pytest.fixture(scope="module")
def kin() -> ArmKinematics:
    return ArmKinematics()


def _random_q(rng: np.random.Generator, inset: float = 0.3) -> np.ndarray:
    return rng.uniform(np.array(LOWER) + inset, np.array(UPPER) - inset)


def _well_conditioned(kin: ArmKinematics, rng: np.random.Generator, n: int) -> list[np.ndarray]:
    """``n`` random configurations whose smallest Jacobian singular value exceeds 0.1."""
    out = []
    while len(out) < n:
        q = _random_q(rng)
        if np.linalg.svd(kin.jacobian(q), compute_uv=False)[-1] > 0.1:
            out.append(q)
    return out


# -- model ---------------------------------------------------------------------------------------------


def test_implements_the_kinematics_protocol(kin):
    assert isinstance(kin, Kinematics)
    assert kin.joint_names == ("joint1", "joint2", "joint3", "joint4", "joint5", "joint6")


def test_limits_are_the_published_ones(kin):
    np.testing.assert_allclose(kin.lower, LOWER, atol=1e-12)
    np.testing.assert_allclose(kin.upper, UPPER, atol=1e-12)
    np.testing.assert_allclose(kin.velocity_limit, [2.14] * 6)
    assert VELOCITY_LIMIT_RADPS == 2.14


def test_fk_at_zero_is_the_published_home_pose(kin):
    # Flange at (0.207, 0, 0.112) m pointing down: the TCP 0.172 m below it.
    pose = kin.fk(np.zeros(6))
    np.testing.assert_allclose(pose.position, [0.207, 0.0, 0.112 - TCP_M], atol=1e-5)
    np.testing.assert_allclose(pose.rotation[:, 2], [0.0, 0.0, -1.0], atol=1e-4)


@pytest.mark.parametrize("seed", range(6))
def test_fk_matches_the_chained_table(kin, seed):
    q = _random_q(np.random.default_rng(seed), inset=0.0)
    pose = kin.fk(q)
    p, r = table_fk(q)
    np.testing.assert_allclose(pose.position, p, atol=1e-9)
    np.testing.assert_allclose(pose.rotation, r, atol=1e-9)


def test_fk_refuses_bad_joint_vectors(kin):
    with pytest.raises(ValueError):
        kin.fk(np.zeros(5))
    with pytest.raises(ValueError):
        kin.fk([0, 0, float("nan"), 0, 0, 0])


# -- Jacobian ------------------------------------------------------------------------------------------


@pytest.mark.parametrize("seed", range(4))
def test_jacobian_matches_finite_differences_of_fk(kin, seed):
    q = _random_q(np.random.default_rng(10 + seed))
    jac = kin.jacobian(q)
    assert jac.shape == (6, 6)
    h = 1e-6
    p0, r0 = table_fk(q)
    for i in range(6):
        dq = np.zeros(6)
        dq[i] = h
        p1, r1 = table_fk(q + dq)
        np.testing.assert_allclose(jac[:3, i], (p1 - p0) / h, atol=1e-5)  # m/rad, base frame
        w = Rotation.from_matrix(r1 @ r0.T).as_rotvec() / h  # base-frame angular velocity per rad/s
        np.testing.assert_allclose(jac[3:, i], w, atol=1e-5)


# -- joint velocities ----------------------------------------------------------------------------------


def test_joint_velocities_reproduce_a_twist_away_from_singularities(kin):
    rng = np.random.default_rng(3)
    for q in _well_conditioned(kin, rng, 8):
        twist = np.concatenate((rng.uniform(-0.05, 0.05, 3), rng.uniform(-0.2, 0.2, 3)))
        qdot = kin.joint_velocities(q, twist)
        if np.max(np.abs(qdot)) < 2.14 * 0.999:  # not scaled
            np.testing.assert_allclose(kin.jacobian(q) @ qdot, twist, atol=1e-9)


def test_zero_twist_gives_zero_joint_velocities(kin):
    assert np.array_equal(kin.joint_velocities(np.zeros(6) + 0.3, np.zeros(6)), np.zeros(6))


def test_fast_twist_is_scaled_to_the_velocity_limit_keeping_direction(kin):
    rng = np.random.default_rng(5)
    for q in _well_conditioned(kin, rng, 5):
        twist = np.array([3.0, -2.0, 1.0, 4.0, 0.0, -3.0])
        qdot = kin.joint_velocities(q, twist)
        assert np.max(np.abs(qdot)) == pytest.approx(2.14, rel=1e-9)
        realised = kin.jacobian(q) @ qdot
        scale = realised @ twist / (twist @ twist)
        assert 0.0 < scale < 1.0
        np.testing.assert_allclose(realised, scale * twist, atol=1e-9)  # same direction, slower


@settings(max_examples=60, deadline=None)
@given(
    q=st.lists(st.floats(-1.6, 0.15), min_size=6, max_size=6),
    twist=st.lists(st.floats(-5.0, 5.0), min_size=6, max_size=6),
)
def test_joint_velocities_never_exceed_the_limit(kin, q, twist):
    qdot = kin.joint_velocities(np.array(q), np.array(twist))
    assert np.all(np.isfinite(qdot))
    assert np.max(np.abs(qdot)) <= 2.14 + 1e-9


@pytest.mark.parametrize("joint, bound", [(0, "upper"), (3, "lower"), (4, "lower"), (5, "upper")])
def test_motion_toward_a_bound_inside_the_margin_is_halted(kin, joint, bound):
    q = np.array([0.1, 0.3, -1.0, 0.2, 1.0, 0.1])
    sign = 1.0 if bound == "upper" else -1.0
    q[joint] = (UPPER if bound == "upper" else LOWER)[joint] - sign * 0.05  # within the 0.1 rad margin
    jac = kin.jacobian(q)
    assert np.linalg.svd(jac, compute_uv=False)[-1] > 0.1
    e = np.zeros(6)
    e[joint] = sign * 0.2
    toward = jac @ e  # the twist this joint alone would make, moving toward its bound
    qdot = kin.joint_velocities(q, toward)
    assert qdot[joint] == 0.0
    assert np.any(qdot != 0.0)  # the other joints still do what they can
    away = kin.joint_velocities(q, -toward)  # leaving the bound is allowed, exactly
    np.testing.assert_allclose(away, -e, atol=1e-9)


def test_outside_the_margin_the_joint_may_approach_its_bound(kin):
    q = np.array([UPPER[0] - 0.3, 0.3, -1.0, 0.2, 1.0, 0.1])
    e = np.array([0.2, 0, 0, 0, 0, 0])
    np.testing.assert_allclose(kin.joint_velocities(q, kin.jacobian(q) @ e), e, atol=1e-9)


def test_joint_velocities_refuse_a_bad_twist(kin):
    with pytest.raises(ValueError):
        kin.joint_velocities(np.zeros(6), [0, 0, float("nan"), 0, 0, 0])
    with pytest.raises(ValueError):
        kin.joint_velocities(np.zeros(6), [0, 0, 0])


def test_damped_solution_stays_finite_at_a_singularity(kin):
    # Joint 5 = 0 aligns joints 4 and 6; with this elbow angle the offset wrist is singular too.
    q = np.array([0.001, 0.2639, -0.2628, -0.0003, 0.0004, 0.0009])
    assert np.linalg.svd(kin.jacobian(q), compute_uv=False)[-1] < 1e-3
    qdot = kin.joint_velocities(q, np.array([0.0, 0.05, 0.0, 0.0, 0.0, 0.0]))
    assert np.all(np.isfinite(qdot)) and np.max(np.abs(qdot)) <= 2.14


# -- inverse kinematics --------------------------------------------------------------------------------


def test_ik_round_trip(kin):
    rng = np.random.default_rng(8)
    for q in _well_conditioned(kin, rng, 6):
        target = kin.fk(q)
        seed = q + rng.normal(0.0, 0.15, 6)
        q_ik = kin.ik(target, seed)
        d_t, d_r = kin.fk(q_ik).distance(target)
        assert d_t < 1e-5 and d_r < 1e-5
        assert np.all(q_ik >= kin.lower) and np.all(q_ik <= kin.upper)


def test_ik_raises_for_an_unreachable_pose(kin):
    with pytest.raises(IKError, match="mm"):
        kin.ik(Pose.from_rpy([1.5, 0.0, 0.3], [math.pi, 0.0, 0.0]), np.zeros(6), max_iter=50)


def test_start_configuration_of_scene1_is_the_elbow_up_solution(kin):
    start = load_scene("scene1").start
    q = start_configuration(kin, start)
    d_t, d_r = kin.fk(q).distance(start)
    assert d_t < 1e-3 and d_r < 1e-3
    assert abs(q[0]) < 0.1  # facing the table, not the sideways solutions with joint 1 near +-2.1 rad
    assert kin.joint_origins(q)[2, 2] > 0.267  # elbow above the shoulder
