"""One grasp pose per goal for HO, the moves and the planner's rollouts (``intent.reach_pose``).

``closest`` (the paper's) keeps the paper's ``k_c`` for the moves and the rollouts and each goal's
lowest-value pose for HO; ``tracked`` takes, for all of them, the pose the input since the last
resampling points at: each goal's posterior over its poses times ``exp(-V)`` at the gripper;
``tracked_moves`` (the default since session 43) takes it for the moves and the rollouts and leaves HO
the paper's.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from sa_daemon.arm.base import ArmState
from sa_daemon.config import Config, config_from_dict
from sa_daemon.control.controller import Controller
from sa_daemon.geometry import Pose
from sa_daemon.model.actions import HO_ACTION, Action, ActionKind
from sa_daemon.model.belief import Belief
from sa_daemon.model.huber import nearest_goal_poses, tracked_goal_poses
from sa_daemon.model.model import SharedAutonomyModel
from sa_daemon.planner.snapshot import Snapshot
from sa_daemon.planner.solver import Solver
from sa_daemon.planner.watch import WatchSearch
from sa_daemon.world.goals import Goal, GraspType
from sa_daemon.world.goalset import GoalSet

TOP = (math.pi, 0.0, 0.0)
CLOSEST = config_from_dict({"intent": {"reach_pose": "closest"}})
TRACKED = config_from_dict({"intent": {"reach_pose": "tracked"}})
MOVES = config_from_dict({"intent": {"reach_pose": "tracked_moves"}})
# The gripper 1 cm toward the cup's -y grasp: that grasp is the closer and the lower-value one.
GRIPPER = Pose.from_rpy([0.30, -0.01, 0.20], TOP)
MINUS_Y, PLUS_Y = [0.40, -0.05, 0.20], [0.40, 0.05, 0.20]
AT_PLUS_Y = np.array([0.1, 0.06, 0.0, 0.0, 0.0, 0.0])  # m/s: from the gripper at the cup's +y grasp


def goal(obj: str, *positions) -> Goal:
    return Goal(obj, GraspType.TOP, tuple(Pose.from_rpy(p, TOP) for p in positions))


def cup_and_bowl() -> GoalSet:
    """A cup with grasps 5 cm either side of the path and a bowl (one grasp, the cup's poses pad it)."""
    return GoalSet((goal("cup", MINUS_Y, PLUS_Y), goal("bowl", [0.40, 0.20, 0.20])))


def driven(cfg: Config, samples: int = 40) -> Belief:
    """The belief after ``samples`` input samples at the cup's +y grasp, the gripper held at ``GRIPPER``."""
    b = Belief.uniform(cup_and_bowl())
    for _ in range(samples):
        b = b.after_input(GRIPPER, AT_PLUS_Y, cfg.intent)
    return b


def test_closest_keeps_no_pose_posterior_and_reaches_as_the_paper():
    model = SharedAutonomyModel(CLOSEST)
    b = driven(CLOSEST)
    assert b.pose_log_w is None
    assert model.reach_poses(b.goals, GRIPPER, b.pose_log_w) is None


def test_tracking_the_poses_leaves_the_belief_over_goals_as_it_was():
    """With ``poses = "marginal"`` the option only keeps the pose posterior: the goals' probabilities are
    the marginal tracker's, and the posterior is the one ``poses = "tracked"`` keeps."""
    reach, plain = driven(TRACKED), driven(CLOSEST)
    np.testing.assert_array_equal(reach.log_p, plain.log_p)
    both = driven(config_from_dict({"intent": {"poses": "tracked"}}))
    np.testing.assert_allclose(reach.pose_log_w, both.pose_log_w, atol=1e-12)
    w = np.exp(reach.pose_log_w)
    np.testing.assert_allclose(w.sum(axis=1), 1.0, atol=1e-12)
    assert w[0, 1] > 0.99  # the cup's +y grasp, where the input points
    assert w[1, 1] == 0.0  # the bowl's padding


def test_with_no_input_the_tracked_pose_of_one_orientation_is_the_lowest_value_pose():
    """A uniform posterior leaves ``exp(-V)`` alone to choose: among poses of one orientation, HO's pose
    under ``closest`` (the two weigh rotation differently, so only there are they the same)."""
    rng = np.random.default_rng(3)
    positions = 0.3 + 0.2 * rng.random((5, 4, 3))
    q = rng.normal(size=4)
    quats = np.broadcast_to(q / np.linalg.norm(q), (5, 4, 4))
    uniform = np.full((5, 4), -math.log(4))
    for _ in range(10):
        p, q = 0.3 + 0.2 * rng.random(3), rng.normal(size=4)
        q /= np.linalg.norm(q)
        want = nearest_goal_poses(p, q, positions, quats, CLOSEST.intent)
        got = tracked_goal_poses(p, q, positions, quats, uniform, CLOSEST.intent)
        np.testing.assert_array_equal(got[0], want[0])
        np.testing.assert_array_equal(got[1], want[1])


def test_ho_and_a_move_head_for_the_grasp_the_input_pointed_at():
    """The gripper nearer the cup's -y grasp, the input so far at its +y grasp: under ``closest`` HO and the
    move to the cup pull toward -y, under ``tracked`` toward +y; under ``tracked_moves`` the move toward +y
    and HO toward -y, as the paper's."""
    b = driven(TRACKED)
    move = Action(ActionKind.MOVE, 0, "cup:top")
    for cfg, ho_sign, move_sign in ((CLOSEST, -1.0, -1.0), (TRACKED, 1.0, 1.0), (MOVES, -1.0, 1.0)):
        model = SharedAutonomyModel(cfg)
        reach = model.reach_poses(b.goals, GRIPPER, b.pose_log_w)
        cup_only = np.array([1.0, 0.0])
        ho = model.robot_twist(HO_ACTION, b.goals, cup_only, GRIPPER, np.zeros(6), reach)
        mv = model.robot_twist(move, b.goals, b.probs, GRIPPER, np.zeros(6), reach)
        assert ho_sign * ho[1] > 0.0 and move_sign * mv[1] > 0.0
    kp, _ = SharedAutonomyModel(TRACKED).reach_poses(b.goals, GRIPPER, b.pose_log_w)
    np.testing.assert_allclose(kp[0], PLUS_Y)


def test_snapshot_carries_the_pose_posterior_and_refuses_a_malformed_one():
    b = driven(TRACKED)
    snap = Snapshot(b.goals, b.probs, GRIPPER, AT_PLUS_Y, pose_log_w=b.pose_log_w)
    back = Snapshot.from_dict(json.loads(json.dumps(snap.to_dict())))
    np.testing.assert_allclose(np.exp(back.pose_log_w), np.exp(b.pose_log_w), atol=1e-12)
    assert back.pose_log_w[1, 1] == -np.inf
    faint = np.array(b.pose_log_w)
    faint[0, 0] = -760.0  # a pose the input has all but ruled out: exp rounds it to zero
    back = Snapshot.from_dict(json.loads(json.dumps(Snapshot(b.goals, b.probs, GRIPPER, AT_PLUS_Y,
                                                             pose_log_w=faint).to_dict())))
    assert -760.0 < back.pose_log_w[0, 0] < -740.0 and back.pose_log_w[1, 1] == -np.inf
    for bad in (np.zeros((2, 3)), np.where(np.isfinite(b.pose_log_w), np.nan, -np.inf),
                np.full((2, 2), -np.inf)):
        with pytest.raises(ValueError, match="pose_log_w"):
            Snapshot(b.goals, b.probs, GRIPPER, AT_PLUS_Y, pose_log_w=bad)


@pytest.mark.parametrize("cfg", [CLOSEST, TRACKED, MOVES], ids=["closest", "tracked", "tracked_moves"])
def test_the_planner_scores_the_goals_at_the_pose_the_controller_drives_to(cfg):
    """The watch model's rollouts take each goal's pose from the same place as the arm's commands."""
    model = SharedAutonomyModel(cfg)
    b = driven(TRACKED)
    snap = Snapshot(b.goals, b.probs, GRIPPER, AT_PLUS_Y, budget_s=None, node_budget=200, pose_log_w=b.pose_log_w)
    search = WatchSearch(model, snap)
    reach = model.reach_poses(b.goals, GRIPPER, b.pose_log_w)
    want = reach or b.goals.desired_poses(GRIPPER, cfg.intent.rotation_weight_m_per_rad)
    np.testing.assert_array_equal(search.kp, want[0])
    np.testing.assert_array_equal(search.kq, want[1])
    assert np.allclose(search.kp[0], MINUS_Y if cfg is CLOSEST else PLUS_Y)
    assert Solver(model).plan(snap).action is not None


def ho_tick(cfg: Config):
    """The controller's HO tick after 40 input samples at the cup's +y grasp, and its belief."""
    ctl = Controller(cfg, cup_and_bowl(), "ho", 0.025)
    ctl.adopt_fixed()
    t = 0.0
    axes = AT_PLUS_Y[:3] / cfg.input.linear_scale_mps
    for _ in range(40):
        ctl.on_input(axes, t)
        ctl.update_belief(GRIPPER, t)
        t += 0.025
    return ctl.tick(ArmState(GRIPPER, False), t), ctl


def test_the_controller_sends_ho_to_the_tracked_pose():
    """In the daemon's and the evaluation's control core: HO's tick toward the belief's tracked poses."""
    model = SharedAutonomyModel(TRACKED)
    tick, ctl = ho_tick(TRACKED)
    b = ctl.belief
    assert np.exp(b.pose_log_w[0, 1]) > 0.99
    want = model.command(HO_ACTION, b.goals, b.probs, GRIPPER, ctl.user_twist, "ho",
                         model.reach_poses(b.goals, GRIPPER, b.pose_log_w))
    np.testing.assert_allclose(tick.command.robot_twist, want.robot_twist, atol=1e-12)
    closest = model.command(HO_ACTION, b.goals, b.probs, GRIPPER, ctl.user_twist, "ho")
    assert not np.allclose(tick.command.robot_twist, closest.robot_twist)


def test_tracked_moves_leaves_the_ho_method_as_the_paper_has_it():
    """Under ``tracked_moves`` the HO method's tick is the default's, bit for bit, though the belief keeps
    the pose posterior: the HO baseline the option is compared with does not move."""
    moves, plain = ho_tick(MOVES), ho_tick(CLOSEST)
    assert moves[1].belief.pose_log_w is not None and plain[1].belief.pose_log_w is None
    np.testing.assert_array_equal(moves[1].belief.log_p, plain[1].belief.log_p)
    np.testing.assert_array_equal(moves[0].command.robot_twist, plain[0].command.robot_twist)
    np.testing.assert_array_equal(moves[0].safety.twist, plain[0].safety.twist)
