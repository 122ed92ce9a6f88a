"""Lagged data matrices, canonical variates and subspace identification: the algebra of the
``dpca``, ``cva`` and ``n4sid-glr`` monitors.

Everything here is a pure function of arrays, so that it can be checked against an oracle
(``tests/diagnosers/test_subspace.py``: numpy/scipy canonical correlations on a VAR process, a
known state-space system's transfer function):

* :func:`lagged` - the stacked vectors ``[y_t; y_{t-1}; ...]`` of one record;
* :func:`canonical_variates` - the CVA of a past and a future vector (Russell, Chiang &
  Braatz 2000): the SVD of the scaled Hankel covariance ``Σ_ff^{-1/2} Σ_fp Σ_pp^{-1/2}``;
* :func:`aic_order` - Larimore's (1990) AIC over the number of retained canonical states;
* :func:`n4sid` - a subspace identification of a state-space model in innovation form
  ``x_{t+1} = A x_t + B u_t + K e_t``, ``y_t = C x_t + D u_t + e_t`` (Van Overschee & De Moor's
  N4SID with identity weights: the oblique projection of the future outputs on the past, its
  SVD for the states, least squares for the matrices, the Kalman gain from the residuals).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import linalg

__all__ = [
    "CanonicalVariates",
    "StateSpace",
    "aic_order",
    "canonical_variates",
    "inverse_sqrt",
    "lagged",
    "n4sid",
    "past_future",
]


def lagged(y: np.ndarray, lags: int) -> np.ndarray:
    """The stacked vectors ``[y_t; y_{t-1}; ...; y_{t-lags+1}]`` of a record ``y`` ``(T, m)``:
    ``(T - lags + 1, m · lags)``, row ``i`` for ``t = i + lags - 1``, newest block first.

    >>> lagged(np.arange(4.0)[:, None], 2).tolist()
    [[1.0, 0.0], [2.0, 1.0], [3.0, 2.0]]
    """
    y = np.asarray(y, dtype=np.float64)
    n = y.shape[0] - lags + 1
    if n <= 0:
        return np.empty((0, y.shape[1] * lags))
    return np.concatenate([y[lags - 1 - j : lags - 1 - j + n] for j in range(lags)], axis=1)


def past_future(y: np.ndarray, past: int, future: int) -> tuple[np.ndarray, np.ndarray]:
    """Past ``p_t = [y_{t-1}; ...; y_{t-past}]`` and future ``f_t = [y_t; ...; y_{t+future-1}]``
    vectors of a record ``y`` ``(T, m)``, aligned row by row: ``(N, m·past)``, ``(N, m·future)``
    with ``N = T - past - future + 1``."""
    y = np.asarray(y, dtype=np.float64)
    n = y.shape[0] - past - future + 1
    if n <= 0:
        return np.empty((0, y.shape[1] * past)), np.empty((0, y.shape[1] * future))
    p = lagged(y[: past + n - 1], past)
    f = np.concatenate([y[past + j : past + j + n] for j in range(future)], axis=1)
    return p, f


def inverse_sqrt(cov: np.ndarray, rcond: float = 1e-10) -> np.ndarray:
    """The symmetric inverse square root of a covariance matrix; eigenvalues below ``rcond``
    times the largest are treated as that floor (a rank-deficient lagged covariance, e.g. a
    constant channel, must not blow the scaled Hankel matrix up)."""
    w, v = np.linalg.eigh(0.5 * (cov + cov.T))
    w = np.maximum(w, rcond * max(float(w.max()), 1e-300))
    return (v / np.sqrt(w)) @ v.T


@dataclass(frozen=True)
class CanonicalVariates:
    """The CVA of a past and a future vector.

    Attributes:
        correlations: canonical correlations ``(r,)``, descending, ``r = min(dim p, dim f)``.
        past_weights: ``J = Vᵀ Σ_pp^{-1/2}`` ``(dim p, dim p)``: row ``i`` maps a centred past
            vector to its ``i``-th canonical variate (unit variance, mutually uncorrelated);
            the rows past ``r`` complete an orthonormal basis (variates of zero correlation).
        mean: the past vector's mean ``(dim p,)``.
    """

    correlations: np.ndarray
    past_weights: np.ndarray
    mean: np.ndarray


def canonical_variates(past: np.ndarray, future: np.ndarray) -> CanonicalVariates:
    """Canonical variate analysis of samples ``past`` ``(N, dp)`` and ``future`` ``(N, df)``:
    the SVD ``Σ_ff^{-1/2} Σ_fp Σ_pp^{-1/2} = U S Vᵀ`` of the scaled Hankel covariance (Russell,
    Chiang & Braatz 2000, eq. 6-8); ``S``'s diagonal holds the canonical correlations."""
    mp, mf = past.mean(axis=0), future.mean(axis=0)
    p, f = past - mp, future - mf
    n = past.shape[0] - 1
    spp, sff, sfp = p.T @ p / n, f.T @ f / n, f.T @ p / n
    wp = inverse_sqrt(spp)
    h = inverse_sqrt(sff) @ sfp @ wp
    _, s, vt = np.linalg.svd(h, full_matrices=True)
    # every canonical direction, the uncorrelated ones after the correlated
    dp = past.shape[1]
    corr = np.clip(s[: min(dp, h.shape[0])], 0.0, 1.0)
    return CanonicalVariates(corr, vt[:dp] @ wp, mp)


def aic_order(correlations: np.ndarray, n_samples: int, dim: int, max_order: int) -> int:
    """Larimore's (1990) AIC for the number ``k`` of canonical states of a ``dim``-channel
    process without inputs: ``N Σ_{i≤k} ln(1 − ρ_i²) + 2 M_k``, ``M_k = 2 k dim + dim(dim+1)/2``
    the parameters of a ``k``-state innovation model; the minimiser over ``1..max_order``.

    >>> aic_order(np.array([0.9, 0.5, 0.01]), 1000, 1, 3)
    2
    """
    rho2 = np.clip(np.asarray(correlations[:max_order], dtype=np.float64) ** 2, 0.0, 1 - 1e-12)
    ks = np.arange(1, rho2.size + 1)
    aic = n_samples * np.cumsum(np.log1p(-rho2)) + 2.0 * (2 * ks * dim + dim * (dim + 1) / 2)
    return int(ks[int(np.argmin(aic))])


@dataclass(frozen=True)
class StateSpace:
    """A discrete state-space model in innovation form, ``e_t`` white with covariance ``R``::

    x_{t+1} = A x_t + B u_t + K e_t,    y_t = C x_t + D u_t + e_t
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    K: np.ndarray
    R: np.ndarray

    @property
    def order(self) -> int:
        return int(self.A.shape[0])

    def predictor_poles(self) -> np.ndarray:
        """The eigenvalues of ``A − K C``, the one-step predictor's dynamics."""
        return np.linalg.eigvals(self.A - self.K @ self.C)


def n4sid(u: list[np.ndarray], y: list[np.ndarray], order: int, horizon: int) -> StateSpace:
    """Identify an innovation-form model of order ``order`` from records ``u`` ``(T_i, n_u)``
    (``n_u`` may be 0) and ``y`` ``(T_i, n_y)``, past and future horizon ``horizon``.

    Steps (N4SID with identity weights, the state from the oblique projection):

    1. per record, past ``w_p = [y; u]`` lags ``1..horizon``, future outputs ``Y_f`` and inputs
       ``U_f`` lags ``0..horizon-1`` (and the same shifted by one sample for the next state);
    2. least squares ``Y_f ≈ L_p w_p + L_u U_f``: ``L_p w_p`` is the oblique projection
       ``Γ x_t``; its SVD gives the extended observability ``Γ`` and the states
       ``x_t = Γ† L_p w_p``; the next states use the same ``Γ`` with the shifted regression
       (Van Overschee & De Moor 1996, sec. 4.3, with ``Γ_{-}`` for the shift);
    3. least squares ``[x_{t+1}; y_t] ≈ [A B; C D] [x_t; u_t]``;
    4. ``K = Σ_we Σ_ee^{-1}`` and ``R = Σ_ee`` from the two equations' residuals ``w``, ``e``.
    """
    ny = y[0].shape[1]
    nu = u[0].shape[1]
    rows_p, rows_f, rows_uf, rows_p1, rows_f1, rows_uf1, y_out, u_in = ([] for _ in range(8))
    for ui, yi in zip(u, y, strict=True):
        w = np.concatenate([yi, ui], axis=1)
        n = yi.shape[0] - 2 * horizon
        if n <= 1:
            continue
        # time index t runs over horizon .. horizon + n - 1; t + 1 for the shifted rows
        p = lagged(w[: horizon + n], horizon)  # rows for t-1 .. t-horizon at t = horizon..
        yf = np.concatenate([yi[horizon + j : horizon + j + n] for j in range(horizon)], axis=1)
        uf = np.concatenate([ui[horizon + j : horizon + j + n] for j in range(horizon)], axis=1)
        # p has n + 1 rows (pasts of t = horizon .. horizon + n); pairs (t, t + 1) use n - 1
        rows_p.append(p[: n - 1])
        rows_f.append(yf[:-1])
        rows_uf.append(uf[:-1])
        rows_p1.append(p[1:n])  # past of t + 1: [w_t; ...; w_{t-horizon+1}]
        rows_f1.append(yf[1:, : ny * (horizon - 1)] if horizon > 1 else yf[1:, :0])
        rows_uf1.append(uf[1:, : nu * (horizon - 1)] if horizon > 1 else uf[1:, :0])
        y_out.append(yi[horizon : horizon + n - 1])
        u_in.append(ui[horizon : horizon + n - 1])
    if not rows_p:
        raise ValueError(f"every record is shorter than 2·horizon + 2 = {2 * horizon + 2} samples")
    wp, yf, uf = np.concatenate(rows_p), np.concatenate(rows_f), np.concatenate(rows_uf)
    theta = np.linalg.lstsq(np.concatenate([wp, uf], axis=1), yf, rcond=None)[0]
    lp = theta[: wp.shape[1]].T  # (ny·h, dim wp)
    o = wp @ lp.T  # oblique projection Γ x_t, (N, ny·h)
    uu, s, _ = np.linalg.svd(o.T, full_matrices=False)
    gamma = uu[:, :order] * np.sqrt(s[:order])
    x = (np.linalg.pinv(gamma) @ o.T).T
    # next state: the projection of the shifted future (horizon - 1 blocks) on the shifted past
    wp1, yf1, uf1 = np.concatenate(rows_p1), np.concatenate(rows_f1), np.concatenate(rows_uf1)
    theta1 = np.linalg.lstsq(np.concatenate([wp1, uf1], axis=1), yf1, rcond=None)[0]
    o1 = wp1 @ theta1[: wp1.shape[1]]
    x1 = (np.linalg.pinv(gamma[: ny * (horizon - 1)]) @ o1.T).T
    ys, us = np.concatenate(y_out), np.concatenate(u_in)
    reg = np.concatenate([x, us], axis=1)
    abcd = np.linalg.lstsq(reg, np.concatenate([x1, ys], axis=1), rcond=None)[0].T
    A, B = abcd[:order, :order], abcd[:order, order:]
    C, D = abcd[order:, :order], abcd[order:, order:]
    res = np.concatenate([x1, ys], axis=1) - reg @ abcd.T
    w_res, e_res = res[:, :order], res[:, order:]
    R = e_res.T @ e_res / max(1, e_res.shape[0] - 1)
    K = linalg.solve(R, e_res.T @ w_res / max(1, e_res.shape[0] - 1), assume_a="pos").T
    # contiguous copies: a saved and loaded model must compute bit for bit as the fitted one
    return StateSpace(*(np.ascontiguousarray(m) for m in (A, B, C, D, K, R)))
