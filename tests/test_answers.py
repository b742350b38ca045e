"""``planner/answers.py``: the answer model both searches use, on Scene 2's goals (objects with one,
two and three grasp types)."""

from __future__ import annotations

import numpy as np
import pytest

from sa_daemon.model.actions import Action, ActionKind
from sa_daemon.model.model import SharedAutonomyModel
from sa_daemon.planner.answers import ThirdAnswer, yes_likelihood
from sa_daemon.world.scene import load_scene

GOALS = SharedAutonomyModel().initial_belief(load_scene("scene2").goals).goals
QUESTIONS = [Action(ActionKind.QUESTION, target=t) for t in GOALS.targets]
P = 0.999


def test_yes_is_likely_exactly_for_the_goals_of_the_asked_target():
    L = yes_likelihood(QUESTIONS, GOALS, P)
    for q, question in enumerate(QUESTIONS):
        mine = np.array([g.target == question.target for g in GOALS.goals])
        assert mine.any()
        np.testing.assert_array_equal(L[q], np.where(mine, P, 1.0 - P))


def test_the_three_answers_are_a_distribution_and_other_means_another_grasp_of_the_object():
    t = ThirdAnswer.of(QUESTIONS, GOALS, P)
    np.testing.assert_allclose(t.P_yes + t.P_no + t.P_other, 1.0)
    assert (t.P_no >= 0).all()
    for q, question in enumerate(QUESTIONS):
        obj = question.target.split(":")[0]
        for g, goal in enumerate(GOALS.goals):
            sibling = goal.object == obj and goal.target != question.target
            assert t.siblings[q, g] == sibling
            if sibling:
                assert t.P_other[q, g] == pytest.approx(P)
        if not t.siblings[q].any():  # an object of one grasp type: "other" is never answered
            assert (t.P_other[q] == 0).all()


def test_after_other_the_asked_target_is_out_and_the_belief_sums_to_one():
    t = ThirdAnswer.of(QUESTIONS, GOALS, P)
    rng = np.random.default_rng(3)
    B = rng.dirichlet(np.ones(len(GOALS)), size=len(QUESTIONS))
    B[0, t.siblings[0]] = 0.0  # one row whose siblings hold nothing: shared out equally
    B[0] /= B[0].sum()
    after = t.other_grasp(B, np.arange(len(QUESTIONS)))
    has_sib = t.siblings.any(axis=1)  # (an object of one grasp type: "other" has probability 0 there)
    assert has_sib[0] and not has_sib.all()
    np.testing.assert_allclose(after[has_sib].sum(axis=1), 1.0)
    assert (after[t.asked] == 0).all()
    assert (after[has_sib][t.siblings[has_sib]] > 0).all()
    others = ~t.asked & ~t.siblings
    np.testing.assert_array_equal(after[others], B[others])  # other objects keep theirs
