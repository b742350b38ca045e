"""The evaluation's statistics against hand-computed answers and independent implementations."""

from __future__ import annotations

import dataclasses
import math
import random
from itertools import product

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.stats import wilcoxon

from sa_daemon.sim.stats import (
    PairedTest,
    bootstrap_ci,
    compare_paired,
    holm,
    paired_wilcoxon,
    stars,
)

pytestmark = pytest.mark.filterwarnings("error")  # no scipy warning may leak out of these functions


def exact_signed_rank_p(d: list[float]) -> float:
    """Independent two-sided exact p: zeros dropped, average ranks by counting, all 2^n sign flips."""
    nz = [abs(v) for v in d if v != 0]
    n = len(nz)
    ranks = [1 + sum(u < v for u in nz) + (sum(u == v for u in nz) - 1) / 2 for v in nz]
    w = sum(r for r, v in zip(ranks, [v for v in d if v != 0]) if v > 0)
    ge = le = 0
    for signs in product((1, -1), repeat=n):
        wp = sum(r for r, s in zip(ranks, signs) if s > 0)
        ge += wp >= w - 1e-9
        le += wp <= w + 1e-9
    return min(1.0, 2 * min(ge, le) / 2**n)


# -- bootstrap_ci --------------------------------------------------------------------------------------


def test_bootstrap_is_deterministic_for_a_seed():
    x = np.random.default_rng(1).normal(5.0, 2.0, 25)
    assert bootstrap_ci(x, seed=3) == bootstrap_ci(list(x), seed=3)
    assert bootstrap_ci(x, seed=3) != bootstrap_ci(x, seed=4)


def test_bootstrap_interval_contains_the_sample_mean():
    x = np.random.default_rng(2).normal(10.0, 3.0, 30)
    lo, hi = bootstrap_ci(x)
    assert lo < x.mean() < hi


def test_bootstrap_width_of_a_large_normal_sample_is_the_normal_theory_width():
    x = np.random.default_rng(7).normal(0.0, 1.0, 400)
    lo, hi = bootstrap_ci(x, level=0.95, n_boot=2000, seed=0)
    assert hi - lo == pytest.approx(2 * 1.96 / math.sqrt(400), rel=0.15)


def test_bootstrap_of_two_points_by_hand():
    # resampled means of [0, 1]: 0, 0.5, 1 with probabilities 1/4, 1/2, 1/4
    assert bootstrap_ci([0.0, 1.0], level=0.95) == (0.0, 1.0)  # 2.5 % and 97.5 % quantiles
    assert bootstrap_ci([0.0, 1.0], level=0.40) == (0.5, 0.5)  # 30 % and 70 % quantiles


def test_bootstrap_higher_level_gives_a_wider_interval_for_the_same_resamples():
    x = np.random.default_rng(3).exponential(2.0, 40)
    lo95, hi95 = bootstrap_ci(x, level=0.95)
    lo99, hi99 = bootstrap_ci(x, level=0.99)
    assert lo99 < lo95 < hi95 < hi99


def test_bootstrap_within_strata_leaves_out_the_spread_between_them():
    # two users, each always the same: only the seeds are resampled, so the mean of the mix cannot move
    values, users = [0.0, 0.0, 1.0, 1.0], ["a", "a", "b", "b"]
    assert bootstrap_ci(values, strata=users) == (0.5, 0.5)
    lo, hi = bootstrap_ci(values)
    assert lo < 0.5 < hi


def test_bootstrap_within_one_stratum_draws_as_without_strata():
    x = np.random.default_rng(5).normal(1.0, 1.0, 20)
    assert bootstrap_ci(x, seed=2, strata=["all"] * 20) == bootstrap_ci(x, seed=2)


def test_bootstrap_within_strata_is_narrower_where_the_strata_differ():
    rng = np.random.default_rng(6)
    x = np.concatenate([rng.normal(0.0, 0.3, 20), rng.normal(3.0, 0.3, 20)])
    users = ["calm"] * 20 + ["hasty"] * 20
    lo_s, hi_s = bootstrap_ci(x, strata=users)
    lo, hi = bootstrap_ci(x)
    assert lo_s < x.mean() < hi_s
    assert hi_s - lo_s < 0.5 * (hi - lo)


def test_bootstrap_strata_must_label_every_value():
    with pytest.raises(ValueError, match="strata"):
        bootstrap_ci([1.0, 2.0, 3.0], strata=["a", "b"])


def test_bootstrap_of_no_values_is_none():
    assert bootstrap_ci([]) is None


@pytest.mark.parametrize("values", [[4.25], [0.1] * 7, [3, 3, 3]])
def test_bootstrap_of_one_value_or_equal_values_is_degenerate_exactly(values):
    v = float(values[0])
    assert bootstrap_ci(values) == (v, v)


def test_bootstrap_returns_plain_floats():
    lo, hi = bootstrap_ci([1, 2, 3, 4])
    assert type(lo) is float and type(hi) is float


@pytest.mark.parametrize("values", [[1.0, float("nan")], [1.0, None], [1.0, math.inf], [[1.0, 2.0]]])
def test_bootstrap_refuses_missing_infinite_or_2d_values(values):
    with pytest.raises(ValueError):
        bootstrap_ci(values)


@pytest.mark.parametrize("kwargs", [{"level": 0.0}, {"level": 1.0}, {"n_boot": 0}])
def test_bootstrap_refuses_bad_level_or_resample_count(kwargs):
    with pytest.raises(ValueError):
        bootstrap_ci([1.0, 2.0], **kwargs)


# -- paired_wilcoxon -----------------------------------------------------------------------------------


def test_six_positive_differences_give_the_exact_p_2_over_64():
    a = [11.0, 12.0, 13.0, 14.0, 15.0, 16.0]
    b = [10.0, 10.0, 10.0, 10.0, 10.0, 10.0]  # d = 1..6, all positive: W+ = 21, the maximum
    r = paired_wilcoxon(a, b)
    assert r.p_value == pytest.approx(2 / 64, abs=1e-12)
    assert r.p_value == pytest.approx(wilcoxon([1, 2, 3, 4, 5, 6], method="exact").pvalue, abs=1e-12)
    assert abs(r.p_value - wilcoxon([1, 2, 3, 4, 5, 6], method="asymptotic").pvalue) > 1e-3  # not normal
    assert (r.n_pairs, r.median_diff) == (6, 3.5)


def test_swapping_the_sides_keeps_p_and_negates_the_median():
    a, b = [3.0, 1.0, 4.0, 1.5, 9.0], [2.0, 7.0, 1.0, 8.0, 2.5]
    ab, ba = paired_wilcoxon(a, b), paired_wilcoxon(b, a)
    assert ab.p_value == pytest.approx(ba.p_value)
    assert ab.median_diff == -ba.median_diff


def test_mixed_signs_by_hand_and_by_enumeration():
    d = [1.5, -0.5, 2.5, 3.5, -1.0, 4.5, 6.0]
    b = [10.0, 20.0, 30.0, 40.0, 50.0, 60.0, 70.0]
    a = [bi + di for bi, di in zip(b, d)]
    # ranks of |d|: 0.5->1, 1.0->2, 1.5->3, 2.5->4, 3.5->5, 4.5->6, 6.0->7; W+ = 3+4+5+6+7 = 25 of 28.
    # P(W+ >= 25) = P(W- <= 3) = |{}, {1}, {2}, {3}, {1,2}| / 2^7 = 5/128, two-sided 10/128.
    r = paired_wilcoxon(a, b)
    assert r.p_value == pytest.approx(10 / 128, abs=1e-12)
    assert r.p_value == pytest.approx(exact_signed_rank_p(d), abs=1e-12)
    assert r.median_diff == 2.5


def test_ties_and_zeros_by_hand_and_by_enumeration():
    d = [0.0, 0.0, 2.0, 2.0, -1.0, 3.0, 3.0, 3.0]
    # zeros dropped; |d| ranks 1 -> 1, 2 -> 2.5 (x2), 3 -> 5 (x3); W+ = 20 of 21: only all-positive (21)
    # or just the rank-1 pair negative (20) reach it, 2 of 2^6 sign flips, two-sided 4/64.
    r = paired_wilcoxon(d, [0.0] * len(d))
    assert r.p_value == pytest.approx(4 / 64, abs=1e-12)
    assert r.p_value == pytest.approx(exact_signed_rank_p(d), abs=1e-12)
    assert (r.n_pairs, r.median_diff) == (8, 2.0)


@pytest.mark.parametrize("seed", range(6))
def test_small_samples_with_ties_and_zeros_are_exact(seed):
    rng = np.random.default_rng(seed)
    d = [float(v) for v in rng.integers(-3, 5, size=int(rng.integers(3, 11)))]
    if not any(d):
        d[0] = 1.0
    assert paired_wilcoxon(d, [0.0] * len(d)).p_value == pytest.approx(exact_signed_rank_p(d), abs=1e-12)


def test_zeros_do_not_push_a_small_sample_onto_the_normal_approximation():
    d = [0.0] * 10 + [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]  # scipy alone would go normal (16 entries, zeros)
    r = paired_wilcoxon(d, [0.0] * 16)
    assert r.p_value == pytest.approx(2 / 64, abs=1e-12)
    assert (r.n_pairs, r.median_diff) == (16, 0.0)


def test_all_zero_differences_give_p_one():
    r = paired_wilcoxon([5.0, 6.0, 7.0], [5.0, 6.0, 7.0])
    assert r == PairedTest(3, 0.0, 1.0)


def test_a_single_non_zero_difference_gives_p_one():
    assert paired_wilcoxon([1.0, 2.0, 4.0], [1.0, 2.0, 3.0]).p_value == pytest.approx(1.0)


def test_pairs_with_a_missing_side_are_dropped():
    a = [11.0, None, 13.0, 14.0, float("nan"), 15.0, 16.0, 17.0]
    b = [10.0, 10.0, None, 10.0, 10.0, 10.0, 10.0, 10.0]
    r = paired_wilcoxon(a, b)
    assert r == paired_wilcoxon([11.0, 14.0, 15.0, 16.0, 17.0], [10.0] * 5)
    assert r.n_pairs == 5
    assert r.median_diff == 5.0  # d = 1, 4, 5, 6, 7
    assert r.p_value == pytest.approx(2 / 32, abs=1e-12)


def test_median_of_an_even_number_of_differences_is_the_mean_of_the_middle_two():
    assert paired_wilcoxon([1.0, 5.0, 2.0, 10.0], [0.0, 0.0, 0.0, 0.0]).median_diff == 3.5


def test_fewer_than_two_pairs_have_no_p_value():
    assert paired_wilcoxon([], []) == PairedTest(0, None, None)
    assert paired_wilcoxon([3.0, None], [1.0, 2.0]) == PairedTest(1, 2.0, None)


def test_paired_wilcoxon_refuses_unequal_lengths_and_infinities():
    with pytest.raises(ValueError):
        paired_wilcoxon([1.0, 2.0], [1.0])
    with pytest.raises(ValueError):
        paired_wilcoxon([1.0, math.inf, 3.0], [0.0, 0.0, 0.0])


def test_paired_test_is_frozen():
    r = paired_wilcoxon([1.0, 2.0], [0.0, 0.0])
    with pytest.raises(dataclasses.FrozenInstanceError):
        r.p_value = 0.0


# -- holm ----------------------------------------------------------------------------------------------


def test_holm_by_hand():
    # sorted 0.01, 0.03, 0.04 -> 3*0.01, 2*0.03, max(0.06, 1*0.04); back in input order
    assert holm([0.01, 0.04, 0.03]) == pytest.approx([0.03, 0.06, 0.06])


def test_holm_keeps_none_and_leaves_it_out_of_the_family():
    out = holm([0.04, None, 0.01])
    assert out[1] is None
    assert out[0] == pytest.approx(0.04) and out[2] == pytest.approx(0.02)


def test_holm_caps_at_one():
    assert holm([0.4, 0.5, 0.45]) == [1.0, 1.0, 1.0]
    assert holm([0.3, 0.9, 0.02]) == pytest.approx([0.6, 0.9, 0.06])


def test_holm_of_one_or_no_p_values():
    assert holm([0.03]) == [0.03]
    assert holm([]) == []
    assert holm([None, None]) == [None, None]


@pytest.mark.parametrize("bad", [float("nan"), 1.5, -0.1])
def test_holm_refuses_values_that_are_not_probabilities(bad):
    with pytest.raises(ValueError):
        holm([0.01, bad])


@settings(max_examples=100, deadline=None)
@given(st.lists(st.one_of(st.none(), st.floats(0.0, 1.0)), max_size=12))
def test_holm_properties(ps):
    out = holm(ps)
    assert len(out) == len(ps)
    assert [q is None for q in out] == [p is None for p in ps]
    pairs = [(p, q) for p, q in zip(ps, out) if p is not None]
    m = len(pairs)
    for p, q in pairs:
        assert p <= q <= 1.0
        # independent definition: q = min(1, max over p' <= p of (m - rank(p') + 1) p'), rank = 1 + #smaller
        ref = max((m - sum(x < pj for x, _ in pairs)) * pj for pj, _ in pairs if pj <= p)
        assert q == pytest.approx(min(1.0, ref))
    for p1, q1 in pairs:
        for p2, q2 in pairs:
            if p1 < p2:
                assert q1 <= q2
            if p1 == p2:
                assert q1 == q2


# -- stars ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("p", "mark"),
    [
        (None, ""), (float("nan"), ""), (1.0, ""), (0.05, ""), (0.0499, "*"), (0.01, "*"), (0.00999, "**"),
        (0.001, "**"), (0.000999, "***"), (0.0001, "***"), (0.0000999, "****"), (0.0, "****"),
    ],
)
def test_stars_at_and_around_each_threshold(p, mark):
    assert stars(p) == mark


# -- compare_paired ------------------------------------------------------------------------------------


def _trial(method, seed, time, success=True, **extra):
    return {"method": method, "seed": seed, "success": success, "completion_time_s": time, **extra}


def _trials():
    policy = [10.0, 12.0, 9.0, 11.0, 14.0, 8.0]
    direct = [15.0, 14.0, 12.0, 10.0, 20.0, 12.0]  # d = -5, -2, -3, 1, -6, -4: ranks 5 2 3 1 6 4, W+ = 1
    ts = [_trial("policy", s, t) for s, t in enumerate(policy)] + [_trial("direct", s, t) for s, t in enumerate(direct)]
    ts += [_trial("policy", 6, 9.0), _trial("direct", 6, 60.0, success=False)]  # baseline timed out
    ts += [_trial("policy", 7, 30.0, success=False), _trial("direct", 7, 5.0)]  # policy failed
    ts += [_trial("policy", 8, 1.0)]  # no baseline trial for seed 8
    ts += [_trial("policy", 9, None), _trial("direct", 9, 7.0)]  # no value
    ts += [_trial("blend", s, 100.0) for s in range(6)]  # another method, ignored
    return ts


def test_compare_paired_by_seed_drops_failed_and_unpaired_trials():
    ts = _trials()
    random.Random(0).shuffle(ts)
    r = compare_paired(ts, "completion_time_s", "policy", "direct")
    assert r.n_pairs == 6
    assert r.median_diff == -3.5  # of -6, -5, -4, -3, -2, 1
    assert r.p_value == pytest.approx(2 * 2 / 64, abs=1e-12)  # P(W+ <= 1) = |{}, {1}| / 2^6


def test_compare_paired_is_independent_of_the_input_order():
    ts = _trials()
    base = compare_paired(ts, "completion_time_s", "policy", "direct")
    for k in range(3):
        random.Random(k).shuffle(ts)
        assert compare_paired(ts, "completion_time_s", "policy", "direct") == base


def test_compare_paired_keeps_failed_trials_when_not_success_only():
    r = compare_paired(_trials(), "completion_time_s", "policy", "direct", success_only=False)
    assert r.n_pairs == 8  # seeds 0-7; seed 8 unpaired, seed 9 has no value


def test_compare_paired_counts_success_as_zero_one():
    ts = [_trial("policy", s, 10.0) for s in range(8)]
    ts += [_trial("direct", s, 10.0, success=s not in (1, 4, 6)) for s in range(8)]
    r = compare_paired(ts, "success", "policy", "direct", success_only=False)
    # d = 1 on three discordant seeds, 0 on five: the exact sign test, 2 * (1/2)^3
    assert r == PairedTest(8, 0.0, pytest.approx(0.25, abs=1e-12))


def test_compare_paired_refuses_a_repeated_seed_and_a_method_against_itself():
    ts = [_trial("policy", 0, 1.0), _trial("policy", 0, 2.0), _trial("direct", 0, 3.0)]
    with pytest.raises(ValueError):
        compare_paired(ts, "completion_time_s", "policy", "direct")
    with pytest.raises(ValueError):
        compare_paired(ts[:1], "completion_time_s", "policy", "policy")
