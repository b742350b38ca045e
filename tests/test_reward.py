"""Reward of section III-E, each term by hand."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sa_daemon.config import RewardConfig
from sa_daemon.model.reward import (
    approach_return,
    distance_reward,
    opposes,
    opposition_reward,
    question_reward,
)

CFG = RewardConfig()


def r_t(d: float) -> float:
    return -100.0 * (1.0 - 2.0 ** (-8.0 * d))


def r_r(d_rot: float) -> float:
    return -100.0 * d_rot / (2.0 * math.pi)


def reward(d_t, d_r) -> float:
    return float(distance_reward(d_t, d_r, CFG))


# -- the approach after the horizon (planner.terminal = "approach") ------------------------------------


@pytest.mark.parametrize("d_t, d_r, v_t, v_r", [
    (0.30, 0.4, 0.1, 0.2),   # translation takes longer: tau = 3 s
    (0.30, 1.5, 0.1, 0.2),   # rotation takes longer: tau = 7.5 s
    (0.05, 0.8, 0.1, 0.15),  # inside delta all the way: R_r from the start
    (0.12, 0.0, 0.1, 0.2),   # no rotation left
])
def test_the_approach_return_is_r_d_summed_along_a_straight_constant_speed_approach(d_t, d_r, v_t, v_r):
    """Walk the approach by hand in 1 ms steps (both parts shrinking together, arriving at ``tau``),
    summing the section III-E reward per paper step, then the goal bonus."""
    tau = max(d_t / v_t, d_r / v_r)
    dt = 1e-3
    total = 0.0
    for i in range(round(tau / dt)):
        u = 1.0 - (i + 0.5) * dt / tau  # the share of the way still to go, at the middle of the step
        total += (r_t(u * d_t) + (r_r(u * d_r) if u * d_t <= 0.1 else 0.0)) * dt / CFG.step_s
    got = float(approach_return(d_t, d_r, v_t, v_r, CFG))
    assert got == pytest.approx(total + 100.0, rel=1e-4, abs=1e-3)


def test_the_approach_return_at_the_goal_is_the_bonus_and_grows_with_time_to_go():
    assert float(approach_return(0.0, 0.0, 0.1, 0.2, CFG)) == pytest.approx(100.0)
    slow, fast = (float(approach_return(0.2, 1.0, 0.1, v_r, CFG)) for v_r in (0.05, 0.3))
    assert slow < fast < 100.0  # the same distances, a slower turn: more time to go, dearer


# -- R_d ------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("d_t", [0.15, 0.3, 1.0, 5.0])
def test_translation_reward_only_beyond_delta(d_t):
    assert reward(d_t, 1.0) == pytest.approx(r_t(d_t), abs=1e-12)  # rotation ignored when far


def test_translation_reward_values_by_hand():
    assert reward(0.125, 0.0) == pytest.approx(-50.0)  # 2^-(8 * 0.125) = 1/2
    assert reward(0.25, 0.0) == pytest.approx(-75.0)
    assert reward(1e6, 0.0) == pytest.approx(-100.0)  # bounded at -100


@pytest.mark.parametrize("d_t", [0.02, 0.05, 0.1])
def test_rotation_reward_added_within_delta_inclusive(d_t):
    assert reward(d_t, 1.0) == pytest.approx(r_t(d_t) + r_r(1.0), abs=1e-12)


def test_rotation_reward_switches_off_just_beyond_delta():
    d = math.nextafter(0.1, 1.0)
    assert reward(d, 1.0) == pytest.approx(r_t(d), abs=1e-12)


def test_goal_bonus_within_1cm_and_pi_over_48():
    assert reward(0.005, 0.05) == pytest.approx(r_t(0.005) + r_r(0.05) + 100.0, abs=1e-12)
    assert reward(0.0, 0.0) == pytest.approx(100.0)


@pytest.mark.parametrize("d_t, d_r", [(0.011, 0.0), (0.0, math.pi / 48 + 1e-3), (0.02, 0.1)])
def test_no_goal_bonus_outside_the_goal_region(d_t, d_r):
    assert reward(d_t, d_r) == pytest.approx(r_t(d_t) + r_r(d_r), abs=1e-12)


def test_distance_reward_broadcasts():
    got = distance_reward(np.array([[0.5, 0.05]]), np.array([[0.3, 0.3]]), CFG)
    np.testing.assert_allclose(got, [[r_t(0.5), r_t(0.05) + r_r(0.3)]])


# -- R_u: opposition ------------------------------------------------------------------------------------


def twist(i: int, value: float) -> np.ndarray:
    t = np.zeros(6)
    t[i] = value
    return t


@pytest.mark.parametrize("i", range(6))
def test_opposition_in_any_dimension(i):
    assert opposes(twist(i, 0.2), twist(i, -0.05), 0.01)
    assert opposes(twist(i, -0.2), twist(i, 0.05), 0.01)
    assert not opposes(twist(i, 0.2), twist(i, 0.05), 0.01)  # same sign


def test_no_opposition_across_different_dimensions():
    assert not opposes(twist(0, 0.2), twist(1, -0.2), 0.01)


@pytest.mark.parametrize(
    "u, r, expected",
    [
        (0.01, -0.2, False),  # user exactly at the threshold: not strictly above
        (0.2, -0.01, False),  # robot exactly at the threshold
        (0.0100001, -0.0100001, True),  # both just above
        (0.009, -0.5, False),
        (0.0, -0.5, False),
    ],
)
def test_opposition_threshold_is_strict(u, r, expected):
    assert bool(opposes(twist(2, u), twist(2, r), 0.01)) is expected


def test_opposition_in_one_dimension_is_enough():
    u = np.array([0.2, 0.2, 0.0, 0.0, 0.0, 0.3])
    r = np.array([0.2, 0.2, 0.0, 0.0, 0.0, -0.02])
    assert opposes(u, r, 0.01)


def test_opposition_reward_is_minus_five():
    np.testing.assert_array_equal(opposition_reward(np.array([True, False]), CFG), [-5.0, 0.0])


def test_question_rewards():
    assert question_reward(False, CFG) == -5.0
    assert question_reward(True, CFG) == -100.0
