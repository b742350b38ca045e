"""The model's action sets (section III-B, top G_m goals, methods) and the rule-based baselines."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sa_daemon.config import Config, config_from_dict
from sa_daemon.geometry import Pose
from sa_daemon.model.actions import HO_ACTION, NO_ASSIST, Action, ActionKind
from sa_daemon.model.methods import method_spec
from sa_daemon.model.model import SharedAutonomyModel
from sa_daemon.world.goalset import GoalSet


def model_with(**planner) -> SharedAutonomyModel:
    return SharedAutonomyModel(config_from_dict({"planner": planner}))


def kinds(actions) -> list[ActionKind]:
    return [a.kind for a in actions]


# -- candidate goals ------------------------------------------------------------------------------------


def test_candidate_goals_by_probability(scene, start_pose):
    m = model_with(top_goals=2)
    got = m.candidate_goals(scene, np.array([0.1, 0.4, 0.2, 0.3]), start_pose)
    assert list(got) == [1, 3]


def test_candidate_goal_ties_broken_by_distance(make_goal, start_pose):
    p = start_pose.position
    goals = GoalSet(
        (
            make_goal("far", "top", p + [0.30, 0.0, 0.0]),
            make_goal("near", "top", p + [0.05, 0.0, 0.0]),
            make_goal("best", "top", p + [0.50, 0.0, 0.0]),
            make_goal("mid", "top", p + [0.10, 0.0, 0.0]),
        )
    )
    probs = np.array([0.2, 0.2, 0.4, 0.2])  # a three-way tie behind "best"
    assert list(model_with(top_goals=2).candidate_goals(goals, probs, start_pose)) == [2, 1]
    assert list(model_with(top_goals=3).candidate_goals(goals, probs, start_pose)) == [2, 1, 3]
    assert list(model_with(top_goals=10).candidate_goals(goals, probs, start_pose)) == [2, 1, 3, 0]


def _split_bowl(make_goal, start_pose) -> tuple[GoalSet, np.ndarray]:
    """A bowl target resampled into four copies (0.06 each, 0.24 in all) among four one-goal targets."""
    p = start_pose.position
    copies = [make_goal("bowl", "top", p + [0.10 * (k + 1), 0.0, 0.0]) for k in range(4)]
    others = [make_goal(name, "top", p + [0.0, 0.1, 0.0]) for name in ("cup", "plate", "apple", "can")]
    return GoalSet((*copies, *others)), np.array([0.06, 0.06, 0.06, 0.06, 0.10, 0.09, 0.08, 0.07])


def test_candidate_goals_ranked_by_goal_drop_a_split_target(make_goal, start_pose):
    goals, probs = _split_bowl(make_goal, start_pose)
    got = model_with(top_goals=3, rank_goals="goal").candidate_goals(goals, probs, start_pose)
    assert list(got) == [4, 5, 6]  # the likeliest target (0.24) has no move and no question


def test_candidate_goals_ranked_by_target_keep_a_split_target(make_goal, start_pose):
    goals, probs = _split_bowl(make_goal, start_pose)
    m = model_with(top_goals=3, rank_goals="target")
    assert list(m.candidate_goals(goals, probs, start_pose)) == [0, 1, 2]  # its copies, nearest first
    assert list(model_with(top_goals=6, rank_goals="target").candidate_goals(goals, probs, start_pose)) == [
        0, 1, 2, 3, 4, 5]
    moves, questions = m.action_set("policy", goals, probs, start_pose, frozenset())
    assert [a.target for a in questions] == ["bowl:top"]  # one question per target
    assert [a.goal for a in moves if a.kind is ActionKind.MOVE] == [0, 1, 2]


def test_candidate_goals_ranked_by_target_within_it_by_own_probability(make_goal, start_pose):
    goals, probs = _split_bowl(make_goal, start_pose)
    probs = probs.copy()
    probs[:4] = [0.02, 0.03, 0.09, 0.10]  # the copies told apart by input; the far ones likelier
    got = model_with(top_goals=5, rank_goals="target").candidate_goals(goals, probs, start_pose)
    assert list(got) == [3, 2, 1, 0, 4]


def test_candidate_goals_ranked_by_lead_keep_one_copy_of_a_split_target(make_goal, start_pose):
    goals, probs = _split_bowl(make_goal, start_pose)
    assert list(model_with(top_goals=3, rank_goals="lead").candidate_goals(goals, probs, start_pose)) == [0, 4, 5]
    probs = probs.copy()
    probs[:4] = [0.02, 0.03, 0.09, 0.10]  # the lead is the likeliest copy; the others rank by their own
    got = model_with(top_goals=5, rank_goals="lead").candidate_goals(goals, probs, start_pose)
    assert list(got) == [3, 4, 5, 2, 6]  # 0.09 each: the plate is nearer than the bowl's third copy


def test_candidate_goals_covered_keep_the_likeliest_targets_in_goal_order(make_goal, start_pose):
    goals, probs = _split_bowl(make_goal, start_pose)
    # the bowl (0.24) is the likeliest target: its nearest copy replaces the last of "goal"'s three
    assert list(model_with(top_goals=3, rank_goals="cover").candidate_goals(goals, probs, start_pose)) == [4, 5, 0]
    # the cup (0.10) is the second: already in, so one copy of the bowl is all that changes
    assert list(model_with(top_goals=3, rank_goals="cover", cover_targets=1).candidate_goals(
        goals, probs, start_pose)) == [4, 5, 0]
    assert list(model_with(top_goals=5, rank_goals="cover").candidate_goals(goals, probs, start_pose)) == [
        4, 5, 6, 7, 0]
    probs = probs.copy()
    probs[:4] = [0.02, 0.03, 0.09, 0.10]  # the bowl's likeliest copy is its farthest
    got = model_with(top_goals=2, rank_goals="cover").candidate_goals(goals, probs, start_pose)
    assert list(got) == [4, 3]  # already "goal"'s top two (0.10 each, the cup nearer): nothing changes
    probs[:4] = [0.06, 0.06, 0.06, 0.06]
    probs[4:] = [0.07, 0.07, 0.07, 0.05]  # three-way tie for second: the one "goal" puts first (the cup)
    got = model_with(top_goals=2, rank_goals="cover", cover_targets=2).candidate_goals(goals, probs, start_pose)
    assert sorted(got) == [0, 4]


def test_candidate_goals_rank_alike_when_no_target_is_split(make_goal, start_pose):
    rng = np.random.default_rng(3)
    p = start_pose.position
    goals = GoalSet(tuple(make_goal(f"obj{k}", "top", p + rng.uniform(-0.3, 0.3, 3)) for k in range(14)))
    for _ in range(20):
        probs = rng.dirichlet(np.ones(14))
        probs[rng.integers(14)] = probs[rng.integers(14)]  # a tie now and then, broken by distance
        a = model_with(rank_goals="goal").candidate_goals(goals, probs, start_pose)
        for rank in ("lead", "target", "cover"):
            b = model_with(rank_goals=rank).candidate_goals(goals, probs, start_pose)
            assert list(a) == list(b)


def test_rank_goals_refused_by_its_key():
    with pytest.raises(Exception, match="rank_goals"):
        config_from_dict({"planner": {"rank_goals": "object"}})
    with pytest.raises(Exception, match="cover_targets"):
        config_from_dict({"planner": {"rank_goals": "cover", "cover_targets": 0}})


def test_candidate_tie_distance_includes_rotation(make_goal, start_pose):
    p = start_pose.position
    # same position; the one whose orientation matches the gripper's is closer
    matching = make_goal("a", "side", p + [0.1, 0, 0], rpy=[math.pi, -math.pi / 4, 0.0])
    turned = make_goal("b", "top", p + [0.1, 0, 0])
    goals = GoalSet((turned, matching))
    assert list(model_with(top_goals=1).candidate_goals(goals, np.array([0.5, 0.5]), start_pose)) == [1]


# -- action sets ----------------------------------------------------------------------------------------


def test_policy_action_set_has_2gm_plus_2_actions(scene, start_pose):
    probs = np.full(4, 0.25)
    for gm in (1, 2, 3, 4):
        moves, questions = model_with(top_goals=gm).action_set("policy", scene, probs, start_pose, frozenset())
        assert len(moves) + len(questions) == 2 * gm + 2
        assert kinds(moves).count(ActionKind.MOVE) == gm
        assert HO_ACTION in moves and NO_ASSIST in moves
        assert len(questions) == gm


def test_paper_default_gm_caps_at_the_number_of_goals(scene, start_pose):
    moves, questions = SharedAutonomyModel(Config()).action_set(
        "policy", scene, np.full(4, 0.25), start_pose, frozenset()
    )
    assert len(moves) + len(questions) == 2 * 4 + 2


def test_move_actions_name_their_goal_and_target(scene, start_pose):
    moves, questions = model_with(top_goals=4).action_set("policy", scene, np.full(4, 0.25), start_pose, frozenset())
    for a in moves:
        if a.kind is ActionKind.MOVE:
            assert scene.goals[a.goal].target == a.target
    assert sorted(q.target for q in questions) == sorted(scene.targets)


def test_questions_deduplicated_by_target(make_goal, start_pose):
    p = start_pose.position
    cup = make_goal("cup", "top", p + [0.1, 0, 0], p + [0.12, 0, 0])
    goals = GoalSet((cup.with_poses(cup.poses[:1]), cup.with_poses(cup.poses[1:]), make_goal("bowl", "top", p + [0, 0.1, 0])))
    moves, questions = model_with(top_goals=3).action_set("policy", goals, np.array([0.4, 0.4, 0.2]), start_pose, frozenset())
    assert [q.target for q in questions] == ["cup:top", "bowl:top"]
    assert kinds(moves).count(ActionKind.MOVE) == 3  # one move per copy
    assert {a.goal for a in moves if a.kind is ActionKind.MOVE} == {0, 1, 2}


def test_questions_exclude_asked_targets(scene, start_pose):
    asked = frozenset({"cup:top", "bowl:top"})
    _, questions = model_with(top_goals=4).action_set("policy", scene, np.full(4, 0.25), start_pose, asked)
    assert sorted(q.target for q in questions) == ["chips_can:side", "cup:side"]
    assert all(q.kind is ActionKind.QUESTION for q in questions)


def test_questions_only_about_candidate_goals(scene, start_pose):
    probs = np.array([0.1, 0.4, 0.2, 0.3])
    _, questions = model_with(top_goals=2).action_set("policy", scene, probs, start_pose, frozenset())
    assert [q.target for q in questions] == ["cup:side", "bowl:top"]


@pytest.mark.parametrize(
    "method, n_moves, ho, none, questions",
    [
        ("policy", 4, True, True, True),
        ("policy+noqns", 4, True, True, False),
        ("policy+noho", 4, False, True, True),
        ("policy+withoutnoassist", 4, True, False, True),
    ],
)
def test_each_method_has_its_actions(scene, start_pose, method, n_moves, ho, none, questions):
    moves, qs = model_with(top_goals=4).action_set(method, scene, np.full(4, 0.25), start_pose, frozenset())
    assert kinds(moves).count(ActionKind.MOVE) == n_moves
    assert (HO_ACTION in moves) is ho
    assert (NO_ASSIST in moves) is none
    assert (len(qs) == 4) is questions and (len(qs) == 0) is (not questions)


def test_baseline_specs():
    assert not method_spec("manual").planned and not method_spec("ho").planned
    assert method_spec("policy").planned
    with pytest.raises(ValueError, match="unknown method"):
        method_spec("optimal")


# -- fixed actions of the baselines ---------------------------------------------------------------------


def test_manual_and_ho_fixed_actions(scene):
    m = SharedAutonomyModel(Config())
    probs = np.array([0.97, 0.01, 0.01, 0.01])
    assert m.fixed_action("manual", scene, probs) == NO_ASSIST
    assert m.fixed_action("ho", scene, probs) == HO_ACTION
    assert m.fixed_action("ho+noassist", scene, probs) == HO_ACTION


def test_planned_method_has_no_fixed_action(scene):
    with pytest.raises(ValueError):
        SharedAutonomyModel(Config()).fixed_action("policy", scene, np.full(4, 0.25))


def test_blend_moves_to_the_top_target_beyond_the_margin(scene):
    m = SharedAutonomyModel(Config())
    assert m.fixed_action("blend", scene, np.array([0.1, 0.7, 0.1, 0.1])) == Action(ActionKind.MOVE, 1, "cup:side")


def test_blend_passes_through_within_the_margin(scene):
    m = SharedAutonomyModel(Config())
    assert m.fixed_action("blend", scene, np.array([0.05, 0.6, 0.05, 0.3])) == NO_ASSIST  # 0.3 apart
    assert m.fixed_action("blend", scene, np.full(4, 0.25)) == NO_ASSIST


def test_blend_margin_is_on_target_probabilities(make_goal, start_pose):
    p = start_pose.position
    cup = make_goal("cup", "top", p + [0.1, 0, 0], p + [0.12, 0, 0])
    goals = GoalSet(
        (
            cup.with_poses(cup.poses[:1]),
            make_goal("bowl", "top", p + [0, 0.1, 0]),
            cup.with_poses(cup.poses[1:]),
            make_goal("plate", "top", p + [0, -0.1, 0]),
        )
    )
    # per goal the top two (0.40, 0.26) are only 0.14 apart; per target cup 0.66 leads bowl 0.2 by 0.46
    act = SharedAutonomyModel(Config()).fixed_action("blend", goals, np.array([0.26, 0.2, 0.40, 0.14]))
    assert act == Action(ActionKind.MOVE, 2, "cup:top")  # the most likely copy


def test_blend_with_a_single_target(make_goal, start_pose):
    goals = GoalSet((make_goal("cup", "top", start_pose.position + [0.1, 0, 0]),))
    assert SharedAutonomyModel(Config()).fixed_action("blend", goals, np.array([1.0])) == Action(
        ActionKind.MOVE, 0, "cup:top"
    )


def test_move_robot_twist_uses_the_goals_closest_pose(make_goal):
    pose = Pose.from_rpy([0.3, 0.0, 0.2], [math.pi, 0, 0])
    p = pose.position
    g = make_goal("cup", "top", p + [0.0, -0.15, 0.0], p + [0.05, 0.0, 0.0])
    twist = SharedAutonomyModel(Config()).robot_twist(
        Action(ActionKind.MOVE, 0, "cup:top"), GoalSet((g,)), np.array([1.0]), pose, np.zeros(6)
    )
    np.testing.assert_allclose(twist, [0.05, 0, 0, 0, 0, 0], atol=1e-12)
