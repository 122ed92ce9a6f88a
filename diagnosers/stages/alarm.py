"""The alarm stage as small parts: residual filters, statistics and limit calibration.

A residual-based detector ends in the same three steps whatever its model: filter the normalised
residuals over time (:class:`EWMA`), combine the channels into one statistic
(:class:`HotellingT2`), and compare with a limit set on healthy calibration data
(:func:`calibrate_limit`). The parts here know nothing about diagnosers, so detectors, baselines
and the evaluation's oracle rows compose the same code.

Every streaming part follows :class:`ResidualEvaluator`: ``reset()`` starts a sequence,
``update(x)`` consumes one sample, ``filter(X)`` evaluates a whole sequence (time on axis 0) and
equals ``reset()`` then ``update`` on every row, and ``get_state``/``set_state`` carry what a
saved detector needs. The sequential tests :class:`CUSUM` and :class:`DirectionalGLR` slot in
beside :class:`EWMA`; :class:`DirectionalProjection` turns a residual vector into one
standardised score per known fault direction (the matched filter those tests run on).

>>> import numpy as np
>>> ewma = EWMA(0.5)
>>> ewma.filter(np.array([[2.0], [0.0], [0.0]]))[:, 0].tolist()
[1.0, 0.5, 0.25]
>>> ewma.reset(); [float(ewma.update(np.array([2.0]))[0]) for _ in range(2)]
[1.0, 1.5]
>>> t2 = HotellingT2(centered=False).fit(np.array([[1.0, 0.0], [-1.0, 0.0], [0.0, 2.0], [0.0, -2.0]]))
>>> float(t2.score(np.array([1.0, 2.0])))
3.0
>>> calibrate_limit(np.arange(1000.0)[:, None], 0.01, method="empirical").round(2).tolist()
[989.01]
"""

from __future__ import annotations

import functools
from enum import StrEnum
from typing import Protocol, runtime_checkable

import numpy as np
from scipy import stats

from fcc_common.validation import Integer, Options, Real, check

__all__ = [
    "CUSUM",
    "EWMA",
    "TAIL_FIT_QUANTILE",
    "DirectionalGLR",
    "DirectionalProjection",
    "HotellingT2",
    "LimitMethod",
    "OnDelay",
    "RecursiveStatistic",
    "ResidualEvaluator",
    "calibrate_limit",
    "chi2_tail_limit",
    "empirical_limit",
    "normal_tail_limit",
    "two_sided_normal_quantile",
]

#: calibration quantile at which ``"chi2-tail"`` measures the tail inflation
TAIL_FIT_QUANTILE = 0.99


@functools.lru_cache(maxsize=64)
def two_sided_normal_quantile(alpha: float) -> float:
    """``t_α = Φ⁻¹(1 - α/2)``: standard normal quantile with ``alpha`` split over both tails.

    Cached because band detectors ask for it at every sample.

    >>> round(two_sided_normal_quantile(0.01), 4)
    2.5758
    """
    alpha = check("alpha", alpha, Real(0, 1, closed="neither"))
    return float(stats.norm.ppf(1.0 - alpha / 2.0))


@runtime_checkable
class ResidualEvaluator(Protocol):
    """A streaming evaluator of residuals (filter or sequential test); time runs along axis 0."""

    def reset(self) -> None:
        """Start a new sequence."""

    def update(self, x: np.ndarray) -> np.ndarray:
        """Consume one sample ``x`` (shape ``(k,)``) and return the output for it."""

    def filter(self, X: np.ndarray) -> np.ndarray:
        """Outputs for a whole sequence ``X`` (shape ``(T, k)``) from a fresh start.

        Equal to ``reset()`` then ``update`` on every row; the streaming state is left untouched.
        """

    def get_state(self) -> dict[str, np.ndarray]:
        """Learned numeric state as named arrays (empty for a part with none)."""

    def set_state(self, state: dict[str, np.ndarray]) -> None:
        """Inverse of :meth:`get_state`."""


class RecursiveStatistic:
    """A statistic defined by one recursion ``s(k) = step(x(k), s(k-1))``, ``s(-1) = 0``.

    Subclasses write only :meth:`_step`; streaming :meth:`update` and batch :meth:`filter` both
    call it, so the two agree to the bit. Nothing is learned (``get_state`` is empty).
    """

    def reset(self) -> None:
        self._s: np.ndarray | None = None

    def _step(self, x: np.ndarray, s: np.ndarray) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def update(self, x: np.ndarray) -> np.ndarray:
        x = np.asarray(x, dtype=np.float64)
        self._s = self._step(x, np.zeros_like(x) if self._s is None else self._s)
        return self._s

    def filter(self, X: np.ndarray) -> np.ndarray:
        X = np.asarray(X, dtype=np.float64)
        out = np.empty_like(X)
        s = np.zeros(X.shape[1:])
        for k in range(X.shape[0]):
            s = self._step(X[k], s)
            out[k] = s
        return out

    def get_state(self) -> dict[str, np.ndarray]:
        return {}

    def set_state(self, state: dict[str, np.ndarray]) -> None:
        pass  # nothing learned: the recursion's constants are hyperparameters


class EWMA(RecursiveStatistic):
    """Exponentially weighted moving average ``z(k) = λ x(k) + (1 - λ) z(k-1)``, ``z(-1) = 0``.

    Args:
        lam: weight of the newest sample, in (0, 1]; ``1`` passes the input through.

    Shape: ``update`` ``(k,) -> (k,)``; ``filter`` ``(T, k) -> (T, k)``.
    """

    def __init__(self, lam: float) -> None:
        self.lam = check("lam", lam, Real(0, 1, closed="right"))
        self.reset()

    def _step(self, x: np.ndarray, z: np.ndarray) -> np.ndarray:
        # The one place the recursion is written: streaming and batch must agree to the bit.
        return self.lam * x + (1.0 - self.lam) * z


class HotellingT2:
    """Hotelling's T² ``(z - μ)ᵀ S⁺ (z - μ)`` with ``μ`` and ``S`` learned on calibration vectors.

    Args:
        centered: learn ``μ`` as the calibration mean; ``False`` fixes ``μ = 0`` (for residual
            filters whose healthy output is zero-mean by construction, where a short calibration
            would only add the noise of its mean).

    Attributes:
        mean_: ``μ``, shape ``(k,)``.
        precision_: ``S⁺``, the pseudo-inverse of the calibration covariance (ddof 1), ``(k, k)``.
    """

    def __init__(self, *, centered: bool = True) -> None:
        self.centered = centered

    def fit(self, Z: np.ndarray) -> HotellingT2:
        """Learn ``mean_`` and ``precision_`` from calibration vectors ``Z`` (shape ``(T, k)``)."""
        Z = np.asarray(Z, dtype=np.float64)
        self.mean_ = Z.mean(axis=0) if self.centered else np.zeros(Z.shape[1])
        self.precision_ = np.linalg.pinv(np.atleast_2d(np.cov(Z.T)))
        return self

    def score(self, Z: np.ndarray) -> np.ndarray | float:
        """T² of one vector ``(k,) -> float`` or of each row ``(T, k) -> (T,)``."""
        d = np.asarray(Z, dtype=np.float64) - self.mean_
        if d.ndim == 1:
            return d @ self.precision_ @ d
        return np.einsum("ti,ij,tj->t", d, self.precision_, d)

    def get_state(self) -> dict[str, np.ndarray]:
        return {"mean": self.mean_, "precision": self.precision_}

    def set_state(self, state: dict[str, np.ndarray]) -> None:
        self.mean_ = np.asarray(state["mean"], dtype=np.float64)
        self.precision_ = np.asarray(state["precision"], dtype=np.float64)


class LimitMethod(StrEnum):
    """How :func:`calibrate_limit` turns a healthy calibration statistic into an alarm limit."""

    EMPIRICAL = "empirical"
    CHI2_TAIL = "chi2-tail"


def empirical_limit(stat: np.ndarray, target: float) -> np.ndarray:
    """Calibration quantile at ``1 - target`` of each column of ``stat`` ``(T, c) -> (c,)``."""
    return np.quantile(stat, 1.0 - target, axis=0)


def chi2_tail_limit(
    stat: np.ndarray, target: float, dof: int, *, tail_quantile: float = TAIL_FIT_QUANTILE
) -> np.ndarray:
    """Reference quantile at ``1 - target`` scaled by the calibration's tail inflation.

    The reference is χ²_dof for ``dof >= 1`` (a T² column) and, for ``dof = 0``, the normal with
    each column's RMS as its scale (columns of |EWMA|). The inflation is
    ``max(1, q_emp(tail_quantile) / q_ref(tail_quantile))``. Why: a calibration of a few strongly
    autocorrelated episodes puts its empirical 0.998 quantile on a few dozen dependent samples,
    dominated by single excursions, while its 0.99 quantile is stable and the reference tail
    extrapolates it. Shape: ``(T, c) -> (c,)``.
    """
    inflation, ref_target = _chi2_tail_parts(stat, target, dof, tail_quantile)
    return inflation * ref_target


def _chi2_tail_parts(
    stat: np.ndarray, target: float, dof: int, tail_quantile: float
) -> tuple[np.ndarray, np.ndarray]:
    if dof == 0:
        sd = np.sqrt(np.mean(stat**2, axis=0))
        ref_fit = sd * stats.norm.ppf(0.5 + tail_quantile / 2)
        ref_target = sd * two_sided_normal_quantile(target)
    else:
        ref_fit = np.full(stat.shape[1], stats.chi2.ppf(tail_quantile, dof))
        ref_target = np.full(stat.shape[1], stats.chi2.ppf(1.0 - target, dof))
    inflation = np.maximum(1.0, np.quantile(stat, tail_quantile, axis=0) / ref_fit)
    return inflation, ref_target


def calibrate_limit(
    stat: np.ndarray,
    target: float,
    *,
    method: LimitMethod | str,
    dof: int = 0,
    margin: float = 1.0,
    tail_quantile: float = TAIL_FIT_QUANTILE,
) -> np.ndarray:
    """Alarm limit per column of a healthy calibration statistic ``stat`` ``(T, c) -> (c,)``.

    Args:
        stat: the statistic on healthy calibration samples (|EWMA| columns or one T² column).
        target: share of healthy samples allowed beyond the limit, per column.
        method: ``"empirical"`` (:func:`empirical_limit`) or ``"chi2-tail"``
            (:func:`chi2_tail_limit`).
        dof: reference of ``"chi2-tail"``: ``0`` normal, ``k`` χ²_k.
        margin: factor applied to the limit.
        tail_quantile: where ``"chi2-tail"`` measures the tail inflation.
    """
    method = check("limit_method", method, Options(LimitMethod))
    if method is LimitMethod.EMPIRICAL:
        return margin * empirical_limit(stat, target)
    inflation, ref_target = _chi2_tail_parts(stat, target, dof, tail_quantile)
    # (margin * inflation) * reference: the order the saved limits were computed in
    return margin * inflation * ref_target


class CUSUM(RecursiveStatistic):
    """One-sided CUSUM per column ``g(k) = max(0, g(k-1) + x(k) - drift)``, ``g(-1) = 0``.

    Page's test for an increase of the mean of ``x``: tuned to a shift ``δ`` (in units of the
    standard deviation of a white ``x``) with ``drift = δ / 2``. For a decrease pass ``-x``.

    Args:
        drift: reference value subtracted from every sample, ``>= 0``.

    Shape: ``update`` ``(k,) -> (k,)``; ``filter`` ``(T, k) -> (T, k)``.

    >>> CUSUM(0.5).filter(np.array([[1.0], [1.0], [-2.0], [3.0]]))[:, 0].tolist()
    [0.5, 1.0, 0.0, 2.5]
    """

    def __init__(self, drift: float) -> None:
        self.drift = check("drift", drift, Real(0))
        self.reset()

    def _step(self, x: np.ndarray, g: np.ndarray) -> np.ndarray:
        return np.maximum(0.0, g + x - self.drift)


class DirectionalProjection:
    """Matched filter: one standardised score per known fault direction.

    For a residual ``x`` with healthy covariance ``Σ`` and fault directions ``d_i`` (a fault adds
    ``μ d_i``, ``μ > 0``), the score ``p_i = d_iᵀ Σ⁻¹ x / sqrt(d_iᵀ Σ⁻¹ d_i)`` is the
    log-likelihood-ratio direction for that fault: unit variance on healthy data, and of all
    linear scores the one a shift along ``d_i`` moves most. One-sided: the sign of ``d_i`` is the
    fault's.

    Attributes:
        weights_: rows ``Σ⁻¹ d_i / sqrt(d_iᵀ Σ⁻¹ d_i)``, shape ``(m, k)``.

    >>> proj = DirectionalProjection().fit(np.array([[1.0, 0.0]]), np.diag([4.0, 1.0]))
    >>> proj.weights_.tolist(), float(proj.score(np.array([2.0, 5.0]))[0])
    ([[0.5, 0.0]], 1.0)
    """

    def fit(self, directions: np.ndarray, covariance: np.ndarray) -> DirectionalProjection:
        """Learn ``weights_`` from directions ``(m, k)`` and the healthy covariance ``(k, k)``."""
        d = np.atleast_2d(np.asarray(directions, dtype=np.float64))
        prec = np.linalg.pinv(np.atleast_2d(np.asarray(covariance, dtype=np.float64)))
        w = d @ prec
        norm = np.sqrt(np.einsum("ij,ij->i", w, d))
        if np.any(norm <= 0):
            raise ValueError("every fault direction must be non-zero in the residual space")
        self.weights_ = w / norm[:, None]
        return self

    def score(self, X: np.ndarray) -> np.ndarray:
        """Scores of one vector ``(k,) -> (m,)`` or of each row ``(T, k) -> (T, m)``."""
        return np.asarray(X, dtype=np.float64) @ self.weights_.T

    def get_state(self) -> dict[str, np.ndarray]:
        return {"weights": self.weights_}

    def set_state(self, state: dict[str, np.ndarray]) -> None:
        self.weights_ = np.asarray(state["weights"], dtype=np.float64)


class DirectionalGLR:
    """Generalised likelihood ratio for a step of unknown size ``μ >= 0`` and unknown onset.

    On a unit-variance white score ``p`` per column (e.g. :class:`DirectionalProjection`
    scores), the log-likelihood ratio of "the mean rose by the best ``μ >= 0`` over the last
    ``n`` samples" against "no change", maximised over ``n = 1..window`` (Willsky & Jones;
    Basseville & Nikiforov, sec. 2.4), times two:

        G(k) = max_{1 <= n <= min(window, k+1)} max(0, S_n(k))² / n,
        S_n(k) = p(k-n+1) + ... + p(k)

    A limited window keeps the cost per sample fixed and forgets changes long past.

    Args:
        window: longest onset delay searched, in samples.

    Shape: ``update`` ``(m,) -> (m,)``; ``filter`` ``(T, m) -> (T, m)``.

    >>> DirectionalGLR(2).filter(np.array([[1.0], [3.0], [-5.0]]))[:, 0].tolist()
    [1.0, 9.0, 0.0]
    """

    def __init__(self, window: int) -> None:
        self.window = int(check("window", window, Integer(1)))
        self.reset()

    def reset(self) -> None:
        self._buf: np.ndarray | None = None
        self._pos = 0  # the newest sample is _buf[_pos], the ones before it follow
        self._n = 0

    def update(self, x: np.ndarray) -> np.ndarray:
        x = np.asarray(x, dtype=np.float64)
        w = self.window
        if self._buf is None:
            # Each sample is written twice, at p and p + w, with p stepping down modulo w: then
            # _buf[p : p + w] always holds the last w samples newest first, without a copy.
            self._buf = np.zeros((2 * w, *x.shape))
            self._count = np.arange(1.0, w + 1.0).reshape(-1, *([1] * x.ndim))
            self._pos = w
        self._pos = (self._pos - 1) % w
        self._buf[self._pos] = self._buf[self._pos + w] = x
        self._n = min(self._n + 1, w)
        s = np.cumsum(self._buf[self._pos : self._pos + self._n], axis=0)  # S_1, ..., S_n
        return np.max(np.maximum(s, 0.0) ** 2 / self._count[: self._n], axis=0)

    def filter(self, X: np.ndarray) -> np.ndarray:
        X = np.asarray(X, dtype=np.float64)
        T = X.shape[0]
        c = np.concatenate([np.zeros((1, *X.shape[1:])), np.cumsum(X, axis=0)])  # c[k] = sum_<k
        out = np.zeros_like(X)
        for n in range(1, self.window + 1):
            if n > T:
                break
            s = c[n:] - c[:-n]  # S_n(k) for k = n-1 .. T-1
            np.maximum(out[n - 1 :], np.maximum(s, 0.0) ** 2 / n, out=out[n - 1 :])
        return out

    def get_state(self) -> dict[str, np.ndarray]:
        return {}

    def set_state(self, state: dict[str, np.ndarray]) -> None:
        pass  # nothing learned: the window is a hyperparameter


class OnDelay:
    """ISA-18.2's on-delay: an alarm once a condition has held for ``delay`` samples in a row.

    Args:
        delay: samples in a row, ``>= 1`` (1: the condition itself).

    Shape: ``update`` ``bool -> bool``; ``filter`` ``(T,) -> (T,)`` bool, equal to ``reset()``
    then ``update`` on every sample.

    >>> OnDelay(2).filter(np.array([True, True, False, True, True, True])).tolist()
    [False, True, False, False, True, True]
    """

    def __init__(self, delay: int) -> None:
        self.delay = int(check("delay", delay, Integer(1)))
        self.reset()

    def reset(self) -> None:
        self._run = 0  # samples in a row with the condition

    def update(self, x: bool) -> bool:
        self._run = self._run + 1 if x else 0
        return self._run >= self.delay

    def filter(self, X: np.ndarray) -> np.ndarray:
        # the samples with the condition among the last `delay`, from a cumulative count
        count = np.concatenate([[0], np.cumsum(np.asarray(X, dtype=bool))])
        k = np.arange(1, len(count))
        return (k >= self.delay) & (count[k] - count[np.maximum(k - self.delay, 0)] == self.delay)


def normal_tail_limit(
    stat: np.ndarray, target: float, *, tail_quantile: float = TAIL_FIT_QUANTILE
) -> np.ndarray:
    """One-sided limit of each column of a signed, zero-mean statistic ``(T, c) -> (c,)``.

    The normal reference with each column's RMS as its scale, at ``1 - target``, scaled by the
    calibration's tail inflation at ``tail_quantile`` (as :func:`chi2_tail_limit` does for T²).

    >>> rng = np.random.default_rng(0)
    >>> float(normal_tail_limit(rng.standard_normal((200_000, 1)), 0.002)[0].round(1))
    2.9
    """
    stat = np.asarray(stat, dtype=np.float64)
    sd = np.sqrt(np.mean(stat**2, axis=0))
    ref_fit = sd * stats.norm.ppf(tail_quantile)
    inflation = np.maximum(1.0, np.quantile(stat, tail_quantile, axis=0) / ref_fit)
    return inflation * sd * stats.norm.ppf(1.0 - target)
