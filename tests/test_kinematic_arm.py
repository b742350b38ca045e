"""The kinematic arm: exact twist integration, per-axis speed limits, refused commands, the gripper."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sa_daemon.arm.base import ArmState, limit_twist
from sa_daemon.arm.kinematic import KinematicArm
from sa_daemon.config import LimitsConfig
from sa_daemon.geometry import Pose

START = Pose.from_rpy([0.3, -0.1, 0.25], [math.pi, -0.4, 0.2])
WIDE = LimitsConfig(linear_mps=10.0, angular_radps=10.0)


def _axis_angle_matrix(axis, angle: float) -> np.ndarray:
    """Rotation matrix of ``angle`` about unit ``axis`` (Rodrigues), written out independently."""
    k = np.asarray(axis, dtype=float)
    k = k / np.linalg.norm(k)
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + math.sin(angle) * kx + (1.0 - math.cos(angle)) * (kx @ kx)


# -- read ----------------------------------------------------------------------------------------------


def test_read_returns_start_pose_open_gripper_and_no_fault():
    arm = KinematicArm(START)
    s = arm.read()
    assert isinstance(s, ArmState)
    np.testing.assert_allclose(s.pose.position, START.position, atol=1e-15)
    np.testing.assert_allclose(s.pose.rotation, START.rotation, atol=1e-12)
    assert s.gripper_closed is False
    assert s.fault is None


def test_read_is_a_snapshot_not_a_live_view():
    arm = KinematicArm(START, WIDE)
    before = arm.read().pose
    arm.command_twist([0.1, 0.0, 0.0, 0.0, 0.0, 0.3])
    arm.step(0.5)
    np.testing.assert_allclose(before.position, START.position, atol=1e-15)
    np.testing.assert_allclose(before.quat_wxyz, START.quat_wxyz, atol=1e-15)
    assert arm.read().pose.distance(before)[0] > 0.04


def test_no_command_no_motion():
    arm = KinematicArm(START)
    arm.step(1.0)
    d_t, d_r = arm.read().pose.distance(START)
    assert d_t == 0.0 and d_r < 1e-7


# -- exact integration ---------------------------------------------------------------------------------


def test_pure_translation_integrates_exactly():
    arm = KinematicArm(START, WIDE)
    v = np.array([0.12, -0.05, 0.02])
    arm.command_twist(np.concatenate([v, np.zeros(3)]))
    arm.step(0.4)
    p = arm.read().pose
    np.testing.assert_allclose(p.position, START.position + 0.4 * v, atol=1e-12)
    np.testing.assert_allclose(p.rotation, START.rotation, atol=1e-12)


@pytest.mark.parametrize("axis", [[0, 0, 1], [1, 0, 0], [0.3, -0.5, 0.8]])
def test_pure_rotation_integrates_exactly_about_a_base_frame_axis(axis):
    arm = KinematicArm(START, WIDE)
    rate, dt = 0.7, 0.6
    w = rate * np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    arm.command_twist(np.concatenate([np.zeros(3), w]))
    arm.step(dt)
    p = arm.read().pose
    np.testing.assert_allclose(p.position, START.position, atol=1e-12)
    expected = _axis_angle_matrix(axis, rate * dt) @ START.rotation
    np.testing.assert_allclose(p.rotation, expected, atol=1e-9)


def test_constant_twist_in_many_small_steps_equals_one_big_step():
    twist = [0.05, 0.02, -0.03, 0.2, -0.1, 0.4]
    a, b = KinematicArm(START, WIDE), KinematicArm(START, WIDE)
    a.command_twist(twist)
    b.command_twist(twist)
    for _ in range(40):
        a.step(0.025)
    b.step(1.0)
    pa, pb = a.read().pose, b.read().pose
    np.testing.assert_allclose(pa.position, pb.position, atol=1e-12)
    # The angular part is about one fixed base axis: composing the steps is exact.
    np.testing.assert_allclose(pa.rotation, pb.rotation, atol=1e-9)


def test_command_is_held_until_the_next_one():
    arm = KinematicArm(START, WIDE)
    arm.command_twist([0.1, 0, 0, 0, 0, 0])
    arm.step(0.5)
    arm.step(0.5)
    arm.command_twist([0, 0.2, 0, 0, 0, 0])
    arm.step(0.5)
    np.testing.assert_allclose(arm.read().pose.position, START.position + [0.1, 0.1, 0.0], atol=1e-12)


# -- limits --------------------------------------------------------------------------------------------


def test_limit_twist_scales_linear_part_keeping_direction():
    t = limit_twist(np.array([0.5, -0.25, 0.1, 0.2, 0.0, -0.1]), 0.25, 1.0)
    np.testing.assert_allclose(t[:3], [0.25, -0.125, 0.05], atol=1e-15)
    np.testing.assert_allclose(t[3:], [0.2, 0.0, -0.1], atol=1e-15)  # angular under its limit


def test_limit_twist_scales_angular_part_by_its_largest_axis():
    t = limit_twist(np.array([0.1, 0.0, 0.0, 0.5, -2.0, 1.0]), 0.25, 1.0)
    np.testing.assert_allclose(t[:3], [0.1, 0.0, 0.0], atol=1e-15)
    np.testing.assert_allclose(t[3:], [0.25, -1.0, 0.5], atol=1e-15)


def test_limit_twist_does_not_touch_its_input():
    raw = np.array([1.0, 1.0, 1.0, 3.0, 3.0, 3.0])
    limit_twist(raw, 0.25, 1.0)
    np.testing.assert_array_equal(raw, [1.0, 1.0, 1.0, 3.0, 3.0, 3.0])


finite = st.floats(min_value=-50.0, max_value=50.0, allow_nan=False)


@settings(max_examples=200, deadline=None)
@given(
    st.lists(finite, min_size=6, max_size=6),
    st.floats(min_value=0.01, max_value=2.0),
    st.floats(min_value=0.01, max_value=3.0),
)
def test_limit_twist_properties(raw, lin, ang):
    t_in = np.array(raw)
    t = limit_twist(t_in, lin, ang)
    for part, limit in ((slice(0, 3), lin), (slice(3, 6), ang)):
        a, b = t_in[part], t[part]
        assert np.all(np.abs(b) <= limit * (1 + 1e-12))
        peak = np.max(np.abs(a))
        if peak <= limit:
            np.testing.assert_array_equal(b, a)  # untouched
        else:
            # b = s a with one positive factor s: direction kept, the largest axis at the limit.
            s = limit / peak
            np.testing.assert_allclose(b, s * a, rtol=1e-12, atol=1e-15)
            assert math.isclose(np.max(np.abs(b)), limit, rel_tol=1e-12)


def test_arm_applies_its_limits_to_commands():
    arm = KinematicArm(START, LimitsConfig(linear_mps=0.25, angular_radps=0.5, tcp_mps=1.0))
    arm.command_twist([1.0, 0.5, 0.0, 0.0, 0.0, 2.0])
    arm.step(1.0)
    p = arm.read().pose
    np.testing.assert_allclose(p.position, START.position + [0.25, 0.125, 0.0], atol=1e-12)
    expected = _axis_angle_matrix([0, 0, 1], 0.5) @ START.rotation
    np.testing.assert_allclose(p.rotation, expected, atol=1e-9)
    arm = KinematicArm(START, LimitsConfig(linear_mps=0.25, angular_radps=0.5, tcp_mps=0.1))
    arm.command_twist([1.0, 0.5, 0.0, 0.0, 0.0, 0.0])
    arm.step(1.0)  # per axis (0.25, 0.125), then the TCP speed 0.1 m/s, direction kept
    np.testing.assert_allclose(arm.read().pose.position, START.position + 0.1 * np.array([2, 1, 0]) / math.sqrt(5),
                               atol=1e-12)


def test_default_limits_are_the_configs():
    lim = LimitsConfig()
    arm = KinematicArm(START)
    arm.command_twist([10.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    arm.step(1.0)
    assert math.isclose(arm.read().pose.position[0] - START.position[0], lim.linear_mps, rel_tol=1e-12)


# -- refused commands ----------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "bad",
    [
        [math.nan, 0, 0, 0, 0, 0],
        [0, 0, 0, 0, 0, math.inf],
        [0, -math.inf, 0, 0, 0, 0],
        [0.1, 0, 0],
        [0.1, 0, 0, 0, 0, 0, 0],
        np.zeros((2, 6)),
        [],
    ],
    ids=["nan", "inf", "-inf", "3", "7", "2x6", "empty"],
)
def test_bad_twist_is_refused_and_the_held_command_kept(bad):
    arm = KinematicArm(START, WIDE)
    arm.command_twist([0.1, 0.0, 0.0, 0.0, 0.0, 0.0])
    with pytest.raises(ValueError):
        arm.command_twist(bad)
    arm.step(1.0)
    np.testing.assert_allclose(arm.read().pose.position, START.position + [0.1, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(arm.read().pose.rotation, START.rotation, atol=1e-12)


# -- gripper -------------------------------------------------------------------------------------------


def test_the_gripper_reports_its_state_and_does_not_gate_motion():
    """Like the xArm, the arm carries what it holds: a closed gripper does not stop a commanded twist.
    Holding the arm still while the gripper is closed is the safety pipeline's stage 5
    (``test_controller.py::test_gripper_closed_commands_zero_and_reopening_restarts_from_rest``)."""
    arm = KinematicArm(START, WIDE)
    arm.command_gripper(True)
    assert arm.read().gripper_closed is True
    arm.command_twist([0.0, 0.0, 0.05, 0.0, 0.0, 0.0])
    arm.step(1.0)
    np.testing.assert_allclose(arm.read().pose.position, START.position + [0.0, 0.0, 0.05], atol=1e-12)
    arm.command_gripper(False)
    assert arm.read().gripper_closed is False


def test_reset_returns_to_the_start_at_rest_with_the_gripper_open():
    arm = KinematicArm(START, WIDE)
    arm.command_twist(np.array([0.1, 0.0, 0.0, 0.0, 0.0, 0.5]))
    arm.step(1.0)
    arm.command_gripper(True)
    assert arm.reset() is True
    s = arm.read()
    assert s.gripper_closed is False
    assert s.pose.distance(START) == pytest.approx((0.0, 0.0), abs=1e-12)
    arm.step(1.0)  # the old twist is gone
    assert arm.read().pose.distance(START) == pytest.approx((0.0, 0.0), abs=1e-12)
