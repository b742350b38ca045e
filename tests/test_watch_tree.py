"""The watch model written down as a tree (``planner/watch_tree.py``) and planned by pomdp_py's POUCT.

The tree must be the problem the search solves: solved by plain recursion it gives every root action the
search's value, for the default model and its switches. The peer (``bench/peer.py``) plans that tree.
"""

from __future__ import annotations

import numpy as np
import pytest

from sa_daemon.config import config_from_dict
from sa_daemon.geometry import Pose
from sa_daemon.model.actions import ActionKind, Mode
from sa_daemon.model.model import SharedAutonomyModel
from sa_daemon.planner.snapshot import Snapshot
from sa_daemon.planner.watch import WatchSearch, plan_watch
from sa_daemon.planner.watch_tree import exact_values
from sa_daemon.world.scene import load_scene

SCENE1 = load_scene("scene1")
SCENE2 = load_scene("scene2")
COMPLEX = load_scene("study-complex")


def _model(planner=None, reward=None, asking=None):
    data = {"planner": planner or {}, "reward": reward or {}, "asking": asking or {}}
    return SharedAutonomyModel(config_from_dict(data, "test"))


def _snapshots(scene, n, seed):
    """``n`` snapshots: random beliefs (some peaked, some spread) at the start pose and above the first
    object, in either mode, at a range of user speeds."""
    rng = np.random.default_rng(seed)
    goals = SharedAutonomyModel().initial_belief(scene.goals).goals
    first = scene.objects[0].position
    above = Pose(np.asarray(first) + np.array([-0.08, 0.0, 0.15]), scene.start.quat_wxyz)
    out = []
    for i in range(n):
        probs = rng.dirichlet(np.full(len(goals), 0.3 if i % 2 else 3.0))
        out.append(Snapshot(goals, probs, scene.start if i % 3 else above, np.zeros(6),
                            mode=Mode.ROTATION if i % 4 == 3 else Mode.TRANSLATION, budget_s=None,
                            user_speed=(float(rng.uniform(0.0, 0.06)), float(rng.uniform(0.0, 0.3)))))
    return out


VARIANTS = {
    "default": {},
    "no gate": {"planner": {"question_gate": "none"}},
    "mapped branches": {"planner": {"watch_branches": "mapped"}},
    "all branches": {"planner": {"watch_branches": "all"}},
    "one-second questions": {"reward": {"question_time_s": 1.0}},  # chains five deep
    "questions as long as the horizon, no gate": {"reward": {"question_time_s": 5.0},
                                                  "planner": {"question_gate": "none"}},
    "a watch that may be continued": {"planner": {"watch_levels": 2}},  # still a terminal payoff per goal
}


@pytest.mark.parametrize("variant", list(VARIANTS))
def test_the_tree_solved_by_recursion_gives_every_root_action_the_search_s_value(variant):
    model = _model(**VARIANTS[variant])
    asked_any = 0
    for snap in _snapshots(SCENE1, 6, seed=len(variant)):
        ref = plan_watch(model, snap).root_values
        tree = WatchSearch(model, snap).tree()
        got = exact_values(tree)
        assert set(got) == set(ref)
        for action, value in ref.items():
            assert got[action] == pytest.approx(value, rel=1e-9, abs=1e-6), (variant, action)
        asked_any += any(a.kind is ActionKind.QUESTION for a in ref)
    assert asked_any  # the question trees were exercised, not only the commits


@pytest.mark.parametrize("scene", [SCENE2, COMPLEX], ids=["scene2", "22 goals"])
def test_the_tree_holds_the_larger_scenes(scene):
    model = _model()
    for snap in _snapshots(scene, 3, seed=7):
        ref = plan_watch(model, snap).root_values
        got = exact_values(WatchSearch(model, snap).tree())
        assert got == pytest.approx(ref, rel=1e-9, abs=1e-6)


def test_the_tree_lists_only_its_own_nodes():
    """The gate decides "without asking" at fewer steps than a node's answers leave: those are not nodes of
    the tree and are not listed (one-second questions: chains deep enough to have many of them)."""
    model = _model(reward={"question_time_s": 1.0})
    listed = 0
    for snap in _snapshots(SCENE1, 3, seed=4):
        tree = WatchSearch(model, snap).tree()
        for steps, asked, yes in tree.askable:
            assert steps == tree.n - len(asked) * tree.n_q and yes <= asked
        listed += len(tree.askable)
    assert listed > 3


def test_a_watch_pays_on_average_what_the_search_values_it():
    model = _model()
    for snap in _snapshots(SCENE1, 4, seed=3):
        search = WatchSearch(model, snap)
        _, watched, complete = search.run()
        tree = WatchSearch(model, snap).tree()
        assert complete and watched
        assert {tree.moves[w] for w in tree.watches} == set(watched)
        for w, payoff in tree.watches.items():
            assert payoff.shape == (len(snap.goals),) and not payoff.flags.writeable
            assert float(tree.b @ payoff) == pytest.approx(watched[tree.moves[w]], rel=1e-12, abs=1e-9)


def test_the_gate_s_closed_questions_are_not_open_in_the_tree():
    """A target the belief has all but ruled out is not worth asking about (``planner.question_gate``):
    the tree does not let the root ask it; without the gate it may."""
    goals = SharedAutonomyModel().initial_belief(SCENE1.goals).goals
    probs = np.where(goals.target_index == goals.targets.index("chips can:side"), 1e-6, 1.0)
    snap = Snapshot(goals, probs / probs.sum(), SCENE1.start, np.zeros(6), budget_s=None, user_speed=(0.03, 0.1))
    gated = WatchSearch(_model(), snap).tree()
    open_ = _model(planner={"question_gate": "none"})
    ungated = WatchSearch(open_, snap).tree()
    chips = [q for q, a in enumerate(gated.questions) if a.target == "chips can:side"]
    assert chips, "the chips can is among the questions"
    root = gated.open_questions(frozenset())
    assert chips[0] not in root
    assert chips[0] in ungated.open_questions(frozenset())
    assert len(root) < len(gated.questions)


def test_a_question_that_fills_the_horizon_ends_the_tree():
    model = _model(reward={"question_time_s": 5.0}, planner={"question_gate": "none"})
    snap = _snapshots(SCENE1, 1, seed=1)[0]
    tree = WatchSearch(model, snap).tree()
    assert tree.n == tree.n_q == 5
    assert tree.open_questions(frozenset()) == frozenset(range(len(tree.questions)))
    assert tree.open_questions(frozenset({(0, True)})) == frozenset()  # nothing after the answer
    assert np.allclose(tree.last_question, tree.question_cost + tree.value[:, 0, 0])


def test_the_tree_refuses_models_it_cannot_hold():
    snap = _snapshots(SCENE1, 1, seed=2)[0]
    with pytest.raises(ValueError, match="asking.third_answer"):
        WatchSearch(_model(asking={"third_answer": True}), snap).tree()
    with pytest.raises(ValueError, match="planner.root_goals"):
        WatchSearch(_model(planner={"root_goals": "top"}), snap).tree()


# -- the pomdp_py peer -------------------------------------------------------------------------------------


def test_pouct_planning_the_tree_finds_the_optimum_with_enough_simulations():
    pytest.importorskip("pomdp_py", reason="the pomdp_py peer needs the bench extra: pip install -e '.[bench]'")
    from sa_daemon.bench.peer import pouct_plan_watch

    model = _model()
    found, chose_watch = 0, 0
    snaps = _snapshots(SCENE1, 6, seed=11)
    for i, snap in enumerate(snaps):
        result = plan_watch(model, snap)
        tree = WatchSearch(model, snap).tree()
        action = pouct_plan_watch(tree, None, seed=i, sims=3000)
        assert action in result.root_values  # a root action of the same problem (a watch maps to its motion)
        found += result.root_values[action] >= result.value - 1e-6
        chose_watch += action in {tree.moves[w] for w in tree.watches}
    assert found >= len(snaps) - 1
    assert chose_watch  # watched motions are among the peer's actions


def test_pouct_needs_a_budget_or_a_number_of_simulations():
    pytest.importorskip("pomdp_py", reason="the pomdp_py peer needs the bench extra: pip install -e '.[bench]'")
    from sa_daemon.bench.peer import pouct_plan_watch

    tree = WatchSearch(_model(), _snapshots(SCENE1, 1, seed=5)[0]).tree()
    with pytest.raises(ValueError, match="budget_s"):
        pouct_plan_watch(tree, None)


def test_pouct_is_deterministic_for_a_seed_and_a_number_of_simulations():
    pytest.importorskip("pomdp_py", reason="the pomdp_py peer needs the bench extra: pip install -e '.[bench]'")
    from sa_daemon.bench.peer import pouct_plan_watch

    model = _model()
    tree = WatchSearch(model, _snapshots(SCENE1, 1, seed=5)[0]).tree()
    first = pouct_plan_watch(tree, None, seed=3, sims=300)
    assert all(pouct_plan_watch(tree, None, seed=3, sims=300) == first for _ in range(2))
