"""The alarm stage as small parts: residual filters, statistics and limit calibration.

A residual-based detector ends in the same three steps whatever its model: filter the normalised
residuals over time (:class:`EWMA`), combine the channels into one statistic
(:class:`HotellingT2`), and compare with a limit set on healthy calibration data
(:func:`calibrate_limit`). The parts here know nothing about diagnosers, so detectors, baselines
and the evaluation's oracle rows compose the same code.

Every streaming part follows :class:`ResidualEvaluator`: ``reset()`` starts a sequence,
``update(x)`` consumes one sample, ``filter(X)`` evaluates a whole sequence (time on axis 0) and
equals ``reset()`` then ``update`` on every row, and ``get_state``/``set_state`` carry what a
saved detector needs. Sequential tests (CUSUM, GLR) are meant to slot in beside :class:`EWMA`.

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

from fcc_env.validation import Options, Real, check

__all__ = [
    "EWMA",
    "TAIL_FIT_QUANTILE",
    "HotellingT2",
    "LimitMethod",
    "ResidualEvaluator",
    "calibrate_limit",
    "chi2_tail_limit",
    "empirical_limit",
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


class EWMA:
    """Exponentially weighted moving average ``z(k) = λ x(k) + (1 - λ) z(k-1)``, ``z(-1) = 0``.

    Args:
        lam: weight of the newest sample, in (0, 1]; ``1`` passes the input through.

    Shape: ``update`` ``(k,) -> (k,)``; ``filter`` ``(T, k) -> (T, k)``.
    """

    def __init__(self, lam: float) -> None:
        self.lam = check("lam", lam, Real(0, 1, closed="right"))
        self.reset()

    def reset(self) -> None:
        self._z: np.ndarray | None = None

    def _step(self, x: np.ndarray, z: np.ndarray) -> np.ndarray:
        # The one place the recursion is written: streaming and batch must agree to the bit.
        return self.lam * x + (1.0 - self.lam) * z

    def update(self, x: np.ndarray) -> np.ndarray:
        x = np.asarray(x, dtype=np.float64)
        self._z = self._step(x, np.zeros_like(x) if self._z is None else self._z)
        return self._z

    def filter(self, X: np.ndarray) -> np.ndarray:
        X = np.asarray(X, dtype=np.float64)
        out = np.empty_like(X)
        z = np.zeros(X.shape[1:])
        for k in range(X.shape[0]):
            z = self._step(X[k], z)
            out[k] = z
        return out

    def get_state(self) -> dict[str, np.ndarray]:
        return {}

    def set_state(self, state: dict[str, np.ndarray]) -> None:
        pass  # nothing learned: λ is a hyperparameter


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
