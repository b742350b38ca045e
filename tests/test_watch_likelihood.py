"""How the watch model's rollouts read the input they predict (``planner.watch_likelihood``).

``kc`` (the default) scores a predicted input by MaxEnt IOC against each goal's ``k_c`` alone; ``marginal``
scores it as the belief tracker does (``intent.poses = "marginal"``): each goal's grasp poses summed with
weights ``exp(-V)``. The two differ where a goal owns several poses, most of all for the copies that
resampling makes of one target: the tracker reads an input toward one copy's pose as evidence for a
copy that owns that pose's neighbours too, and the search under ``kc`` expects the two to part.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from sa_daemon.config import ConfigError, config_from_dict
from sa_daemon.geometry import Pose
from sa_daemon.model.actions import HO_ACTION, NO_ASSIST, Action, ActionKind, Mode
from sa_daemon.model.belief import Belief
from sa_daemon.model.huber import marginal_nll, marginal_nll_driven
from sa_daemon.model.model import SharedAutonomyModel
from sa_daemon.model.twists import user_angular, user_linear
from sa_daemon.planner.rollouts import Rollouts
from sa_daemon.planner.snapshot import Snapshot
from sa_daemon.planner.solver import Solver
from sa_daemon.planner.watch import WatchSearch
from sa_daemon.world.goals import Goal, GraspType
from sa_daemon.world.goalset import GoalSet
from sa_daemon.world.scene import load_scene

TOP = (math.pi, 0.0, 0.0)
KC = config_from_dict({"planner": {"threads": 1, "watch_likelihood": "kc"}}, "test")
MARGINAL = config_from_dict({"planner": {"threads": 1, "watch_likelihood": "marginal"}}, "test")


@pytest.mark.parametrize("translating", [True, False])
def test_the_batched_marginal_is_the_trackers_likelihood(translating):
    """``marginal_nll_driven`` over a batch of poses equals the tracker's ``marginal_nll`` at each."""
    intent = KC.intent
    goals = GoalSet(load_scene("scene1").goals)
    rng = np.random.default_rng(5)
    start = load_scene("scene1").start
    positions = start.position + rng.normal(scale=0.08, size=(6, 3))
    quats = np.array([Pose.from_rpy(p, (math.pi + r[0], r[1], r[2])).quat_wxyz
                      for p, r in zip(positions, rng.normal(scale=0.3, size=(6, 3)))])
    parts = rng.normal(scale=0.1 if translating else 0.4, size=(6, 3))
    batched = marginal_nll_driven(positions, quats, parts if translating else None, None if translating else parts,
                                  goals.positions, goals.quats_wxyz, intent)
    for i in range(6):
        u = np.concatenate((parts[i], np.zeros(3)) if translating else (np.zeros(3), parts[i]))
        one = marginal_nll(positions[i], quats[i], u, goals.positions, goals.quats_wxyz, intent)
        np.testing.assert_allclose(batched[i], one, rtol=1e-12, atol=1e-12)
    assert np.ptp(batched) > 0.01  # the inputs are told apart


def one_pose_goals() -> GoalSet:
    return GoalSet(tuple(Goal(o, GraspType.TOP, (Pose.from_rpy(p, (math.pi, 0.0, yaw)),)) for o, p, yaw in (
        ("cup", [0.45, 0.05, 0.25], 0.0), ("bowl", [0.38, 0.24, 0.23], 0.8), ("can", [0.50, -0.15, 0.28], -0.6))))


@pytest.mark.parametrize("mode", [Mode.TRANSLATION, Mode.ROTATION])
def test_with_one_pose_a_goal_both_readings_agree(mode):
    """A goal with one grasp pose: the marginal is MaxEnt IOC against that pose, which is its ``k_c``."""
    goals = one_pose_goals()
    start = Pose.from_rpy([0.25, 0.0, 0.45], (math.pi, -0.5, 0.2))
    kp, kq = goals.desired_poses(start, KC.intent.rotation_weight_m_per_rad)
    actions = [Action(ActionKind.MOVE, goal=0), HO_ACTION, NO_ASSIST]
    args = (start.position[None], start.quat_wxyz[None], np.full((1, 3), 1 / 3), kp, kq, actions, mode,
            (0.06, 0.3), 4, 0.5, 2)
    plain = Rollouts(KC, *args, compiled=False)
    read = Rollouts(MARGINAL, *args, poses=(goals.positions, goals.quats_wxyz))
    np.testing.assert_allclose(read.loglik, plain.loglik, rtol=1e-9, atol=1e-9)
    np.testing.assert_array_equal(read.value, plain.value)
    assert np.ptp(plain.loglik) > 0.1


def split_cup(turned: bool = False) -> tuple[GoalSet, np.ndarray]:
    """``cup:top`` held as two copies: ``#0`` owns one pose on the rim, ``#1`` the eleven others (30 deg
    apart, 4 cm radius), all with one orientation or (``turned``) the fingers across the rim; a bowl
    elsewhere. The belief 0.35 / 0.45 / 0.2."""
    centre = np.array([0.45, 0.05, 0.25])
    rim = [Pose.from_rpy(centre + 0.04 * np.array([math.cos(a), math.sin(a), 0.0]),
                         (math.pi, 0.0, a if turned else 0.0)) for a in np.radians(np.arange(0, 360, 30))]
    own = Goal("cup", GraspType.TOP, rim[:1])
    rest = Goal("cup", GraspType.TOP, tuple(rim[1:]))
    bowl = Goal("bowl", GraspType.TOP, (Pose.from_rpy([0.38, 0.30, 0.23], TOP),))
    return GoalSet((own, rest, bowl)), np.array([0.35, 0.45, 0.2])


def test_copies_of_one_target_part_less_as_the_tracker_reads_them():
    """A user heading to copy ``#0``'s pose, watched for a second: read against each copy's ``k_c`` the
    input parts the copies by more than the tracker's marginal does (the copy that owns the neighbouring
    poses explains much of it). Not a law: where the poses differ in orientation, the weights ``exp(-V)``
    at the gripper can make the marginal the sharper (the next test holds what is one)."""
    goals, probs = split_cup()
    snap = Snapshot(goals, probs, Pose.from_rpy([0.40, 0.05, 0.40], TOP), np.zeros(6), budget_s=None,
                    node_budget=400, user_speed=(0.06, 0.3))

    def parting(cfg) -> float:
        ws = WatchSearch(SharedAutonomyModel(cfg), snap)
        pose = snap.pose
        R = ws.rollouts(pose.position[None], pose.quat_wxyz[None], ws.b0[None], ws.n, ws.n_w)
        a = ws.moves.index(NO_ASSIST)
        ll = R.loglik[0, 0, a]  # the user heads to copy #0, the arm leaves the input alone
        return float(ll[0] - ll[1])  # log-likelihood ratio of #0 over #1

    kc, marginal = parting(KC), parting(MARGINAL)
    assert kc > 0.0 and marginal > 0.0  # both read the input as #0's
    assert marginal < kc


@pytest.mark.parametrize("mode", [Mode.TRANSLATION, Mode.ROTATION])
def test_the_watch_expects_the_belief_the_tracker_will_reach(mode):
    """For a user heading to each goal, the belief the watch search predicts after one watched step is the
    one the belief tracker reaches reading that predicted input for as many samples (``runtime.belief_hz``
    x the step) at the pose where it is read."""
    goals, probs = split_cup(turned=True)
    pose = Pose.from_rpy([0.40, 0.05, 0.40], (math.pi, 0.2, 0.3))
    speed = (0.06, 0.3)
    snap = Snapshot(goals, probs, pose, np.zeros(6), mode=mode, budget_s=None, node_budget=400, user_speed=speed)
    ws = WatchSearch(SharedAutonomyModel(MARGINAL), snap)
    assert ws.n_w == 1
    R = ws.rollouts(pose.position[None], pose.quat_wxyz[None], ws.b0[None], ws.n, ws.n_w)
    samples = MARGINAL.runtime.belief_hz * ws.dt
    assert samples == int(samples)
    moved = 0.0
    for g in range(len(goals)):
        u = np.zeros(6)
        if mode is Mode.TRANSLATION:
            u[:3] = user_linear(pose.position, ws.kp[g], ws.pregrasp[g], speed[0], MARGINAL.intent.user_standoff_m)
        else:
            u[3:] = user_angular(pose.quat_wxyz, ws.kq[g], speed[1])
        b = Belief.from_probs(goals, probs)
        for _ in range(int(samples)):
            b = b.after_input(pose, u, MARGINAL.intent)
        for a in range(len(ws.moves)):
            predicted = probs * np.exp(R.loglik[0, g, a] - R.loglik[0, g, a].max())
            np.testing.assert_allclose(b.probs, predicted / predicted.sum(), rtol=1e-9, atol=1e-12)
        moved = max(moved, float(np.abs(b.probs - probs).max()))
    assert moved > 0.05  # the input does move the belief


def test_the_planner_plans_with_the_marginal_reading():
    goals, probs = split_cup()
    snap = Snapshot(goals, probs, Pose.from_rpy([0.40, 0.05, 0.40], TOP), np.zeros(6), budget_s=None,
                    node_budget=400, user_speed=(0.06, 0.3))
    values = {cfg.planner.watch_likelihood: Solver(SharedAutonomyModel(cfg)).plan(snap).root_values
              for cfg in (KC, MARGINAL)}
    assert values["kc"].keys() == values["marginal"].keys()
    # watching is worth less when the input is expected to tell the copies apart less
    assert values["marginal"][NO_ASSIST] < values["kc"][NO_ASSIST]


def test_an_unknown_watch_likelihood_is_refused_by_name():
    with pytest.raises(ConfigError, match=r"planner\.watch_likelihood"):
        config_from_dict({"planner": {"watch_likelihood": "nearest"}})


@pytest.mark.parametrize("mode", [Mode.TRANSLATION, Mode.ROTATION])
def test_the_compiled_one_step_watch_reads_the_marginal_as_the_numpy_form(mode):
    """A watch of one rollout step (the default): the compiled rollouts with the marginal read at the start
    equal the numpy form, which reads it inside its loop."""
    goals, probs = split_cup(turned=True)
    rng = np.random.default_rng(11)
    positions = np.array([0.40, 0.05, 0.40]) + rng.normal(scale=0.05, size=(3, 3))
    quats = np.array([Pose.from_rpy(p, (math.pi, 0.3 * i, -0.2 * i)).quat_wxyz for i, p in enumerate(positions)])
    kp, kq = goals.desired_poses(Pose(positions[0], quats[0]), KC.intent.rotation_weight_m_per_rad)
    actions = [Action(ActionKind.MOVE, goal=1), HO_ACTION, NO_ASSIST]
    args = (positions, quats, np.tile(probs, (3, 1)), kp, kq, actions, mode, (0.06, 0.3), 4, 1.0, 1)
    poses = (goals.positions, goals.quats_wxyz)
    compiled = Rollouts(MARGINAL, *args, compiled=True, poses=poses)
    numpy_form = Rollouts(MARGINAL, *args, compiled=False, poses=poses)
    np.testing.assert_allclose(compiled.loglik, numpy_form.loglik, rtol=1e-9, atol=1e-6)
    np.testing.assert_allclose(compiled.value, numpy_form.value, rtol=1e-9, atol=1e-6)
    plain = Rollouts(KC, *args, compiled=True)
    assert np.abs(compiled.loglik - plain.loglik).max() > 0.01  # the reading did change
