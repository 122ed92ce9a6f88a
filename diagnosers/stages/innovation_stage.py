"""The alarm stage of a filter's whitened innovations: a GLR per fault direction, a variance
CUSUM for anything else, one shared tail for their limits (:class:`InnovationStage`).

A state estimator's whitened innovations ``e_t`` (``n`` channels) are standard normal and white
while its model is right, so the tests on them are the textbook ones (Willsky & Jones 1976;
Basseville & Nikiforov 1993, ch. 7):

1. per fault direction ``d_g`` (a unit vector: the fault's innovation signature), the
   window-limited GLR of a step of unknown size and onset along it,
   :class:`~diagnosers.stages.alarm.DirectionalGLR` on the matched innovation ``a_t = d_gᵀe_t``;
2. an omnibus for any other departure: Page's CUSUM (:class:`~diagnosers.stages.alarm.CUSUM`)
   of the log-likelihood ratio of an innovation covariance ``v`` times larger,
   :func:`variance_llr`, which a mean shift of any direction also drives up (its NIS grows by
   the shift's square);
3. an alarm when any statistic passes its limit; the limits share one tail
   (:func:`union_limits`): each is its statistic's healthy ``1 − p`` quantile, ``p`` chosen so
   that the *union* alarms on the target share of the calibration samples, so that no
   statistic's scale buys it the false alarms.

Optionally (``bias_memory``) the innovations first lose their slowly varying mean
(:class:`BiasTracker`): a model that is wrong in a way it does not estimate (a plant's
undeclared heat loss, a drifting activity) leaves a per-plant bias that a 1000-sample GLR
accumulates into an alarm; what is tested then is a *change* against the recent past.

Used by ``ukf-glr`` (:mod:`diagnosers.filters.ukf_glr`) and by the reachable-bound reference
row (:mod:`evaluation.tracks.filter_bound`), the same formulas in both.

>>> rng = np.random.default_rng(0)
>>> stage = InnovationStage(np.eye(2)[:1], window=50)
>>> stage.fit([rng.standard_normal((5000, 2))], 0.01).limits_.shape
(2,)
>>> e = rng.standard_normal((300, 2)); stats_ = stage.statistics(e)
>>> stage.reset(); bool(np.allclose(np.array([stage.step(x) for x in e]), stats_))
True
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from diagnosers.stages.alarm import CUSUM, DirectionalGLR
from fcc_common.validation import Integer, Real, check, invalid

__all__ = [
    "DEFAULT_GLR_WINDOW",
    "OMNIBUS_VARIANCE",
    "BiasTracker",
    "InnovationStage",
    "union_limits",
    "variance_llr",
]

#: Samples the GLR looks back for a change's start (1000: as long as the shortest incipient
#: ramps of the tracks, so a ramp is seen whole; beyond it a start changes little).
DEFAULT_GLR_WINDOW = 1000
#: The omnibus CUSUM's alternative: the innovations' covariance times this.
OMNIBUS_VARIANCE = 2.0


class BiasTracker:
    """Each channel's slowly varying mean of the whitened innovations, removed as it goes.

    ``out_t = (e_t − m_{t−1}) / sqrt(1 + var m_{t−1})`` with ``m`` the running mean of the
    finite samples so far, turning into an exponential average of memory ``memory`` samples
    (``λ_t = max(1/k, 1/memory)``); ``var m`` is its variance on white unit innovations, so
    that ``out`` stays white and of unit variance under the healthy model (the recursive
    residuals of a constant mean) while a constant bias leaves it within ``memory`` samples.
    A step (a fault) passes at once and fades over ``memory`` samples. A sample with a
    non-finite entry passes as NaN and is not learnt from.

    >>> t = BiasTracker(100); e = np.full((500, 1), 0.7)
    >>> out = t.filter(e); float(abs(out[-1, 0])) < 1e-9, float(out[0, 0])
    (True, 0.7)
    """

    def __init__(self, memory: int) -> None:
        self.memory = check("memory", memory, Integer(1))
        self.reset()

    def reset(self) -> None:
        self._m: np.ndarray | None = None
        self._var = 0.0
        self._k = 0

    def update(self, e: np.ndarray) -> np.ndarray:
        """The de-biased ``(n,)`` of one sample ``e`` ``(n,)``."""
        e = np.asarray(e, dtype=np.float64)
        if self._m is None:
            self._m = np.zeros_like(e)
        if not np.isfinite(e).all():
            return np.full_like(e, np.nan)
        out = (e - self._m) / math.sqrt(1.0 + self._var)
        lam = max(1.0 / (self._k + 1), 1.0 / self.memory)
        self._m += lam * (e - self._m)
        self._var = (1.0 - lam) ** 2 * self._var + lam * lam
        self._k += 1
        return out

    def filter(self, e: np.ndarray) -> np.ndarray:
        """The de-biased ``(T, n)`` of a whole sequence ``e`` ``(T, n)``, from a fresh start
        (the tracker's own state is left alone)."""
        fresh = BiasTracker(self.memory)
        e = np.asarray(e, dtype=np.float64)
        return np.array([fresh.update(x) for x in e]).reshape(e.shape)


def union_limits(stats: np.ndarray, target: float, *, iterations: int = 40) -> np.ndarray:
    """Limits ``(k,)`` of ``k`` statistics ``stats`` ``(N, k)`` (healthy samples): each its
    ``1 − p`` quantile, ``p`` the largest (bisection) with at most ``target`` of the samples
    over any limit.

    >>> z = np.random.default_rng(0).normal(size=(10_000, 3))
    >>> h = union_limits(z, 0.01)
    >>> bool(abs(float(np.mean((z > h).any(axis=1))) - 0.01) < 0.002)
    True
    """
    target = check("target", target, Real(0.0, 1.0, closed="neither"))
    stats = np.asarray(stats, dtype=np.float64)
    if stats.ndim != 2 or stats.shape[0] == 0:
        raise invalid("stats", f"shape {stats.shape}", "a (samples, statistics) array")
    lo, hi = target / stats.shape[1], target  # the union's share lies in [p, k·p]
    for _ in range(iterations):
        p = 0.5 * (lo + hi)
        share = np.mean((stats > np.quantile(stats, 1.0 - p, axis=0)).any(axis=1))
        lo, hi = (p, hi) if share <= target else (lo, p)
    return np.quantile(stats, 1.0 - lo, axis=0)


def variance_llr(nis: np.ndarray, n_channels: int, variance: float) -> np.ndarray:
    """Per sample, the log-likelihood ratio of ``e ~ N(0, v·I)`` against ``N(0, I)`` from the
    normalised innovation squared ``NIS = |e|²``: ``½(1 − 1/v)·NIS − (n/2)·ln v``.

    >>> float(variance_llr(np.array([8.0]), 8, 2.0)[0]).__round__(4)
    -0.7726
    """
    v = float(variance)
    return 0.5 * (1.0 - 1.0 / v) * np.asarray(nis, dtype=np.float64) - 0.5 * n_channels * math.log(
        v
    )


class InnovationStage:
    """GLRs along fault directions and a variance CUSUM on whitened innovations (module
    docstring), with limits on one shared tail.

    Args:
        directions: unit fault directions ``(k, n)`` in the whitened innovations' space (one GLR
            each; ``k`` may be 0: the omnibus alone).
        window: the GLR's onset search window [samples], ≥ 1.
        omnibus_variance: the omnibus CUSUM's alternative covariance factor, > 1.
        bias_memory: when set, the innovations lose their slowly varying mean
            (:class:`BiasTracker` of this memory, samples) before both tests; ``None`` (the
            default): tested as they are.

    Statistics, in order: ``glr[0..k−1]``, then the omnibus. A non-finite innovation (a sample
    the filter skipped) counts as zero: it carries no evidence.

    Attributes:
        limits_: ``(k + 1,)`` after :meth:`fit` (or :meth:`set_state`).
    """

    def __init__(
        self,
        directions: np.ndarray,
        *,
        window: int = DEFAULT_GLR_WINDOW,
        omnibus_variance: float = OMNIBUS_VARIANCE,
        bias_memory: int | None = None,
    ) -> None:
        d = np.asarray(directions, dtype=np.float64)
        if d.ndim != 2:
            raise invalid("directions", f"shape {d.shape}", "a (k, n) array of unit directions")
        self.directions = d
        self.window = check("window", window, Integer(1))
        self.omnibus_variance = check(
            "omnibus_variance", omnibus_variance, Real(1.0, 100.0, closed="right")
        )
        self.bias_memory = (
            None if bias_memory is None else check("bias_memory", bias_memory, Integer(1))
        )
        self._glr = DirectionalGLR(self.window)
        self._cusum = CUSUM(0.0)
        self._bias = None if self.bias_memory is None else BiasTracker(self.bias_memory)

    @property
    def n_statistics(self) -> int:
        return self.directions.shape[0] + 1

    def _parts(self, e: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(matched innovations ``(…, k)``, variance LLR ``(…,)``) of innovations ``(…, n)``."""
        e = np.where(np.isfinite(e), e, 0.0)
        llr = variance_llr(np.sum(e**2, axis=-1), e.shape[-1], self.omnibus_variance)
        return e @ self.directions.T, llr

    def statistics(self, e: np.ndarray) -> np.ndarray:
        """The statistics ``(T, k + 1)`` of one sequence of innovations ``e`` ``(T, n)``."""
        e = np.asarray(e, dtype=np.float64)
        if self._bias is not None:
            e = self._bias.filter(e)
        a, llr = self._parts(e)
        glr = self._glr.filter(a) if a.shape[1] else np.zeros((a.shape[0], 0))
        return np.column_stack([glr, self._cusum.filter(llr[:, None])])

    def matched(self, e: np.ndarray) -> np.ndarray:
        """``(T, k + 1)``: the matched innovations ``d_gᵀe_t`` and the NIS (what each statistic
        accumulates, before any de-biasing; the decisions' residual)."""
        e = np.asarray(e, dtype=np.float64)
        clean = np.where(np.isfinite(e), e, 0.0)
        return np.column_stack([clean @ self.directions.T, np.sum(clean**2, axis=-1)])

    def reset(self) -> None:
        """Start a new sequence for :meth:`step`."""
        self._glr.reset()
        self._cusum.reset()
        if self._bias is not None:
            self._bias.reset()

    def step(self, e: np.ndarray) -> np.ndarray:
        """The statistics ``(k + 1,)`` after one more innovation ``(n,)``; equals the same row
        of :meth:`statistics` (to rounding: the GLR sums in another order)."""
        e = np.asarray(e, dtype=np.float64)
        if self._bias is not None:
            e = self._bias.update(e)
        a, llr = self._parts(e)
        glr = self._glr.update(a) if a.shape[0] else np.zeros(0)
        return np.concatenate([glr, self._cusum.update(np.atleast_1d(llr))])

    def fit(self, healthy: Sequence[np.ndarray], target: float) -> InnovationStage:
        """Set the limits on healthy innovation sequences (each ``(T_i, n)``) so that the
        union alarms on at most ``target`` of their samples."""
        if not healthy:
            raise invalid("healthy", healthy, "at least one sequence of healthy innovations")
        stats = np.concatenate([self.statistics(e) for e in healthy])
        self.limits_ = union_limits(stats, target)
        return self

    def alarm(self, stats: np.ndarray) -> np.ndarray:
        """Whether any statistic is over its limit, per row of ``stats`` ``(…, k + 1)``."""
        return np.any(stats > self.limits_, axis=-1)
