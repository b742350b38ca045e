"""How much the watch model expects the predicted input to tell (``planner.watch_evidence`` and
``planner.watch_copy_evidence``).

The watch predicts the input of a user heading exactly to each goal, and updates a branch's belief with
all of its MaxEnt IOC evidence. ``watch_evidence`` takes a share of that evidence (a noisier user);
``watch_copy_evidence`` takes a share of it *between the copies of one target* (resampled grasp poses,
III-G) while each target's mass is updated with all of it. Until session 31 both were 1; since then the
watch takes half the evidence (``watch_evidence = 0.5``), split between copies as the rest.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from test_watch_likelihood import TOP, split_cup
from test_watch_model import _reference_values

from sa_daemon.config import ConfigError, config_from_dict
from sa_daemon.geometry import Pose
from sa_daemon.model.actions import NO_ASSIST, Mode
from sa_daemon.model.model import SharedAutonomyModel
from sa_daemon.planner.snapshot import Snapshot
from sa_daemon.planner.watch import WatchSearch
from sa_daemon.planner.watched_beliefs import watched_beliefs
from sa_daemon.world.goals import Goal, GraspType
from sa_daemon.world.goalset import GoalSet

TARGETS = np.array([0, 0, 0, 1, 2, 2])
"""Six goals: target 0 held as three copies, target 1 as one, target 2 as two."""


def _problem(seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    b0 = rng.dirichlet(np.ones(len(TARGETS)))
    ll = rng.normal(scale=3.0, size=(4, len(TARGETS)))
    return b0, ll


def _mass(b: np.ndarray) -> np.ndarray:
    return np.stack([b[..., TARGETS == t].sum(axis=-1) for t in range(3)], axis=-1)


@pytest.mark.parametrize("seed", range(5))
def test_all_the_evidence_is_bayes_rule(seed):
    b0, ll = _problem(seed)
    bayes = b0 * np.exp(ll)
    np.testing.assert_allclose(watched_beliefs(b0, ll, TARGETS), bayes / bayes.sum(axis=1, keepdims=True),
                               rtol=1e-12)


@pytest.mark.parametrize("seed", range(5))
def test_a_share_of_the_evidence_is_bayes_rule_on_the_tempered_likelihood(seed):
    b0, ll = _problem(seed)
    np.testing.assert_allclose(watched_beliefs(b0, ll, TARGETS, evidence=0.3), watched_beliefs(b0, 0.3 * ll, TARGETS),
                               rtol=1e-12)
    np.testing.assert_allclose(watched_beliefs(b0, ll, TARGETS, evidence=0.0), np.tile(b0, (len(ll), 1)), rtol=1e-12)


@pytest.mark.parametrize("kappa", [0.0, 0.4])
@pytest.mark.parametrize("seed", range(5))
def test_copies_part_by_their_share_and_targets_keep_their_mass(seed, kappa):
    """Each target's mass is Bayes' rule's; within a target, two copies' odds move by ``kappa`` of their
    log-likelihood ratio (``kappa = 0``: the plan's split)."""
    b0, ll = _problem(seed)
    full = watched_beliefs(b0, ll, TARGETS)
    b = watched_beliefs(b0, ll, TARGETS, copy_evidence=kappa)
    np.testing.assert_allclose(b.sum(axis=1), 1.0, rtol=1e-12)
    np.testing.assert_allclose(_mass(b), _mass(full), rtol=1e-10)
    for g, h in ((0, 1), (1, 2), (4, 5)):
        odds = np.log(b[:, g] / b[:, h]) - np.log(b0[g] / b0[h])
        np.testing.assert_allclose(odds, kappa * (ll[:, g] - ll[:, h]), atol=1e-9)
    assert np.abs(b - full).max() > 1e-3  # the copies did part less


def test_goals_the_belief_rules_out_stay_out():
    b0, ll = _problem(0)
    b0[1] = 0.0
    b0 /= b0.sum()
    for kappa in (0.0, 0.5, 1.0):
        assert np.all(watched_beliefs(b0, ll, TARGETS, copy_evidence=kappa)[:, 1] == 0.0)


def _split_cup_snapshot() -> Snapshot:
    goals, probs = split_cup()
    return Snapshot(goals, probs, Pose.from_rpy([0.40, 0.05, 0.40], TOP), np.zeros(6), budget_s=None,
                    node_budget=400, user_speed=(0.06, 0.3))


def _cfg(**planner):
    return config_from_dict({"planner": {"threads": 1, **planner}}, "test")


def _assert_search_is_the_recursion(model: SharedAutonomyModel, snap: Snapshot) -> None:
    """The batched search, run to completion, gives every root action the plain recursion's value
    (``_reference_values``, tests/test_watch_model.py), with at least one motion watched."""
    values, watched, complete = WatchSearch(model, snap).run()
    ref_values, ref_watched = _reference_values(model, snap)
    assert complete and watched.keys() == ref_watched.keys() and watched
    for a, v in ref_values.items():
        assert values[a] == pytest.approx(v, rel=1e-9, abs=1e-6), a.label
    for a, v in ref_watched.items():
        assert watched[a] == pytest.approx(v, rel=1e-9, abs=1e-6), a.label


@pytest.mark.parametrize(("evidence", "kappa"), [(1.0, 0.0), (0.6, 0.5), (0.5, 1.0)])
def test_the_search_with_copies_equals_the_plain_recursion(evidence, kappa):
    """The cup held as two copies: the batched search's values equal the plain recursion's, which updates
    each branch's belief goal by goal (tests/test_watch_model.py)."""
    model = SharedAutonomyModel(_cfg(watch_evidence=evidence, watch_copy_evidence=kappa, max_questions=2))
    snap = _split_cup_snapshot()
    _assert_search_is_the_recursion(model, snap)


def test_watching_is_worth_less_when_the_copies_are_not_expected_to_part():
    """No-assist, watched for a second near the cup, earns its value from the input telling the copies
    apart; expecting less of that, it is worth less. The commits do not depend on the watch."""
    snap = _split_cup_snapshot()
    values = {k: WatchSearch(SharedAutonomyModel(_cfg(watch_copy_evidence=k)), snap).run() for k in (1.0, 0.0)}
    assert values[0.0][1][NO_ASSIST] < values[1.0][1][NO_ASSIST] - 1.0
    assert values[0.0][0] == values[1.0][0]


def _cup_top_or_side(mode: Mode) -> Snapshot:
    """The cup's top and side grasps at 0.45 / 0.45 (a bowl 0.1), the gripper 8 cm off, half turned
    between them: turning tells the two grasps apart, and so does translating."""
    c = np.array([0.45, 0.05, 0.25])
    goals = GoalSet((Goal("cup", GraspType.TOP, (Pose.from_rpy(c, TOP),)),
                     Goal("cup", GraspType.SIDE, (Pose.from_rpy(c + [-0.03, 0, 0], (math.pi / 2, 0, -math.pi / 2)),)),
                     Goal("bowl", GraspType.TOP, (Pose.from_rpy([0.38, 0.30, 0.23], TOP),))))
    return Snapshot(goals, np.array([0.45, 0.45, 0.1]), Pose.from_rpy(c + [-0.05, 0, 0.08], (3 * math.pi / 4, 0, -math.pi / 4)),
                    np.zeros(6), mode=mode, budget_s=None, node_budget=400, user_speed=(0.06, 0.3))


@pytest.mark.parametrize("mode", [Mode.TRANSLATION, Mode.ROTATION])
def test_the_search_with_a_rotation_share_equals_the_plain_recursion(mode):
    """``watch_evidence_rotation`` set: the batched search's values equal the plain recursion's, which
    takes the share by the snapshot's mode (tests/test_watch_model.py)."""
    model = SharedAutonomyModel(_cfg(watch_evidence_rotation=0.2, max_questions=2))
    snap = _cup_top_or_side(mode)
    _assert_search_is_the_recursion(model, snap)


@pytest.mark.parametrize("mode", [Mode.TRANSLATION, Mode.ROTATION])
def test_the_rotation_share_is_the_share_in_rotation_mode_only(mode):
    """``planner.watch_evidence_rotation``: in rotation mode the watch takes that share of the predicted
    evidence (the same values as ``watch_evidence`` set to it), in translation mode it changes nothing;
    unset, rotation takes ``watch_evidence``."""
    snap = _cup_top_or_side(mode)

    def watch(**planner):
        return WatchSearch(SharedAutonomyModel(_cfg(**planner)), snap).run()[1]

    rotation_share, same_share, default = watch(watch_evidence_rotation=0.0), watch(watch_evidence=0.0), watch()
    assert watch(watch_evidence_rotation=0.5) == default  # 0.5: watch_evidence's default
    if mode is Mode.ROTATION:
        assert rotation_share == same_share
        assert max(abs(rotation_share[a] - default[a]) for a in default) > 50.0
    else:
        assert rotation_share == default
        assert max(abs(same_share[a] - default[a]) for a in default) > 50.0


@pytest.mark.parametrize("key", ["watch_evidence", "watch_copy_evidence", "watch_evidence_rotation"])
@pytest.mark.parametrize("value", [-0.1, 1.5, "most"])
def test_a_share_outside_zero_to_one_is_refused_by_name(key, value):
    with pytest.raises(ConfigError, match=rf"planner\.{key}"):
        config_from_dict({"planner": {key: value}})
