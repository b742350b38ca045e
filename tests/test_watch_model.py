"""The watch model (issue 16, in progress; ``planner.model = "watch"``): rollouts and search.

Not yet the default: these tests pin its pieces, not the paper's behaviours.
"""

from __future__ import annotations

import numpy as np
import pytest

from sa_daemon.config import config_from_dict
from sa_daemon.model.actions import HO_ACTION, NO_ASSIST, Action, ActionKind, Mode
from sa_daemon.model.model import SharedAutonomyModel
from sa_daemon.model.twists import user_twist_toward
from sa_daemon.planner.rollouts import Rollouts
from sa_daemon.planner.snapshot import Snapshot
from sa_daemon.planner.solver import Solver
from sa_daemon.planner.watch import WatchSearch
from sa_daemon.world.scene import load_scene

SCENE = load_scene("scene1")


def _cfg(**planner):
    return config_from_dict({"planner": {"model": "watch", **planner}, "reward": {"question_time_s": 2.5}}, "test")


def _snap(speed=(0.02, 0.0), probs=None, budget_s=None):
    goals = SharedAutonomyModel().initial_belief(SCENE.goals).goals
    p = np.full(len(goals), 1.0 / len(goals)) if probs is None else np.asarray(probs, dtype=float)
    return Snapshot(goals, p, SCENE.start, np.zeros(6), budget_s=budget_s, user_speed=speed)


def test_the_predicted_user_heads_to_the_goal_in_its_mode_at_its_speed():
    p, q = SCENE.start.position, SCENE.start.quat_wxyz
    goal = p + np.array([0.3, 0.0, -0.4])
    u = user_twist_toward(p, q, goal, q, Mode.TRANSLATION, (0.05, 0.2))
    assert np.linalg.norm(u[:3]) == pytest.approx(0.05)
    assert np.allclose(u[:3] / 0.05, (goal - p) / 0.5) and np.all(u[3:] == 0.0)
    near = user_twist_toward(p, q, p + np.array([0.01, 0.0, 0.0]), q, Mode.TRANSLATION, (0.05, 0.2))
    assert near[0] == pytest.approx(0.01)  # slows within a second of the goal
    assert np.all(user_twist_toward(p, q, goal, q, Mode.ROTATION, (0.05, 0.2)) == 0.0)  # aligned already


def test_rollouts_standing_still_earn_the_stay_reward_each_step_and_a_move_gains_on_its_own_goal():
    cfg = _cfg()
    snap = _snap(speed=(0.0, 0.0))
    goals = snap.goals
    kp, kq = goals.desired_poses(snap.pose, cfg.intent.rotation_weight_m_per_rad)
    actions = [Action(ActionKind.MOVE, 0, goals.goals[0].target), HO_ACTION, NO_ASSIST]
    R = Rollouts(cfg, snap.pose.position[None], snap.pose.quat_wxyz[None], snap.probs[None], kp, kq, actions,
                 Mode.TRANSLATION, (0.0, 0.0), steps=8, dt=0.25, watch_steps=4)
    none = R.value[0, :, 2, :]  # an idle user and no assistance: the arm stands, each step earns stay
    assert np.allclose(none, none[:, :1] + np.arange(9)[None] * R.stay[0][:, None])
    assert np.all(R.stay < 0.0)  # far from every goal, standing costs
    assert R.value[0, 0, 0, 8] > R.value[0, 0, 2, 8] + 1.0  # moving to goal 0 beats standing, for goal 0
    assert R.loglik.shape == (1, len(goals), 3, len(goals))


def test_watch_search_values_every_root_action_and_picks_the_best():
    model = SharedAutonomyModel(_cfg())
    r = Solver(model).plan(_snap())
    assert r.complete and r.value == max(r.root_values.values())
    kinds = {a.kind for a in r.root_values}
    assert {ActionKind.MOVE, ActionKind.HO, ActionKind.NONE, ActionKind.QUESTION} <= kinds
    assert Solver(model).plan(_snap()).action == r.action  # deterministic


def test_watching_a_user_heading_to_a_goal_moves_the_branch_belief_toward_that_goal():
    """The predicted joystick input of a user heading to ``g`` is evidence for ``g``: in every branch of
    every watched motion the belief in the branch's goal grows from the uniform prior."""
    model = SharedAutonomyModel(_cfg())
    s = WatchSearch(model, _snap(speed=(0.05, 0.0)))
    pose = s.snap.pose
    R = s._rollouts(pose.position[None], pose.quat_wxyz[None], s.b0[None], s.n, s.n_w)
    for w in s.watched:
        B = s.child_beliefs(R, w)
        assert np.allclose(B.sum(axis=1), 1.0)
        assert np.all(B[np.arange(len(s.branches)), s.branches] > s.b0[s.branches]), s.moves[w].label


def test_without_watch_levels_only_commits_and_questions_are_valued():
    model = SharedAutonomyModel(_cfg(watch_levels=0))
    values, watched, complete = WatchSearch(model, _snap()).run()
    assert complete and watched == {}
    assert any(a.kind is ActionKind.QUESTION for a in values)


def test_a_node_budget_stops_before_the_watched_motions():
    model = SharedAutonomyModel(_cfg())
    snap = _snap()
    snap = Snapshot(snap.goals, snap.probs, snap.pose, snap.user_twist, budget_s=None, node_budget=1,
                    user_speed=snap.user_speed)
    r = Solver(model).plan(snap)
    assert not r.complete and r.upper_bound >= r.value
