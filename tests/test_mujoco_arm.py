"""The MuJoCo xArm-6: real physics for start pose, twist tracking, refusals, the gripper, a whole trial."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import textwrap
import time

import mujoco
import numpy as np
import pytest

from sa_daemon.arm.base import Arm, ArmState
from sa_daemon.arm.factory import make_arm
from sa_daemon.arm.kinematics import ArmKinematics
from sa_daemon.arm.mujoco_arm import MujocoArm
from sa_daemon.arm.reach import reachable_scene
from sa_daemon.config import Config, config_from_dict
from sa_daemon.control.safety import SafetyCode, SafetyPipeline
from sa_daemon.geometry import Pose
from sa_daemon.model.actions import Action, ActionKind
from sa_daemon.model.model import SharedAutonomyModel
from sa_daemon.sim.episode import arm_factory, run_trial
from sa_daemon.sim.success import NOT_LIFTED, grasp_outcome
from sa_daemon.world.goals import Goal
from sa_daemon.world.goalset import GoalSet
from sa_daemon.world.scene import load_scene


@pytest.fixture(scope="module")
def scene1():
    return load_scene("scene1")


@pytest.fixture
def arm(scene1):
    a = MujocoArm(scene1, Config())
    yield a
    a.close()


def _hold(arm: MujocoArm, twist, seconds: float, dt: float = 0.01) -> None:
    arm.command_twist(np.asarray(twist, dtype=float))
    for _ in range(round(seconds / dt)):
        arm.step(dt)


# -- construction --------------------------------------------------------------------------------------


def test_start_pose_matches_scene_start_within_1_mm(arm, scene1):
    s = arm.read()
    assert isinstance(arm, Arm) and arm.name == "mujoco" and isinstance(s, ArmState)
    d_t, d_r = s.pose.distance(scene1.start)
    assert d_t < 1e-3 and d_r < 1e-3
    assert s.gripper_closed is False and s.fault is None
    assert s.joints is not None and s.joints.shape == (6,)
    assert isinstance(arm.kinematics, ArmKinematics)
    np.testing.assert_allclose(arm.fingers, [0.0425, 0.0425], atol=1e-9)


def test_status_reports_simulation_diagnostics(arm):
    st = arm.status()
    assert st["sim_time_s"] == 0.0 and st["fingers_m"] == [0.0425, 0.0425] and st["viewer"] is False
    json.dumps(st)


def test_holding_still_keeps_the_start_pose(arm, scene1):
    arm.step(0.5)
    d_t, d_r = arm.read().pose.distance(scene1.start)
    assert d_t < 1e-3 and d_r < 1e-3


def test_pinocchio_and_mujoco_agree_on_the_tcp(arm):
    # One MJCF, two engines: the Pinocchio frame and the MuJoCo site coincide at random joints.
    d = mujoco.MjData(arm.model)
    rng = np.random.default_rng(0)
    for _ in range(5):
        q = rng.uniform(arm.kinematics.lower, arm.kinematics.upper)
        d.qpos[:6] = q
        mujoco.mj_kinematics(arm.model, d)
        pose = arm.kinematics.fk(q)
        np.testing.assert_allclose(d.site("tcp").xpos, pose.position, atol=1e-9)
        np.testing.assert_allclose(d.site("tcp").xmat.reshape(3, 3), pose.rotation, atol=1e-9)


def test_factory_builds_the_mujoco_arm(scene1):
    a = make_arm("mujoco", scene1, Config())
    assert isinstance(a, MujocoArm)
    a.close()
    a.close()  # idempotent


def test_reset_gives_the_state_of_a_fresh_arm(arm, scene1):
    # Between the sim user's tasks the daemon resets the arm instead of recompiling the model.
    _hold(arm, [0.05, -0.03, -0.04, 0.0, 0.2, 0.1], 1.0)
    arm.command_gripper(True)
    arm.step(0.3)
    assert arm.read().gripper_closed and arm.status()["sim_time_s"] > 1.0
    assert arm.reset() is True
    fresh = MujocoArm(scene1, Config())
    try:
        np.testing.assert_allclose(arm.data.qpos, fresh.data.qpos, atol=1e-12)  # arm, fingers and objects
        np.testing.assert_array_equal(arm.data.qvel, 0.0)
        np.testing.assert_allclose(arm.data.ctrl, fresh.data.ctrl, atol=1e-12)
        s = arm.read()
        assert s.gripper_closed is False and arm.status()["sim_time_s"] == 0.0
        assert s.pose.distance(fresh.read().pose) == pytest.approx((0.0, 0.0), abs=1e-12)
    finally:
        fresh.close()
    arm.step(0.5)  # and it holds still from there, like a fresh arm
    d_t, d_r = arm.read().pose.distance(scene1.start)
    assert d_t < 1e-3 and d_r < 1e-3


# -- twist tracking ------------------------------------------------------------------------------------


def test_held_linear_twist_moves_5_cm_in_1_s_with_small_orientation_drift(arm):
    p0 = arm.read().pose
    t0 = time.perf_counter()
    _hold(arm, [0.05, 0, 0, 0, 0, 0], 1.0)
    us_per_step = (time.perf_counter() - t0) / 100 * 1e6
    p1 = arm.read().pose
    moved = p1.position - p0.position
    assert moved[0] == pytest.approx(0.05, abs=1e-3)
    assert np.max(np.abs(moved[1:])) < 1e-3
    assert p1.distance(p0)[1] < 0.005  # rad
    assert us_per_step < 5000  # at least twice faster than real time, even on a slow machine


def test_rotation_twist_rotates_about_the_tcp(arm):
    p0 = arm.read().pose
    _hold(arm, [0, 0, 0, 0, 0, 0.3], 1.0)
    p1 = arm.read().pose
    d_t, d_r = p1.distance(p0)
    assert d_r == pytest.approx(0.3, abs=0.01)
    assert d_t < 2e-3
    # about base z: the tool z axis keeps its height component
    assert p1.rotation[2, 2] == pytest.approx(p0.rotation[2, 2], abs=1e-3)


def test_twist_is_limited_per_axis(arm):
    p0 = arm.read().pose
    _hold(arm, [1.0, 0, 0, 0, 0, 0], 0.2)  # 4 x the 0.25 m/s limit
    assert arm.read().pose.position[0] - p0.position[0] == pytest.approx(0.05, abs=2e-3)


def test_a_bad_twist_raises_and_changes_nothing(arm):
    arm.command_twist(np.zeros(6))
    p0 = arm.read().pose
    for bad in ([0.0, 0.0, float("nan"), 0.0, 0.0, 0.0], [0.0, float("inf"), 0, 0, 0, 0], [0.1, 0.0, 0.0]):
        with pytest.raises(ValueError):
            arm.command_twist(bad)
    arm.step(0.2)
    assert arm.read().pose.distance(p0)[0] < 1e-5


def test_step_keeps_simulated_time_on_the_callers_clock(arm):
    t0 = arm.time
    for _ in range(40):
        arm.step(0.025)  # not a multiple of the 2 ms physics step
    assert arm.time - t0 == pytest.approx(1.0, abs=0.001)
    with pytest.raises(ValueError):
        arm.step(float("nan"))


# -- gripper -------------------------------------------------------------------------------------------


def test_gripper_closes_on_the_cup_at_a_side_grasp_the_pipeline_holds_the_arm_and_it_lifts(scene1):
    cfg = Config()
    goal = scene1.goal("cup:side")
    arm = MujocoArm(scene1, cfg)
    # The head-on poses (approach along base x) need joint 5 beyond its -1.69 rad bound; this one turns
    # the approach 45 deg and closes across the cup's diameter.
    arm.place(goal.poses[2])
    arm.step(0.1)
    p0 = arm.read().pose
    arm.command_gripper(True)
    # A closed gripper stops the arm through the safety pipeline's stage 5 (the arm itself carries what
    # it holds, as the xArm does): the twist asked for becomes zero before it reaches the arm.
    safety = SafetyPipeline(cfg.safety, cfg.limits, 0.1, arm.kinematics)
    for _ in range(6):
        s = arm.read()
        out = safety.filter(np.array([0.05, 0, 0, 0, 0, 0]), s.pose, joints=s.joints, gripper_closed=s.gripper_closed)
        assert out.status is SafetyCode.GRIPPER
        arm.command_twist(out.twist)
        arm.step(0.1)
    assert arm.read().gripper_closed is True
    fingers = arm.fingers
    assert np.all(fingers < 0.0425 - 1e-3)  # moved in ...
    assert np.all(fingers > 0.03)  # ... and stopped by the 0.08 m wide cup
    assert arm.read().pose.distance(p0)[0] < 2e-3
    assert arm.lift_test() == "cup"
    arm.close()


def test_closing_on_nothing_lifts_nothing(arm):
    arm.command_gripper(True)
    assert arm.lift_test() is None
    assert np.all(arm.fingers < 1e-3)
    arm.command_gripper(False)
    arm.step(0.6)
    assert np.all(arm.fingers > 0.04)


def test_the_lift_test_closes_where_the_arm_was_not_where_its_last_twist_would_carry_it(scene1, arm):
    """A trial ends at the close with the arm's last twist still held (a user closing on the move). The
    lift test stands the arm still first: the fingers close where the gripper was, 3 cm above the grasp
    (the rim 1.5 cm below the pads' tips), and nothing rises; carried on down by the held 4 cm/s over
    the settle they would close round the rim and lift the cup."""
    grasp = scene1.goal("cup:top").poses[0]
    arm.place(Pose(grasp.position + np.array([0.0, 0.0, 0.05]), grasp.quat_wxyz))
    arm.step(0.1)
    _hold(arm, [0.0, 0.0, -0.04, 0.0, 0.0, 0.0], 0.5)  # still descending, 3 cm above the grasp
    z_close = arm.read().pose.position[2]
    assert z_close - grasp.position[2] == pytest.approx(0.03, abs=3e-3)
    arm.command_gripper(True)
    assert arm.lift_test() is None
    assert arm.read().pose.position[2] - z_close == pytest.approx(0.05, abs=3e-3)  # the lift, from the close


def test_a_pose_that_holds_on_paper_fails_when_the_physical_gripper_lifts_nothing(scene1, arm):
    """The geometric rule passes the cup's own grasp pose, but this arm closed at its start pose, so the
    lift raises nothing and the outcome says so."""
    pose = scene1.goal("cup:top").poses[0]
    arm.command_gripper(True)
    outcome = grasp_outcome(scene1, "cup:top", pose, arm)
    assert outcome.success is False and outcome.kind == NOT_LIFTED
    assert "raised nothing" in outcome.reason
    assert outcome.rule_held is True  # the kinematic arm would have counted it: the run says so


def test_a_lift_records_the_rule_s_verdict_on_the_same_close(scene1, arm):
    """Where the lift decides, the outcome carries what the rule says of the same close: the cup lifted
    from its rim grasp, which the rule holds too (the other way round, see the test above)."""
    grasp = scene1.goal("cup:top").poses[0]
    arm.place(grasp)
    arm.step(0.1)
    held = grasp_outcome(scene1, "cup:top", arm.read().pose, arm)
    assert held.success is True and held.rule_held is True


def _drive_move(arm: MujocoArm, cfg: Config, goal: Goal, grasp: Pose, limit_s: float) -> float:
    """The robot's own move-to-goal twist (no user, no blend) toward ``grasp`` until within 3 mm and 0.02 rad
    or ``limit_s``; returns how far (m, in the table's plane) the goal's object was pushed meanwhile."""
    body = arm.world.object_bodies[arm.world.object_names.index(goal.object)]
    start = np.array(arm.data.xpos[body][:2])
    goals = GoalSet((Goal(goal.object, goal.grasp_type, (grasp,)),))
    model, move = SharedAutonomyModel(cfg), Action(ActionKind.MOVE, 0, goal.target)
    for _ in range(round(limit_s / 0.025)):
        pose = arm.read().pose
        d_t, d_r = pose.distance(grasp)
        if d_t < 3e-3 and d_r < 0.02:
            break
        arm.command_twist(model.robot_twist(move, goals, np.ones(1), pose, np.zeros(6)))
        arm.step(0.025)
    return float(np.linalg.norm(np.array(arm.data.xpos[body][:2]) - start))


def test_a_straight_move_pushes_the_cup_off_its_side_grasp_and_the_approach_corridor_lifts_it(scene1):
    """From the start pose to one of the cup's side grasps (the gripper turns 90 deg on the way), the
    straight move (the paper's generator) sweeps a finger into the cup and pushes it 2 cm or more: the
    lift raises nothing. With the approach corridor (``move.approach_standoff_m = 0.06``: turn while
    behind the grasp, come in along the gripper's approach) the cup stays put and lifts."""
    for standoff, pushed, lifted in ((0.0, True, None), (0.06, False, "cup")):
        cfg = config_from_dict({"move": {"approach_standoff_m": standoff}})
        arm = MujocoArm(scene1, cfg)
        goal = reachable_scene(scene1, arm.kinematics, cfg.safety.joint_margin_rad).goal("cup:side")
        grasp = goal.poses[3]
        push = _drive_move(arm, cfg, goal, grasp, 12.0)
        d_t, _ = arm.read().pose.distance(grasp)
        assert d_t < 4e-3, standoff  # both arrive
        assert push > 0.02 if pushed else push < 2e-3, (standoff, push)
        assert arm.lift_test() == lifted
        arm.close()


# -- evaluation ----------------------------------------------------------------------------------------


def test_manual_trial_on_mujoco_succeeds_with_a_physical_lift(scene1):
    r = run_trial(scene1, "cup:top", "manual", 0, Config(), arm_factory=arm_factory("mujoco"))
    assert r.success
    assert 20.0 < r.completion_time_s < 80.0


def test_cli_eval_accepts_the_mujoco_arm_in_a_spawn_pool(tmp_path):
    out = tmp_path / "eval.json"
    r = subprocess.run(
        [sys.executable, "-m", "sa_daemon.cli", "eval", "--scene", "scene1", "--task", "cup:top", "--method",
         "ho", "--seeds", "2", "--jobs", "2", "--arm", "mujoco", "--quiet", "--json", str(out)],
        check=False, capture_output=True, text=True, timeout=120,
    )
    assert r.returncode == 0, r.stderr
    data = json.loads(out.read_text())
    assert data["meta"]["arm"] == "mujoco"
    assert [t["success"] for t in data["trials"]] == [True, True]
    # Each close is judged by the holding rule too; the run counts where the two disagree.
    assert all(isinstance(t["rule_held"], bool) for t in data["trials"])
    (row,) = data["summary"]
    assert row["rule_judged"] == 2 and row["rule_failed_lifted"] == sum(not t["rule_held"] for t in data["trials"])
    assert row["rule_held_not_lifted"] == 0
    assert f"on the 2 closes a lift decided: the rule holds 0 that did not lift and fails {row['rule_failed_lifted']}" in r.stdout


# -- viewing -------------------------------------------------------------------------------------------


def test_viewer_without_a_display_warns_and_runs_headless(scene1, monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    with pytest.warns(RuntimeWarning, match="no display"):
        a = MujocoArm(scene1, Config(), viewer=True)
    a.step(0.01)
    a.close()


def test_offscreen_render_writes_png_frames(tmp_path):
    # A fresh process: the GL backend is chosen when mujoco is first imported.
    code = textwrap.dedent(f"""
        from sa_daemon.arm.mujoco_arm import MujocoArm
        from sa_daemon.arm.mujoco_render import read_png_size
        from sa_daemon.world.scene import load_scene
        arm = MujocoArm(load_scene("scene1"))
        try:
            a = arm.render({str(tmp_path / "one.png")!r}, 320, 240)
            arm.step(0.05)
            b = arm.render({str(tmp_path / "frames")!r}, 160, 120)
            c = arm.render({str(tmp_path / "frames")!r}, 160, 120)
        except RuntimeError as e:
            print("SKIP", e)
            raise SystemExit(0)
        print(read_png_size(a), read_png_size(b), c.name)
    """)
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    r = subprocess.run([sys.executable, "-c", code], check=False, capture_output=True, text=True, timeout=60, env=env)
    assert r.returncode == 0, r.stderr
    if r.stdout.startswith("SKIP"):
        pytest.skip(f"no offscreen OpenGL here (tried MUJOCO_GL={env.get('MUJOCO_GL', 'egl')}): {r.stdout[5:]}")
    assert r.stdout.split() == ["(320,", "240)", "(160,", "120)", "frame_00001.png"]
    assert (tmp_path / "frames" / "frame_00000.png").stat().st_size > 1000


def test_scene_objects_are_free_bodies_resting_on_the_table(arm, scene1):
    assert arm.world.object_names == tuple(o.name for o in scene1.objects)
    assert math.isclose(arm.time, 0.0)
    arm.step(0.5)
    for obj, body in zip(scene1.objects, arm.world.object_bodies):
        assert arm.model.body_jntnum[body] == 1  # one free joint
        np.testing.assert_allclose(arm.data.xpos[body], obj.position, atol=1e-3)
    table = arm.model.geom("table")
    assert arm.data.geom_xpos[table.id][2] + table.size[2] == pytest.approx(scene1.table_z)  # top at table_z
