"""The safety pipeline: each stage, and properties over thousands of random twists, poses and timings."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sa_daemon.config import LimitsConfig, SafetyConfig
from sa_daemon.control.safety import SafetyCode, SafetyPipeline, SafetyResult
from sa_daemon.geometry import Pose

CFG = SafetyConfig()
LIM = LimitsConfig()
DT = 0.01
CENTRE = Pose(np.array([0.35, 0.0, 0.3]), np.array([1.0, 0.0, 0.0, 0.0]))
AMAX = np.array([CFG.linear_accel_mps2] * 3 + [CFG.angular_accel_radps2] * 3)


def pipe(**kw) -> SafetyPipeline:
    return SafetyPipeline(CFG, LIM, DT, **kw)


def ramp(p: SafetyPipeline, twist, pose=CENTRE, n=200, joints=None):
    r = None
    for _ in range(n):
        r = p.filter(twist, pose, joints=joints)
    return r


def test_small_twist_passes_after_ramp_up():
    r = ramp(pipe(), [0.05, 0, 0, 0, 0, 0.1])
    assert r.codes == () and r.status is SafetyCode.OK
    np.testing.assert_allclose(r.twist, [0.05, 0, 0, 0, 0, 0.1])


@pytest.mark.parametrize("bad", [[np.nan, 0, 0, 0, 0, 0], [0, 0, np.inf, 0, 0, 0], [1, 2, 3], "x", None])
def test_nan_inf_and_wrong_shape_become_zero(bad):
    p = pipe()
    ramp(p, [0.05, 0, 0, 0, 0, 0])
    r = p.filter(bad, CENTRE)
    assert r.status is SafetyCode.NAN and not np.any(r.twist)


def test_stale_input_is_zero_at_once():
    p = pipe()
    ramp(p, [0.1, 0, 0, 0, 0, 0])
    r = p.filter([0.1, 0, 0, 0, 0, 0], CENTRE, input_fresh=False)
    assert r.status is SafetyCode.STALE and not np.any(r.twist)


def test_stop_latches_until_resume_and_restarts_from_rest():
    p = pipe()
    ramp(p, [0.1, 0, 0, 0, 0, 0])
    p.stop()
    for _ in range(5):
        r = p.filter([0.1, 0, 0, 0, 0, 0], CENTRE)
        assert r.status is SafetyCode.STOPPED and not np.any(r.twist)
    p.resume()
    r = p.filter([0.1, 0, 0, 0, 0, 0], CENTRE)
    assert SafetyCode.ACCEL in r.codes and r.twist[0] == pytest.approx(CFG.linear_accel_mps2 * DT)


def test_a_closed_gripper_zeroes_with_its_code_and_reopening_restarts_from_rest():
    p = pipe()
    ramp(p, [0.1, 0, 0, 0, 0, 0])
    r = p.filter([0.1, 0, 0, 0, 0, 0], CENTRE, gripper_closed=True)
    assert r.codes == (SafetyCode.GRIPPER,) and r.status is SafetyCode.GRIPPER and not np.any(r.twist)
    r = p.filter([0.1, 0, 0, 0, 0, 0], CENTRE)  # reopened
    assert SafetyCode.ACCEL in r.codes and r.twist[0] == pytest.approx(CFG.linear_accel_mps2 * DT)


_ZEROING = {SafetyCode.STOPPED, SafetyCode.ARM_FAULT, SafetyCode.NAN, SafetyCode.STALE, SafetyCode.GRIPPER}


@settings(max_examples=300, deadline=None)
@given(st.lists(st.tuples(st.lists(st.floats(-1.0, 1.0), min_size=6, max_size=6), st.booleans()),
                min_size=2, max_size=60))
def test_acceleration_limit_holds_across_gripper_close_and_reopen(steps):
    """What reaches the arm never changes by more than the acceleration limit in one period, except to
    zero at a zeroing stage; in particular not when the gripper reopens (the first command after it
    starts from the zero that was sent)."""
    p = pipe()
    sent = np.zeros(6)
    for twist, closed in steps:
        r = p.filter(np.asarray(twist), CENTRE, gripper_closed=closed)
        if not set(r.codes) & _ZEROING:
            assert np.all(np.abs(r.twist - sent) <= AMAX * DT + 1e-12), (sent, r.twist, r.codes)
        else:
            assert not np.any(r.twist)
        sent = r.twist


def test_arm_fault_zeroes():
    r = pipe().filter([0.1, 0, 0, 0, 0, 0], CENTRE, fault=True)
    assert r.status is SafetyCode.ARM_FAULT and not np.any(r.twist)


def test_speed_limit_keeps_direction():
    r = ramp(pipe(), [1.0, 0.5, 0, 0, 0, 0])
    assert SafetyCode.SPEED in r.codes
    # per axis to (0.25, 0.125), whose norm 0.28 m/s is then scaled to the TCP limit
    assert np.linalg.norm(r.twist[:3]) == pytest.approx(LIM.tcp_mps)
    assert r.twist[1] / r.twist[0] == pytest.approx(0.5)
    wide = LimitsConfig(tcp_mps=1.0)
    r = ramp(SafetyPipeline(CFG, wide, DT), [1.0, 0.5, 0, 0, 0, 0])
    assert r.twist[0] == pytest.approx(wide.linear_mps) and r.twist[1] == pytest.approx(0.5 * wide.linear_mps)


def test_tcp_speed_limit_bounds_a_diagonal_within_the_per_axis_limits():
    """0.2 m/s on each axis passes the per-axis limit (0.25) but is 0.35 m/s at the TCP: scaled to 0.25."""
    r = ramp(pipe(), [0.2, -0.2, 0.2, 0, 0, 0])
    assert SafetyCode.SPEED in r.codes
    assert np.linalg.norm(r.twist[:3]) == pytest.approx(LIM.tcp_mps)
    np.testing.assert_allclose(r.twist[:3] / np.linalg.norm(r.twist[:3]), np.array([1, -1, 1]) / math.sqrt(3))


def test_acceleration_limited_from_rest():
    r = pipe().filter([0.2, 0, 0, 0, 0, 0], CENTRE)
    assert SafetyCode.ACCEL in r.codes
    assert r.twist[0] == pytest.approx(CFG.linear_accel_mps2 * DT)


def test_workspace_blocks_leaving_but_allows_returning():
    hi = np.asarray(CFG.workspace_max_m)
    at_edge = Pose(np.array([0.35, 0.0, hi[2] - 1e-4]), CENTRE.quat_wxyz)
    p = pipe()
    r = ramp(p, [0, 0, 0.1, 0, 0, 0], pose=at_edge, n=50)
    assert SafetyCode.WORKSPACE in r.codes
    assert at_edge.position[2] + r.twist[2] * DT <= hi[2] + 1e-12
    r = ramp(p, [0, 0, -0.1, 0, 0, 0], pose=at_edge, n=50)
    assert r.twist[2] == pytest.approx(-0.1) and SafetyCode.WORKSPACE not in r.codes


class _Kin:
    """A 6-joint arm whose Jacobian is diagonal with configurable conditioning (test double of the
    ``Kinematics`` protocol: the real one is Pinocchio's, tested in test_arm_kinematics). The weak
    direction is linear x: joint 0 moves the TCP along x at ``ell / k(q)``, so with ``k`` growing in
    ``q0`` a +x command drives the arm toward the singularity."""

    def __init__(self, kappa_of_q):
        self.lower = np.full(6, -2.0)
        self.upper = np.full(6, 2.0)
        self.velocity_limit = np.full(6, 2.14)
        self.kappa_of_q = kappa_of_q

    def jacobian(self, q):
        k = self.kappa_of_q(np.asarray(q))
        ell = CFG.characteristic_length_m  # the pipeline divides linear rows by it: condition = k
        return np.diag([ell / k, ell, ell, 1.0, 1.0, 1.0])

    def joint_velocities(self, q, twist):
        return np.linalg.solve(self.jacobian(q), np.asarray(twist, dtype=float))

    def fk(self, q):  # pragma: no cover - unused here
        return CENTRE


def test_singularity_slows_then_halts_when_moving_toward_it():
    kin = _Kin(lambda q: 10.0 + 20.0 * q[0])  # kappa grows with q0
    twist = [0.02, 0, 0, 0, 0, 0]
    q_slow = np.array([0.4, 0, 0, 0, 0, 0])  # kappa 18
    p = pipe(kinematics=kin)
    for _ in range(100):
        r = p.filter(twist, CENTRE, joints=q_slow)
    assert r.status is SafetyCode.SINGULARITY_SLOW
    assert r.twist[0] == pytest.approx(0.02 * (1 - (18 - 17) / 13))
    r = p.filter(twist, CENTRE, joints=np.array([1.2, 0, 0, 0, 0, 0]))  # kappa 34
    assert r.status is SafetyCode.SINGULARITY_HALT and not np.any(r.twist)
    # Moving away from it is allowed at full speed.
    p2 = pipe(kinematics=kin)
    for _ in range(100):
        r = p2.filter([-0.015, 0, 0, 0, 0, 0], CENTRE, joints=np.array([1.2, 0, 0, 0, 0, 0]))
    assert r.codes == () and r.twist[0] == pytest.approx(-0.015)


@pytest.mark.parametrize("twist, halted", [
    ([0.0, 0.05, 0.0, 0.0, 0.0, 0.0], False),  # no share along the weak direction (x): passes
    ([0.01, 0.05, 0.0, 0.0, 0.0, 0.0], True),  # share 0.2 > 0.15
    ([0.005, 0.05, 0.0, 0.0, 0.0, 0.0], False),  # share 0.1: within the dead band
])
def test_beyond_stop_only_the_part_toward_the_singularity_is_removed(twist, halted):
    kin = _Kin(lambda q: 10.0 + 20.0 * q[0])
    p = pipe(kinematics=kin)
    q = np.array([1.2, 0, 0, 0, 0, 0])  # kappa 34
    for _ in range(100):
        r = p.filter(twist, CENTRE, joints=q)
    if halted:
        assert r.status is SafetyCode.SINGULARITY_HALT
        np.testing.assert_allclose(r.twist, [0.0] + list(twist[1:]), atol=1e-12)  # the y part moves on
    else:
        assert r.codes == ()
        np.testing.assert_allclose(r.twist, twist)


def test_slowing_scales_only_the_part_toward_the_singularity():
    kin = _Kin(lambda q: 10.0 + 20.0 * q[0])
    p = pipe(kinematics=kin)
    q_slow = np.array([0.4, 0, 0, 0, 0, 0])  # kappa 18
    for _ in range(100):
        r = p.filter([0.02, 0.03, 0, 0, 0, 0.1], CENTRE, joints=q_slow)
    assert r.status is SafetyCode.SINGULARITY_SLOW
    np.testing.assert_allclose(r.twist, [0.02 * (1 - (18 - 17) / 13), 0.03, 0, 0, 0, 0.1], atol=1e-12)


def test_joint_near_bound_halts_only_toward_it():
    kin = _Kin(lambda q: 1.0)
    q = np.array([0, 0, 1.95, 0, 0, 0])  # joint 3 within 0.1 rad of +2
    p = pipe(kinematics=kin)
    r = p.filter([0, 0, 0.005, 0, 0, 0], CENTRE, joints=q)
    assert r.status is SafetyCode.JOINT_BOUND and not np.any(r.twist)
    r = p.filter([0, 0, -0.005, 0, 0, 0], CENTRE, joints=q)
    assert SafetyCode.JOINT_BOUND not in r.codes and r.twist[2] < 0


def test_joint_speed_scales_the_whole_command():
    kin = _Kin(lambda q: 16.0)  # joint 0 needs 16 / 0.3 rad per m of x
    p = pipe(kinematics=kin)
    r = ramp(p, [0.1, 0.05, 0, 0, 0, 0], n=300, joints=np.zeros(6))
    assert SafetyCode.JOINT_SPEED in r.codes
    qdot = kin.joint_velocities(np.zeros(6), r.twist)
    assert np.max(np.abs(qdot)) == pytest.approx(2.14)
    assert r.twist[1] / r.twist[0] == pytest.approx(0.5)  # the whole command scaled: direction kept


def test_most_severe_code_is_the_status():
    p = pipe()
    r = p.filter([5.0, 0, 0, 0, 0, 0], CENTRE)
    assert set(r.codes) >= {SafetyCode.SPEED, SafetyCode.ACCEL}
    assert r.status is SafetyCode.ACCEL


# -- properties -------------------------------------------------------------------------------------

finite = st.floats(min_value=-5.0, max_value=5.0, allow_nan=False)
anything = st.one_of(finite, st.just(float("nan")), st.just(float("inf")), st.just(-float("inf")))
twists = st.lists(anything, min_size=6, max_size=6)
lo, hi = np.asarray(CFG.workspace_min_m), np.asarray(CFG.workspace_max_m)
positions = st.tuples(*[st.floats(min_value=float(a) - 0.05, max_value=float(b) + 0.05) for a, b in zip(lo, hi)])
steps = st.lists(
    st.tuples(twists, positions, st.booleans(), st.booleans(), st.sampled_from(["none", "stop", "resume"])),
    min_size=1, max_size=40,
)


@settings(max_examples=300, deadline=None)
@given(steps)
def test_every_output_respects_every_limit(seq):
    """Finite; within per-axis speed limits; never moves (further) out of the box; acceleration
    within limits unless a zeroing or position stage says why; zero while stopped or stale."""
    p = pipe()
    last = np.zeros(6)
    for twist, pos, fresh, fault, latch in seq:
        if latch == "stop":
            p.stop()
        elif latch == "resume":
            p.resume()
            last = np.zeros(6)
        pose = Pose(np.array(pos), CENTRE.quat_wxyz)
        r = p.filter(twist, pose, input_fresh=fresh, fault=fault)
        out = r.twist
        assert out.shape == (6,) and np.all(np.isfinite(out))
        assert np.all(np.abs(out[:3]) <= LIM.linear_mps + 1e-12)
        assert np.all(np.abs(out[3:]) <= LIM.angular_radps + 1e-12)
        nxt = pose.position + out[:3] * DT
        outside_before = np.maximum(lo - pose.position, 0) + np.maximum(pose.position - hi, 0)
        outside_after = np.maximum(lo - nxt, 0) + np.maximum(nxt - hi, 0)
        assert np.all(outside_after <= outside_before + 1e-12)
        if p.stopped or fault or not fresh or not np.all(np.isfinite(np.asarray(twist, float))):
            assert not np.any(out)
        zeroing = {SafetyCode.STOPPED, SafetyCode.ARM_FAULT, SafetyCode.NAN, SafetyCode.STALE}
        if not (set(r.codes) & (zeroing | {SafetyCode.WORKSPACE})):
            assert np.all(np.abs(out - last) <= AMAX * DT + 1e-9)
        last = out


@settings(max_examples=200, deadline=None)
@given(st.lists(st.tuples(twists, st.lists(st.floats(-2.5, 2.5), min_size=6, max_size=6)), min_size=1, max_size=30))
def test_joint_stages_never_drive_a_joint_past_its_margin_or_speed(seq):
    kin = _Kin(lambda q: 1.0 + 40.0 * abs(float(q[0])) / 2.5)
    p = pipe(kinematics=kin)
    for twist, q in seq:
        q = np.clip(np.array(q), kin.lower, kin.upper)
        r = p.filter(twist, CENTRE, joints=q)
        if not np.any(r.twist):
            continue
        qdot = kin.joint_velocities(q, r.twist)
        assert np.all(np.abs(qdot) <= kin.velocity_limit + 1e-9)
        near_lo = q - kin.lower < CFG.joint_margin_rad
        near_hi = kin.upper - q < CFG.joint_margin_rad
        assert not np.any(near_lo & (qdot < 0)) and not np.any(near_hi & (qdot > 0))
        kappa, share = p.singularity_share(q, r.twist)
        if kappa >= CFG.singularity_stop:
            assert share <= CFG.singularity_share + 1e-9


def test_the_xarm_crosses_its_wrist_singularity_in_plane_but_not_sideways():
    """Real kinematics: joint 5 at 0.005 rad (wrist straight, condition number above the stop). A pitch
    or an in-plane translation needs nothing the singularity removes and passes untouched; a sideways
    translation into the singularity halts, and out of it passes."""
    from sa_daemon.arm.kinematics import ArmKinematics

    q = np.array([0.0, -0.99, -0.07, 0.0, 0.005, 0.0])
    p = pipe(kinematics=ArmKinematics())
    assert p._condition(q) > CFG.singularity_stop
    for twist in ([0, 0, 0, 0, -0.3, 0], [0, 0, -0.05, 0, 0, 0], [0.04, 0, 0.03, 0, 0, 0]):
        r = ramp(pipe(kinematics=ArmKinematics()), twist, n=100, joints=q)
        assert SafetyCode.SINGULARITY_HALT not in r.codes and SafetyCode.SINGULARITY_SLOW not in r.codes
        np.testing.assert_allclose(r.twist, twist, atol=1e-12)
    sideways = [ramp(pipe(kinematics=ArmKinematics()), [0, s, 0, 0, 0, 0], n=100, joints=q) for s in (0.05, -0.05)]
    assert sorted(r.status.value for r in sideways) == ["ok", "singularity_halt"]


def test_refuses_means_a_joint_stage_let_almost_nothing_through():
    asked = np.array([0.05, 0.0, 0.0, 0.0, 0.0, 0.0])
    assert SafetyResult(np.zeros(6), (SafetyCode.SINGULARITY_HALT,)).refuses(asked)
    assert SafetyResult(asked * 0.05, (SafetyCode.SINGULARITY_SLOW,)).refuses(asked)
    assert not SafetyResult(asked * 0.5, (SafetyCode.SINGULARITY_SLOW,)).refuses(asked)
    assert not SafetyResult(np.zeros(6), (SafetyCode.ACCEL,)).refuses(asked)  # not the arm refusing
    assert not SafetyResult(np.zeros(6), (SafetyCode.JOINT_BOUND,)).refuses(np.zeros(6))  # nothing asked


def _align_through_the_pipeline(q, target, seconds=30.0):
    """Rotate the real xArm-6 (Pinocchio kinematics, joints integrated at the pipeline's rate) toward
    ``target``'s orientation with a saturated proportional command, as a user in rotation mode does.
    Returns the final joints, the rotation error left (rad) and the largest joint speed (rad/s)."""
    from sa_daemon.arm.kinematics import ArmKinematics
    from sa_daemon.geometry import quat_angle, rotation_error

    kin = ArmKinematics()
    p = pipe(kinematics=kin)
    fastest = 0.0
    for _ in range(int(seconds / DT)):
        pose = kin.fk(q)
        w = 1.5 * rotation_error(target.quat_wxyz, pose.quat_wxyz)
        w *= min(1.0, 0.4 / max(float(np.linalg.norm(w)), 1e-12))
        r = p.filter(np.concatenate((np.zeros(3), w)), pose, joints=q)
        qdot = kin.joint_velocities(q, r.twist)
        fastest = max(fastest, float(np.max(np.abs(qdot))))
        q = q + qdot * DT
    return q, float(quat_angle(target.quat_wxyz, kin.fk(q).quat_wxyz)), fastest


def test_a_user_rotating_at_the_wrist_singularity_gets_through_it():
    """Scene 1 ``cup:side`` through the daemon (session 4): the arm arrived next to the cup with joint 5
    at 0.12 rad while the side grasp needs the wrist turned across it. Slowing the whole command (MoveIt
    Servo) held it there until the timeout (1.2 rad of rotation left); removing only the part toward the
    singularity lets the rest of the user's rotation carry the wrist across joint 5 = 0, at joint
    speeds far below the arm's limits."""
    from sa_daemon.arm.kinematics import ArmKinematics
    from sa_daemon.arm.reach import reachable_scene
    from sa_daemon.world.scene import load_scene

    kin = ArmKinematics()
    scene = reachable_scene(load_scene("scene1"), kin, CFG.joint_margin_rad)
    side = scene.goal("cup:side").desired_pose(scene.start, 0.05)
    q_trap = np.array([0.141, -0.677, -0.313, 1.319, 0.118, -1.351])
    assert pipe(kinematics=kin)._condition(q_trap) > CFG.singularity_slow
    q, left, fastest = _align_through_the_pipeline(q_trap, side)
    assert left < math.pi / 48
    assert q[4] < 0.0  # the wrist went through joint 5 = 0
    assert fastest < 1.0  # rad/s, against 2.14 rad/s limits
