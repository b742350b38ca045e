"""The xArm controller's own limits (issue 17): the fake models them as UFactory documents them, the driver
sets or verifies them before it enables motion and refuses to move when the controller disagrees, the
installer's ``run --arm xarm --check`` reports them without moving the arm, and the safety pipeline is the
stricter of the two layers: nothing it lets through is refused by the limits it configured."""

from __future__ import annotations

import math
import os
import subprocess

import numpy as np
import pytest
from helpers import CLI
from test_fake_xarm import Clock, ready_arm
from test_xarm_arm import VC, WAIT_S, make_cfg, vc_calls, wait_until

from sa_daemon.arm.xarm_arm import XArm
from sa_daemon.arm.xarm_check import format_check, run_check
from sa_daemon.arm.xarm_limits import SETTINGS, expected_limits
from sa_daemon.config import Config, config_from_dict
from sa_daemon.testing.fake_xarm import (
    BOUNDARY_ERROR,
    HAS_ERROR,
    PARAM_ERROR,
    SPEED_LIMIT_ERROR,
    FakeXArmAPI,
)

SETTERS = ("set_reduced_max_tcp_speed", "set_reduced_tcp_boundary", "set_fence_mode", "set_collision_sensitivity",
           "set_self_collision_detection", "set_reduced_mode")
ENABLING = ("motion_enable", "set_mode", "set_state")

#: What the default config asks of the controller, by hand: [limits] tcp_mps 0.25 m/s; the [safety] box
#: (-0.1, -0.6, 0.0) .. (0.8, 0.6, 0.7) m grown by arm.xarm.fence_margin_m = 0.02 m, in mm, max first.
DEFAULT_WANT = {
    "reduced_mode": True,
    "reduced_tcp_speed_mm_s": 250.0,
    "tcp_boundary_mm": [820, -120, 620, -620, 720, -20],
    "fence_mode": True,
    "collision_sensitivity": 3,
    "self_collision_detection": True,
}

#: A controller configured like that already (by an earlier run, or by hand in xArm Studio).
CONFIGURED = {"reduced_mode": True, "tcp_speed_mm_s": 250.0, "boundary_mm": (820, -120, 620, -620, 720, -20),
              "fence": True, "collision_sensitivity": 3, "self_collision": True}


def test_config_maps_to_the_controller_settings_by_hand():
    assert dict(expected_limits(Config()).items()) == DEFAULT_WANT
    cfg = config_from_dict({"limits": {"tcp_mps": 0.1}, "safety": {"workspace_min_m": [0.1234, -0.3, 0.05],
                                                                    "workspace_max_m": [0.5, 0.3, 0.6001]},
                            "arm": {"xarm": {"fence_margin_m": 0.01, "collision_sensitivity": 5}}})
    want = expected_limits(cfg)
    # outward to whole mm: 0.5 + 0.01 -> 510; 0.1234 - 0.01 = 0.1134 -> 113; 0.6001 + 0.01 -> 611 (ceil)
    assert want.boundary_mm == (510, 113, 310, -310, 611, 40)
    assert want.tcp_speed_mm_s == 100.0 and want.collision_sensitivity == 5


@pytest.mark.parametrize("key, value", [("arm.xarm.collision_sensitivity", 0), ("arm.xarm.collision_sensitivity", 6),
                                        ("arm.xarm.controller_limits", "off"), ("limits.tcp_mps", 0.0),
                                        ("arm.xarm.fence_margin_m", 0.0)])
def test_bad_controller_settings_are_refused_naming_the_key(key, value):
    from sa_daemon.config import ConfigError

    section, *rest = key.split(".")
    data: dict = {}
    node = data.setdefault(section, {})
    for k in rest[:-1]:
        node = node.setdefault(k, {})
    node[rest[-1]] = value
    with pytest.raises(ConfigError, match=rest[-1]):
        config_from_dict(data)


# -- the fake: UFactory's documented setters, getters and refusals ----------------------------------------


def test_fake_setters_round_trip_through_the_documented_getters():
    clock = Clock()
    arm = FakeXArmAPI("fake", is_radian=True, clock=clock)
    assert arm.get_reduced_states() == (0, [0, [1000, -1000, 1000, -1000, 1000, -1000], 250.0, math.pi,
                                            [0.0] * 14, 0, 0])
    assert arm.set_reduced_max_tcp_speed(123.456) == 0
    assert arm.set_reduced_tcp_boundary([-120.7, 820.9, 620, -620, 720.2, -20]) == 0  # min first: swapped, truncated
    assert arm.set_fence_mode(True) == [0]  # the SDK returns the reply list
    assert arm.set_collision_sensitivity(4) == 0
    assert arm.set_self_collision_detection(True) == 0
    assert arm.set_reduced_mode(True) == 0
    code, states = arm.get_reduced_states()
    assert code == 0 and states[0] == 1 and states[1] == [820, -120, 620, -620, 720, -20] and states[5] == 1
    assert states[2] == pytest.approx(123.456, abs=1e-4) and states[2] != 123.456  # stored as float32
    assert arm.get_reduced_mode() == (0, 1)
    assert arm.collision_sensitivity == 4 and arm.self_collision_params[0] == 1
    assert arm.set_reduced_tcp_boundary([40000, 0, 10, -10, 10, -10]) == PARAM_ERROR  # beyond int16
    with pytest.raises(AssertionError):
        arm.set_collision_sensitivity(6)  # the SDK asserts 0..5
    with pytest.raises(AssertionError):
        arm.set_reduced_tcp_boundary([1, 2, 3])


def test_fake_refuses_a_velocity_above_the_reduced_tcp_speed_with_error_24():
    clock = Clock()
    arm = ready_arm(clock)
    fired: list[dict] = []
    arm.register_error_warn_changed_callback(fired.append)
    arm.set_reduced_max_tcp_speed(100.0)
    assert arm.vc_set_cartesian_velocity([300, 0, 0, 0, 0, 0], duration=1.0) == 0  # reduced mode off: no limit
    arm.vc_set_cartesian_velocity([0] * 6)
    assert arm.set_reduced_mode(True) == 0
    assert arm.vc_set_cartesian_velocity([60, 0, 80, 0, 0, 0], duration=1.0) == 0  # 100 mm/s: at the limit
    assert arm.vc_set_cartesian_velocity([60, 0, 80.1, 0, 0, 0], duration=1.0) == HAS_ERROR
    assert arm.error_code == SPEED_LIMIT_ERROR and fired[-1]["error_code"] == SPEED_LIMIT_ERROR
    assert not np.any(arm.speed) and arm.state == 4


def test_fake_speed_and_boundary_take_effect_when_reduced_mode_is_switched_on():
    """The SDK: a new reduced TCP speed 'takes effect' on ``set_reduced_mode(True)``; the order matters."""
    arm = ready_arm(Clock())
    arm.set_reduced_max_tcp_speed(100.0)
    arm.set_reduced_mode(True)
    arm.set_reduced_max_tcp_speed(500.0)  # after: read back, but not in force
    assert arm.get_reduced_states()[1][2] == 500.0
    assert arm.vc_set_cartesian_velocity([200, 0, 0, 0, 0, 0], duration=1.0) == HAS_ERROR


def test_fake_stops_at_the_boundary_with_error_35_only_with_the_fence_on():
    clock = Clock()
    start = (770.0, 0.0, 300.0, math.pi, 0.0, 0.0)  # 50 mm inside x_max = 820
    arm = ready_arm(clock, start_mm_rad=start, limits=CONFIGURED)
    fired: list[dict] = []
    arm.register_error_warn_changed_callback(fired.append)
    assert arm.vc_set_cartesian_velocity([100, 0, 0, 0, 0, 0], duration=2.0) == 0
    clock.advance(0.4)
    assert arm.error_code == 0 and arm.position_mm[0] == pytest.approx(810.0)
    clock.advance(0.4)  # crossed x_max at 0.5 s: stopped there
    assert arm.error_code == BOUNDARY_ERROR and fired[-1]["error_code"] == BOUNDARY_ERROR
    assert arm.position_mm[0] == pytest.approx(820.0) and arm.stopped_since == pytest.approx(1000.5)
    assert arm.vc_set_cartesian_velocity([-10, 0, 0, 0, 0, 0], duration=1.0) == HAS_ERROR

    free = ready_arm(Clock(), start_mm_rad=start, limits={**CONFIGURED, "fence": False})
    free.vc_set_cartesian_velocity([100, 0, 0, 0, 0, 0], duration=2.0)
    free._clock.advance(1.0)
    assert free.error_code == 0 and free.position_mm[0] == pytest.approx(870.0)


# -- the driver: set, read back, refuse to move on a disagreement ---------------------------------------


def test_driver_sets_every_limit_before_enabling_and_reports_them(tmp_path):
    fake = FakeXArmAPI("fake", is_radian=True, do_not_open=True)
    arm = XArm(make_cfg(), api_factory=lambda: fake)
    try:
        names = [c.name for c in fake.calls]
        args = {c.name: c.args for c in fake.calls}
        assert args["set_reduced_max_tcp_speed"] == (250.0,)
        assert args["set_reduced_tcp_boundary"] == ([820, -120, 620, -620, 720, -20],)
        assert args["set_fence_mode"] == (True,) and args["set_collision_sensitivity"] == (3,)
        assert args["set_self_collision_detection"] == (True,) and args["set_reduced_mode"] == (True,)
        assert max(names.index(n) for n in SETTERS) == names.index("set_reduced_mode")  # on last
        assert names.index("get_reduced_states") < min(names.index(n) for n in ENABLING)
        st = arm.status()["controller_limits"]
        assert set(st) == set(SETTINGS)
        assert all(v["ok"] and v["controller"] == DEFAULT_WANT[k] == v["expected"] for k, v in st.items())
        assert arm.read().fault is None
    finally:
        arm.close()


def test_verify_mode_on_an_unconfigured_controller_names_every_disagreement_and_never_moves():
    fake = FakeXArmAPI("fake", is_radian=True, do_not_open=True)
    arm = XArm(make_cfg(controller_limits="verify"), api_factory=lambda: fake)
    try:
        fault = arm.read().fault
        assert fault.startswith("xArm controller limits: ")
        for name, value in (("reduced_mode", False), ("tcp_boundary_mm", [1000, -1000, 1000, -1000, 1000, -1000]),
                            ("fence_mode", False), ("self_collision_detection", False)):
            assert f"{name}: controller {value!r}, expected {DEFAULT_WANT[name]!r}" in fault
        assert "reduced_tcp_speed_mm_s" not in fault and "collision_sensitivity:" not in fault  # those agree
        names = {c.name for c in fake.calls}
        assert not names & set(SETTERS), "verify only reads"
        assert not names & set(ENABLING), "motion never enabled"
        arm.command_twist(np.array([0.05, 0, 0, 0, 0, 0]))
        assert wait_until(lambda: arm.status()["twists_dropped"] >= 1)
        assert vc_calls(fake) == [] or all(not any(c.args[0]) for c in vc_calls(fake))
        st = arm.status()["controller_limits"]
        assert not st["fence_mode"]["ok"] and st["fence_mode"]["controller"] is False
        # resume re-checks: still wrong, still not moving
        arm.reset_fault()
        assert wait_until(lambda: len(fake.calls_named("get_reduced_states")) >= 2)
        assert wait_until(lambda: not arm.status()["recovering"])
        assert arm.read().fault.startswith("xArm controller limits: ")
        assert not {c.name for c in fake.calls} & set(ENABLING)
    finally:
        arm.close()


def test_verify_mode_on_a_configured_controller_moves():
    fake = FakeXArmAPI("fake", is_radian=True, do_not_open=True, limits=CONFIGURED)
    arm = XArm(make_cfg(controller_limits="verify"), api_factory=lambda: fake)
    try:
        assert arm.read().fault is None
        arm.command_twist(np.array([0.05, 0, 0, 0, 0, 0]))
        assert fake.wait_for_calls(VC, 1, WAIT_S) and vc_calls(fake)[0].result == 0
    finally:
        arm.close()


class ClampingController(FakeXArmAPI):
    """A controller that keeps at most 100 mm/s whatever it is asked, and refuses the boundary (12)."""

    def set_reduced_max_tcp_speed(self, speed: float) -> int:
        return super().set_reduced_max_tcp_speed(min(speed, 100.0))

    def set_reduced_tcp_boundary(self, boundary) -> int:
        super().set_reduced_tcp_boundary(boundary)
        return PARAM_ERROR


def test_a_refused_setter_and_a_value_that_did_not_stick_are_faults_naming_them():
    fake = ClampingController("fake", is_radian=True, do_not_open=True)
    arm = XArm(make_cfg(), api_factory=lambda: fake)
    try:
        fault = arm.read().fault
        assert "set_reduced_tcp_boundary([820, -120, 620, -620, 720, -20],) returned code 12" in fault
        assert "reduced_tcp_speed_mm_s: controller 100.0, expected 250.0" in fault
        assert not {c.name for c in fake.calls} & set(ENABLING)
    finally:
        arm.close()


def test_limits_are_set_again_at_every_recovery_before_motion_is_enabled():
    fake = FakeXArmAPI("fake", is_radian=True, do_not_open=True)
    arm = XArm(make_cfg(), api_factory=lambda: fake)
    try:
        fake.set_reduced_mode(False)  # someone changed it in xArm Studio ...
        fake.set_fence_mode(False)
        fake.inject_error(31)  # ... then a collision
        mark = len(fake.calls)
        arm.reset_fault()
        assert wait_until(lambda: arm.read().fault is None)
        after = [c.name for c in fake.calls[mark:]]
        assert all(n in after for n in SETTERS)
        assert after.index("get_reduced_states") < after.index("motion_enable")
        assert fake.get_reduced_states()[1][0] == 1 and fake.get_reduced_states()[1][5] == 1
    finally:
        arm.close()


def test_the_controllers_own_refusals_reach_the_driver_as_named_faults():
    """Were the pipeline bypassed (here: limits changed behind the driver's back), the controller's layer
    still acts: above the reduced speed it stops with 24, at the fence with 35, and the driver latches it."""
    fake = FakeXArmAPI("fake", is_radian=True, do_not_open=True)
    arm = XArm(make_cfg(), api_factory=lambda: fake)
    try:
        fake.set_reduced_max_tcp_speed(20.0)
        fake.set_reduced_mode(True)
        arm.command_twist(np.array([0.05, 0, 0, 0, 0, 0]))  # 50 mm/s > 20
        assert wait_until(lambda: arm.read().fault is not None)
        assert arm.read().fault == "xArm error 24: speed limit"
        fake.set_reduced_max_tcp_speed(250.0)
        arm.reset_fault()  # recovery sets 250 mm/s again
        assert wait_until(lambda: arm.read().fault is None)
        fake.place((818.0, 0.0, 300.0), (math.pi, 0.0, 0.0))  # 2 mm inside the fence

        def push() -> bool:  # the daemon commands every control period; each command lasts 30 ms
            arm.command_twist(np.array([0.05, 0, 0, 0, 0, 0]))
            return arm.read().fault is not None

        assert wait_until(push)
        assert arm.read().fault == "xArm error 35: safety boundary"
        assert fake.position_mm[0] == pytest.approx(820.0)
    finally:
        arm.close()


# -- run --arm xarm --check ------------------------------------------------------------------------------


def test_check_sets_verifies_and_never_enables_motion():
    fake = FakeXArmAPI("fake", is_radian=True, do_not_open=True)
    items = run_check(make_cfg(), api_factory=lambda: fake)
    assert all(i.ok for i in items), format_check(items)
    assert [i.name for i in items] == ["connection", "firmware >= 1.8.0", "no controller error",
                                       "controller limits set", *SETTINGS, "TCP in the workspace"]
    names = {c.name for c in fake.calls}
    assert not names & {*ENABLING, VC}
    assert not fake.connected  # disconnected at the end


def test_check_in_verify_mode_fails_on_an_unconfigured_controller_naming_values():
    fake = FakeXArmAPI("fake", is_radian=True, do_not_open=True)
    items = {i.name: i for i in run_check(make_cfg(controller_limits="verify"), api_factory=lambda: fake)}
    assert not items["fence_mode"].ok and items["fence_mode"].detail == "controller False, expected True"
    assert items["collision_sensitivity"].ok and "controller limits set" not in items
    assert not {c.name for c in fake.calls} & set(SETTERS)


def test_check_reports_an_error_a_pose_outside_the_workspace_and_no_connection():
    fake = FakeXArmAPI("fake", is_radian=True, do_not_open=True, start_mm_rad=(900.0, 0.0, 300.0, math.pi, 0, 0))
    fake.inject_error(2)
    items = {i.name: i for i in run_check(make_cfg(), api_factory=lambda: fake)}
    assert not items["no controller error"].ok and "error 2" in items["no controller error"].detail
    assert not items["TCP in the workspace"].ok and "(0.900, 0.000, 0.300)" in items["TCP in the workspace"].detail
    down = FakeXArmAPI("fake", is_radian=True, do_not_open=True)
    down.drop_connection()
    items = run_check(make_cfg(), api_factory=lambda: down)
    assert len(items) == 1 and not items[0].ok and "connect socket failed" in items[0].detail


def test_check_command_line_exit_codes(tmp_path):
    ok = tmp_path / "ok.toml"
    ok.write_text('[arm.xarm]\nsdk = "fake"\n')
    r = subprocess.run([*CLI, "run", "--arm", "xarm", "--check", "--config", str(ok)],
                       capture_output=True, text=True, timeout=120, check=False)
    assert r.returncode == 0, r.stdout + r.stderr
    assert r.stdout.count("PASS") == 11 and "all checks passed" in r.stdout
    verify = tmp_path / "verify.toml"
    verify.write_text('[arm.xarm]\nsdk = "fake"\ncontroller_limits = "verify"\n')
    r = subprocess.run([*CLI, "run", "--arm", "xarm", "--check", "--config", str(verify)],
                       capture_output=True, text=True, timeout=120, check=False)
    assert r.returncode == 1 and "4 of 10 checks FAILED" in r.stdout
    assert "FAIL  fence_mode                 controller False, expected True" in r.stdout
    r = subprocess.run([*CLI, "run", "--check"], capture_output=True, text=True,
                       timeout=120, check=False)
    assert r.returncode == 2 and "arm.backend" in r.stderr


# -- the two layers agree, the pipeline the stricter --------------------------------------------------------


def test_no_command_the_pipeline_passes_is_refused_by_the_controller_limits_it_configured():
    """Thousands of random poses and twists: TCP poses of random joint configurations (the xArm-6 model,
    so the joint stages act too) and poses within 1 cm of a workspace face (no joints); twists up to 8
    times the limits, after a random previous command. Every output of the safety pipeline, sent to a
    controller set from the same config for one control period, is accepted, does not reach the fence
    and does not trip the reduced TCP speed."""
    from sa_daemon.arm.kinematics import ArmKinematics
    from sa_daemon.control.safety import SafetyPipeline
    from sa_daemon.geometry import Pose, rpy_to_quat
    from sa_daemon.testing.fake_xarm import matrix_to_rpy

    # The acceleration stage only ever moves the command toward the last output (which passed), so it is
    # opened up here: every sample meets the speed, workspace and joint stages at full speed.
    cfg = config_from_dict({"safety": {"linear_accel_mps2": 1e4, "angular_accel_radps2": 1e4}})
    kin = ArmKinematics(joint_margin=cfg.safety.joint_margin_rad)
    dt = 1.0 / cfg.runtime.control_hz
    clock = Clock()
    ctl = ready_arm(clock, limits=CONFIGURED)
    rng = np.random.default_rng(17)
    fastest = 0.0
    lo, hi = np.array(cfg.safety.workspace_min_m), np.array(cfg.safety.workspace_max_m)
    counts = {"joints": 0, "faces": 0}
    refused: list[tuple] = []
    while min(counts.values()) < 1500:
        if counts["joints"] <= counts["faces"]:
            q = rng.uniform(kin.lower + 0.05, kin.upper - 0.05)
            pos, rot = kin.tcp_transform(q)
            if not (np.all(pos >= lo) and np.all(pos <= hi)):
                continue  # the pipeline's promise starts inside its box
            kind, pose, joints = "joints", Pose.from_matrix(pos, rot), q
        else:
            pos = rng.uniform(lo, hi)
            axis = rng.integers(3)
            pos[axis] = rng.choice([lo[axis] + rng.uniform(0, 0.01), hi[axis] - rng.uniform(0, 0.01)])
            kind, pose, joints = "faces", Pose(pos, rpy_to_quat(rng.uniform(-np.pi, np.pi, 3))), None
        pipe = SafetyPipeline(cfg.safety, cfg.limits, dt, kin if joints is not None else None)
        pipe.filter(rng.uniform(-1, 1, 6) * np.array([0.25] * 3 + [1.0] * 3), pose, joints=joints)  # some past
        twist = rng.uniform(-2.0, 2.0, 6) * rng.choice([0.1, 1.0, 4.0])
        out = pipe.filter(twist, pose, joints=joints).twist
        fastest = max(fastest, float(np.linalg.norm(out[:3])))
        ctl.place(pose.position * 1000.0, matrix_to_rpy(pose.rotation))
        code = ctl.vc_set_cartesian_velocity([*(out[:3] * 1000.0), *out[3:]], is_radian=True, duration=dt)
        clock.advance(dt)
        if code != 0 or ctl.error_code != 0:
            refused.append((kind, ctl.error_code, pose.position, out))
            ctl.clean_error()
            ctl.motion_enable(True), ctl.set_mode(5), ctl.set_state(0)
        counts[kind] += 1
    assert not refused, f"{len(refused)} of {sum(counts.values())} pipeline outputs refused: {refused[:3]}"
    assert fastest > 0.99 * cfg.limits.tcp_mps  # the samples reached the limit the two layers share


# -- real arm (opt-in) ----------------------------------------------------------------------------------


@pytest.mark.skipif(not os.environ.get("SA_XARM_IP"), reason="set SA_XARM_IP to test against a real xArm")
def test_real_arm_check():
    """``run --arm xarm --check`` on the real controller: every line passes, and motion is never enabled
    (the arm must be where the safety workspace allows)."""
    cfg = config_from_dict({"arm": {"backend": "xarm", "xarm": {"ip": os.environ["SA_XARM_IP"]}}})
    items = run_check(cfg)
    assert all(i.ok for i in items), format_check(items)
