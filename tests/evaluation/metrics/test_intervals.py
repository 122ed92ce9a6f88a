"""Tests of evaluation.metrics.intervals: scipy agreement, degenerate cases, tie-aware ranks, limit ratio."""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats

from evaluation.metrics.intervals import (
    UNRANKED,
    Interval,
    Worst,
    bootstrap_ci,
    limit_ratio,
    limit_ratio_ci,
    rank_with_ties,
    share_with_alarm,
    worst,
)

# A fixed, skewed sample like per-seed detection times (a long right tail).
SAMPLE = np.array([3.0, 5.0, 4.0, 12.0, 7.0, 3.0, 40.0, 6.0, 5.0, 9.0, 4.0, 18.0])


# ---- bootstrap_ci ------------------------------------------------------------------------------
@pytest.mark.parametrize("method", ["percentile", "BCa"])
@pytest.mark.parametrize("confidence", [0.9, 0.95])
def test_bootstrap_ci_agrees_with_scipy(method: str, confidence: float) -> None:
    ci = bootstrap_ci(SAMPLE, confidence=confidence, n_resamples=2000, method=method, rng=7)
    ref = stats.bootstrap(
        (SAMPLE,),
        np.mean,
        n_resamples=2000,
        confidence_level=confidence,
        method=method,
        rng=np.random.default_rng(7),
    ).confidence_interval
    assert ci.low == pytest.approx(ref.low, abs=1e-12)
    assert ci.high == pytest.approx(ref.high, abs=1e-12)
    assert ci.estimate == pytest.approx(SAMPLE.mean(), abs=1e-12)
    assert ci.n == SAMPLE.size


def test_percentile_matches_a_hand_computed_bootstrap() -> None:
    # scipy draws all resamples at once as rng.integers(0, n, (n_resamples, n)) and takes
    # linear-interpolated quantiles; re-derive the interval from that draw by hand.
    n_resamples, alpha = 3000, 0.05
    rng = np.random.default_rng(11)
    idx = rng.integers(0, SAMPLE.size, (n_resamples, SAMPLE.size))
    means = SAMPLE[idx].mean(axis=-1)
    low, high = np.quantile(means, [alpha / 2, 1 - alpha / 2])
    ci = bootstrap_ci(SAMPLE, n_resamples=n_resamples, method="percentile", rng=11)
    assert ci.low == pytest.approx(low, abs=1e-12)
    assert ci.high == pytest.approx(high, abs=1e-12)


def test_bca_differs_from_percentile_on_skewed_data() -> None:
    p = bootstrap_ci(SAMPLE, method="percentile", n_resamples=2000, rng=1)
    b = bootstrap_ci(SAMPLE, method="BCa", n_resamples=2000, rng=1)
    assert (p.low, p.high) != (b.low, b.high)
    assert b.high > p.high  # BCa shifts right for a right-skewed sample


def test_nan_values_are_ignored() -> None:
    with_nan = np.concatenate([SAMPLE, [np.nan, np.nan]])
    a = bootstrap_ci(with_nan, n_resamples=500, rng=3)
    b = bootstrap_ci(SAMPLE, n_resamples=500, rng=3)
    assert a == b
    assert a.n == SAMPLE.size


def test_degenerate_cases() -> None:
    assert bootstrap_ci([4.0]) == Interval(4.0, 4.0, 4.0, 1)
    assert bootstrap_ci([np.nan, 4.0]) == Interval(4.0, 4.0, 4.0, 1)
    empty = bootstrap_ci([])
    assert empty.n == 0 and all(math.isnan(v) for v in (empty.estimate, empty.low, empty.high))
    assert bootstrap_ci([np.nan, np.nan]).n == 0
    # all equal: BCa is undefined in scipy (warning + NaN); here the point interval
    assert bootstrap_ci([0.0] * 20) == Interval(0.0, 0.0, 0.0, 20)


def test_bca_falls_back_to_percentile_when_undefined() -> None:
    # one outlier among equal values: the jackknife gives no usable acceleration in some
    # resamples; the interval must still be finite and hold the mean
    x = [0.0] * 19 + [1.0]
    ci = bootstrap_ci(x, n_resamples=999, rng=0)
    assert math.isfinite(ci.low) and math.isfinite(ci.high)
    assert ci.low <= ci.estimate <= ci.high


def test_deterministic_and_leaves_global_rng_alone() -> None:
    np.random.seed(123)
    state = np.random.get_state()[1].copy()
    a = bootstrap_ci(SAMPLE, n_resamples=500, rng=5)
    b = bootstrap_ci(SAMPLE, n_resamples=500, rng=5)
    c = bootstrap_ci(SAMPLE, n_resamples=500, rng=6)
    assert a == b
    assert a != c
    assert np.array_equal(np.random.get_state()[1], state)
    g = bootstrap_ci(SAMPLE, n_resamples=500, rng=np.random.default_rng(5))
    assert g == a


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        (
            {"method": "bca"},
            r"method='bca' is outside the allowed range: one of \['percentile', 'BCa'\]",
        ),
        (
            {"confidence": 1.5},
            r"confidence=1\.5 is outside the allowed range: a number in \(0, 1\)",
        ),
        ({"n_resamples": 0}, r"n_resamples=0 is outside the allowed range: an integer in \[1,"),
        ({"rng": -1}, r"rng=-1 is outside the allowed range: an integer in \[0, inf\)"),
    ],
)
def test_bad_arguments_name_value_and_range(kwargs: dict, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        bootstrap_ci(SAMPLE, **kwargs)


def test_infinite_values_rejected() -> None:
    with pytest.raises(ValueError, match=r"values=.* is outside the allowed range: finite"):
        bootstrap_ci([1.0, math.inf])


@settings(max_examples=40, deadline=None)
@given(
    st.lists(st.floats(-1e3, 1e3, allow_nan=False), min_size=2, max_size=15),
    st.floats(-100, 100, allow_nan=False),
)
def test_percentile_interval_properties(values: list[float], shift: float) -> None:
    ci = bootstrap_ci(values, method="percentile", n_resamples=200, rng=0)
    assert min(values) - 1e-9 <= ci.low <= ci.high <= max(values) + 1e-9
    # same resamples after a shift of every value: the interval shifts with them
    moved = bootstrap_ci([v + shift for v in values], method="percentile", n_resamples=200, rng=0)
    assert moved.low == pytest.approx(ci.low + shift, abs=1e-7)
    assert moved.high == pytest.approx(ci.high + shift, abs=1e-7)


# ---- r_fd extras -------------------------------------------------------------------------------
@dataclass
class Cell:
    diagnoser: str
    scenario: str
    seed: int
    fault_onset: int | None
    r_fd: float
    n_alarms: int


def test_share_with_alarm_counts_healthy_episodes_only() -> None:
    cells = [
        Cell("pca", "nominal", 0, None, 0.0, 0),
        Cell("pca", "nominal", 1, None, 0.0005, 2),
        Cell("pca", "nominal", 2, None, 0.0, 0),
        Cell("pca", "nominal", 3, None, 0.0, 0),
        Cell("pca", "f1", 0, 1900, 0.0, 500),  # alarms after the onset: not false
    ]
    assert share_with_alarm(cells) == 0.25
    assert math.isnan(share_with_alarm(cells[-1:]))


def test_worst_returns_the_largest_rfd_and_its_seed() -> None:
    cells = [
        Cell("pca", "nominal", 0, None, 0.01, 40),
        Cell("pca", "f2", 3, 1900, 0.2, 900),
        Cell("pca", "nominal", 1, None, 0.2, 800),
        Cell("pca", "nominal", 2, None, math.nan, 0),
    ]
    assert worst(cells) == Worst(0.2, 1, "nominal")  # tie: smallest seed
    assert worst([cells[-1]]).seed == -1


def test_extras_refuse_mixed_diagnosers() -> None:
    cells = [Cell("pca", "nominal", 0, None, 0.0, 0), Cell("limits", "nominal", 0, None, 0.0, 0)]
    with pytest.raises(
        ValueError,
        match=r"diagnosers of records=\['limits', 'pca'\] is outside the allowed range: a single diagnoser",
    ):
        share_with_alarm(cells)
    with pytest.raises(ValueError, match="a single diagnoser"):
        worst(cells)


# ---- ranks -------------------------------------------------------------------------------------
def iv(est: float, half: float) -> Interval:
    return Interval(est, est - half, est + half, 20)


def test_ranks_without_overlap_are_strict() -> None:
    assert rank_with_ties([iv(3, 0.1), iv(1, 0.1), iv(2, 0.1)], lower_is_better=True) == [
        "3",
        "1",
        "2",
    ]
    assert rank_with_ties([iv(3, 0.1), iv(1, 0.1), iv(2, 0.1)], lower_is_better=False) == [
        "1",
        "3",
        "2",
    ]


def test_overlapping_intervals_tie_and_skip_ranks() -> None:
    ranks = rank_with_ties(
        [iv(1.0, 0.3), iv(1.4, 0.3), iv(5.0, 0.1), iv(6.0, 0.1)], lower_is_better=True
    )
    assert ranks == ["1=", "1=", "3", "4"]


def test_touching_intervals_tie_and_ties_chain() -> None:
    # [0, 2] touches [2, 4] (closed intervals); [2, 4] overlaps [3.5, 5.5] but [0, 2] does not
    ranks = rank_with_ties([iv(1, 1), iv(3, 1), iv(4.5, 1), iv(10, 1)], lower_is_better=True)
    assert ranks == ["1=", "1=", "1=", "4"]


def test_nan_estimates_are_unranked() -> None:
    nan = Interval(math.nan, math.nan, math.nan, 0)
    assert rank_with_ties([nan, iv(1, 0.1)], lower_is_better=True) == [UNRANKED, "1"]


def test_rank_arguments_validated() -> None:
    with pytest.raises(
        ValueError, match=r"lower_is_better='yes' is outside the allowed range: True or False"
    ):
        rank_with_ties([iv(1, 1)], lower_is_better="yes")  # type: ignore[arg-type]
    with pytest.raises(
        ValueError, match=r"intervals\[0\]=\(1, 2\) is outside the allowed range: an Interval"
    ):
        rank_with_ties([(1, 2)], lower_is_better=True)  # type: ignore[list-item]


@settings(max_examples=50, deadline=None)
@given(st.lists(st.tuples(st.floats(0, 100), st.floats(0, 10)), min_size=1, max_size=8))
def test_rank_properties(pairs: list[tuple[float, float]]) -> None:
    ivs = [iv(e, h) for e, h in pairs]
    ranks = rank_with_ties(ivs, lower_is_better=True)
    numbers = [int(r.rstrip("=")) for r in ranks]
    order = sorted(range(len(ivs)), key=lambda i: ivs[i].estimate)
    assert numbers[order[0]] == 1
    for a, b in itertools.pairwise(order):
        assert numbers[a] <= numbers[b]
        # a new rank starts exactly where neighbouring intervals are disjoint
        assert (numbers[a] == numbers[b]) == ivs[a].overlaps(ivs[b])
    for i, r in enumerate(ranks):
        assert r.endswith("=") == (numbers.count(numbers[i]) > 1)


# ---- limit ratio -------------------------------------------------------------------------------
def test_limit_ratio_formula() -> None:
    assert limit_ratio(9, 4) == 2.0
    assert limit_ratio(0, 0) == 1.0
    assert limit_ratio(0.0, 9.0) == pytest.approx(0.1)
    assert math.isnan(limit_ratio(math.nan, 3.0))
    assert math.isnan(limit_ratio(3.0, math.nan))
    with pytest.raises(
        ValueError, match=r"t_dt=-2 is outside the allowed range: a number in \[0, inf\) samples"
    ):
        limit_ratio(-2, 3)


def test_limit_ratio_ci_is_a_paired_bootstrap_of_the_ratio_of_means() -> None:
    rng = np.random.default_rng(0)
    oracle = rng.integers(0, 10, 15).astype(float)
    t = oracle * 2 + rng.integers(0, 20, 15)
    t[3] = np.nan  # missed by the detector
    oracle[7] = np.nan  # missed by the oracle
    ci = limit_ratio_ci(t, oracle, n_resamples=1500, method="percentile", rng=4)
    keep = ~np.isnan(t) & ~np.isnan(oracle)
    a, b = t[keep] + 1, oracle[keep] + 1
    assert ci.n == 13
    assert ci.estimate == pytest.approx(a.mean() / b.mean(), abs=1e-12)
    assert ci.estimate == pytest.approx(limit_ratio(np.mean(t[keep]), np.mean(oracle[keep])))
    # by hand: one index draw shared by both arrays (paired), then the percentile interval
    idx = np.random.default_rng(4).integers(0, ci.n, (1500, ci.n))
    ratios = a[idx].mean(axis=-1) / b[idx].mean(axis=-1)
    low, high = np.quantile(ratios, [0.025, 0.975])
    assert ci.low == pytest.approx(low, abs=1e-12)
    assert ci.high == pytest.approx(high, abs=1e-12)
    bca = limit_ratio_ci(t, oracle, n_resamples=1500, rng=4)
    assert bca.low <= bca.estimate <= bca.high


def test_limit_ratio_ci_degenerate_and_validation() -> None:
    assert limit_ratio_ci([4.0], [1.0]) == Interval(2.5, 2.5, 2.5, 1)
    assert limit_ratio_ci([1.0, 3.0], [1.0, 3.0]) == Interval(1.0, 1.0, 1.0, 2)
    assert limit_ratio_ci([np.nan], [1.0]).n == 0
    with pytest.raises(
        ValueError, match=r"len\(oracle_t_dt\)=2 is outside the allowed range: 3, one per seed"
    ):
        limit_ratio_ci([1.0, 2.0, 3.0], [1.0, 2.0])
