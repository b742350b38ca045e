"""The xArm driver against the fake SDK: start-up order, units, latched faults, reconnection, close.

Synchronisation is by waiting for the fake's call log (``wait_for_calls``) or a condition with a
generous timeout, never by sleeping and hoping: the tests stay fast on an idle machine and correct on a
loaded one. The last test drives a real arm and runs only when ``SA_XARM_IP`` is set.
"""

from __future__ import annotations

import math
import os
import threading
import time
from collections.abc import Callable, Iterator

import numpy as np
import pytest

from sa_daemon.arm.xarm_arm import CLOSED, DISCONNECTED, XArm
from sa_daemon.arm.xarm_sdk import (
    GRIPPER_CLOSED_POS,
    GRIPPER_OPEN_POS,
    error_text,
    pose_from_sdk,
    twist_to_speeds,
)
from sa_daemon.config import Config, config_from_dict
from sa_daemon.testing.fake_xarm import SDK_METHODS, FakeXArmAPI

WAIT_S = 10.0  # generous: only ever reached when something is broken
VC = "vc_set_cartesian_velocity"


def make_cfg(**xarm) -> Config:
    base = {"sdk": "fake", "reconnect_min_s": 0.05, "reconnect_max_s": 0.2}
    base.update(xarm)
    return config_from_dict({"arm": {"xarm": base}})


def wait_until(pred: Callable[[], bool], timeout: float = WAIT_S) -> bool:
    """Poll ``pred`` every millisecond until it holds (``True``) or ``timeout`` s pass."""
    deadline = time.monotonic() + timeout
    while not pred():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.001)
    return True


def sync(fake: FakeXArmAPI, polls: int = 3) -> None:
    """Wait until the I/O thread has polled ``polls`` more times, so it has seen earlier requests."""
    n = len(fake.calls_named("get_position"))
    assert fake.wait_for_calls("get_position", n + polls, WAIT_S)


@pytest.fixture
def fake() -> FakeXArmAPI:
    return FakeXArmAPI("fake", is_radian=True, do_not_open=True)


@pytest.fixture
def arm(fake) -> Iterator[XArm]:
    a = XArm(make_cfg(), api_factory=lambda: fake)
    yield a
    a.close()


def vc_calls(fake: FakeXArmAPI):
    return fake.calls_named(VC)


# -- start-up -------------------------------------------------------------------------------------------


def test_startup_call_order(arm, fake):
    names = [c.name for c in fake.calls]
    expected = [
        "connect", "get_err_warn_code",  # an error already present would stay latched
        "clean_warn",
        # the controller's own limits, before motion is enabled; reduced mode last (it makes the speed and
        # boundary set before it take effect), then everything read back
        "set_reduced_max_tcp_speed", "set_reduced_tcp_boundary", "set_fence_mode", "set_collision_sensitivity",
        "set_self_collision_detection", "set_reduced_mode", "get_reduced_states",
        "motion_enable", "set_mode", "set_state",
        "get_err_warn_code", "get_state",  # verified: no error, state ready
        "set_gripper_mode", "set_gripper_enable", "set_gripper_speed",
        "get_position", "get_servo_angle",
    ]
    assert names[: len(expected)] == expected
    args = {c.name: c.args for c in fake.calls[: len(expected)]}
    assert args["motion_enable"] == (True,)
    assert args["set_mode"] == (5,)
    assert args["set_state"] == (0,)
    assert args["set_gripper_mode"] == (0,)
    assert args["set_gripper_enable"] == (True,)
    assert args["set_gripper_speed"] == (2000.0,)
    assert VC not in names[: len(expected)]
    st = arm.read()
    assert st.fault is None and not st.gripper_closed
    assert arm.name == "xarm" and arm.realtime is True


def test_first_pose_is_si(arm, fake):
    _, pos = fake.get_position(is_radian=True)
    st = arm.read()
    np.testing.assert_allclose(st.pose.position, np.array(pos[:3]) / 1000.0, atol=1e-12)
    np.testing.assert_allclose(st.pose.rotation @ [0, 0, 1], [0, 0, -1], atol=1e-9)  # tool z points down
    np.testing.assert_allclose(st.joints, [0.0, -0.5, -1.0, 0.0, 1.5, 0.0])
    assert st.joints.shape == (6,)


def test_pose_conversion_helpers():
    pose = pose_from_sdk([100.0, -200.0, 300.0, math.pi, 0.0, math.pi / 2])
    np.testing.assert_allclose(pose.position, [0.1, -0.2, 0.3])
    np.testing.assert_allclose(pose.rotation @ [1, 0, 0], [0, 1, 0], atol=1e-12)
    assert twist_to_speeds(np.array([0.1, -0.02, 0.0, 0.0, 0.3, -0.5])) == pytest.approx(
        [100.0, -20.0, 0.0, 0.0, 0.3, -0.5])


def test_unreachable_controller_raises(fake):
    fake.drop_connection()
    with pytest.raises(ConnectionError, match="cannot connect"):
        XArm(make_cfg(), api_factory=lambda: fake)


def test_error_present_at_startup_stays_latched(fake):
    fake.inject_error(2)
    arm = XArm(make_cfg(), api_factory=lambda: fake)
    try:
        assert arm.read().fault == error_text(2)
        assert "motion_enable" not in [c.name for c in fake.calls]
        arm.command_twist(np.array([0.05, 0, 0, 0, 0, 0]))
        sync(fake)
        assert all(c.args[0] == [0.0] * 6 for c in vc_calls(fake))  # at most the zero sent on an error
        arm.reset_fault()
        assert wait_until(lambda: arm.read().fault is None)
    finally:
        arm.close()


def test_old_firmware_is_a_fault(fake):
    old = FakeXArmAPI("fake", is_radian=True, do_not_open=True, firmware=(1, 7, 0))
    arm = XArm(make_cfg(), api_factory=lambda: old)
    try:
        assert "firmware 1.7.0" in arm.read().fault
        arm.command_twist(np.array([0.05, 0, 0, 0, 0, 0]))
        arm.reset_fault()  # cannot help: the check runs again
        sync(old)
        assert wait_until(lambda: not arm.status()["recovering"])
        assert "firmware" in arm.read().fault
        assert vc_calls(old) == []
    finally:
        arm.close()


def test_sdk_fake_uses_the_fake_through_the_factory():
    from sa_daemon.arm.factory import make_arm
    from sa_daemon.world.scene import load_scene

    arm = make_arm("xarm", load_scene("scene1"), make_cfg())
    try:
        assert isinstance(arm, XArm) and isinstance(arm.api, FakeXArmAPI)
        assert arm.read().fault is None
    finally:
        arm.close()


def test_a_real_arm_does_not_reset(arm, fake):
    # It cannot teleport back to a start pose: the caller must build a fresh driver (and a person must
    # move the arm).
    assert arm.reset() is False
    assert not [c.name for c in fake.calls if c.name.startswith(("set_position", "set_servo", "move_gohome"))]


# -- commands -------------------------------------------------------------------------------------------


def test_twist_becomes_mm_and_rad_per_s_with_duration(arm, fake):
    arm.command_twist(np.array([0.1, 0.0, 0.0, 0.0, 0.0, 0.5]))
    assert fake.wait_for_calls(VC, 1, WAIT_S)
    call = vc_calls(fake)[0]
    assert call.args[0] == pytest.approx([100.0, 0.0, 0.0, 0.0, 0.0, 0.5])
    assert call.kwargs["is_radian"] is True and call.kwargs["is_tool_coord"] is False
    assert call.kwargs["duration"] == pytest.approx(3.0 / 100.0)
    assert call.result == 0
    assert arm.status()["commands_sent"] == 1


def test_duration_follows_control_rate_and_is_capped_at_250_hz():
    for hz, rate in ((50.0, 50.0), (500.0, 250.0)):
        cfg = config_from_dict({"runtime": {"control_hz": hz}, "arm": {"xarm": {"sdk": "fake", "command_periods": 4}}})
        arm = XArm(cfg)
        try:
            assert arm.rate_hz == rate and arm.duration_s == pytest.approx(4.0 / rate)
        finally:
            arm.close()


def test_the_arm_moves_and_read_follows(arm, fake):
    x0 = arm.read().pose.position[0]
    for _ in range(20):
        arm.command_twist(np.array([0.1, 0.0, 0.0, 0.0, 0.0, 0.0]))
        time.sleep(0.01)
    sync(fake)
    assert arm.read().pose.position[0] > x0 + 0.005  # at least a quarter of the 20 mm commanded


@pytest.mark.parametrize("bad", [[math.nan, 0, 0, 0, 0, 0], [0, 0, 0, 0, 0, math.inf], [0.1] * 5, [[0.1] * 6]])
def test_non_finite_or_malformed_twist_refused_and_nothing_sent(arm, fake, bad):
    with pytest.raises(ValueError):
        arm.command_twist(np.array(bad, dtype=float))
    sync(fake)
    assert vc_calls(fake) == []
    assert arm.read().fault is None


def test_twist_is_limited_to_the_configured_speeds(arm, fake):
    arm.command_twist(np.array([1.0, 0.0, 0.0, 0.0, 0.0, 0.0]))  # 1 m/s > limits.linear_mps = 0.25
    assert fake.wait_for_calls(VC, 1, WAIT_S)
    assert vc_calls(fake)[0].args[0][0] == pytest.approx(250.0)


def test_only_the_latest_twist_is_sent(arm, fake):
    entered, release = threading.Event(), threading.Event()
    original = fake.get_position

    def slow_poll(*args, **kwargs):  # a slow (not failed) reply keeps the I/O thread busy
        entered.set()
        release.wait(WAIT_S)
        return original(*args, **kwargs)

    fake.get_position = slow_poll  # type: ignore[method-assign]
    assert entered.wait(WAIT_S)
    for vx in (0.01, 0.02, 0.03):
        arm.command_twist(np.array([vx, 0, 0, 0, 0, 0]))
    del fake.get_position
    release.set()
    assert fake.wait_for_calls(VC, 1, WAIT_S)
    sync(fake)
    assert [c.args[0][0] for c in vc_calls(fake)] == [pytest.approx(30.0)]


def test_twists_during_a_hang_are_void(arm, fake):
    fake.hang(0.3)
    assert fake.wait_for_blocked(WAIT_S)  # the I/O thread is stuck in a poll
    arm.command_twist(np.array([0.05, 0, 0, 0, 0, 0]))
    # The poll returns "reply timeout": the link counts as lost, so the queued twist is never sent.
    assert wait_until(lambda: arm.status()["reconnects"] == 1)
    sync(fake)
    assert vc_calls(fake) == []


def test_gripper_mapping(arm, fake):
    arm.command_gripper(True)
    assert fake.wait_for_calls("set_gripper_position", 1, WAIT_S)
    assert wait_until(lambda: arm.read().gripper_closed)
    arm.command_gripper(False)
    assert fake.wait_for_calls("set_gripper_position", 2, WAIT_S)
    assert wait_until(lambda: not arm.read().gripper_closed)
    assert [c.args[0] for c in fake.calls_named("set_gripper_position")] == [GRIPPER_CLOSED_POS, GRIPPER_OPEN_POS]
    assert fake.gripper_position == 850.0


def test_gripper_failure_is_reported_not_an_arm_fault(arm, fake):
    fake.inject_gripper_error(5)
    arm.command_gripper(True)
    assert fake.wait_for_calls("set_gripper_position", 1, WAIT_S)
    assert wait_until(lambda: arm.status()["gripper_code"] == 102)
    assert not arm.read().gripper_closed and arm.read().fault is None


# -- read() and command_twist() never block ------------------------------------------------------------


def test_read_never_blocks_while_the_sdk_hangs(arm, fake):
    fake.hang(0.5)
    assert fake.wait_for_blocked(WAIT_S)
    reads, commands = [], []
    for _ in range(200):
        t0 = time.perf_counter()
        st = arm.read()
        reads.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        arm.command_twist(np.array([0.01, 0, 0, 0, 0, 0]))
        arm.status()
        commands.append(time.perf_counter() - t0)
    assert st.pose is not None
    assert vc_calls(fake) == []  # nothing got through the hung link
    # Typical read: microseconds. A percentile, not the max, so an OS preemption cannot fail the test;
    # the max still proves nothing waited for the 0.5 s hang.
    assert np.percentile(reads, 90) < 0.005 and max(reads) < 0.2
    assert np.percentile(commands, 90) < 0.005 and max(commands) < 0.2
    # The hang ends in a reply timeout (code 3): treated as a lost link, then reconnected, still faulted.
    assert wait_until(lambda: arm.status()["reconnects"] == 1)
    assert DISCONNECTED in arm.read().fault
    assert "code 3" in arm.status()["disconnect_reason"]


# -- controller errors ----------------------------------------------------------------------------------


def test_injected_error_stops_the_stream_until_reset(arm, fake):
    arm.command_twist(np.array([0.05, 0, 0, 0, 0, 0]))
    assert fake.wait_for_calls(VC, 1, WAIT_S)
    fake.inject_error(22)
    assert arm.read().fault == "xArm error 22: self collision"
    assert fake.wait_for_calls(VC, 2, WAIT_S)  # the one zero command after the error
    assert vc_calls(fake)[1].args[0] == [0.0] * 6
    assert arm.status()["error_code"] == 22
    n = len(vc_calls(fake))
    for _ in range(10):
        arm.command_twist(np.array([0.05, 0, 0, 0, 0, 0]))
        time.sleep(0.002)
    sync(fake)
    assert len(vc_calls(fake)) == n  # nothing sent while latched
    assert arm.read().fault == "xArm error 22: self collision"
    assert arm.status()["twists_dropped"] >= 10

    mark = len(fake.calls)
    arm.reset_fault()
    assert wait_until(lambda: arm.read().fault is None)
    recovery = [c.name for c in fake.calls[mark:]]
    order = ["clean_error", "motion_enable", "set_mode", "set_state"]
    assert [recovery.index(name) for name in order] == sorted(recovery.index(name) for name in order)
    arm.command_twist(np.array([0.05, 0, 0, 0, 0, 0]))
    assert fake.wait_for_calls(VC, n + 1, WAIT_S)
    assert vc_calls(fake)[-1].result == 0 and vc_calls(fake)[-1].args[0][0] == pytest.approx(50.0)


def test_reset_without_fault_does_nothing(arm, fake):
    mark = len(fake.calls)
    arm.reset_fault()
    sync(fake)
    assert "clean_error" not in [c.name for c in fake.calls[mark:]]


def test_refused_command_latches_a_fault(arm, fake):
    # Someone switches the arm to mode 0 behind the daemon's back (e.g. xArm Studio): code 9.
    fake.set_mode(0)
    arm.command_twist(np.array([0.05, 0, 0, 0, 0, 0]))
    assert wait_until(lambda: arm.read().fault is not None)
    assert "code 9" in arm.read().fault
    arm.reset_fault()
    assert wait_until(lambda: arm.read().fault is None)
    assert fake.mode == 5


def test_error_reply_without_callback_names_the_error(fake):
    arm = XArm(make_cfg(), api_factory=lambda: fake)
    try:
        fake.release_error_warn_changed_callback(None)  # as if the report socket missed it
        fake.inject_error(35)
        arm.command_twist(np.array([0.05, 0, 0, 0, 0, 0]))
        assert wait_until(lambda: arm.read().fault is not None)
        assert arm.read().fault == error_text(35) == "xArm error 35: safety boundary"
    finally:
        arm.close()


def test_unknown_error_code_still_named():
    assert error_text(999) == "xArm error 999: controller error (see the SDK error list)"
    assert error_text(1).startswith("xArm error 1: emergency stop")


def test_unusable_pose_replies_latch_a_fault_after_a_while(arm, fake):
    fake.get_position = lambda *a, **k: (10, None)  # type: ignore[method-assign]  # "result invalid"
    assert wait_until(lambda: arm.read().fault is not None)
    assert "pose not updated" in arm.read().fault and "code 10" in arm.read().fault
    assert arm.status()["poll_errors"] >= 2 and arm.status()["connected"]
    del fake.get_position
    arm.reset_fault()
    assert wait_until(lambda: arm.read().fault is None)


# -- connection loss ------------------------------------------------------------------------------------


def test_connection_drop_backoff_and_latched_until_reset(arm, fake):
    arm.command_twist(np.array([0.05, 0, 0, 0, 0, 0]))
    assert fake.wait_for_calls(VC, 1, WAIT_S)
    t_drop = time.monotonic()
    fake.drop_connection()
    assert arm.read().fault == DISCONNECTED
    assert fake.wait_for_calls("connect", 1 + 4, WAIT_S)  # the start-up connect + 4 failed attempts
    attempts = [c.t for c in fake.calls_named("connect")[1:5]]
    delays = np.diff([t_drop, *attempts])
    nominal = np.array([0.05, 0.1, 0.2, 0.2])  # min, doubling, capped at max
    assert np.all(delays >= nominal - 1e-3), delays
    assert np.all(delays < nominal + 0.5), delays  # generous on a loaded machine
    assert all(c.result == "failed" for c in fake.calls_named("connect")[1:5])
    assert not arm.status()["connected"]

    fake.restore_connection()
    assert wait_until(lambda: arm.status()["connected"])
    assert DISCONNECTED in arm.read().fault  # reconnected but latched
    n = len(vc_calls(fake))
    arm.command_twist(np.array([0.05, 0, 0, 0, 0, 0]))
    sync(fake)
    assert len(vc_calls(fake)) == n

    arm.reset_fault()
    assert wait_until(lambda: arm.read().fault is None)
    arm.command_twist(np.array([0.05, 0, 0, 0, 0, 0]))
    assert fake.wait_for_calls(VC, n + 1, WAIT_S)
    assert vc_calls(fake)[-1].result == 0
    st = arm.status()
    assert st["reconnects"] == 1 and st["connect_attempts"] >= 6


def test_reset_while_disconnected_is_ignored(arm, fake):
    fake.drop_connection()
    arm.reset_fault()
    assert fake.wait_for_calls("connect", 2, WAIT_S)
    assert arm.read().fault == DISCONNECTED
    assert "clean_error" not in [c.name for c in fake.calls]
    fake.restore_connection()
    assert wait_until(lambda: arm.status()["connected"])
    assert DISCONNECTED in arm.read().fault


def test_sdk_exception_is_a_lost_link(arm, fake):
    def broken(*args, **kwargs):
        raise OSError("socket closed")

    fake.get_position = broken  # type: ignore[method-assign]
    assert wait_until(lambda: arm.read().fault == DISCONNECTED or arm.status()["disconnect_reason"] is not None)
    assert "OSError" in arm.status()["disconnect_reason"]
    del fake.get_position  # the instance attribute; the method is back
    assert wait_until(lambda: arm.status()["connected"] and arm.status()["reconnects"] >= 1)
    assert DISCONNECTED in arm.read().fault


# -- close ----------------------------------------------------------------------------------------------


def test_close_is_idempotent_and_leaves_a_zero_command(arm, fake):
    arm.command_twist(np.array([0.05, 0, 0, 0, 0, 0.2]))
    assert fake.wait_for_calls(VC, 1, WAIT_S)
    arm.close()
    arm.close()
    last_vc = vc_calls(fake)[-1]
    assert last_vc.args[0] == [0.0] * 6 and last_vc.result == 0
    assert fake.calls[-1].name == "disconnect" and not fake.connected
    n = len(fake.calls)
    arm.command_twist(np.array([0.05, 0, 0, 0, 0, 0]))
    arm.command_gripper(True)
    arm.reset_fault()
    assert len(fake.calls) == n
    assert arm.read().fault == CLOSED
    assert not arm.status()["connected"]


def _hold(fake: FakeXArmAPI, name: str) -> tuple[threading.Event, threading.Event]:
    """Make the fake's ``name`` wait for ``release`` (a slow reply, not a failed one); ``entered`` is set
    when a call has reached it."""
    entered, release = threading.Event(), threading.Event()
    original = getattr(fake, name)

    def slow(*args, **kwargs):
        entered.set()
        release.wait(WAIT_S)
        return original(*args, **kwargs)

    setattr(fake, name, slow)
    return entered, release


def test_halt_waits_for_a_moving_command_in_flight_then_only_zeros_are_sent(arm, fake):
    """The daemon's stop: nothing moving may reach the controller after ``halt`` returns. A moving command
    already in the SDK's hands is waited for; later moving commands are refused; the zero follows."""
    entered, release = _hold(fake, VC)
    arm.command_twist(np.array([0.05, 0, 0, 0, 0, 0]))
    assert entered.wait(WAIT_S)
    threading.Timer(0.05, release.set).start()
    t0 = time.monotonic()
    assert arm.halt(timeout_s=WAIT_S)
    waited = time.monotonic() - t0
    assert waited >= 0.04 and release.is_set()  # returned only once the moving command had its reply
    assert vc_calls(fake)[0].args[0][0] == pytest.approx(50.0)  # the one in flight (mm/s)
    dropped = arm.status()["twists_dropped"]
    arm.command_twist(np.array([0.05, 0, 0, 0, 0, 0]))  # refused from now on
    arm.command_twist(np.zeros(6))  # accepted
    assert arm.status()["twists_dropped"] == dropped + 1
    assert fake.wait_for_calls(VC, 2, WAIT_S)
    sync(fake)
    assert all(c.args[0] == [0.0] * 6 for c in vc_calls(fake)[1:])
    assert not np.any(fake.speed)


def test_halt_drops_a_moving_command_taken_but_not_yet_sent(arm, fake):
    """The I/O thread has taken a twist with a gripper request and is busy with the gripper when the halt
    comes: the twist it holds is moving, so it is never sent."""
    poll_in, poll_out = _hold(fake, "get_position")
    assert poll_in.wait(WAIT_S)  # the I/O thread is inside a poll: both requests below wait for it
    grip_in, grip_out = _hold(fake, "set_gripper_position")
    arm.command_gripper(True)
    arm.command_twist(np.array([0.05, 0, 0, 0, 0, 0]))
    del fake.get_position
    poll_out.set()
    assert grip_in.wait(WAIT_S)  # now in the gripper call, the twist taken with it
    assert arm.halt(timeout_s=WAIT_S)  # nothing moving is in the SDK's hands: at once
    grip_out.set()
    del fake.set_gripper_position
    assert fake.wait_for_calls(VC, 1, WAIT_S)
    sync(fake)
    assert all(c.args[0] == [0.0] * 6 for c in vc_calls(fake))


def test_halt_gives_up_after_its_timeout_when_the_sdk_hangs_in_a_moving_command(arm, fake):
    entered, release = _hold(fake, VC)
    arm.command_twist(np.array([0.05, 0, 0, 0, 0, 0]))
    assert entered.wait(WAIT_S)
    t0 = time.monotonic()
    assert arm.halt(timeout_s=0.05) is False
    assert 0.04 <= time.monotonic() - t0 < 1.0
    release.set()
    assert fake.wait_for_calls(VC, 2, WAIT_S)  # the zero follows the hung command once it returns
    assert vc_calls(fake)[-1].args[0] == [0.0] * 6


def test_close_while_the_sdk_hangs_returns(arm, fake):
    fake.hang(0.5)
    assert fake.wait_for_blocked(WAIT_S)
    t0 = time.monotonic()
    arm.close()
    assert time.monotonic() - t0 < 5.5


def test_driver_calls_only_methods_the_fake_checks_against_the_sdk(arm, fake):
    arm.command_twist(np.array([0.05, 0, 0, 0, 0, 0]))
    arm.command_gripper(True)
    fake.inject_error(23)
    arm.reset_fault()
    assert wait_until(lambda: arm.read().fault is None)
    arm.close()
    assert {c.name for c in fake.calls} <= set(SDK_METHODS)


# -- real arm (opt-in) ----------------------------------------------------------------------------------


@pytest.mark.skipif(not os.environ.get("SA_XARM_IP"), reason="set SA_XARM_IP to test against a real xArm")
def test_real_arm_connect_enable_read_zero_close():
    cfg = config_from_dict({"arm": {"xarm": {"ip": os.environ["SA_XARM_IP"]}}})
    arm = XArm(cfg)
    try:
        st = arm.read()
        assert st.fault is None, st.fault
        assert np.all(np.isfinite(st.pose.position)) and st.joints is not None
        arm.command_twist(np.zeros(6))
        assert wait_until(lambda: arm.status()["commands_sent"] >= 1)
        assert arm.read().fault is None and arm.status()["commands_refused"] == 0
    finally:
        arm.close()
    assert not arm.status()["connected"]
