"""Belief tracking (sections III-D, F, G) against hand computations.

Expected numbers are computed here with plain ``math`` from the published constants, never by calling the
function under test.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from helpers import PAPER_REACH

from sa_daemon.config import Config, IntentConfig
from sa_daemon.geometry import Pose
from sa_daemon.model.belief import Belief, cap_probabilities
from sa_daemon.model.huber import (
    huber_slope,
    huber_value,
    marginal_nll,
    q_minus_v,
    tracked_goal_poses,
)
from sa_daemon.world.goals import Goal, GraspType
from sa_daemon.world.goalset import GoalSet

TOP = (math.pi, 0.0, 0.0)
GRIPPER = Pose.from_rpy([0.30, 0.0, 0.20], TOP)
# The paper's reach (helpers.PAPER_REACH); the tests of the pose posterior kept through a resampling set
# their own.
INTENT = IntentConfig(step_cost="time", rationality=1.0, copy_weights="equal", **PAPER_REACH)  # Javdani's form, the paper's Fig. 2 copies
PATH = IntentConfig(step_cost="path", rationality=1.0, **PAPER_REACH)
MARGINAL = PATH.model_copy(update={"rationality": 10.0, "poses": "marginal"})
NEAREST = MARGINAL.model_copy(update={"poses": "nearest"})
T = 0.1  # ACTION_APPLY_TIME (s)


# -- hand versions of the published Huber value (translation: c 2.25, delta 0.07, a 0.2) ------------------


def v_trans(d: float) -> float:
    c, delta, a = 2.25, 0.07, 0.2
    return 0.5 * (c / delta) * d * d + a * d if d <= delta else (c + a) * d - c * delta / 2


def slope_trans(d: float) -> float:
    c, delta, a = 2.25, 0.07, 0.2
    return (c / delta) * d + a if d <= delta else c + a


ROT_SLOPE_AT_ZERO = 0.07 * 0.01  # weight * a of the rotation term


def hand_q_minus_v(gripper: list[float], goal: list[float], u_lin: list[float]) -> float:
    """Q - V for a pure-translation twist when gripper and goal orientations coincide."""
    d0 = math.dist(gripper, goal)
    moved = [x + v * T for x, v in zip(gripper, u_lin)]
    d1 = math.dist(moved, goal)
    cost = T * (slope_trans(d0) + ROT_SLOPE_AT_ZERO)
    return cost + v_trans(d1) - v_trans(d0)


def hand_q_minus_v_path(gripper: list[float], goal: list[float], u_lin: list[float]) -> float:
    """Q - V with the step's cost proportional to the distance it moves the gripper (``step_cost = "path"``)."""
    d0 = math.dist(gripper, goal)
    moved = [x + v * T for x, v in zip(gripper, u_lin)]
    cost = T * slope_trans(d0) * math.hypot(*u_lin)
    return cost + v_trans(math.dist(moved, goal)) - v_trans(d0)


def top_goal(obj: str, *positions) -> Goal:
    return Goal(obj, GraspType.TOP, tuple(Pose.from_rpy(p, TOP) for p in positions))


def offset(dx=0.0, dy=0.0, dz=0.0) -> list[float]:
    return [0.30 + dx, 0.0 + dy, 0.20 + dz]


# -- Huber value ----------------------------------------------------------------------------------------


@pytest.mark.parametrize("d", [0.0, 0.03, 0.07, 0.2])
def test_translation_huber_value_and_slope_by_hand(d):
    h = INTENT.translation
    assert float(huber_value(d, h)) == pytest.approx(v_trans(d), abs=1e-12)
    assert float(huber_slope(d, h)) == pytest.approx(slope_trans(d), abs=1e-12)


def test_huber_value_by_hand_literal_numbers():
    h = INTENT.translation
    # below delta: 0.5 * (2.25 / 0.07) * 0.03^2 + 0.2 * 0.03
    assert float(huber_value(0.03, h)) == pytest.approx(0.5 * 2.25 / 0.07 * 0.0009 + 0.006)
    # above delta: 2.45 * 0.2 - 2.25 * 0.07 / 2
    assert float(huber_value(0.2, h)) == pytest.approx(0.49 - 0.07875)
    assert float(huber_slope(0.2, h)) == pytest.approx(2.45)


def test_rotation_huber_is_weighted_by_0_07():
    h = INTENT.rotation
    c, delta, a, w = 0.20, math.pi / 32, 0.01, 0.07
    d_in, d_out = 0.05, 1.0
    assert float(huber_value(d_in, h)) == pytest.approx(w * (0.5 * c / delta * d_in**2 + a * d_in))
    assert float(huber_value(d_out, h)) == pytest.approx(w * ((c + a) * d_out - c * delta / 2))
    assert float(huber_slope(d_in, h)) == pytest.approx(w * (c / delta * d_in + a))
    assert float(huber_slope(d_out, h)) == pytest.approx(w * (c + a))


@pytest.mark.parametrize("which", ["translation", "rotation"])
def test_huber_value_and_slope_continuous_at_delta(which):
    h = getattr(INTENT, which)
    eps = 1e-9
    below, above = h.delta - eps, h.delta + eps
    assert float(huber_value(above, h)) - float(huber_value(below, h)) == pytest.approx(0.0, abs=1e-7)
    assert float(huber_slope(above, h)) == pytest.approx(float(huber_slope(below, h)), abs=1e-6)
    assert float(huber_slope(h.delta, h)) == pytest.approx(h.weight * (h.c + h.a))


# -- MaxEnt IOC likelihood ------------------------------------------------------------------------------


def one_goal_arrays(position) -> tuple[np.ndarray, np.ndarray]:
    pose = Pose.from_rpy(position, TOP)
    return pose.position.reshape(1, 1, 3), pose.quat_wxyz.reshape(1, 1, 4)


@pytest.mark.parametrize("dist", [0.05, 0.15])
def test_q_minus_v_toward_beats_away_and_matches_hand(dist):
    goal = offset(dx=dist)
    gp, gq = one_goal_arrays(goal)
    toward, away = [0.2, 0, 0], [-0.2, 0, 0]
    nll_toward = float(q_minus_v(GRIPPER.position, GRIPPER.quat_wxyz, np.r_[toward, 0, 0, 0], gp, gq, INTENT)[0])
    nll_away = float(q_minus_v(GRIPPER.position, GRIPPER.quat_wxyz, np.r_[away, 0, 0, 0], gp, gq, INTENT)[0])
    assert nll_toward == pytest.approx(hand_q_minus_v(offset(), goal, toward), abs=1e-12)
    assert nll_away == pytest.approx(hand_q_minus_v(offset(), goal, away), abs=1e-12)
    assert nll_toward < nll_away  # moving toward the goal is more likely (exp(-nll) larger)


def test_q_minus_v_uses_the_lowest_value_pose_of_a_goal():
    near, far = offset(dx=0.04), offset(dx=-0.3)
    g = top_goal("cup", far, near)
    gs = GoalSet((g,))
    u = [0.0, 0.1, 0.0]
    got = float(q_minus_v(GRIPPER.position, GRIPPER.quat_wxyz, np.r_[u, 0, 0, 0], gs.positions, gs.quats_wxyz, INTENT)[0])
    assert got == pytest.approx(hand_q_minus_v(offset(), near, u), abs=1e-12)


def _padded_case(form: str):
    """``(likelihood, config, tolerance, goal checked by hand, its value by hand)`` for
    :func:`test_the_likelihood_of_a_padded_goal_set_equals_each_goal_alone`."""
    if form == "nearest":  # the multi-pose goal takes its lowest-value pose
        return q_minus_v, INTENT, 1e-15, 0, hand_q_minus_v(offset(), offset(dy=0.06), [0.05, 0.1, 0.0])
    # marginal: a one-pose goal's marginal is beta (Q - V) of that pose
    return marginal_nll, MARGINAL, 1e-12, 1, 10.0 * hand_q_minus_v_path(offset(), offset(dx=0.08), [0.05, 0.1, 0.0])


@pytest.mark.parametrize("form", ["nearest", "marginal"])
def test_the_likelihood_of_a_padded_goal_set_equals_each_goal_alone(form):
    """Padding (poses far away) changes no goal's likelihood, nearest pose or marginalised."""
    likelihood, cfg, tol, checked, by_hand = _padded_case(form)
    multi = top_goal("cup", offset(dx=-0.2), offset(dy=0.06), offset(dz=0.3))
    single = top_goal("bowl", offset(dx=0.08))
    gs = GoalSet((multi, single))  # padded to 3 poses per goal
    u = np.array([0.05, 0.1, 0.0, 0.0, 0.0, 0.0])
    both = likelihood(GRIPPER.position, GRIPPER.quat_wxyz, u, gs.positions, gs.quats_wxyz, cfg)
    for i, g in enumerate((multi, single)):
        alone = GoalSet((g,))
        got = likelihood(GRIPPER.position, GRIPPER.quat_wxyz, u, alone.positions, alone.quats_wxyz, cfg)
        assert both[i] == pytest.approx(float(got[0]), abs=tol)
    assert both[checked] == pytest.approx(by_hand, abs=1e-12)


def two_goal_belief(probs=(0.5, 0.5), second=None) -> tuple[Belief, list[list[float]]]:
    """Goals at 0.10 m along x and (by default) 0.05 m along y from the gripper."""
    positions = [offset(dx=0.10), second or offset(dy=0.05)]
    gs = GoalSet((top_goal("cup", positions[0]), top_goal("bowl", positions[1])))
    return Belief.from_probs(gs, np.array(probs)), positions


def hand_update(prior: list[float], nll: list[float]) -> list[float]:
    w = [p * math.exp(-n) for p, n in zip(prior, nll)]
    s = sum(w)
    return [x / s for x in w]


@pytest.mark.parametrize("u_lin", [[0.2, 0.0, 0.0], [0.0, 0.2, 0.0], [-0.1, 0.05, 0.1]])
def test_maxent_update_of_two_goals_matches_hand(u_lin):
    prior = [0.3, 0.7]
    b, positions = two_goal_belief(prior)
    nll = [hand_q_minus_v(offset(), g, u_lin) for g in positions]
    want = hand_update(prior, nll)
    got = b.after_input(GRIPPER, np.r_[u_lin, 0, 0, 0], INTENT)
    np.testing.assert_allclose(got.probs, want, atol=1e-12)


def test_input_toward_a_goal_raises_its_probability():
    b, _ = two_goal_belief(second=offset(dy=0.10))  # equidistant goals
    toward_first = b.after_input(GRIPPER, np.array([0.2, 0, 0, 0, 0, 0]), INTENT)
    toward_second = b.after_input(GRIPPER, np.array([0, 0.2, 0, 0, 0, 0]), INTENT)
    assert toward_first.probs[0] > 0.5 > toward_second.probs[0]


def test_zero_input_still_updates_by_the_step_cost():
    b, positions = two_goal_belief()
    got = b.after_input(GRIPPER, np.zeros(6), INTENT)
    nll = [hand_q_minus_v(offset(), g, [0, 0, 0]) for g in positions]
    want = hand_update([0.5, 0.5], nll)
    assert not np.allclose(got.probs, [0.5, 0.5])
    np.testing.assert_allclose(got.probs, want, atol=1e-12)
    assert got.probs[1] > got.probs[0]  # the nearer goal (smaller slope) gains


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_user_twist_is_refused_and_belief_unchanged(bad):
    b, _ = two_goal_belief((0.3, 0.7))
    before = b.log_p.copy()
    u = np.array([0.1, 0.0, bad, 0.0, 0.0, 0.0])
    with pytest.raises(ValueError):
        b.after_input(GRIPPER, u, INTENT)
    np.testing.assert_array_equal(b.log_p, before)
    np.testing.assert_allclose(b.probs, [0.3, 0.7])


def test_wrong_shape_user_twist_is_refused():
    b, _ = two_goal_belief()
    with pytest.raises(ValueError):
        b.after_input(GRIPPER, np.zeros(3), INTENT)


# -- cap ------------------------------------------------------------------------------------------------


def test_cap_spreads_excess_only_over_the_goals_given():
    p = cap_probabilities(np.array([0.995, 0.001, 0.002, 0.002]), 0.99, np.array([True, False, True, True]))
    assert p == pytest.approx([0.99, 0.001, 0.0045, 0.0045])


def test_cap_spreads_excess_equally():
    got = cap_probabilities(np.array([0.995, 0.003, 0.002]), 0.99)
    excess = 0.995 - 0.99
    np.testing.assert_allclose(got, [0.99, 0.003 + excess / 2, 0.002 + excess / 2], atol=1e-15)
    np.testing.assert_allclose(cap_probabilities(np.array([0.5, 0.5]), 0.99), [0.5, 0.5])


def test_repeated_input_never_exceeds_the_cap():
    b, _ = two_goal_belief(second=offset(dy=0.10))
    for _ in range(300):
        b = b.after_input(GRIPPER, np.array([0.2, 0, 0, 0, 0, 0]), INTENT)
    assert b.probs.max() == pytest.approx(0.99, abs=1e-12)
    assert b.probs.sum() == pytest.approx(1.0)


def test_answer_yes_capped_at_0_99_with_excess_spread():
    gs = GoalSet((top_goal("a", offset()), top_goal("b", offset(0.1)), top_goal("c", offset(0.2))))
    b = Belief.uniform(gs).after_answer("a:top", True, INTENT)
    raw_a = 0.999 / (0.999 + 2 * 0.001)
    raw_other = 0.001 / (0.999 + 2 * 0.001)
    excess = raw_a - 0.99
    np.testing.assert_allclose(b.probs, [0.99, raw_other + excess / 2, raw_other + excess / 2], atol=1e-12)


# -- answers --------------------------------------------------------------------------------------------


def four_targets() -> GoalSet:
    return GoalSet(tuple(top_goal(n, offset(dx=0.05 * i)) for i, n in enumerate("abcd")))


def test_answer_yes_by_hand():
    prior = [0.01, 0.33, 0.33, 0.33]
    b = Belief.from_probs(four_targets(), np.array(prior)).after_answer("a:top", True, INTENT)
    w = [prior[0] * 0.999] + [p * 0.001 for p in prior[1:]]
    np.testing.assert_allclose(b.probs, [x / sum(w) for x in w], atol=1e-12)


def test_answer_no_by_hand():
    b = Belief.uniform(four_targets()).after_answer("b:top", False, INTENT)
    w = [0.25 * 0.999, 0.25 * 0.001, 0.25 * 0.999, 0.25 * 0.999]
    np.testing.assert_allclose(b.probs, [x / sum(w) for x in w], atol=1e-12)


def test_answer_about_a_target_with_several_copies_moves_all_copies():
    a = top_goal("cup", offset(dx=0.05), offset(dx=0.08))
    others = (top_goal("bowl", offset(dy=0.1)), top_goal("plate", offset(dy=-0.1)))
    gs = GoalSet((a.with_poses(a.poses[:1]), a.with_poses(a.poses[1:])) + others)
    prior = [0.2, 0.2, 0.3, 0.3]
    yes = Belief.from_probs(gs, np.array(prior)).after_answer("cup:top", True, INTENT)
    w = [0.2 * 0.999, 0.2 * 0.999, 0.3 * 0.001, 0.3 * 0.001]
    np.testing.assert_allclose(yes.probs, [x / sum(w) for x in w], atol=1e-12)
    assert yes.target_probabilities()["cup:top"] == pytest.approx(0.4 * 0.999 / (0.4 * 0.999 + 0.6 * 0.001))
    no = Belief.from_probs(gs, np.array(prior)).after_answer("cup:top", False, INTENT)
    w = [0.2 * 0.001, 0.2 * 0.001, 0.3 * 0.999, 0.3 * 0.999]
    np.testing.assert_allclose(no.probs, [x / sum(w) for x in w], atol=1e-12)


def test_a_surprising_no_mixes_the_open_targets_toward_uniform_by_hand():
    """``intent.reading_trust`` 0.9: a "no" to the target the belief held at 0.7 leaves the input's reading
    sound with posterior 0.9 * 0.3 / (0.9 * 0.3 + 0.1 * 0.75), and the three open targets' mass is dealt
    that share as it was and the rest equally."""
    prior = [0.7, 0.2, 0.06, 0.04]
    doubt = INTENT.model_copy(update={"reading_trust": 0.9})
    b = Belief.from_probs(four_targets(), np.array(prior)).after_answer("a:top", False, doubt)
    w = [prior[0] * 0.001] + [p * 0.999 for p in prior[1:]]
    bayes = [x / sum(w) for x in w]
    trust = 0.9 * 0.3 / (0.9 * 0.3 + 0.1 * (1 - 1 / 4))
    rest = sum(bayes[1:])
    np.testing.assert_allclose(b.probs, [bayes[0]] + [trust * q + (1 - trust) * rest / 3 for q in bayes[1:]],
                               atol=1e-12)
    assert b.ruled_out == {"a:top"}
    # the default trusts the reading: the plain Bayes update
    plain = Belief.from_probs(four_targets(), np.array(prior)).after_answer("a:top", False, INTENT)
    np.testing.assert_allclose(plain.probs, bayes, atol=1e-12)


def test_the_likelier_the_denied_target_the_more_the_reading_is_doubted():
    """Each open target's share of the open mass moves toward uniform by ``1 - trust``, the posterior doubt:
    0.22 after a "no" to the target held at 0.7, 0.08 after one to the target held at 0.04."""
    doubt = INTENT.model_copy(update={"reading_trust": 0.9})
    prior = np.array([0.7, 0.2, 0.06, 0.04])
    for denied, watched, b_t in (("a:top", 1, 0.7), ("d:top", 0, 0.04)):
        plain = Belief.from_probs(four_targets(), prior).after_answer(denied, False, INTENT).probs
        mixed = Belief.from_probs(four_targets(), prior).after_answer(denied, False, doubt).probs
        open_ = [k for k in range(4) if "abcd"[k] != denied[0]]
        share_plain = plain[watched] / plain[open_].sum()
        share_mixed = mixed[watched] / mixed[open_].sum()
        trust = 0.9 * (1 - b_t) / (0.9 * (1 - b_t) + 0.1 * 0.75)
        assert (share_plain - share_mixed) / (share_plain - 1 / 3) == pytest.approx(1 - trust, rel=1e-9)


def test_a_doubted_no_leaves_denied_targets_and_a_yes_alone():
    doubt = INTENT.model_copy(update={"reading_trust": 0.5})
    first = Belief.from_probs(four_targets(), np.array([0.1, 0.6, 0.2, 0.1])).after_answer("a:top", False, doubt)
    second = first.after_answer("b:top", False, doubt).probs
    # by hand: Bayes for "no" to b, then only c and d (open, not b) mixed; a, denied before, keeps its share
    q = first.probs
    w = [q[0] * 0.999, q[1] * 0.001, q[2] * 0.999, q[3] * 0.999]
    bayes = [x / sum(w) for x in w]
    trust = 0.5 * (1 - q[1]) / (0.5 * (1 - q[1]) + 0.5 * (1 - 1 / 3))  # b, c, d open before the answer
    rest = bayes[2] + bayes[3]
    np.testing.assert_allclose(second, [bayes[0], bayes[1]] + [trust * x + (1 - trust) * rest / 2 for x in bayes[2:]],
                               atol=1e-12)
    confirmed = Belief.from_probs(four_targets(), np.array([0.1, 0.6, 0.2, 0.1])).after_answer("b:top", True, doubt)
    after = confirmed.after_answer("c:top", False, doubt)
    plain = confirmed.after_answer("c:top", False, INTENT)
    np.testing.assert_allclose(after.probs, plain.probs, atol=1e-15)  # after a yes the reading is not doubted


def test_answer_about_unknown_target_is_refused():
    with pytest.raises(ValueError):
        Belief.uniform(four_targets()).after_answer("spoon:top", True, INTENT)


# -- resampling and redistribution ----------------------------------------------------------------------

# Target "a" has four grasp poses at 0.05, 0.02, 0.08 and 0.11 m from the gripper (same orientation), so
# the closeness order of its pose indices is 1, 0, 2, 3.
A_POSES = [offset(dx=0.05), offset(dx=0.02), offset(dx=0.08), offset(dx=0.11)]


def scene_with_multi_pose_target() -> GoalSet:
    return GoalSet(
        (
            top_goal("a", *A_POSES),
            top_goal("b", offset(dy=0.1)),
            top_goal("c", offset(dy=-0.1)),
            top_goal("d", offset(dz=0.1)),
        )
    )


def n_eff(p) -> float:
    return 1.0 / sum(x * x for x in p)


def test_resampling_allocates_copies_and_redistributes_poses_by_distance():
    probs = [0.8, 0.1, 0.05, 0.05]
    assert n_eff(probs) < 4 / 2
    b = Belief.from_probs(scene_with_multi_pose_target(), np.array(probs))
    r = b.resampled(GRIPPER, INTENT)
    # allocation: clip(round(p * 4), 1, K): a -> round(3.2) = 3, the others round(<= 0.4) = 0 -> 1
    assert [g.target for g in r.goals.goals] == ["a:top"] * 3 + ["b:top", "c:top", "d:top"]
    copies = r.goals.goals[:3]
    owned = [[list(p.position) for p in g.poses] for g in copies]
    np.testing.assert_allclose(owned[0], [A_POSES[1]])  # closest
    np.testing.assert_allclose(owned[1], [A_POSES[0]])  # second closest
    np.testing.assert_allclose(owned[2], [A_POSES[2], A_POSES[3]])  # the last copy owns the rest
    np.testing.assert_allclose(r.probs, [0.8 / 3] * 3 + [0.1, 0.05, 0.05], atol=1e-12)


def test_resampled_copies_have_distinct_desired_poses():
    b = Belief.from_probs(scene_with_multi_pose_target(), np.array([0.8, 0.1, 0.05, 0.05]))
    r = b.resampled(GRIPPER, INTENT)
    kp, _ = r.goals.desired_poses(GRIPPER, INTENT.rotation_weight_m_per_rad)
    copies = kp[:3]
    assert len({tuple(np.round(p, 9)) for p in copies}) == 3


def test_resampling_preserves_target_marginals_and_keeps_every_target():
    probs = [0.9, 0.002, 0.05, 0.048]
    b = Belief.from_probs(scene_with_multi_pose_target(), np.array(probs))
    r = b.resampled(GRIPPER, INTENT)
    assert r is not b
    before, after = b.target_probabilities(), r.target_probabilities()
    assert set(after) == set(before) == {"a:top", "b:top", "c:top", "d:top"}
    for t in before:
        assert after[t] == pytest.approx(before[t], abs=1e-15)


def _target_nll(belief: Belief, target: str, u: np.ndarray, cfg: IntentConfig) -> float:
    """``-log P(u | target)`` of one input at the gripper, the target's copies mixed by their probabilities."""
    nll = marginal_nll(GRIPPER.position, GRIPPER.quat_wxyz, u, belief.goals.positions, belief.goals.quats_wxyz, cfg)
    m = belief.goals.target_mask(target)
    return float(-(np.logaddexp.reduce(belief.log_p[m] - nll[m]) - np.logaddexp.reduce(belief.log_p[m])))


@pytest.mark.parametrize("u", [[0.1, 0.0, 0.0, 0, 0, 0], [0.0, -0.1, 0.02, 0, 0, 0], [-0.1, 0.0, 0.0, 0, 0, 0]])
def test_copies_weighted_by_their_poses_read_the_next_input_as_the_target_did(u):
    """``intent.copy_weights = "poses"``: each copy resampling makes gets its share of the target's pose
    weights ``exp(-V)`` at the gripper, so the marginal tracker reads the next input at that pose exactly
    as it read it before the split (the target's likelihood is a mixture over its poses either way). With
    equal shares (the paper's reading of III-G) copies holding unlikely poses get as much as the others
    and the likelihood changes: a target split that way loses probability it had not lost."""
    u = np.array(u, dtype=float)
    cfg = MARGINAL.model_copy(update={"rotation_rationality": 200.0})
    b = Belief.from_probs(scene_with_multi_pose_target(), np.array([0.8, 0.1, 0.05, 0.05]))
    for weights, same in (("poses", True), ("equal", False)):
        c = cfg.model_copy(update={"copy_weights": weights})
        r = b.resampled(GRIPPER, c)
        assert [g.target for g in r.goals.goals].count("a:top") == 3
        assert r.target_probabilities()["a:top"] == pytest.approx(0.8, abs=1e-12)
        before, after = _target_nll(b, "a:top", u, c), _target_nll(r, "a:top", u, c)
        if same:
            assert after == pytest.approx(before, abs=1e-12)
        else:
            assert abs(after - before) > 1e-3


def test_allocation_is_clipped_by_the_number_of_grasp_poses():
    two_pose = top_goal("a", offset(dx=0.03), offset(dx=0.06))
    gs = GoalSet((two_pose, top_goal("b", offset(dy=0.1)), top_goal("c", offset(dy=-0.1)), top_goal("d", offset(dz=0.1))))
    b = Belief.from_probs(gs, np.array([0.9, 0.04, 0.03, 0.03]))  # round(3.6) = 4 > K = 2
    r = b.resampled(GRIPPER, INTENT)
    assert [g.target for g in r.goals.goals].count("a:top") == 2
    assert [len(g.poses) for g in r.goals.goals[:2]] == [1, 1]


def test_resampling_trigger_requires_n_eff_below_half_the_goals():
    gs = scene_with_multi_pose_target()
    # Both beliefs would change the allocation of "a" (round(1.8) = 2 and round(2.8) = 3).
    above = [0.45, 0.35, 0.1, 0.1]
    below = [0.7, 0.1, 0.1, 0.1]
    assert n_eff(above) >= 2 > n_eff(below)
    b_above = Belief.from_probs(gs, np.array(above))
    assert b_above.resampled(GRIPPER, INTENT) is b_above
    b_below = Belief.from_probs(gs, np.array(below))
    assert len(b_below.resampled(GRIPPER, INTENT).goals) == 6


def test_trigger_near_the_boundary():
    gs = scene_with_multi_pose_target()
    # p = [x, y, y, y]: sum p^2 just below / just above 0.5 (N_eff just above / below 2); a gets 3 copies.
    def probs_with_sum_sq(s):
        # solve x^2 + 3 y^2 = s, x + 3 y = 1 for the larger x
        y = (6 - math.sqrt(36 - 48 * (1 - s))) / 24
        return [1 - 3 * y, y, y, y]

    just_above = probs_with_sum_sq(0.499)
    just_below = probs_with_sum_sq(0.501)
    assert n_eff(just_above) > 2 > n_eff(just_below)
    assert round(just_above[0] * 4) == round(just_below[0] * 4) == 3
    b = Belief.from_probs(gs, np.array(just_above))
    assert b.resampled(GRIPPER, INTENT) is b
    assert len(Belief.from_probs(gs, np.array(just_below)).resampled(GRIPPER, INTENT).goals) == 6


def test_no_resampling_when_the_allocation_would_not_change():
    # Single-pose targets: K_T = 1 caps every allocation at 1, so however skewed, nothing changes.
    b = Belief.from_probs(four_targets(), np.array([0.97, 0.01, 0.01, 0.01]))
    assert b.n_eff < 2
    assert b.resampled(GRIPPER, INTENT) is b
    # An already resampled belief with the same target probabilities is left alone too.
    r = Belief.from_probs(scene_with_multi_pose_target(), np.array([0.8, 0.1, 0.05, 0.05])).resampled(GRIPPER, INTENT)
    assert r.resampled(GRIPPER, INTENT) is r


def test_resampling_disabled_by_config():
    b = Belief.from_probs(scene_with_multi_pose_target(), np.array([0.8, 0.1, 0.05, 0.05]))
    cfg = IntentConfig(resample=False)
    assert b.resampled(GRIPPER, cfg) is b


def test_second_resampling_pools_the_copies_poses():
    b = Belief.from_probs(scene_with_multi_pose_target(), np.array([0.8, 0.1, 0.05, 0.05]))
    r = b.resampled(GRIPPER, INTENT)  # a: 3 copies
    # input has since favoured one copy: N_eff = 1 / 0.5336 < 6 / 2, and a now gets round(3.8) = 4 copies
    probs = np.array([0.7, 0.2, 0.05, 0.03, 0.01, 0.01])
    assert n_eff(probs) < 3
    r2 = Belief.from_probs(r.goals, probs).resampled(GRIPPER, INTENT)
    a_copies = [g for g in r2.goals.goals if g.target == "a:top"]
    assert [len(g.poses) for g in a_copies] == [1, 1, 1, 1]
    got = sorted(tuple(np.round(g.poses[0].position, 9)) for g in a_copies)
    assert got == sorted(tuple(np.round(p, 9)) for p in A_POSES)


def test_paper_fig2_example():
    # Four targets with five grasp poses each; target 2 dominates.
    gs = GoalSet(
        tuple(
            top_goal(f"obj{i}", *[offset(dx=0.03 * (i + 1), dy=0.02 * k) for k in range(5)])
            for i in range(1, 5)
        )
    )
    probs = [0.03, 0.70, 0.02, 0.25]
    assert n_eff(probs) < 2
    r = Belief.from_probs(gs, np.array(probs)).resampled(GRIPPER, INTENT)
    targets = [g.target for g in r.goals.goals]
    assert targets.count("obj2:top") == 3
    assert targets.count("obj4:top") == 1  # round(1.0)
    assert set(targets) == {"obj1:top", "obj2:top", "obj3:top", "obj4:top"}  # nothing thrown away
    copies = [g for g in r.goals.goals if g.target == "obj2:top"]
    assert [len(g.poses) for g in copies] == [1, 1, 3]
    for g, p in zip(r.goals.goals, r.probs):
        if g.target == "obj2:top":
            assert p == pytest.approx(0.70 / 3, abs=1e-12)
    # the copies' poses are the 1st, 2nd and the rest of the closest to the gripper (dy = 0, 0.02, ...)
    dists = [min(math.dist(offset(), list(q.position)) for q in g.poses) for g in copies]
    assert dists == sorted(dists)


def test_model_update_input_resamples_when_due():
    from sa_daemon.model.model import SharedAutonomyModel

    model = SharedAutonomyModel(Config())
    b = Belief.from_probs(scene_with_multi_pose_target(), np.array([0.8, 0.1, 0.05, 0.05]))
    nb = model.update_input(b, GRIPPER, np.zeros(6))
    assert len(nb.goals) == 6


# -- a "yes" answer fixes the high-level target (section III-B) ----------------------------------------


def _toward(pose, goal, speed=0.2):
    d = goal.positions[0] - pose.position
    return np.concatenate((speed * d / np.linalg.norm(d), np.zeros(3)))


def test_yes_confirms_the_target_against_later_joystick_evidence(scene, start_pose, cfg):
    b = Belief.uniform(scene).after_answer("cup:side", True, cfg.intent)
    assert b.confirmed == "cup:side"
    before = b.target_probabilities()["cup:side"]
    u = _toward(start_pose, scene.goals[3])  # straight at the bowl
    for _ in range(200):
        b = b.after_input(start_pose, u, cfg.intent)
    assert b.target_probabilities()["cup:side"] == pytest.approx(before, abs=1e-12)


def test_without_confirmation_the_same_evidence_moves_the_target(scene, start_pose, cfg):
    b = Belief.uniform(scene).after_answer("cup:side", False, cfg.intent)  # "no" confirms nothing
    assert b.confirmed is None
    u = _toward(start_pose, scene.goals[3])
    before = b.target_probabilities()["bowl:top"]
    for _ in range(50):
        b = b.after_input(start_pose, u, cfg.intent)
    assert b.target_probabilities()["bowl:top"] > before + 0.1


def test_confirmed_target_copies_still_compete(make_goal, start_pose, cfg):
    left = make_goal("cup", "top", [0.45, 0.20, 0.09])
    right = make_goal("cup", "top", [0.45, -0.20, 0.09])
    other = make_goal("bowl", "top", [0.30, 0.0, 0.06])
    b = Belief.uniform(GoalSet((left, right, other))).after_answer("cup:top", True, cfg.intent)
    total = b.target_probabilities()["cup:top"]
    u = _toward(start_pose, left)
    for _ in range(40):
        b = b.after_input(start_pose, u, cfg.intent)
    assert b.probs[0] > b.probs[1] + 0.2  # the copy the user heads for wins
    assert b.target_probabilities()["cup:top"] == pytest.approx(total, abs=1e-12)


def test_confirmation_survives_resampling(make_goal, start_pose, cfg):
    poses = [[0.45, y, 0.09] for y in (0.10, 0.12, 0.14, 0.16)]
    cup = make_goal("cup", "top", *poses)
    others = [make_goal(o, "top", [0.3, y, 0.06]) for o, y in (("bowl", -0.2), ("plate", -0.3), ("box", 0.3))]
    goals = GoalSet((cup, *others))
    b = Belief.uniform(goals).after_answer("cup:top", True, cfg.intent)
    r = b.resampled(start_pose, cfg.intent)
    assert len(r.goals) > len(b.goals)  # copies were made
    assert r.confirmed == "cup:top"


# -- a "no" answer is final too: the denied target's share stays where the answer put it -------------------


def test_no_keeps_the_denied_target_down_against_joystick_evidence(scene, start_pose, cfg):
    b = Belief.uniform(scene).after_answer("bowl:top", False, cfg.intent)
    assert b.ruled_out == frozenset({"bowl:top"})
    denied = b.target_probabilities()["bowl:top"]
    assert denied < 0.002
    u = _toward(start_pose, scene.goals[3])  # straight at the bowl the user said no to
    for _ in range(400):
        b = b.after_input(start_pose, u, cfg.intent)
    assert b.target_probabilities()["bowl:top"] == pytest.approx(denied, rel=1e-9)


def test_without_the_answer_the_same_evidence_brings_the_target_up(scene, start_pose, cfg):
    b = Belief.from_probs(scene, np.array([0.333, 0.333, 0.333, 0.001]))
    u = _toward(start_pose, scene.goals[3])
    for _ in range(400):
        b = b.after_input(start_pose, u, cfg.intent)
    assert b.target_probabilities()["bowl:top"] > 0.05  # 50x up: what the "no" prevents above


def test_after_a_no_the_other_targets_still_compete(scene, start_pose, cfg):
    b = Belief.uniform(scene).after_answer("cup:side", False, cfg.intent)
    before = b.target_probabilities()
    u = _toward(start_pose, scene.goals[3])
    for _ in range(50):
        b = b.after_input(start_pose, u, cfg.intent)
    after = b.target_probabilities()
    assert after["bowl:top"] > before["bowl:top"] + 0.1
    assert after["cup:side"] == pytest.approx(before["cup:side"], rel=1e-9)


def test_answers_accumulate_and_survive_resampling(make_goal, start_pose, cfg):
    poses = [[0.45, y, 0.09] for y in (0.10, 0.12, 0.14, 0.16)]
    cup = make_goal("cup", "top", *poses)
    others = [make_goal(o, "top", [0.3, y, 0.06]) for o, y in (("bowl", -0.2), ("plate", -0.3), ("box", 0.3))]
    b = Belief.uniform(GoalSet((cup, *others)))
    b = b.after_answer("bowl:top", False, cfg.intent).after_answer("plate:top", False, cfg.intent)
    assert b.ruled_out == frozenset({"bowl:top", "plate:top"})
    b = b.after_answer("cup:top", True, cfg.intent)
    r = b.resampled(start_pose, cfg.intent)
    assert len(r.goals) > len(b.goals)  # copies were made
    assert (r.confirmed, r.ruled_out) == ("cup:top", frozenset({"bowl:top", "plate:top"}))


def test_every_target_denied_falls_back_to_the_joystick(scene, start_pose, cfg):
    b = Belief.uniform(scene)
    for t in ("cup:top", "cup:side", "chips_can:side", "bowl:top"):  # one answer must have been wrong
        b = b.after_answer(t, False, cfg.intent)
    before = b.target_probabilities()["bowl:top"]
    u = _toward(start_pose, scene.goals[3])
    for _ in range(50):
        b = b.after_input(start_pose, u, cfg.intent)
    assert b.target_probabilities()["bowl:top"] > before + 0.1


# -- the path form of the step cost and the rationality (docs/model.md, "The tracker") -------------------


@pytest.mark.parametrize("u_lin", [[0.2, 0.0, 0.0], [-0.2, 0.0, 0.0], [0.03, -0.05, 0.01]])
@pytest.mark.parametrize("dist", [0.05, 0.15])
def test_path_cost_q_minus_v_matches_hand(u_lin, dist):
    goal = offset(dx=dist)
    gp, gq = one_goal_arrays(goal)
    got = float(q_minus_v(GRIPPER.position, GRIPPER.quat_wxyz, np.r_[u_lin, 0, 0, 0], gp, gq, PATH)[0])
    assert got == pytest.approx(hand_q_minus_v_path(offset(), goal, u_lin), abs=1e-12)


def test_path_cost_a_step_straight_at_a_far_goal_costs_nothing_and_stillness_tells_nothing():
    gp, gq = one_goal_arrays(offset(dx=0.30))  # in Huber's linear region the whole way
    straight = float(q_minus_v(GRIPPER.position, GRIPPER.quat_wxyz, np.r_[0.05, 0, 0, 0, 0, 0], gp, gq, PATH)[0])
    sideways = float(q_minus_v(GRIPPER.position, GRIPPER.quat_wxyz, np.r_[0, 0.05, 0, 0, 0, 0], gp, gq, PATH)[0])
    assert straight == pytest.approx(0.0, abs=1e-12)
    assert sideways > 1e-3
    b, _ = two_goal_belief((0.3, 0.7))
    np.testing.assert_allclose(b.after_input(GRIPPER, np.zeros(6), PATH).probs, [0.3, 0.7], atol=1e-15)


def test_path_cost_evidence_grows_with_speed_the_time_form_does_not():
    """A slow user pointing at a goal: the path form's log-odds scale with the speed; the time form's
    constant step cost dominates and favours the nearer goal whatever the direction (the misreading
    ``docs/model.md`` measures on Scene 1's ``cup:side``)."""
    b, _ = two_goal_belief(second=offset(dy=0.04))  # the second goal nearer
    log_odds = {}
    for form, cfg in (("path", PATH), ("time", INTENT)):
        for speed in (0.01, 0.05):
            p = b.after_input(GRIPPER, np.array([speed, 0, 0, 0, 0, 0]), cfg).probs  # toward the first goal
            log_odds[form, speed] = math.log(p[0] / p[1])
    assert log_odds["path", 0.05] == pytest.approx(5 * log_odds["path", 0.01], rel=0.05)
    assert log_odds["path", 0.01] > 0  # pointing at the first goal favours it
    assert log_odds["time", 0.01] < 0  # the time form favours the nearer goal even so


@pytest.mark.parametrize("beta", [0.5, 10.0])
def test_rationality_multiplies_the_log_odds_of_an_input(beta):
    b, positions = two_goal_belief()
    u = [0.03, 0.02, 0.0]
    nll = [beta * hand_q_minus_v_path(offset(), g, u) for g in positions]
    got = b.after_input(GRIPPER, np.r_[u, 0, 0, 0], PATH.model_copy(update={"rationality": beta}))
    np.testing.assert_allclose(got.probs, hand_update([0.5, 0.5], nll), atol=1e-12)


def v_rot(d: float) -> float:
    """The published rotation Huber value (c 0.20, delta pi/32, a 0.01, weight 0.07)."""
    c, delta, a = 0.20, math.pi / 32, 0.01
    return 0.07 * (0.5 * (c / delta) * d * d + a * d if d <= delta else (c + a) * d - c * delta / 2)


@pytest.mark.parametrize("rotation_beta", [1.0, 50.0])
def test_rotation_rationality_weighs_rotation_input_alone(rotation_beta):
    """``intent.rotation_rationality`` is the MaxEnt IOC ``beta`` of rotation-mode input and
    ``rationality`` that of translation: two grasps at the gripper's position, 0.5 rad either way about
    the base z axis; one sample turning 0.3 rad/s toward the first gives log-odds ``beta_r (Q_B - V_B)``
    by hand (the first's ``Q - V`` is 0: a turn straight at it in Huber's linear zone), and a translation
    sample's log-odds do not depend on ``beta_r``."""
    cfg = PATH.model_copy(update={"rotation_rationality": rotation_beta})
    pos = [0.30, 0.0, 0.20]
    turned = [Goal("cup", GraspType.TOP, (Pose.from_rpy(pos, (math.pi, 0.0, yaw)),)) for yaw in (0.5, -0.5)]
    b = Belief.from_probs(GoalSet(tuple(turned)), np.array([0.5, 0.5]))
    w = 0.3
    nll_b = T * (0.07 * 0.21) * w + v_rot(0.5 + w * T) - v_rot(0.5)
    got = b.after_input(GRIPPER, np.array([0, 0, 0, 0, 0, w]), cfg).probs
    assert math.log(got[0] / got[1]) == pytest.approx(rotation_beta * nll_b, rel=1e-9)
    b2, positions = two_goal_belief()
    u = [0.03, 0.02, 0.0]
    nll = [hand_q_minus_v_path(offset(), g, u) for g in positions]
    np.testing.assert_allclose(b2.after_input(GRIPPER, np.r_[u, 0, 0, 0], cfg).probs, hand_update([0.5, 0.5], nll),
                               atol=1e-12)


# -- a goal's poses marginalised (intent.poses = "marginal"; docs/model.md, "The tracker") ------------------


def hand_marginal(gripper: list[float], poses: list[list[float]], u_lin: list[float], beta: float) -> float:
    """``-log sum_k w_k exp(-beta (Q_k - V_k))``, ``w_k ~ exp(-beta V_k)``, for a pure-translation input and
    grasps at the gripper's orientation (their rotation terms are zero)."""
    w = [math.exp(-beta * v_trans(math.dist(gripper, p))) for p in poses]
    terms = [wk / sum(w) * math.exp(-beta * hand_q_minus_v_path(gripper, p, u_lin)) for wk, p in zip(w, poses)]
    return -math.log(sum(terms))


@pytest.mark.parametrize("u_lin", [[0.0, 0.1, 0.0], [0.0, -0.1, 0.0], [0.05, 0.02, -0.03]])
def test_marginal_likelihood_matches_hand(u_lin):
    poses = [offset(dy=-0.05), offset(dy=0.05), offset(dx=0.2)]
    gs = GoalSet((top_goal("cup", *poses),))
    got = marginal_nll(GRIPPER.position, GRIPPER.quat_wxyz, np.r_[u_lin, 0, 0, 0], gs.positions, gs.quats_wxyz,
                       MARGINAL)
    assert float(got[0]) == pytest.approx(hand_marginal(offset(), poses, u_lin, 10.0), abs=1e-12)


@pytest.mark.parametrize("twist", [[0.05, -0.1, 0.02, 0, 0, 0], [0, 0, 0, 0.1, -0.3, 0.05],
                                   [0.05, 0, 0, 0.1, 0, 0], [0, 0, 0, 0, 0, 0]])
@pytest.mark.parametrize("step_cost", ["path", "time"])
@pytest.mark.parametrize("rpy", [[3.0, 0.3, 0.4], TOP, [-2.25, 1.02, 0.88]])
def test_per_pose_likelihood_skips_only_parts_that_are_exactly_zero(twist, step_cost, rpy):
    """``pose_nll`` (distances shared with the weights) does not compute a part the input leaves exactly
    where it was: bit for bit the value of both parts computed in full, on Scene 1's cup (16 rim grasps)
    and bowl, for one-part, two-part and zero twists and both step costs (the evaluation's recorded
    trials reproduce only if nothing changes by a rounding). The last orientation's quaternion is not
    exactly the one renormalising it gives, so a turn by nothing moves it by a rounding: its rotation
    part, a rounding away from zero, is computed (by renormalising alone, which must give the turn's
    numbers: the reference here turns in full)."""
    from sa_daemon.geometry import integrate_pose, norms, quat_angle
    from sa_daemon.model.huber import pose_nll
    from sa_daemon.world.scene import load_scene

    gs = GoalSet(load_scene("scene1").goals)
    cfg = MARGINAL.model_copy(update={"step_cost": step_cost, "rotation_rationality": 200.0})
    g = Pose.from_rpy([0.35, -0.05, 0.25], rpy)
    u = np.array(twist, dtype=float)
    T = cfg.action_apply_time_s
    p1, q1 = integrate_pose(g.position[None], g.quat_wxyz[None], u[None], T)
    d_t, d_r = norms(gs.positions - g.position), quat_angle(gs.quats_wxyz, g.quat_wxyz)
    per_t, per_r = (norms(u[:3]), norms(u[3:])) if step_cost == "path" else (1.0, 1.0)
    trans = (T * huber_slope(d_t, cfg.translation) * per_t + huber_value(norms(gs.positions - p1), cfg.translation)
             - huber_value(d_t, cfg.translation))
    rot = (T * huber_slope(d_r, cfg.rotation) * per_r + huber_value(quat_angle(gs.quats_wxyz, q1), cfg.rotation)
           - huber_value(d_r, cfg.rotation))
    whole = cfg.rationality * (trans + cfg.rotation_scale * rot)
    got = pose_nll(g.position, g.quat_wxyz, u, gs.positions, gs.quats_wxyz, cfg)
    assert np.abs(whole).max() > 0.0 or (step_cost == "path" and not u.any())
    np.testing.assert_array_equal(got, whole)


def test_marginal_tends_to_the_nearest_pose_as_the_rationality_grows():
    poses = [offset(dy=-0.04), offset(dy=0.09)]
    gs = GoalSet((top_goal("cup", *poses),))
    u = np.array([0.0, 0.1, 0.0, 0.0, 0.0, 0.0])  # toward the farther pose
    for beta in (1e3, 1e4):
        cfg = MARGINAL.model_copy(update={"rationality": beta})
        got = float(marginal_nll(GRIPPER.position, GRIPPER.quat_wxyz, u, gs.positions, gs.quats_wxyz, cfg)[0])
        assert got == pytest.approx(beta * hand_q_minus_v_path(offset(), poses[0], [0.0, 0.1, 0.0]), rel=1e-6)


def test_an_input_toward_a_goals_other_pose_is_evidence_for_it_when_marginalised():
    """Two grasps of the cup 5 cm either side of the gripper (the nearer behind it) and a bowl where the
    cup's other grasp is: a user pushing toward that grasp. Read by its nearer pose alone the cup loses to
    the bowl as if the input pointed away from the cup; marginalised, the cup's other grasp explains the
    input too and the cup loses at half that rate (still losing: the bowl explains all of it, the cup's
    grasp behind none)."""
    g = Pose.from_rpy(offset(dy=-0.005), TOP)
    gs = GoalSet((top_goal("cup", offset(dy=-0.05), offset(dy=0.05)), top_goal("bowl", offset(dy=0.05))))
    u = np.array([0.0, 0.1, 0.0, 0.0, 0.0, 0.0])
    prior = Belief.uniform(gs)
    near, marginal = prior.after_input(g, u, NEAREST).probs, prior.after_input(g, u, MARGINAL).probs
    odds_near, odds_marginal = math.log(near[1] / near[0]), math.log(marginal[1] / marginal[0])
    assert odds_near == pytest.approx(10.0 * (hand_q_minus_v_path(offset(dy=-0.005), offset(dy=-0.05), u[:3])
                                              - hand_q_minus_v_path(offset(dy=-0.005), offset(dy=0.05), u[:3])))
    assert 0.0 < odds_marginal < 0.6 * odds_near


TRACKED = MARGINAL.model_copy(update={"poses": "tracked"})


def test_tracked_poses_start_uniform_and_follow_bayes_over_a_goals_poses():
    """``poses = "tracked"``: the first sample's likelihood is the mean over the goal's poses (uniform
    weights, padding excluded), and the weights then are each pose's posterior by hand."""
    poses = [offset(dy=-0.05), offset(dy=0.05), offset(dx=0.2)]
    gs = GoalSet((top_goal("cup", *poses), top_goal("bowl", offset(dx=0.08))))  # the bowl padded to 3
    u = [0.0, 0.1, 0.0]
    per = [10.0 * hand_q_minus_v_path(offset(), p, u) for p in poses]
    want_nll = -math.log(sum(math.exp(-x) for x in per) / 3)
    b = Belief.uniform(gs).after_input(GRIPPER, np.r_[u, 0, 0, 0], TRACKED)
    bowl_nll = 10.0 * hand_q_minus_v_path(offset(), offset(dx=0.08), u)
    assert math.log(b.probs[1] / b.probs[0]) == pytest.approx(want_nll - bowl_nll, abs=1e-12)
    post = [math.exp(-x) / sum(math.exp(-y) for y in per) for x in per]
    np.testing.assert_allclose(np.exp(b.pose_log_w[0]), post, atol=1e-12)
    np.testing.assert_allclose(np.exp(b.pose_log_w[1]), [1.0, 0.0, 0.0], atol=1e-15)


def test_tracked_poses_let_a_goal_keep_the_evidence_of_the_pose_the_user_heads_to():
    """A cup with grasps 5 cm either side of the path and a bowl ahead: a user driving at the cup's +y
    grasp. Once the input has told the cup's two grasps apart, the tracked weights sit on the +y grasp
    and the cup loses no more than that grasp explains, while the exp(-V) weights (``marginal``) keep
    charging it for the grasp behind, every sample."""
    gs = GoalSet((top_goal("cup", offset(dx=0.1, dy=-0.05), offset(dx=0.1, dy=0.05)),
                  top_goal("bowl", offset(dx=0.1, dy=0.12))))
    u = np.array([0.1, 0.05, 0.0, 0.0, 0.0, 0.0])  # at the cup's +y grasp from the gripper
    tracked = marginal = Belief.uniform(gs)
    for _ in range(60):
        tracked, marginal = tracked.after_input(GRIPPER, u, TRACKED), marginal.after_input(GRIPPER, u, MARGINAL)
    assert np.exp(tracked.pose_log_w[0, 1]) > 0.99
    assert tracked.probs[0] > marginal.probs[0]
    step = tracked.after_input(GRIPPER, u, TRACKED)
    one_pose = 10.0 * hand_q_minus_v_path(offset(), offset(dx=0.1, dy=0.05), u[:3])
    bowl = 10.0 * hand_q_minus_v_path(offset(), offset(dx=0.1, dy=0.12), u[:3])
    gained = math.log(step.probs[0] / step.probs[1]) - math.log(tracked.probs[0] / tracked.probs[1])
    assert gained == pytest.approx(bowl - one_pose, abs=0.01)


SWITCHING = MARGINAL.model_copy(update={"poses": "switching"})


def test_switching_poses_span_tracked_and_marginal():
    """``poses = "switching"`` with ``pose_switch`` 0 is ``tracked`` and with 1 is ``marginal``, sample by
    sample; in between, one sample's likelihood is the mixture over the poses with the prior ``(1 - s)``
    times the posterior so far plus ``s`` times the weights ``exp(-V)``, by hand."""
    poses = [offset(dx=0.1, dy=-0.05), offset(dx=0.1, dy=0.05)]
    gs = GoalSet((top_goal("cup", *poses), top_goal("bowl", offset(dx=0.1, dy=0.12))))
    u = np.array([0.1, 0.05, 0.0, 0.0, 0.0, 0.0])
    for s, other in ((0.0, TRACKED), (1.0, MARGINAL)):
        a = b = Belief.uniform(gs)
        for _ in range(5):
            a, b = a.after_input(GRIPPER, u, SWITCHING.model_copy(update={"pose_switch": s})), b.after_input(GRIPPER, u, other)
        np.testing.assert_allclose(a.probs, b.probs, rtol=0, atol=1e-12)
    s = 0.3
    cfg = SWITCHING.model_copy(update={"pose_switch": s})
    b = Belief.uniform(gs).after_input(GRIPPER, u, cfg)
    post = np.exp(b.pose_log_w[0, :2])
    v = [10.0 * v_trans(math.dist(offset(), p)) for p in poses]  # the tracker's V at the gripper (same orientation)
    pi = [math.exp(-x) / sum(math.exp(-y) for y in v) for x in v]
    prior = [(1 - s) * w + s * q for w, q in zip(post, pi)]
    per = [10.0 * hand_q_minus_v_path(offset(), p, u[:3]) for p in poses]
    bowl = 10.0 * hand_q_minus_v_path(offset(), offset(dx=0.1, dy=0.12), u[:3])
    cup_nll = -math.log(sum(w * math.exp(-x) for w, x in zip(prior, per)))
    step = b.after_input(GRIPPER, u, cfg)
    gained = math.log(step.probs[0] / step.probs[1]) - math.log(b.probs[0] / b.probs[1])
    assert gained == pytest.approx(bowl - cup_nll, abs=1e-9)


def test_switching_poses_follow_a_user_who_changes_grasp():
    """A user drives at the cup's -y grasp long enough for the tracked posterior to settle there, then at
    its +y grasp: with the pose free to change (``pose_switch`` 0.025) the posterior is on +y within 20
    samples (half a second at 40 a second) while the settled one has hardly moved, and the cup keeps more
    of its probability against the bowl."""
    gs = GoalSet((top_goal("cup", offset(dx=0.1, dy=-0.05), offset(dx=0.1, dy=0.05)),
                  top_goal("bowl", offset(dx=0.1, dy=0.12))))
    first, then = np.array([0.1, -0.05, 0, 0, 0, 0]), np.array([0.1, 0.05, 0, 0, 0, 0])
    tracked = switching = Belief.uniform(gs)
    for _ in range(60):
        tracked, switching = tracked.after_input(GRIPPER, first, TRACKED), switching.after_input(GRIPPER, first, SWITCHING)
    assert np.exp(tracked.pose_log_w[0, 0]) > 0.99 and np.exp(switching.pose_log_w[0, 0]) > 0.9
    for _ in range(20):
        tracked, switching = tracked.after_input(GRIPPER, then, TRACKED), switching.after_input(GRIPPER, then, SWITCHING)
    assert np.exp(switching.pose_log_w[0, 1]) > 0.5
    assert np.exp(tracked.pose_log_w[0, 1]) < 0.05
    assert switching.probs[0] > tracked.probs[0]


POINTS = MARGINAL.model_copy(update={"poses": "points"})


def bowl_with_twin_listings(yaw: float = 0.5) -> GoalSet:
    """A bowl grasp listed at yaw and yaw + pi at one point 2 cm below the gripper, another point 5 cm
    away; a cup elsewhere with one listing at the gripper's orientation."""
    at, other = offset(dz=-0.02), offset(dx=0.05, dz=-0.02)
    bowl = Goal("bowl", GraspType.TOP, (Pose.from_rpy(at, (math.pi, 0.0, yaw)),
                                        Pose.from_rpy(at, (math.pi, 0.0, yaw + math.pi)),
                                        Pose.from_rpy(other, (math.pi, 0.0, yaw))))
    return GoalSet((bowl, top_goal("cup", offset(dx=0.12, dz=-0.02))))


def test_points_weigh_a_grasp_point_as_marginal_and_its_listings_by_their_posterior():
    """``poses = "points"``: a point's weight is the sum of its listings' ``exp(-V)`` weights (as under
    ``marginal``) and its listings share it by their posterior; rows stay normalised, padding weighs
    nothing."""
    from sa_daemon.model.huber import point_listing_log_w, pose_log_weights

    gs = bowl_with_twin_listings()
    prior = pose_log_weights(GRIPPER.position, GRIPPER.quat_wxyz, gs.positions, gs.quats_wxyz, POINTS)
    post = np.array([[np.log(0.1), np.log(0.6), np.log(0.3)], [0.0, -np.inf, -np.inf]])
    w = np.exp(point_listing_log_w(prior, post, gs.same_point))
    pi = np.exp(prior)
    np.testing.assert_allclose(w.sum(axis=1), 1.0, atol=1e-12)
    assert w[0, 0] + w[0, 1] == pytest.approx(pi[0, 0] + pi[0, 1], abs=1e-12)
    assert w[0, 1] / w[0, 0] == pytest.approx(6.0, rel=1e-12)
    assert w[0, 2] == pytest.approx(pi[0, 2], abs=1e-12)
    assert w[1, 1] == 0.0 and w[1, 2] == 0.0
    assert pi[0, 1] < 0.01 * pi[0, 0]  # marginal all but ignores the listing half a turn away


def test_points_read_translation_exactly_as_marginal():
    """Translation moves a point's listings alike, so while the input only translates, ``points`` is
    ``marginal``, sample by sample."""
    gs = bowl_with_twin_listings()
    a = b = Belief.uniform(gs)
    for u in ([0.05, 0.0, -0.02], [0.0, 0.05, 0.0], [0.1, -0.02, 0.01]):
        for _ in range(5):
            twist = np.r_[u, 0.0, 0.0, 0.0]
            a, b = a.after_input(GRIPPER, twist, POINTS), b.after_input(GRIPPER, twist, MARGINAL)
        np.testing.assert_allclose(a.probs, b.probs, rtol=0, atol=1e-12)


def test_points_follow_a_turn_toward_the_listing_that_needs_more_turn():
    """At the bowl's point, a user turning toward its listing half a turn away (the short way round, about
    -z): ``marginal`` reads the turn against the near listing, whose weight is almost all, and the bowl
    loses to the cup; ``points`` lets the turn's posterior pick the far listing and the bowl keeps more."""
    gs = bowl_with_twin_listings()
    turn = np.array([0.0, 0.0, 0.0, 0.0, 0.0, -0.2])
    pts = mar = Belief.uniform(gs)
    for _ in range(40):
        pts, mar = pts.after_input(GRIPPER, turn, POINTS), mar.after_input(GRIPPER, turn, MARGINAL)
    post = np.exp(pts.pose_log_w[0])
    assert post[1] > 0.9 * (post[0] + post[1])
    assert pts.probs[0] > mar.probs[0]


def test_tracked_pose_weights_start_again_when_the_belief_resamples():
    gs = scene_with_multi_pose_target()
    b = Belief.uniform(gs)
    for _ in range(40):
        b = b.after_input(GRIPPER, np.array([0.2, 0.0, 0.0, 0.0, 0.0, 0.0]), TRACKED)
    assert b.pose_log_w is not None and b.needs_resampling()
    r = b.resampled(GRIPPER, TRACKED)
    assert r is not b and r.pose_log_w is None
    np.testing.assert_allclose(np.exp(r.pose_weights()).sum(axis=1), 1.0)


# -- the turn charge (``intent.turn_charge``) -------------------------------------------------------------

CHARGED = MARGINAL.model_copy(update={"turn_charge": 0.03})
TILTED = Pose.from_rpy(offset(), (math.pi - 0.5, 0.0, 0.0))  # at the first goal's grasp, 0.5 rad off its orientation
TURN_BACK = np.array([0.0, 0.0, 0.0, -0.3, 0.0, 0.0])  # rad/s, toward the goals' (shared) orientation


def twins(*positions) -> Belief:
    """Top grasps of one orientation on different objects: a turn alone cannot tell them apart."""
    return Belief.uniform(GoalSet(tuple(top_goal(f"object{i}", p) for i, p in enumerate(positions))))


def test_without_the_charge_a_turn_cannot_tell_twins_apart():
    b = twins(offset(), offset(dy=0.15)).after_input(TILTED, TURN_BACK, MARGINAL)
    np.testing.assert_allclose(b.probs, [0.5, 0.5], atol=1e-12)


def test_a_turn_at_one_goal_tells_it_from_its_twin_out_of_reach_by_hand():
    b = twins(offset(), offset(dy=0.15)).after_input(TILTED, TURN_BACK, CHARGED)
    # each goal pays 0.03 x T x the translation slope at its distance, times beta: 0 m and 0.15 m
    want = 10.0 * 0.03 * T * (slope_trans(0.15) - slope_trans(0.0))
    assert math.log(b.probs[0] / b.probs[1]) == pytest.approx(want, rel=1e-9)
    assert b.probs[0] > 0.5


def test_a_turn_at_the_stand_off_is_a_turn_at_the_goal():
    """0.06 m above a top grasp is its pre-grasp point; 0.06 m beside another is not on its approach."""
    at_standoff = Pose.from_rpy(offset(dz=0.06), (math.pi - 0.5, 0.0, 0.0))
    b = twins(offset(), offset(dz=0.06, dy=0.06)).after_input(at_standoff, TURN_BACK, CHARGED)
    want = 10.0 * 0.03 * T * (slope_trans(0.06) - slope_trans(0.0))
    assert math.log(b.probs[0] / b.probs[1]) == pytest.approx(want, rel=1e-9)


@pytest.mark.parametrize("u", [np.zeros(6), np.array([0.05, 0.0, 0.0, 0.0, 0.0, 0.0]), TURN_BACK])
def test_standing_still_and_moving_pay_no_turn_charge_and_the_time_form_none(u):
    goals = (offset(), offset(dy=0.15))
    turning = bool(u[3:].any())
    for base in (MARGINAL, INTENT):
        with_charge = base.model_copy(update={"turn_charge": 0.03})
        a, b = twins(*goals).after_input(TILTED, u, base), twins(*goals).after_input(TILTED, u, with_charge)
        if turning and base.step_cost == "path":
            assert b.probs[0] > a.probs[0]
        else:  # the time form already charges every step its time
            np.testing.assert_array_equal(a.probs, b.probs)


def test_the_charge_is_measured_where_the_user_last_translated_not_where_the_robot_took_the_gripper():
    """The user drives to the first goal and turns; meanwhile assistance carries the gripper to the second
    (``near_second``). The turn is still a turn where the user left the gripper: it favours the first goal
    by exactly the charge measured there, and a belief that never saw the user translate (anchor at the
    gripper) reads the same turn the other way."""
    goals = (offset(), offset(dy=0.15))
    near_second = Pose.from_rpy(offset(dy=0.15), (math.pi - 0.5, 0.0, 0.0))
    drove = twins(*goals).after_input(TILTED, np.array([0.05, 0.0, 0.0, 0.0, 0.0, 0.0]), CHARGED)
    np.testing.assert_array_equal(drove.anchor, TILTED.position)
    turned = drove.after_input(near_second, TURN_BACK, CHARGED)
    np.testing.assert_array_equal(turned.anchor, TILTED.position)  # a turn does not move the anchor
    want = 10.0 * 0.03 * T * (slope_trans(0.15) - slope_trans(0.0))
    shift = math.log(turned.probs[0] / turned.probs[1]) - math.log(drove.probs[0] / drove.probs[1])
    assert shift == pytest.approx(want, rel=1e-9)
    fresh = twins(*goals).after_input(near_second, TURN_BACK, CHARGED)
    np.testing.assert_array_equal(fresh.anchor, near_second.position)  # no input yet: the gripper
    assert math.log(fresh.probs[0] / fresh.probs[1]) == pytest.approx(-want, rel=1e-9)


def test_the_anchor_survives_answers_and_resampling():
    b = twins(offset(), offset(dy=0.15)).after_input(TILTED, np.array([0.0, 0.05, 0.0, 0.0, 0.0, 0.0]), CHARGED)
    for after in (b.after_answer("object1:top", False, CHARGED), b.after_answer("object0:top", True, CHARGED),
                  b.resampled(GRIPPER, CHARGED)):
        np.testing.assert_array_equal(after.anchor, TILTED.position)


def test_copies_weighted_by_the_input_keep_what_it_said_about_the_pose():
    """``intent.copy_weights = "input"``: resampling gives each copy its share of the target's posterior
    over its grasp poses from the input since the last resampling (:attr:`Belief.pose_log_w`), so input
    that pointed at one of the target's poses still points there after the split, and each copy keeps
    its own poses' posterior; with ``"equal"`` every copy starts at the same share. Target
    probabilities are preserved either way."""
    gs = GoalSet((top_goal("a", offset(dx=-0.06), offset(dy=0.06), offset(dy=-0.06)),
                  top_goal("b", offset(dx=0.15)), top_goal("c", offset(dz=0.15)), top_goal("d", offset(dx=0.15, dz=0.1))))
    u = np.array([-0.1, 0.0, 0.0, 0.0, 0.0, 0.0])  # toward a's first pose (-x), away from every other goal
    shares = {}
    for weights in ("input", "equal"):
        cfg = MARGINAL.model_copy(update={"copy_weights": weights})
        b = Belief.uniform(gs)
        for _ in range(10):
            b = b.after_input(GRIPPER, u, cfg)
        assert (b.pose_log_w is not None) == (weights == "input")
        if weights == "input":  # the input's posterior over a's poses: its first pose well ahead
            w = np.exp(b.pose_log_w[0])
            assert w[0] > 0.5 and w[0] > 2 * max(w[1], w[2])
        r = b.resampled(GRIPPER, cfg)
        assert r is not b and [g.target for g in r.goals.goals].count("a:top") == 3
        assert r.target_probabilities()["a:top"] == pytest.approx(b.target_probabilities()["a:top"], abs=1e-12)
        copies = {tuple(np.round(g.poses[0].position, 6)): p for g, p in zip(r.goals.goals, r.probs) if g.target == "a:top"}
        shares[weights] = copies[tuple(np.round(offset(dx=-0.06), 6))] / r.target_probabilities()["a:top"]
        if weights == "input":  # each copy owns one pose here, so its posterior over its poses is certain
            own = r.pose_log_w[r.goals.target_mask("a:top")]
            assert np.allclose(np.exp(own).max(axis=1), 1.0)
    assert shares["equal"] == pytest.approx(1 / 3)
    assert shares["input"] > 0.5


def test_keep_pose_posterior_carries_each_copys_posterior_over_its_poses_through_a_resampling():
    """``intent.keep_pose_posterior``: a resampling keeps, inside each copy it makes, what the input said
    about the copy's poses (the target's posterior restricted to them); the copies' probabilities stay as
    ``copy_weights`` gives them. Without it each copy's pose weights start afresh."""
    gs = GoalSet((top_goal("a", offset(dx=-0.06), offset(dy=0.07), offset(dy=-0.09), offset(dz=-0.11)),
                  top_goal("b", offset(dx=0.15)), top_goal("c", offset(dz=0.15)), top_goal("d", offset(dx=0.15, dz=0.1))))
    u = np.array([0.0, 0.0, -0.1, 0.0, 0.0, 0.0])  # toward a's farthest pose (-z), away from every other goal
    far = offset(dz=-0.11)
    out = {}
    for keep in (False, True):
        cfg = MARGINAL.model_copy(update={"reach_pose": "tracked", "keep_pose_posterior": keep})
        b = Belief.uniform(gs)
        for _ in range(20):  # a at about 2/3: three copies, the far pose in the last with the next farthest
            b = b.after_input(GRIPPER, u, cfg)
        r = b.resampled(GRIPPER, cfg)
        assert r is not b
        i = next(i for i, g in enumerate(r.goals.goals)
                 if any(np.allclose(p.position, far) for p in g.poses))
        k = next(k for k, p in enumerate(r.goals.goals[i].poses) if np.allclose(p.position, far))
        assert len(r.goals.goals[i].poses) > 1, "the far pose shares its copy with another"
        w = np.exp(r.pose_weights()[i, :len(r.goals.goals[i].poses)])
        out[keep] = (w[k] / w.sum(), r.probs.copy())
    assert out[True][0] > 0.9 and out[True][0] > out[False][0] + 0.2
    np.testing.assert_allclose(out[True][1], out[False][1], atol=1e-12)  # the copies' probabilities alike


def test_copies_weighted_as_the_tracked_reach_scores_keep_its_pose_on_top():
    """``intent.copy_weights = "tracked"``: a copy's share is its poses' ``w_k exp(-V_k)`` (the posterior
    from the input times the weights at the gripper), the score :func:`~sa_daemon.model.huber.tracked_goal_poses`
    picks the reach by; so the pose the reach pointed at before the split is in the likeliest copy after it.
    ``"poses"`` (``exp(-V_k)`` alone) gives the most to the copy nearest the gripper instead, whatever the
    input said. Target probabilities are preserved either way."""
    gs = GoalSet((top_goal("a", offset(dx=-0.06), offset(dy=0.07), offset(dy=-0.09), offset(dz=-0.11)),
                  top_goal("b", offset(dx=0.15)), top_goal("c", offset(dz=0.15)), top_goal("d", offset(dx=0.15, dz=0.1))))
    u = np.array([0.0, 0.0, -0.1, 0.0, 0.0, 0.0])  # toward a's farthest pose (-z), away from every other goal
    far, near = offset(dz=-0.11), offset(dx=-0.06)
    top = {}
    for weights in ("poses", "tracked"):
        cfg = MARGINAL.model_copy(update={"reach_pose": "tracked", "copy_weights": weights})
        b = Belief.uniform(gs)
        for _ in range(20):
            b = b.after_input(GRIPPER, u, cfg)
        kp, _ = tracked_goal_poses(GRIPPER.position, GRIPPER.quat_wxyz, gs.positions, gs.quats_wxyz,
                                   b.pose_log_w, cfg)
        np.testing.assert_allclose(kp[0], far)  # the input pointed the reach at the far pose
        r = b.resampled(GRIPPER, cfg)
        assert r is not b and [g.target for g in r.goals.goals].count("a:top") > 1
        assert r.target_probabilities()["a:top"] == pytest.approx(b.target_probabilities()["a:top"], abs=1e-12)
        copies = [(p, g) for g, p in zip(r.goals.goals, r.probs) if g.target == "a:top"]
        top[weights] = max(copies, key=lambda c: c[0])[1]
    assert any(np.allclose(p.position, far) for p in top["tracked"].poses)
    assert any(np.allclose(p.position, near) for p in top["poses"].poses)
    assert not any(np.allclose(p.position, far) for p in top["poses"].poses)


@pytest.mark.parametrize("weights", ["poses", "input", "tracked"])
def test_a_kept_pose_posterior_that_underflows_stays_finite(weights):
    """A resampling that keeps the pose posterior (``keep_pose_posterior``, ``copy_weights`` ``input`` or
    ``tracked``) may make copies of poses the input has all but ruled out (their posterior below
    ``exp(-745)``, zero in floating point). A copy holding only such poses starts uniform over them, one
    holding some beside a likely pose keeps them at the floor, so every pose weight, the next input's
    likelihood and every probability stay finite."""
    far = offset(dz=-0.11)
    a = top_goal("a", far, offset(dy=0.07), offset(dy=-0.09))  # the gripper is nearest the other two
    gs = GoalSet((a, *(top_goal(o, offset(dx=0.15)) for o in ("b", "b", "b"))))
    cfg = MARGINAL.model_copy(update={"reach_pose": "tracked", "keep_pose_posterior": True, "copy_weights": weights})
    log_w = np.full((4, 3), -np.inf)
    log_w[0] = [0.0, -2000.0, -2000.0]  # a's input: its far pose, beyond doubt
    log_w[1:, 0] = 0.0
    b = Belief(gs, np.log([0.97, 0.01, 0.01, 0.01]), pose_log_w=log_w)
    r = b.resampled(GRIPPER, cfg)
    copies = [g for g in r.goals.goals if g.target == "a:top"]
    assert r is not b and [len(g.poses) for g in copies] == [1, 2]  # (nearest), (next, far)
    w = r.pose_weights()
    assert np.all(np.isfinite(w[r.goals.pose_mask]))
    i = next(i for i, g in enumerate(r.goals.goals) if len(g.poses) == 2 and g.target == "a:top")
    k = next(k for k, p in enumerate(r.goals.goals[i].poses) if np.allclose(p.position, far))
    assert np.exp(w[i, k]) == pytest.approx(1.0)  # the far pose keeps its copy's posterior
    after = r.after_input(GRIPPER, np.array([0.0, 0.0, -0.05, 0.0, 0.0, 0.0]), cfg)
    assert np.all(np.isfinite(after.probs)) and after.probs.sum() == pytest.approx(1.0)
    assert after.target_probabilities()["a:top"] > 0.9
