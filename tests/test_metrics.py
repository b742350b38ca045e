"""The per-trial measures on hand-made trajectories."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sa_daemon.sim import metrics
from sa_daemon.sim.metrics import (
    PREDICTION_THRESHOLD,
    correct_prediction,
    joystick_input,
    mode_changes,
    opposing_pct,
)

# -- joystick input ------------------------------------------------------------------------------------


def test_joystick_input_sums_absolute_values_of_all_three_axes():
    assert joystick_input([[1.0, -1.0, 0.5], [0.0, 0.0, -0.25]]) == pytest.approx(2.75)


def test_joystick_input_accepts_arrays_and_lists_of_arrays():
    rows = [np.array([0.1, -0.2, 0.3]), np.array([-0.4, 0.0, 0.0])]
    assert joystick_input(rows) == pytest.approx(1.0)
    assert joystick_input(np.array(rows)) == pytest.approx(1.0)


def test_joystick_input_of_no_samples_is_zero():
    assert joystick_input([]) == 0.0


def test_joystick_input_is_a_plain_float():
    assert type(joystick_input([[1, 2, 3]])) is float


def test_joystick_input_refuses_rows_that_are_not_three_axes():
    with pytest.raises(ValueError):
        joystick_input([[1.0, 2.0], [3.0, 4.0]])


axes_row = st.lists(st.floats(min_value=-1.0, max_value=1.0), min_size=3, max_size=3)


@settings(max_examples=100, deadline=None)
@given(st.lists(axes_row, max_size=30), st.lists(axes_row, max_size=30))
def test_joystick_input_is_additive_and_sign_blind(a, b):
    total = joystick_input(a + b)
    assert total == pytest.approx(joystick_input(a) + joystick_input(b), abs=1e-9)
    assert joystick_input([[-x for x in r] for r in a]) == pytest.approx(joystick_input(a), abs=1e-12)
    assert total >= 0.0


# -- opposing ------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "opposed, pct",
    [
        ([True, False, False, True], 50.0),
        ([False, False, False], 0.0),
        ([True], 100.0),
        ([True, False, False, False, False], 20.0),
        ([], 0.0),
    ],
)
def test_opposing_pct(opposed, pct):
    assert opposing_pct(opposed) == pytest.approx(pct)


def test_opposing_pct_is_a_percentage_not_a_fraction():
    assert opposing_pct([True, True, False, False, False, False, False, False]) == pytest.approx(25.0)


# -- mode changes --------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "modes, n",
    [
        ([], 0),
        (["translation"], 0),
        (["translation"] * 5, 0),
        (["translation", "rotation"], 1),
        (["translation", "rotation", "rotation", "translation"], 2),
        (["translation", "rotation", "translation", "rotation", "translation"], 4),
        (["rotation", "rotation", "translation", "translation", "translation"], 1),
    ],
)
def test_mode_changes_counts_switches(modes, n):
    assert mode_changes(modes) == n


def test_mode_changes_accepts_tuples():
    assert mode_changes(("rotation", "translation", "rotation")) == 2


# -- correct prediction --------------------------------------------------------------------------------


def test_prediction_threshold_is_point_seven():
    assert PREDICTION_THRESHOLD == 0.7


@pytest.mark.parametrize(
    "p, ok", [(0.7, False), (0.7000001, True), (0.69, False), (0.99, True), (0.0, False), (1.0, True)]
)
def test_correct_prediction_is_strictly_above_threshold(p, ok):
    assert correct_prediction(p) is ok


def test_correct_prediction_with_explicit_threshold():
    assert correct_prediction(0.55, threshold=0.5) is True
    assert correct_prediction(0.5, threshold=0.5) is False


def test_metrics_are_pure():
    axes = [[1.0, -1.0, 0.5]]
    opposed = [True, False]
    modes = ["translation", "rotation"]
    for _ in range(2):
        assert metrics.joystick_input(axes) == 2.5
        assert metrics.opposing_pct(opposed) == 50.0
        assert metrics.mode_changes(modes) == 1
    assert axes == [[1.0, -1.0, 0.5]] and opposed == [True, False] and modes == ["translation", "rotation"]
