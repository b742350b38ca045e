"""The evaluation's statistics: bootstrap intervals, paired Wilcoxon tests, Holm correction, stars.

The evaluation runs every (scene, task, user, method) over matched seeds: trial i of method A and trial
i of method B share seed i (so the same simulated user, desired pose and noise), and method ``policy``
is compared with every other method as in the paper (Yow, Garg, Ang, sections V-VI: Wilcoxon
signed-rank tests, stars ``* p<0.05, ** p<0.01, *** p<0.001, **** p<0.0001``).

Units: an interval or a median difference is in the unit of its metric (s for ``completion_time_s``,
switches for ``mode_changes``, summed raw axis input for ``joystick_input``, % for ``opposing_pct``,
a fraction for a 0/1 rate such as ``success``); p-values are probabilities (dimensionless, in [0, 1]).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from scipy.stats import wilcoxon

STAR_THRESHOLDS = (0.05, 0.01, 0.001, 0.0001)  # p strictly below the k-th threshold earns k stars


def bootstrap_ci(
    values: Sequence[float], level: float = 0.95, n_boot: int = 2000, seed: int = 0,
    strata: Sequence[object] | None = None,
) -> tuple[float, float] | None:
    """Percentile bootstrap confidence interval of the mean of ``values``, in their unit.

    ``n_boot`` resamples of size n are drawn with replacement (all at once, an ``(n_boot, n)`` index
    array from ``np.random.default_rng(seed)``, so the result is deterministic for a seed); the interval
    is the ``(1 - level) / 2`` and ``(1 + level) / 2`` quantiles (linear interpolation) of their means.
    With ``strata`` (one label per value) each resample keeps every stratum's size and draws within it:
    the interval of a mean over a fixed mix, such as the population's users, where only the seeds vary.
    No values: None. One value, or all values equal: the degenerate interval ``(v, v)`` exactly.
    ``values`` must be 1-D and finite: a None, NaN or infinite entry raises ValueError (drop failed
    trials before, deliberately). ``level`` must lie in (0, 1), ``n_boot`` be at least 1 and ``strata``
    as long as ``values``.
    """
    if not 0.0 < level < 1.0:
        raise ValueError(f"level must be in (0, 1), got {level}")
    if n_boot < 1:
        raise ValueError(f"n_boot must be at least 1, got {n_boot}")
    x = np.asarray(values, dtype=float)  # None -> NaN, refused below
    if x.ndim != 1:
        raise ValueError(f"values must be 1-D, got shape {x.shape}")
    if strata is not None and len(strata) != x.size:
        raise ValueError(f"strata must label every value: {len(strata)} labels for {x.size} values")
    if x.size == 0:
        return None
    if not np.all(np.isfinite(x)):
        raise ValueError("values must be finite (no None, NaN or inf)")
    if np.all(x == x[0]):
        return float(x[0]), float(x[0])
    rng = np.random.default_rng(seed)
    if strata is None:
        index = rng.integers(0, x.size, size=(n_boot, x.size))
    else:
        members = {}
        for i, label in enumerate(strata):
            members.setdefault(label, []).append(i)
        index = np.concatenate([np.asarray(m)[rng.integers(0, len(m), size=(n_boot, len(m)))]
                                for m in members.values()], axis=1)
    means = x[index].mean(axis=1)
    lo, hi = np.quantile(means, [(1.0 - level) / 2.0, (1.0 + level) / 2.0])
    return float(lo), float(hi)


@dataclass(frozen=True)
class PairedTest:
    """A paired comparison: complete pairs, the median of (a - b) in the metric's unit, the p-value.

    ``median_diff`` is None with no pairs; ``p_value`` is None with fewer than 2 pairs.
    """

    n_pairs: int
    median_diff: float | None
    p_value: float | None


def paired_wilcoxon(a: Sequence[float | None], b: Sequence[float | None]) -> PairedTest:
    """Two-sided Wilcoxon signed-rank test of the paired differences d_i = a_i - b_i.

    Pairs where either side is None or NaN are dropped (a failed trial has no completion time); an
    infinite value raises ValueError, as do ``a`` and ``b`` of different lengths. ``n_pairs`` counts the
    complete pairs and ``median_diff`` is the median of all their d_i (zeros included), in the unit of
    the metric; positive means ``a`` is larger.

    The statistic is W+ = sum of the ranks of |d_i| (average ranks for ties) over the d_i > 0; under H0
    (the d_i are symmetric about 0) every sign assignment of the ranks is equally likely, and
    p = min(1, 2 min(P(W+ >= w), P(W+ <= w))).

    Choices, and why:

    * Zero differences are discarded before ranking (Wilcoxon's own rule, scipy's
      ``zero_method="wilcox"``, also R's ``wilcox.test``): a pair where both methods did the same says
      nothing about the sign of the difference. For a 0/1 metric such as success this makes the test
      the exact sign test on the discordant pairs (McNemar's exact test), the natural paired test of
      two success rates. ``"pratt"`` would let the ties at zero shift the ranks of the other pairs.
    * The zeros are dropped here, before calling scipy, so that scipy's ``method="auto"`` decides on
      the number of non-zero differences n' (the sample the test actually uses), not on the number of
      pairs: scipy sends any sample with a zero and more than 13 entries to the normal approximation,
      which would turn 6 positive differences among 16 pairs into p = 0.028 instead of the exact
      2/2^6 = 0.03125. The statistic and its null distribution are unchanged by this.
    * ``method="auto"`` (scipy >= 1.13), on the n' non-zero differences: no tied |d_i| and n' <= 50 ->
      the exact null distribution of W+; ties and n' <= 13 -> an exact (complete, 2^n' sign flips,
      hence deterministic) permutation test with the average-rank statistic; otherwise the normal
      approximation with the tie-corrected variance, without continuity correction (scipy's
      default; it only arises for n' > 13 with ties or n' > 50, where the correction is small). So
      the small samples of an evaluation get exact p-values and every result is deterministic.
    * All differences zero (at least 2 pairs): p = 1.0, not scipy's NaN with a warning: the two
      methods behaved identically on every pair, which is no evidence at all against H0.
    * Fewer than 2 pairs: p None; with one pair the smallest possible two-sided p is 1, no test.
    """
    x = np.asarray(a, dtype=float)  # None -> NaN
    y = np.asarray(b, dtype=float)
    if x.ndim != 1 or x.shape != y.shape:
        raise ValueError(f"a and b must be 1-D of the same length, got shapes {x.shape} and {y.shape}")
    keep = ~(np.isnan(x) | np.isnan(y))
    d = x[keep] - y[keep]
    if not np.all(np.isfinite(d)):
        raise ValueError("a and b must be finite where present (None or NaN mark a missing value)")
    n = int(d.size)
    if n == 0:
        return PairedTest(0, None, None)
    median = float(np.median(d))
    if n < 2:
        return PairedTest(n, median, None)
    nonzero = d[d != 0.0]
    if nonzero.size == 0:
        return PairedTest(n, median, 1.0)
    p = float(wilcoxon(nonzero, zero_method="wilcox", alternative="two-sided", method="auto").pvalue)
    return PairedTest(n, median, min(1.0, p))


def holm(p_values: Sequence[float | None]) -> list[float | None]:
    """Holm-Bonferroni step-down adjusted p-values, in the order of the input.

    With the m non-None p-values sorted ascending, p_(1) <= ... <= p_(m), the adjusted values are
    q_(i) = min(1, max_{j <= i} (m - j + 1) p_(j)): monotone in p and never below the raw p. Rejecting
    where q < alpha controls the family-wise error rate at alpha. None entries (no test) stay None and
    are not counted in m. A NaN or a value outside [0, 1] raises ValueError.
    """
    idx = [i for i, p in enumerate(p_values) if p is not None]
    raw = np.asarray([p_values[i] for i in idx], dtype=float)
    if np.any(np.isnan(raw)) or np.any((raw < 0.0) | (raw > 1.0)):
        raise ValueError("p-values must be None or in [0, 1]")
    out: list[float | None] = [None] * len(p_values)
    m = raw.size
    if m == 0:
        return out
    order = np.argsort(raw, kind="stable")
    scaled = (m - np.arange(m)) * raw[order]
    adjusted = np.minimum(1.0, np.maximum.accumulate(scaled))
    for k, q in zip(order, adjusted, strict=True):
        out[idx[k]] = float(q)
    return out


def stars(p: float | None) -> str:
    """The paper's significance marks: "*" for p < 0.05, "**" < 0.01, "***" < 0.001, "****" < 0.0001.

    Empty for p None (no test), p >= 0.05 or NaN.
    """
    if p is None:
        return ""
    return "*" * sum(p < t for t in STAR_THRESHOLDS)


def _value(trial: Mapping, metric: str, success_only: bool) -> float | None:
    """One trial's metric as a float (bool -> 0/1), None when missing or when a failed trial has none."""
    if success_only and not trial["success"]:
        return None
    v = trial.get(metric)
    return None if v is None else float(v)


def compare_paired(
    trials: Sequence[Mapping], metric: str, method: str, baseline: str, success_only: bool = True
) -> PairedTest:
    """:func:`paired_wilcoxon` of ``metric`` for ``method`` (a) against ``baseline`` (b), paired by seed.

    ``trials`` are the evaluation's trial records of one (scene, task, user) in any order: dicts with
    "method", "seed", the metric and, when ``success_only``, "success". Trials of other methods are
    ignored; a seed run by only one of the two methods has no pair and is dropped. A (method, seed)
    that occurs twice raises ValueError (trials of several scenes, tasks or users mixed together).

    ``success_only`` (default True, for completion time, mode changes, joystick input and opposing
    time, which the paper reports over successful trials): a trial with "success" False counts as a
    missing value, so its pair is dropped. A metric value of None is missing in any case. For a rate
    over all trials, such as "success" itself or "correct_prediction", pass ``success_only=False``:
    a bool counts as 0/1, and ``median_diff`` and the test are then over every pair.
    """
    if method == baseline:
        raise ValueError(f"method and baseline are both {method!r}")
    by_seed: dict[str, dict[int, float | None]] = {method: {}, baseline: {}}
    for t in trials:
        m = t["method"]
        if m not in by_seed:
            continue
        seed = t["seed"]
        if seed in by_seed[m]:
            raise ValueError(f"method {m!r} has seed {seed} twice: trials of one (scene, task, user) only")
        by_seed[m][seed] = _value(t, metric, success_only)
    seeds = sorted(by_seed[method].keys() & by_seed[baseline].keys())
    return paired_wilcoxon([by_seed[method][s] for s in seeds], [by_seed[baseline][s] for s in seeds])
