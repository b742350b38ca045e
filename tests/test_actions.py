"""Velocity commands of the high-level actions (section III-B) and the HO assistance twist."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sa_daemon.config import (
    BlendConfig,
    Config,
    HOConfig,
    IntentConfig,
    MoveConfig,
    config_from_dict,
)
from sa_daemon.geometry import Pose, quat_mul, rotvec_to_quat
from sa_daemon.model.actions import HO_ACTION, NO_ASSIST, Action, ActionKind, Mode
from sa_daemon.model.huber import goal_gradients
from sa_daemon.model.model import SharedAutonomyModel
from sa_daemon.model.twists import blend, ho_twist, mask_to_mode, move_twist
from sa_daemon.world.goals import Goal, GraspType
from sa_daemon.world.goalset import GoalSet

MOVE = MoveConfig()
INTENT = IntentConfig()
HO = HOConfig()
TOP = (math.pi, 0.0, 0.0)
P0 = np.array([0.3, 0.0, 0.2])
Q0 = Pose.from_rpy(P0, TOP).quat_wxyz


def rotated(q, rotvec):
    """``q`` turned by the base-frame rotation vector ``rotvec``."""
    return quat_mul(rotvec_to_quat(np.asarray(rotvec, dtype=float)), q)


# -- move-to-goal ---------------------------------------------------------------------------------------


def test_move_twist_points_at_the_goal_proportionally():
    t = move_twist(P0, Q0, P0 + [0.03, -0.04, 0.0], Q0, MOVE)
    np.testing.assert_allclose(t, [0.03, -0.04, 0, 0, 0, 0], atol=1e-12)  # gain 1/s, below 0.2 m/s


def test_move_twist_saturates_linear_speed_keeping_direction():
    t = move_twist(P0, Q0, P0 + [0.3, 0.4, 0.0], Q0, MOVE)  # 0.5 m away
    np.testing.assert_allclose(t[:3], [MOVE.linear_max_mps * 0.6, MOVE.linear_max_mps * 0.8, 0.0], atol=1e-12)
    np.testing.assert_allclose(t[3:], 0.0, atol=1e-12)


def test_move_twist_rotates_about_the_relative_axis():
    goal_q = rotated(Q0, [0.0, 0.0, 0.25])
    t = move_twist(P0, Q0, P0, goal_q, MOVE)
    np.testing.assert_allclose(t, [0, 0, 0, 0, 0, 0.25], atol=1e-12)


def test_move_twist_saturates_angular_speed():
    goal_q = rotated(Q0, [0.6, 0.0, -0.8])  # 1 rad about a tilted axis
    t = move_twist(P0, Q0, P0, goal_q, MOVE)
    w = MOVE.angular_max_radps
    np.testing.assert_allclose(t[3:], [w * 0.6, 0.0, -w * 0.8], atol=1e-12)


def test_move_twist_is_zero_at_the_goal():
    np.testing.assert_allclose(move_twist(P0, Q0, P0, Q0, MOVE), np.zeros(6), atol=1e-12)
    np.testing.assert_allclose(move_twist(P0, Q0, P0, -Q0, MOVE), np.zeros(6), atol=1e-12)  # sign folded


# -- HO -------------------------------------------------------------------------------------------------


def gradients(goal_positions, goal_quats, position=P0, quat=Q0, user=None):
    return goal_gradients(
        np.asarray(position), np.asarray(quat), np.zeros(6) if user is None else np.asarray(user),
        np.asarray(goal_positions, dtype=float), np.asarray(goal_quats, dtype=float), INTENT, HO,
    )


def test_ho_twist_with_one_hot_belief_is_that_goals_gradient():
    grads = np.array([[0.1, 0.0, 0.0, 0.0, 0.0, 0.2], [0.0, -0.05, 0.01, 0.3, 0.0, 0.0], [1, 2, 3, 4, 5, 6.0]])
    np.testing.assert_allclose(ho_twist(np.array([0.0, 1.0, 0.0]), grads), grads[1])


def test_ho_twist_is_the_normalised_weighted_mean():
    grads = np.array([[0.1, 0.0, 0.0, 0.0, 0.0, 0.2], [0.0, -0.05, 0.01, 0.3, 0.0, 0.0]])
    got = ho_twist(np.array([0.2, 0.6]), grads)  # weights need not sum to 1
    np.testing.assert_allclose(got, 0.25 * grads[0] + 0.75 * grads[1])


def test_ho_translation_magnitude_far_away():
    g = gradients([P0 + [0.3, 0.4, 0.0]], [Q0])[0]
    np.testing.assert_allclose(g[:3], 2.45 / 40 * np.array([0.6, 0.8, 0.0]), atol=1e-12)
    np.testing.assert_allclose(g[3:], 0.0, atol=1e-12)


@pytest.mark.parametrize("d", [0.005, 0.01, 0.019])
def test_ho_translation_shrinks_linearly_inside_2cm(d):
    g = gradients([P0 + [0.0, d, 0.0]], [Q0])[0]
    slope = 2.25 / 0.07 * d + 0.2  # quadratic region of V
    np.testing.assert_allclose(g[:3], [0.0, slope / 40 * (d / 0.02), 0.0], atol=1e-12)


def test_ho_translation_between_2cm_and_delta_follows_the_slope():
    d = 0.05
    g = gradients([P0 + [0.0, 0.0, -d]], [Q0])[0]
    np.testing.assert_allclose(g[:3], [0.0, 0.0, -(2.25 / 0.07 * d + 0.2) / 40], atol=1e-12)


def test_ho_rotation_magnitude_far_away():
    g = gradients([P0], [rotated(Q0, [0.0, 1.0, 0.0])])[0]
    np.testing.assert_allclose(g[3:], [0.0, 0.21 * 0.07 / 0.05, 0.0], atol=1e-9)
    np.testing.assert_allclose(g[:3], 0.0, atol=1e-12)


@pytest.mark.parametrize("angle", [0.05, 0.1, 0.2])
def test_ho_rotation_shrinks_inside_pi_over_12(angle):
    g = gradients([P0], [rotated(Q0, [angle, 0.0, 0.0])])[0]
    delta = math.pi / 32
    slope = 0.07 * ((0.20 / delta) * angle + 0.01 if angle <= delta else 0.21)
    np.testing.assert_allclose(g[3:], [slope / 0.05 * angle / (math.pi / 12), 0.0, 0.0], atol=1e-9)


def test_ho_gradient_is_taken_after_the_users_twist():
    user = np.array([0.1, 0.0, 0.0, 0.0, 0.0, 0.0])  # moves 0.01 m in 0.1 s
    goal = P0 + [0.015, 0.0, 0.0]
    g = gradients([goal], [Q0], user=user)[0]
    d = 0.005  # remaining distance after the user's twist
    np.testing.assert_allclose(g[:3], [(2.25 / 0.07 * d + 0.2) / 40 * d / 0.02, 0, 0], atol=1e-12)


def test_ho_gradient_of_a_multi_pose_goal_points_at_its_lowest_value_pose():
    near, far = P0 + [0.0, 0.05, 0.0], P0 + [0.0, -0.5, 0.0]
    gp = np.array([[far, near]])
    gq = np.array([[Q0, Q0]])
    g = gradients(gp, gq)[0]
    assert g[1] > 0 and abs(g[0]) < 1e-12 and abs(g[2]) < 1e-12


# -- mode, blend ----------------------------------------------------------------------------------------


def test_mask_to_mode():
    t = np.arange(1.0, 7.0)
    np.testing.assert_array_equal(mask_to_mode(t, Mode.TRANSLATION), [1, 2, 3, 0, 0, 0])
    np.testing.assert_array_equal(mask_to_mode(t, Mode.ROTATION), [0, 0, 0, 4, 5, 6])
    np.testing.assert_array_equal(t, np.arange(1.0, 7.0))  # input untouched


def test_blend_with_alpha_one_half():
    u = np.array([0.2, 0.0, 0.0, 0.0, 0.0, 0.4])
    r = np.array([0.0, 0.1, 0.0, 0.2, 0.0, 0.0])
    np.testing.assert_allclose(blend(u, r, BlendConfig()), [0.1, 0.05, 0, 0.1, 0, 0.2])
    np.testing.assert_allclose(blend(u, r, BlendConfig(alpha=0.0)), u)


# -- commands through the model -------------------------------------------------------------------------


@pytest.fixture
def two_goal_scene():
    goals = GoalSet(
        (
            Goal("cup", GraspType.TOP, (Pose.from_rpy(P0 + [0.2, 0.0, 0.0], TOP),)),
            Goal("bowl", GraspType.TOP, (Pose.from_rpy(P0 + [0.0, 0.2, 0.0], TOP),)),
        )
    )
    return goals, Pose(P0, Q0)


def test_no_assist_passes_the_users_twist_unscaled(two_goal_scene):
    goals, pose = two_goal_scene
    u = np.array([0.2, -0.1, 0.05, 0.0, 0.0, 0.0])
    cmd = SharedAutonomyModel(Config()).command(NO_ASSIST, goals, np.array([0.5, 0.5]), pose, u)
    np.testing.assert_array_equal(cmd.total_twist, u)
    np.testing.assert_array_equal(cmd.robot_twist, np.zeros(6))
    assert cmd.action == NO_ASSIST and not cmd.opposed


def test_question_holds_the_robot_still(two_goal_scene):
    goals, pose = two_goal_scene
    u = np.array([0.2, -0.1, 0.05, 0.0, 0.0, 0.0])
    q = Action(ActionKind.QUESTION, None, "cup:top")
    cmd = SharedAutonomyModel(Config()).command(q, goals, np.array([0.5, 0.5]), pose, u)
    np.testing.assert_array_equal(cmd.total_twist, np.zeros(6))


def test_move_command_is_the_blend_of_user_and_move_twist(two_goal_scene):
    goals, pose = two_goal_scene
    u = np.array([0.0, 0.1, 0.0, 0.0, 0.0, 0.0])
    cmd = SharedAutonomyModel(Config()).command(Action(ActionKind.MOVE, 0, "cup:top"), goals, np.array([0.5, 0.5]), pose, u)
    v = MOVE.linear_max_mps  # 0.2 m away: saturated
    np.testing.assert_allclose(cmd.robot_twist, [v, 0, 0, 0, 0, 0], atol=1e-12)
    np.testing.assert_allclose(cmd.total_twist, [0.5 * v, 0.05, 0, 0, 0, 0], atol=1e-12)


def test_ho_command_with_javdanis_generator_uses_the_belief_weighted_gradient(two_goal_scene):
    goals, pose = two_goal_scene
    probs = np.array([0.25, 0.75])
    cfg = config_from_dict({"ho": {"generator": "gradient"}})
    cmd = SharedAutonomyModel(cfg).command(HO_ACTION, goals, probs, pose, np.zeros(6))
    far = 2.45 / 40
    np.testing.assert_allclose(cmd.robot_twist, [0.25 * far, 0.75 * far, 0, 0, 0, 0], atol=1e-12)


@pytest.mark.parametrize("probs", [(0.25, 0.75), (0.5, 0.5), (1.0, 0.0)])
def test_ho_command_by_default_is_the_move_generator_on_the_expected_error(two_goal_scene, probs):
    """``ho.generator = "moves"``: gain times the belief-weighted mean of the errors to each goal's
    ``k_c``, saturated at the move's top speed (so HO and a move share gain and speed limit)."""
    goals, pose = two_goal_scene
    cfg = Config()
    b = np.array(probs)
    cmd = SharedAutonomyModel(cfg).command(HO_ACTION, goals, b, pose, np.zeros(6))
    kp, _ = goals.desired_poses(pose, cfg.intent.rotation_weight_m_per_rad)
    error = b[0] * (kp[0] - pose.position) + b[1] * (kp[1] - pose.position)
    want = cfg.move.linear_gain * error
    speed = float(np.linalg.norm(want))
    want = want * min(1.0, cfg.move.linear_max_mps / speed)
    np.testing.assert_allclose(cmd.robot_twist[:3], want, atol=1e-12)
    assert np.linalg.norm(cmd.robot_twist[:3]) <= cfg.move.linear_max_mps + 1e-12
    if probs == (1.0, 0.0):  # a certain belief: HO is the move to that goal
        move = SharedAutonomyModel(cfg).command(Action(ActionKind.MOVE, 0, goals.goals[0].target), goals, b, pose,
                                                np.zeros(6))
        np.testing.assert_allclose(cmd.robot_twist, move.robot_twist, atol=1e-12)


def test_ho_plus_noassist_falls_back_exactly_when_ho_opposes(two_goal_scene):
    goals, pose = two_goal_scene
    model = SharedAutonomyModel(Config())
    probs = np.array([0.9, 0.1])  # HO pulls toward +x
    against = np.array([-0.2, 0.0, 0.0, 0.0, 0.0, 0.0])
    along = np.array([0.2, 0.0, 0.0, 0.0, 0.0, 0.0])

    ho = model.command(HO_ACTION, goals, probs, pose, against, method="ho")
    assert ho.opposed and ho.action == HO_ACTION
    np.testing.assert_allclose(ho.total_twist, 0.5 * against + 0.5 * ho.robot_twist)

    fallback = model.command(HO_ACTION, goals, probs, pose, against, method="ho+noassist")
    assert fallback.action == NO_ASSIST and not fallback.opposed
    np.testing.assert_array_equal(fallback.total_twist, against)

    kept = model.command(HO_ACTION, goals, probs, pose, along, method="ho+noassist")
    assert kept.action == HO_ACTION and not kept.opposed
    np.testing.assert_allclose(kept.total_twist, 0.5 * along + 0.5 * kept.robot_twist)
    assert np.linalg.norm(kept.robot_twist) > 0.01
