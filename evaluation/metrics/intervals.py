"""Figures you can trust: bootstrap intervals over seeds, tie-aware ranks, the limit ratio.

Pure functions, no I/O, never the global random state. Every interval is over the seeds of one
(diagnoser, scenario) group, i.e. it says how much the mean would move with other seeds.

* :func:`bootstrap_ci` - confidence interval of the mean over seeds (:class:`Interval`).
* :func:`share_with_alarm`, :func:`worst` - what a mean r_fd hides (any alarm at all, worst seed).
* :func:`rank_with_ties` - ranks ``"1"``, ``"2="``, ``"2="``, ``"4"`` that do not claim an order
  the intervals cannot support.
* :func:`limit_ratio`, :func:`limit_ratio_ci` - detection time relative to the physical limit
  (an oracle detector), with a paired interval.

>>> ci = bootstrap_ci([0.0, 0.25, 0.5, 0.75], method="percentile", n_resamples=999, rng=0)
>>> ci.estimate, ci.n, ci.low <= ci.estimate <= ci.high
(0.375, 4, True)
>>> rank_with_ties(
...     [Interval(1.0, 0.9, 1.1, 20), Interval(1.05, 1.0, 1.2, 20), Interval(3.0, 2.9, 3.1, 20)],
...     lower_is_better=True,
... )
['1=', '1=', '3']
>>> limit_ratio(9.0, 4.0)
2.0
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple, Protocol

import numpy as np
from scipy import stats

from fcc_common.validation import Boolean, Integer, Options, Real, check, invalid

__all__ = [
    "BOOTSTRAP_METHODS",
    "DEFAULT_N_RESAMPLES",
    "Interval",
    "Worst",
    "bootstrap_ci",
    "limit_ratio",
    "limit_ratio_ci",
    "rank_with_ties",
    "share_with_alarm",
    "worst",
]

#: Interval methods of :func:`bootstrap_ci` (scipy's names, matched exactly).
BOOTSTRAP_METHODS: tuple[str, ...] = ("percentile", "BCa")
#: Resamples per interval: scipy's default; the Monte-Carlo error of a 95 % percentile bound is
#: then about 1 % of the interval's width, well below the seed-to-seed spread it measures.
DEFAULT_N_RESAMPLES = 9999
#: Rank label of an entry whose estimate is undefined (``nan``): it is listed last, unranked.
UNRANKED = "–"

_CONFIDENCE = Real(0.0, 1.0, closed="neither")
_N_RESAMPLES = Integer(1, 10_000_000)


@dataclass(frozen=True)
class Interval:
    """A point estimate (the mean over seeds) with a confidence interval ``[low, high]``.

    ``n`` is the number of values the interval rests on (NaN values excluded). With ``n == 1``
    the interval is degenerate (``low == high == estimate``); with ``n == 0`` all three are NaN.
    """

    estimate: float
    low: float
    high: float
    n: int

    def overlaps(self, other: Interval) -> bool:
        """Closed intervals share at least one point (``False`` when either is NaN)."""
        return self.low <= other.high and other.low <= self.high

    def to_json(self) -> dict[str, Any]:
        return {"estimate": self.estimate, "low": self.low, "high": self.high, "n": self.n}


def _as_rng(rng: int | np.random.Generator) -> np.random.Generator:
    if isinstance(rng, np.random.Generator):
        return rng
    return np.random.default_rng(check("rng", rng, Integer(0)))


def _finite_values(name: str, values: Iterable[float]) -> np.ndarray:
    x = np.asarray(list(values) if not isinstance(values, np.ndarray) else values, dtype=float)
    if x.ndim != 1:
        raise invalid(name, values, "a 1-D sequence of numbers")
    if np.isinf(x).any():
        raise invalid(name, values, "finite numbers or NaN", "an infinite value has no mean")
    return x


def bootstrap_ci(
    values: Iterable[float],
    *,
    confidence: float = 0.95,
    n_resamples: int = DEFAULT_N_RESAMPLES,
    method: str = "BCa",
    rng: int | np.random.Generator = 0,
) -> Interval:
    """Bootstrap confidence interval of the mean of ``values`` (one value per seed).

    NaN values are dropped first (a missed fault has no detection time; report misses apart):
    the interval is that of the mean over the defined values and ``n`` counts them.

    Why scipy: the resampling is :func:`scipy.stats.bootstrap` itself (vectorised, one
    ``rng.integers(0, n, (n_resamples, n))`` draw, quantiles by linear interpolation), so the
    percentile and BCa formulas are scipy's, maintained and tested there; this function adds the
    project's conventions around it (NaN handling, degenerate cases, a seed instead of the
    global RNG). ``tests/test_intervals.py`` re-derives the percentile interval by hand from the
    same draw and requires agreement to 1e-12.

    Method: ``"BCa"`` (the default) corrects for bias and skew, and per-seed scores are skewed
    (r_fd is mostly 0 with a few large values, detection times have a long right tail);
    ``"percentile"`` is the plain quantile interval. When BCa is undefined (the jackknife
    values are all equal, e.g. one outlier among equal values) the percentile interval of the
    same bootstrap distribution is returned instead.

    Args:
        values: one number per seed; NaN allowed (ignored), infinities refused.
        confidence: two-sided confidence level in (0, 1).
        n_resamples: bootstrap resamples.
        method: one of :data:`BOOTSTRAP_METHODS`.
        rng: an integer seed or a ``numpy.random.Generator``; the global RNG is never used.

    Returns:
        :class:`Interval` with ``estimate`` the mean of the non-NaN values.
    """
    confidence = check("confidence", confidence, _CONFIDENCE)
    n_resamples = check("n_resamples", n_resamples, _N_RESAMPLES)
    method = check("method", method, Options(BOOTSTRAP_METHODS))
    gen = _as_rng(rng)
    x = _finite_values("values", values)
    x = x[~np.isnan(x)]
    n = int(x.size)
    if n == 0:
        return Interval(math.nan, math.nan, math.nan, 0)
    mean = float(np.mean(x))
    if n == 1 or np.all(x == x[0]):
        # every resample is the sample itself: the bootstrap distribution is a point
        return Interval(mean, mean, mean, n)
    low, high = _scipy_interval((x,), np.mean, False, confidence, n_resamples, method, gen)
    return Interval(mean, low, high, n)


def _scipy_interval(
    data: tuple[np.ndarray, ...],
    statistic: Any,
    paired: bool,
    confidence: float,
    n_resamples: int,
    method: str,
    gen: np.random.Generator,
) -> tuple[float, float]:
    """``scipy.stats.bootstrap``'s interval; where BCa is undefined (NaN), the percentile
    interval of the same resamples."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", stats.DegenerateDataWarning)
        kw = {"paired": paired, "vectorized": True, "confidence_level": confidence}
        res = stats.bootstrap(
            data, statistic, n_resamples=n_resamples, method=method, rng=gen, **kw
        )
        low, high = float(res.confidence_interval.low), float(res.confidence_interval.high)
        if math.isnan(low) or math.isnan(high):
            res = stats.bootstrap(
                data, statistic, n_resamples=0, method="percentile", bootstrap_result=res, **kw
            )
            low, high = float(res.confidence_interval.low), float(res.confidence_interval.high)
    return low, high


# ---- r_fd extras -------------------------------------------------------------------------------
class _Record(Protocol):
    """The fields of :class:`evaluation.sweep.CellResult` used here."""

    diagnoser: str
    scenario: str
    seed: int
    fault_onset: int | None
    r_fd: float
    n_alarms: int


class Worst(NamedTuple):
    """The largest false detection rate of a set of episodes and where it happened."""

    r_fd: float
    seed: int
    scenario: str


def _one_diagnoser(records: Sequence[_Record]) -> None:
    labels = sorted({r.diagnoser for r in records})
    if len(labels) > 1:
        raise invalid(
            "diagnosers of records", labels, "a single diagnoser", "group cells by diagnoser first"
        )


def share_with_alarm(records: Sequence[_Record]) -> float:
    """Share of the healthy episodes (``fault_onset is None``) with at least one alarm.

    A mean r_fd of 0.001 can be one alarmed sample in every episode or a long false alarm in one:
    an operator sees the first as an alarm per shift. Faulty episodes are ignored (their alarms
    after the onset are true ones). ``nan`` when there is no healthy episode. ``records`` must
    belong to one diagnoser.

    >>> from types import SimpleNamespace as C
    >>> cells = [C(diagnoser="pca", scenario="nominal", seed=s, fault_onset=None, r_fd=f,
    ...            n_alarms=a) for s, f, a in [(0, 0.0, 0), (1, 0.01, 40), (2, 0.0, 0)]]
    >>> round(share_with_alarm(cells), 3), worst(cells)
    (0.333, Worst(r_fd=0.01, seed=1, scenario='nominal'))
    """
    _one_diagnoser(records)
    healthy = [r for r in records if r.fault_onset is None]
    if not healthy:
        return math.nan
    return sum(int(r.n_alarms) > 0 for r in healthy) / len(healthy)


def worst(records: Sequence[_Record]) -> Worst:
    """The largest r_fd over ``records`` (healthy and faulty: r_fd is defined on both) with its
    seed and scenario; ties go to the smallest seed, then scenario. NaN r_fd values are skipped;
    with none left the result is ``Worst(nan, -1, "")``. ``records`` must belong to one diagnoser.
    """
    _one_diagnoser(records)
    scored = [r for r in records if not math.isnan(r.r_fd)]
    if not scored:
        return Worst(math.nan, -1, "")
    best = min(scored, key=lambda r: (-r.r_fd, r.seed, r.scenario))
    return Worst(float(best.r_fd), int(best.seed), str(best.scenario))


# ---- ranks -------------------------------------------------------------------------------------
def rank_with_ties(intervals: Sequence[Interval], *, lower_is_better: bool) -> list[str]:
    """Competition ranks that tie entries whose intervals overlap; aligned with ``intervals``.

    Rule: sort by estimate (best first; equal estimates keep their input order). Walking down
    that order, an entry shares the rank of the entry just above it when their closed intervals
    overlap, otherwise it starts a new rank equal to its position (1-based). Tied ranks carry an
    ``=`` (``"2="``); a rank held by one entry has none. Ties chain: if A overlaps B and B
    overlaps C, all three share A's rank even when A and C do not overlap, because no order
    between neighbours is supported and the chain is the honest reading. Entries with a NaN
    estimate are listed as :data:`UNRANKED`.

    >>> rank_with_ties([Interval(5, 4, 6, 9), Interval(1, 0, 2, 9)], lower_is_better=False)
    ['1', '2']
    """
    lower_is_better = check("lower_is_better", lower_is_better, Boolean())
    for i, iv in enumerate(intervals):
        if not isinstance(iv, Interval):
            raise invalid(f"intervals[{i}]", iv, "an Interval")
    sign = 1.0 if lower_is_better else -1.0
    ranked = [i for i, iv in enumerate(intervals) if not math.isnan(iv.estimate)]
    ranked.sort(key=lambda i: sign * intervals[i].estimate)
    rank = [0] * len(intervals)
    for pos, i in enumerate(ranked):
        prev = ranked[pos - 1] if pos else None
        if prev is not None and intervals[i].overlaps(intervals[prev]):
            rank[i] = rank[prev]
        else:
            rank[i] = pos + 1
    counts: dict[int, int] = {}
    for i in ranked:
        counts[rank[i]] = counts.get(rank[i], 0) + 1
    labels = [UNRANKED] * len(intervals)
    for i in ranked:
        labels[i] = f"{rank[i]}=" if counts[rank[i]] > 1 else str(rank[i])
    return labels


# ---- the physical limit ------------------------------------------------------------------------
def limit_ratio(t_dt: float, oracle_t_dt: float) -> float:
    """Detection time relative to the physical limit: ``(t_dt + 1) / (oracle_t_dt + 1)``.

    Both times are counted from 1 (a detection at the onset sample counts as one sample) so the
    ratio stays finite when the oracle detects at once. 1 means as fast as physically possible.
    NaN (a miss) in either gives NaN.
    """
    for _name, v in (("t_dt", t_dt), ("oracle_t_dt", oracle_t_dt)):
        if isinstance(v, float | np.floating) and math.isnan(v):
            return math.nan
    t = check("t_dt", t_dt, Real(0.0, unit="samples"))
    o = check("oracle_t_dt", oracle_t_dt, Real(0.0, unit="samples"))
    return (t + 1.0) / (o + 1.0)


def limit_ratio_ci(
    t_dt: Sequence[float],
    oracle_t_dt: Sequence[float],
    *,
    confidence: float = 0.95,
    n_resamples: int = DEFAULT_N_RESAMPLES,
    method: str = "BCa",
    rng: int | np.random.Generator = 0,
) -> Interval:
    """Paired interval of the limit ratio over seeds detected by both detectors.

    ``t_dt[i]`` and ``oracle_t_dt[i]`` belong to the same seed (same episode); seeds where
    either is NaN (a miss) are dropped and ``n`` counts the rest. The statistic is the ratio of
    means, ``mean(t_dt + 1) / mean(oracle_t_dt + 1)``, i.e. :func:`limit_ratio` of the mean
    detection times the tables report, so estimate and table agree. The seeds are resampled in
    pairs (``paired=True``), which keeps the seed-to-seed correlation of the two times (a hard
    seed is late for both) and so narrows the interval. Per-seed ratios were not chosen: their
    mean is dominated by the seeds where the oracle detects within a sample or two (denominator
    near 1), a heavy tail that a mean over 20 seeds cannot tame.

    >>> limit_ratio_ci([9.0, 19.0], [4.0, 9.0], method="percentile", n_resamples=99).estimate
    2.0
    """
    confidence = check("confidence", confidence, _CONFIDENCE)
    n_resamples = check("n_resamples", n_resamples, _N_RESAMPLES)
    method = check("method", method, Options(BOOTSTRAP_METHODS))
    gen = _as_rng(rng)
    t = _finite_values("t_dt", t_dt)
    o = _finite_values("oracle_t_dt", oracle_t_dt)
    if t.shape != o.shape:
        raise invalid("len(oracle_t_dt)", o.size, f"{t.size}, one per seed of t_dt")
    if (t < 0).any() or (o < 0).any():
        raise invalid("t_dt", t_dt, "detection times >= 0 or NaN")
    both = ~np.isnan(t) & ~np.isnan(o)
    t, o = t[both] + 1.0, o[both] + 1.0
    n = int(t.size)
    if n == 0:
        return Interval(math.nan, math.nan, math.nan, 0)
    estimate = float(np.mean(t) / np.mean(o))
    ratios = t / o
    if n == 1 or (np.all(t == t[0]) and np.all(o == o[0])) or np.all(ratios == ratios[0]):
        # every paired resample gives the same ratio of means
        return Interval(estimate, estimate, estimate, n)

    def ratio_of_means(a: np.ndarray, b: np.ndarray, axis: int = -1) -> np.ndarray:
        return np.mean(a, axis=axis) / np.mean(b, axis=axis)

    low, high = _scipy_interval((t, o), ratio_of_means, True, confidence, n_resamples, method, gen)
    return Interval(estimate, low, high, n)
