"""The fake xArm SDK follows the documented rules (shared/reference/xarm6.md and the SDK's docstrings).

Motion is checked on a manual clock, so integration and duration expiry are exact and instant; only the
hang test uses real time. If the real SDK is importable, the fake's signatures are compared with it.
"""

from __future__ import annotations

import inspect
import math
import threading
import time

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sa_daemon.geometry import quat_to_matrix, rpy_to_quat
from sa_daemon.testing.fake_xarm import (
    DEFAULT_START_MM_RAD,
    END_EFFECTOR_HAS_FAULT,
    END_EFFECTOR_NOT_ENABLED,
    HAS_ERROR,
    NOT_CONNECTED,
    NOT_READY,
    PARAM_ERROR,
    REPLY_TIMEOUT,
    SDK_METHODS,
    FakeXArmAPI,
    matrix_to_rpy,
)


class Clock:
    """A manual clock (s) for the fake's motion."""

    def __init__(self) -> None:
        self.t = 1000.0

    def __call__(self) -> float:
        return self.t

    def advance(self, dt: float) -> None:
        self.t += dt


@pytest.fixture
def clock() -> Clock:
    return Clock()


def ready_arm(clock: Clock, **kw) -> FakeXArmAPI:
    """A connected fake in Cartesian velocity mode, ready to move."""
    arm = FakeXArmAPI("fake", is_radian=True, clock=clock, **kw)
    assert arm.motion_enable(True) == 0
    assert arm.set_mode(5) == 0
    assert arm.set_state(0) == 0
    return arm


# -- connection -----------------------------------------------------------------------------------------


def test_constructor_connects_unless_do_not_open(clock):
    assert FakeXArmAPI("fake", clock=clock).connected
    arm = FakeXArmAPI("fake", do_not_open=True, clock=clock)
    assert not arm.connected
    assert arm.get_position() == (NOT_CONNECTED, None)
    assert arm.set_mode(5) == NOT_CONNECTED
    arm.connect()
    assert arm.connected
    assert [c.name for c in arm.calls] == ["get_position", "set_mode", "connect"]


def test_constructor_without_port_refused():
    with pytest.raises(ValueError, match="port"):
        FakeXArmAPI()


def test_drop_and_restore_connection(clock):
    arm = ready_arm(clock)
    seen: list[dict] = []
    assert arm.register_connect_changed_callback(seen.append)
    arm.drop_connection()
    assert seen == [{"connected": False, "reported": False}]
    assert not arm.connected
    assert arm.vc_set_cartesian_velocity([0.0] * 6, is_radian=True) == NOT_CONNECTED
    assert arm.get_servo_angle(is_radian=True) == (NOT_CONNECTED, None)
    with pytest.raises(ConnectionError):
        arm.connect()
    arm.restore_connection()
    assert not arm.connected  # a dropped socket stays closed until the client reconnects
    arm.connect()
    assert arm.connected and seen[-1] == {"connected": True, "reported": True}
    # The controller kept its mode and state: the link, not the arm, went away.
    assert arm.vc_set_cartesian_velocity([1.0, 0, 0, 0, 0, 0], is_radian=True, duration=0.1) == 0


def test_disconnect_fires_callback_and_blocks_calls(clock):
    arm = ready_arm(clock)
    seen: list[dict] = []
    arm.register_connect_changed_callback(seen.append)
    arm.disconnect()
    assert seen == [{"connected": False, "reported": False}]
    assert arm.clean_warn() == NOT_CONNECTED


def test_hang_blocks_then_returns_reply_timeout():
    arm = FakeXArmAPI("fake", is_radian=True)
    arm.hang(0.2)
    t0 = time.monotonic()
    other: list = []
    worker = threading.Thread(target=lambda: other.append(arm.set_mode(5)))  # issued within the window too
    worker.start()
    assert arm.get_position(is_radian=True) == (REPLY_TIMEOUT, None)
    assert time.monotonic() - t0 >= 0.2 - 1e-3
    worker.join(5.0)
    assert other == [REPLY_TIMEOUT]
    assert arm.mode == 0  # no effect
    code, _ = arm.get_position(is_radian=True)
    assert code == 0  # normal again


def test_hang_can_be_ended_early_and_blocked_calls_are_visible():
    arm = FakeXArmAPI("fake", is_radian=True)
    arm.hang(30.0)
    result: list = []
    worker = threading.Thread(target=lambda: result.append(arm.get_state()))
    worker.start()
    assert arm.wait_for_blocked(timeout=5.0)
    arm.unhang()
    worker.join(5.0)
    assert result == [(REPLY_TIMEOUT, None)]


# -- mode / state machine -------------------------------------------------------------------------------


def test_velocity_needs_enable_mode_and_state(clock):
    arm = FakeXArmAPI("fake", is_radian=True, clock=clock)
    v = [10.0, 0, 0, 0, 0, 0]
    assert arm.vc_set_cartesian_velocity(v, duration=1) == NOT_READY
    arm.motion_enable(True)
    assert arm.vc_set_cartesian_velocity(v, duration=1) == NOT_READY
    arm.set_mode(5)
    assert arm.vc_set_cartesian_velocity(v, duration=1) == NOT_READY  # state not set after the mode change
    assert arm.get_state() == (0, 4)
    arm.set_state(0)
    assert arm.get_state() == (0, 2)
    assert arm.vc_set_cartesian_velocity(v, duration=1) == 0
    assert arm.get_state() == (0, 1)  # moving


def test_every_mode_change_needs_set_state_again(clock):
    arm = ready_arm(clock)
    arm.set_mode(5)  # even the same mode
    assert arm.vc_set_cartesian_velocity([1.0, 0, 0, 0, 0, 0]) == NOT_READY
    arm.set_state(0)
    assert arm.vc_set_cartesian_velocity([1.0, 0, 0, 0, 0, 0]) == 0


def test_set_state_without_enable_has_no_effect(clock):
    arm = FakeXArmAPI("fake", is_radian=True, clock=clock)
    arm.set_mode(5)
    assert arm.set_state(0) == 0  # the SDK maps "not ready" to 0 for non-motion calls
    assert arm.get_state() == (0, 4)
    assert arm.vc_set_cartesian_velocity([1.0, 0, 0, 0, 0, 0]) == NOT_READY


def test_velocity_outside_mode_5_refused(clock):
    arm = FakeXArmAPI("fake", is_radian=True, clock=clock)
    arm.motion_enable(True)
    arm.set_mode(0)
    arm.set_state(0)
    assert arm.vc_set_cartesian_velocity([1.0, 0, 0, 0, 0, 0]) == NOT_READY


@pytest.mark.parametrize("speeds", [[1.0] * 5, [1.0] * 7, [math.nan, 0, 0, 0, 0, 0], [0, 0, 0, 0, 0, math.inf], "x"])
def test_malformed_speeds_refused(clock, speeds):
    arm = ready_arm(clock)
    assert arm.vc_set_cartesian_velocity(speeds, is_radian=True, duration=1) == PARAM_ERROR
    assert not np.any(arm.speed)


def test_bad_mode_and_state_refused(clock):
    arm = FakeXArmAPI("fake", clock=clock)
    assert arm.set_mode(8) == PARAM_ERROR
    assert arm.set_state(7) == PARAM_ERROR


# -- units and motion -----------------------------------------------------------------------------------


def test_linear_speed_is_mm_per_s_and_position_mm(clock):
    arm = ready_arm(clock)
    _, p0 = arm.get_position(is_radian=True)
    assert p0[:3] == pytest.approx(DEFAULT_START_MM_RAD[:3])
    assert arm.vc_set_cartesian_velocity([100.0, -20.0, 50.0, 0, 0, 0], is_radian=True, duration=0) == 0
    clock.advance(0.5)
    _, p1 = arm.get_position(is_radian=True)
    np.testing.assert_allclose(np.subtract(p1[:3], p0[:3]), [50.0, -10.0, 25.0], atol=1e-9)


def test_angular_speed_degrees_unless_radian(clock):
    arm = ready_arm(clock)  # constructed with is_radian=True: the call's flag overrides it
    assert arm.vc_set_cartesian_velocity([0, 0, 0, 0, 0, 90.0], is_radian=False, duration=0) == 0
    clock.advance(1.0)
    _, deg = arm.get_position(is_radian=False)
    _, rad = arm.get_position(is_radian=True)
    assert deg[5] == pytest.approx(90.0, abs=1e-6)  # yaw, degrees
    assert rad[5] == pytest.approx(math.pi / 2, abs=1e-9)
    assert abs(deg[3]) == pytest.approx(180.0, abs=1e-6)  # roll unchanged (pointing down)


def test_default_units_follow_constructor_is_radian(clock):
    arm = FakeXArmAPI("fake", is_radian=False, clock=clock)
    arm.motion_enable(True)
    arm.set_mode(5)
    arm.set_state(0)
    arm.vc_set_cartesian_velocity([0, 0, 0, 0, 0, 10.0], duration=0)  # deg/s
    clock.advance(2.0)
    _, pos = arm.get_position()
    assert pos[5] == pytest.approx(20.0, abs=1e-6)
    _, q = arm.get_servo_angle()
    assert q[1] == pytest.approx(math.degrees(-0.5))


def test_angular_speed_is_a_base_frame_rate_vector(clock):
    arm = ready_arm(clock)
    w = np.array([0.3, -0.2, 0.4])
    arm.vc_set_cartesian_velocity([0, 0, 0, *w], is_radian=True, duration=0)
    clock.advance(1.0)
    _, pos = arm.get_position(is_radian=True)
    r0 = quat_to_matrix(rpy_to_quat(DEFAULT_START_MM_RAD[3:]))
    angle = float(np.linalg.norm(w))
    k = w / angle
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    rw = np.eye(3) + math.sin(angle) * kx + (1 - math.cos(angle)) * kx @ kx
    np.testing.assert_allclose(quat_to_matrix(rpy_to_quat(pos[3:])), rw @ r0, atol=1e-9)


def test_tool_coordinates_rotate_into_the_base_frame(clock):
    arm = ready_arm(clock)  # tool z points down (roll = pi)
    arm.vc_set_cartesian_velocity([0, 0, 100.0, 0, 0, 0], is_radian=True, is_tool_coord=True, duration=0)
    clock.advance(0.1)
    _, pos = arm.get_position(is_radian=True)
    assert pos[2] == pytest.approx(DEFAULT_START_MM_RAD[2] - 10.0, abs=1e-9)


def test_duration_expiry_zeroes_the_speed(clock):
    arm = ready_arm(clock)
    arm.vc_set_cartesian_velocity([100.0, 0, 0, 0, 0, 0], is_radian=True, duration=0.2)
    clock.advance(0.1)
    assert arm.speed[0] == 100.0 and arm.get_state() == (0, 1)
    clock.advance(0.9)
    _, pos = arm.get_position(is_radian=True)
    assert pos[0] == pytest.approx(DEFAULT_START_MM_RAD[0] + 20.0, abs=1e-9)  # 0.2 s at 100 mm/s
    assert not np.any(arm.speed)
    assert arm.get_state() == (0, 2)  # ready, idle


def test_stopped_since_is_the_model_instant_the_speed_became_zero(clock):
    """The instant a ``duration`` runs out, however late anyone reads it (the fault tests time the
    controller's own stop with it, on a busy machine); a zero command's arrival; ``None`` while moving."""
    arm = ready_arm(clock)
    t0 = clock()
    assert arm.stopped_since == t0
    arm.vc_set_cartesian_velocity([100.0, 0, 0, 0, 0, 0], is_radian=True, duration=0.03)
    assert arm.stopped_since is None
    clock.advance(0.5)  # read 470 ms after the expiry
    assert arm.stopped_since == pytest.approx(t0 + 0.03, abs=1e-12)
    arm.vc_set_cartesian_velocity([100.0, 0, 0, 0, 0, 0], is_radian=True, duration=0)
    clock.advance(0.1)
    assert arm.stopped_since is None
    arm.vc_set_cartesian_velocity([0.0] * 6, is_radian=True, duration=0)
    t_zero = clock()
    clock.advance(0.2)
    assert arm.stopped_since == t_zero


def test_each_command_restarts_the_duration(clock):
    arm = ready_arm(clock)
    for _ in range(10):
        arm.vc_set_cartesian_velocity([100.0, 0, 0, 0, 0, 0], is_radian=True, duration=0.03)
        clock.advance(0.01)
    clock.advance(1.0)
    _, pos = arm.get_position(is_radian=True)
    assert pos[0] == pytest.approx(DEFAULT_START_MM_RAD[0] + 100.0 * (0.1 + 0.02), abs=1e-9)


@pytest.mark.parametrize("duration", [0, -1])
def test_non_positive_duration_holds_the_speed(clock, duration):
    arm = ready_arm(clock)
    arm.vc_set_cartesian_velocity([10.0, 0, 0, 0, 0, 0], is_radian=True, duration=duration)
    clock.advance(10.0)
    assert arm.speed[0] == 10.0


def test_old_firmware_ignores_duration(clock):
    arm = ready_arm(clock, firmware=(1, 7, 9))
    arm.vc_set_cartesian_velocity([10.0, 0, 0, 0, 0, 0], is_radian=True, duration=0.1)
    clock.advance(5.0)
    assert arm.speed[0] == 10.0  # why the driver refuses firmware < 1.8.0


@settings(max_examples=200, deadline=None)
@given(st.tuples(st.floats(-3.1, 3.1), st.floats(-1.55, 1.55), st.floats(-3.1, 3.1)))
def test_rpy_round_trip(rpy):
    m = quat_to_matrix(rpy_to_quat(rpy))
    np.testing.assert_allclose(quat_to_matrix(rpy_to_quat(matrix_to_rpy(m))), m, atol=1e-9)


def test_rpy_at_gimbal_lock():
    m = quat_to_matrix(rpy_to_quat([0.3, math.pi / 2, 0.5]))
    np.testing.assert_allclose(quat_to_matrix(rpy_to_quat(matrix_to_rpy(m))), m, atol=1e-9)


# -- errors and recovery --------------------------------------------------------------------------------


def test_error_stops_the_arm_and_fires_the_callback(clock):
    arm = ready_arm(clock)
    seen: list[dict] = []
    assert arm.register_error_warn_changed_callback(seen.append)
    arm.vc_set_cartesian_velocity([100.0, 0, 0, 0, 0, 0], is_radian=True, duration=0)
    clock.advance(0.1)
    arm.inject_error(22)
    assert seen == [{"error_code": 22, "warn_code": 0}]
    assert (arm.mode, arm.state, arm.error_code) == (0, 4, 22)
    assert arm.get_err_warn_code() == (0, [22, 0])
    _, before = arm.get_position(is_radian=True)
    clock.advance(1.0)
    _, after = arm.get_position(is_radian=True)
    assert after == before  # stopped
    assert arm.vc_set_cartesian_velocity([1.0, 0, 0, 0, 0, 0], is_radian=True) == HAS_ERROR


def test_recovery_sequence(clock):
    arm = ready_arm(clock)
    arm.inject_error(31)
    v = [1.0, 0, 0, 0, 0, 0]
    assert arm.clean_error() == 0
    assert arm.vc_set_cartesian_velocity(v) == NOT_READY
    assert arm.motion_enable(True) == 0
    assert arm.vc_set_cartesian_velocity(v) == NOT_READY
    assert arm.set_mode(5) == 0
    assert arm.vc_set_cartesian_velocity(v) == NOT_READY
    assert arm.set_state(0) == 0
    assert arm.vc_set_cartesian_velocity(v) == 0


def test_recovery_in_the_wrong_order_does_not_recover(clock):
    arm = ready_arm(clock)
    arm.inject_error(24)
    for call in (lambda: arm.motion_enable(True), lambda: arm.set_mode(5), lambda: arm.set_state(0)):
        assert call() == 0  # "succeeds" (the SDK hides the refusal) ...
    assert arm.vc_set_cartesian_velocity([1.0, 0, 0, 0, 0, 0]) == HAS_ERROR  # ... but changed nothing
    arm.clean_error()
    arm.set_mode(5)
    arm.set_state(0)  # motion still disabled by the error
    assert arm.vc_set_cartesian_velocity([1.0, 0, 0, 0, 0, 0]) == NOT_READY


def test_clean_error_fires_the_callback_with_zero(clock):
    arm = ready_arm(clock)
    seen: list[dict] = []
    arm.register_error_warn_changed_callback(seen.append)
    arm.inject_error(35)
    arm.clean_error()
    assert seen == [{"error_code": 35, "warn_code": 0}, {"error_code": 0, "warn_code": 0}]
    assert arm.release_error_warn_changed_callback(seen.append)
    arm.inject_error(35)
    assert len(seen) == 2


def test_warning_does_not_stop_motion(clock):
    arm = ready_arm(clock)
    seen: list[dict] = []
    arm.register_error_warn_changed_callback(seen.append)
    arm.inject_warn(11)
    assert seen == [{"error_code": 0, "warn_code": 11}]
    assert arm.vc_set_cartesian_velocity([1.0, 0, 0, 0, 0, 0], duration=1) == 0
    arm.clean_warn()
    assert arm.warn_code == 0 and seen[-1] == {"error_code": 0, "warn_code": 0}


def test_error_present_at_connect_is_reported(clock):
    arm = FakeXArmAPI("fake", do_not_open=True, clock=clock)
    arm.inject_error(1)  # e-stop pressed before the client connects: no callback yet
    seen: list[dict] = []
    arm.register_error_warn_changed_callback(seen.append)
    arm.connect()
    assert seen == [{"error_code": 1, "warn_code": 0}]


def test_inject_error_needs_a_positive_code(clock):
    with pytest.raises(ValueError):
        FakeXArmAPI("fake", clock=clock).inject_error(0)


# -- gripper --------------------------------------------------------------------------------------------


def test_gripper_setup_and_range(clock):
    arm = FakeXArmAPI("fake", clock=clock)
    assert arm.set_gripper_position(0) == END_EFFECTOR_NOT_ENABLED
    assert arm.set_gripper_mode(1) == PARAM_ERROR
    assert arm.set_gripper_mode(0) == 0
    assert arm.set_gripper_enable(True) == 0
    assert arm.set_gripper_speed(0) == PARAM_ERROR
    assert arm.set_gripper_speed(2000) == 0
    assert arm.set_gripper_position(0) == 0
    assert arm.get_gripper_position() == (0, 0.0)
    assert arm.set_gripper_position(850) == 0 and arm.gripper_position == 850.0
    for bad in (-1, 851, math.nan):
        assert arm.set_gripper_position(bad) == PARAM_ERROR
    assert arm.gripper_position == 850.0


def test_gripper_auto_enable_and_error(clock):
    arm = FakeXArmAPI("fake", clock=clock)
    assert arm.set_gripper_position(400, auto_enable=True) == 0 and arm.gripper_enabled
    arm.inject_gripper_error(9)
    assert arm.get_gripper_err_code() == (0, 9)
    assert arm.set_gripper_position(0) == END_EFFECTOR_HAS_FAULT
    assert arm.clean_gripper_error() == 0
    assert arm.set_gripper_position(0) == 0


# -- call log -------------------------------------------------------------------------------------------


def test_call_log_records_arguments_results_and_fake_time(clock):
    arm = FakeXArmAPI("fake", is_radian=True, clock=clock)
    clock.advance(1.5)
    arm.vc_set_cartesian_velocity([1, 2, 3, 0.1, 0.2, 0.3], is_radian=True, duration=0.03)
    call = arm.calls_named("vc_set_cartesian_velocity")[0]
    assert call.args == ([1, 2, 3, 0.1, 0.2, 0.3],)
    assert call.kwargs == {"is_radian": True, "is_tool_coord": False, "duration": 0.03}
    assert call.result == NOT_READY and call.t == clock.t
    assert arm.wait_for_calls("vc_set_cartesian_velocity", 1, timeout=0.0)
    assert not arm.wait_for_calls("vc_set_cartesian_velocity", 2, timeout=0.01)
    arm.clear_calls()
    assert arm.calls == []


# -- against the real SDK (when installed) --------------------------------------------------------------



def _named_params(fn) -> list[tuple[str, object]]:
    ps = inspect.signature(fn).parameters.values()
    return [(p.name, p.default) for p in ps if p.kind is p.POSITIONAL_OR_KEYWORD and p.name != "self"]


def test_signatures_match_the_sdk():
    """Same parameter names and defaults as the installed SDK (skipped without ``pip install ".[xarm]"``)."""
    wrapper = pytest.importorskip("xarm.wrapper")
    for name in SDK_METHODS:
        assert _named_params(getattr(FakeXArmAPI, name)) == _named_params(getattr(wrapper.XArmAPI, name)), name
    assert _named_params(FakeXArmAPI.__init__)[:3] == _named_params(wrapper.XArmAPI.__init__)[:3]
    for prop in ("connected", "mode", "state", "error_code", "warn_code", "version_number", "collision_sensitivity",
                 "self_collision_params"):
        assert isinstance(getattr(wrapper.XArmAPI, prop), property), prop
