"""The approach corridor of the robot's twist (``move.approach_standoff_m``, ``twists.approach_points``):
off it heads for a pre-grasp point behind the grasp, on it for the grasp, turned away it stays back; off
by default (the paper's straight line). The physical claim - on MuJoCo the straight line pushes the cup
off a side grasp and the corridor does not - is in ``test_mujoco_arm.py``."""

from __future__ import annotations

import math

import numpy as np
import pytest
from helpers import predicted_input

from sa_daemon.config import Config, ConfigError, MoveConfig, config_from_dict
from sa_daemon.geometry import Pose, quat_mul, quat_z_axis, rotvec_to_quat, turn
from sa_daemon.model.actions import HO_ACTION, Action, ActionKind, Mode
from sa_daemon.model.model import SharedAutonomyModel
from sa_daemon.model.twists import approach_points, ho_robot_twist, move_twist
from sa_daemon.planner import kernel
from sa_daemon.planner.rollouts import Rollouts
from sa_daemon.world.goals import Goal, GraspType
from sa_daemon.world.goalset import GoalSet
from sa_daemon.world.scene import load_scene

# A side grasp: the gripper's z (its approach) along base +x, the grasp at G.
SIDE_Q = Pose.from_rpy(np.zeros(3), (0.0, math.pi / 2, 0.0)).quat_wxyz
G = np.array([0.5, 0.1, 0.1])
CORRIDOR = MoveConfig(approach_standoff_m=0.06, approach_funnel=2.0, approach_turn_m=0.12)


def turned(q, rotvec):
    return quat_mul(rotvec_to_quat(np.asarray(rotvec, dtype=float)), q)


def test_the_side_grasp_approaches_along_base_x():
    np.testing.assert_allclose(quat_z_axis(SIDE_Q), [1.0, 0.0, 0.0], atol=1e-12)


def test_off_by_default_the_robot_heads_straight_for_the_grasp():
    cfg = MoveConfig()
    assert cfg.approach_standoff_m == 0.0
    x = G + np.array([-0.2, 0.15, 0.1])
    np.testing.assert_array_equal(approach_points(x, turned(SIDE_Q, [0, 0, 1.0]), G, SIDE_Q, cfg), G)


def test_far_off_the_axis_and_aligned_it_heads_for_the_pre_grasp_point():
    x = G + np.array([-0.2, 0.15, 0.0])  # 15 cm off the axis: 2 x 15 cm > the 6 cm standoff
    np.testing.assert_allclose(approach_points(x, SIDE_Q, G, SIDE_Q, CORRIDOR), G - [0.06, 0, 0], atol=1e-12)


def test_on_the_axis_and_aligned_it_heads_for_the_grasp():
    x = G + np.array([-0.1, 0.0, 0.0])
    np.testing.assert_allclose(approach_points(x, SIDE_Q, G, SIDE_Q, CORRIDOR), G, atol=1e-12)


@pytest.mark.parametrize("lateral", [0.0, 0.005, 0.02, 0.03, 0.1])
def test_near_the_axis_the_point_slides_with_twice_the_distance_from_it(lateral):
    x = G + np.array([-0.1, lateral, 0.0])
    back = min(0.06, 2.0 * lateral)
    np.testing.assert_allclose(approach_points(x, SIDE_Q, G, SIDE_Q, CORRIDOR), G - [back, 0, 0], atol=1e-12)


@pytest.mark.parametrize("angle_deg", [10.0, 45.0, 90.0, 150.0])
def test_turned_away_on_the_axis_it_stays_back_by_the_turn(angle_deg):
    """On the axis the funnel asks for nothing; the orientation ``theta`` off keeps the point
    ``0.12 sin(min(theta, 90 deg))`` m behind the grasp, about any axis of the turn."""
    x = G + np.array([-0.2, 0.0, 0.0])
    theta = math.radians(angle_deg)
    back = 0.12 * math.sin(min(theta, math.pi / 2))
    for axis in np.eye(3):
        aim = approach_points(x, turned(SIDE_Q, theta * axis), G, SIDE_Q, CORRIDOR)
        np.testing.assert_allclose(aim, G - [back, 0, 0], atol=1e-9)


def test_the_point_is_continuous_and_broadcasts_over_poses_and_goals():
    rng = np.random.default_rng(3)
    x = G + rng.normal(0, 0.1, (5, 1, 3))
    q = np.stack([turned(SIDE_Q, r) for r in rng.normal(0, 0.5, (5, 3))])[:, None, :]
    goals_p = np.stack([G, G + [0.0, 0.2, 0.0]])
    goals_q = np.stack([SIDE_Q, turned(SIDE_Q, [0.0, 0.0, 0.7])])
    aim = approach_points(x, q, goals_p, goals_q, CORRIDOR)
    assert aim.shape == (5, 2, 3)
    for i in range(5):
        for j in range(2):
            np.testing.assert_allclose(aim[i, j], approach_points(x[i, 0], q[i, 0], goals_p[j], goals_q[j], CORRIDOR))
    step = np.array([1e-7, -1e-7, 1e-7])
    near = approach_points(x + step, q, goals_p, goals_q, CORRIDOR)
    assert np.max(np.abs(near - aim)) < 1e-5


def test_the_move_twist_heads_for_the_point_and_turns_as_before():
    x, q = G + np.array([-0.2, 0.15, 0.0]), turned(SIDE_Q, [0.0, 0.0, 0.5])
    straight, corridor = move_twist(x, q, G, SIDE_Q, MoveConfig()), move_twist(x, q, G, SIDE_Q, CORRIDOR)
    aim = approach_points(x, q, G, SIDE_Q, CORRIDOR)
    direction = corridor[:3] / np.linalg.norm(corridor[:3])
    np.testing.assert_allclose(direction, (aim - x) / np.linalg.norm(aim - x), atol=1e-12)
    assert np.linalg.norm(corridor[:3]) == pytest.approx(CORRIDOR.linear_max_mps)
    np.testing.assert_allclose(corridor[3:], straight[3:], atol=1e-12)


def test_at_the_grasp_the_corridor_twist_is_zero():
    np.testing.assert_allclose(move_twist(G, SIDE_Q, G, SIDE_Q, CORRIDOR), np.zeros(6), atol=1e-12)


def test_ho_with_a_certain_belief_is_the_move_on_the_same_corridor():
    """HO (``ho.generator = "moves"``) applies the move generator to the belief-weighted error toward each
    goal's corridor point, so a certain belief gives that goal's move, corridor and all."""
    cfg = config_from_dict({"move": {"approach_standoff_m": 0.06, "approach_turn_m": 0.12}})
    goals = GoalSet((Goal("cup", GraspType.SIDE, (Pose(G, SIDE_Q),)),
                     Goal("can", GraspType.SIDE, (Pose(G + [0.0, 0.25, 0.0], SIDE_Q),))))
    pose = Pose(G + np.array([-0.25, 0.1, 0.05]), turned(SIDE_Q, [0.0, 0.3, 0.2]))
    model = SharedAutonomyModel(cfg)
    b = np.array([1.0, 0.0])
    ho = model.command(HO_ACTION, goals, b, pose, np.zeros(6)).robot_twist
    move = model.command(Action(ActionKind.MOVE, 0, "cup:side"), goals, b, pose, np.zeros(6)).robot_twist
    np.testing.assert_allclose(ho, move, atol=1e-12)
    straight = SharedAutonomyModel(Config()).command(HO_ACTION, goals, b, pose, np.zeros(6)).robot_twist
    assert np.linalg.norm(ho[:3] - straight[:3]) > 0.01  # the corridor did change where it heads


@pytest.mark.parametrize(("key", "value"), [("approach_standoff_m", -0.01), ("approach_standoff_m", 0.5),
                                            ("approach_funnel", 0.0), ("approach_turn_m", -1.0)])
def test_a_bad_corridor_setting_is_refused_by_its_key(key, value):
    with pytest.raises(ConfigError, match=f"move.{key}"):
        config_from_dict({"move": {key: value}})


# -- the planner's rollouts follow the same corridor --------------------------------------------------------


def _rollout_by_hand(cfg, kp, kq, b, position, quat, g, action, mode, speed, steps, dt):
    """One rollout for a user heading to goal ``g``, step by step with the product's own generators
    (``move_twist``, ``ho_robot_twist`` under the plan's fixed belief) blended with the predicted input."""
    p, q = np.array(position, dtype=float), np.array(quat, dtype=float)
    alpha = cfg.blend.alpha
    for _ in range(steps):
        u = predicted_input(cfg, p, q, kp, kq, g, mode, speed)
        if action.kind is ActionKind.MOVE:
            robot = move_twist(p, q, kp[action.goal], kq[action.goal], cfg.move)
        else:
            robot = ho_robot_twist(p, q, u, kp, kq, b, cfg)
        twist = (1.0 - alpha) * u + alpha * robot
        p, q = p + twist[:3] * dt, turn(q, twist[3:], dt)
    return p, q


@pytest.mark.parametrize("compiled", [False, True])
@pytest.mark.parametrize(("mode", "speed"), [(Mode.TRANSLATION, (0.05, 0.0)), (Mode.ROTATION, (0.0, 0.3))])
def test_the_rollouts_move_the_arm_as_the_corridor_does(mode, speed, compiled):
    """With the corridor on, the planner's rollouts, numpy and compiled, move every (user goal, move or HO)
    rollout as a plain loop over the product's generators does (numpy to 1e-12; the kernel to rounding);
    and the corridor does change them (the straight rollouts differ)."""
    scene = load_scene("scene1")
    on = config_from_dict({"move": {"approach_standoff_m": 0.06}, "planner": {"ho_belief": "fixed"}})
    off = config_from_dict({"planner": {"ho_belief": "fixed"}})
    assert kernel.supported(on)
    goals = SharedAutonomyModel(on).initial_belief(scene.goals).goals
    pose = scene.start
    b = np.full(len(goals), 1.0 / len(goals))
    kp, kq = goals.desired_poses(pose, on.intent.rotation_weight_m_per_rad)
    actions = [Action(ActionKind.MOVE, 0, goals.goals[0].target), Action(ActionKind.MOVE, 3, goals.goals[3].target),
               HO_ACTION]
    steps, dt = 6, 0.5
    atol = 1e-9 if compiled else 1e-12

    def rollouts(cfg):
        return Rollouts(cfg, pose.position[None], pose.quat_wxyz[None], b[None], kp, kq, actions, mode, speed,
                        steps=steps, dt=dt, watch_steps=steps, compiled=compiled)

    R, S = rollouts(on), rollouts(off)
    P = np.broadcast_to(R.watch_positions[0], (len(goals), len(actions), 3))
    Q = np.broadcast_to(R.watch_quats[0], (len(goals), len(actions), 4))
    for g in range(len(goals)):
        for a, action in enumerate(actions):
            p, q = _rollout_by_hand(on, kp, kq, b, pose.position, pose.quat_wxyz, g, action, mode, speed, steps, dt)
            np.testing.assert_allclose(P[g, a], p, atol=atol, err_msg=f"{g} {action.label}")
            np.testing.assert_allclose(Q[g, a], q, atol=atol, err_msg=f"{g} {action.label}")
    assert np.max(np.abs(R.watch_positions - S.watch_positions)) > 0.01
