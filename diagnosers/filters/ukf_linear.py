"""The filter's algebra on a linear-Gaussian model, ``z_k+1 = A z_k + w``, ``y_k = C z_k + v``:
the oracle of :mod:`diagnosers.filters.ukf_kernels`.

The unscented transform of a linear map is exact, so on this model the filter must equal the
Kalman filter, whatever its sigma-point spread (``tests/diagnosers/test_filters.py`` checks it
against a hand-written one). :func:`linear_filter` runs the same phase functions, in the same
order, as the FCC model's sample function (:func:`diagnosers.filters.ukf_model.fcc_sample`),
with the model's two functions swapped for ``A z`` and ``C z``.
"""

from __future__ import annotations

import numpy as np

from diagnosers.filters.ukf_kernels import (
    STATUS_SKIPPED,
    posterior,
    predict_finish,
    predict_prepare,
    sigma_weights,
    skip_outputs,
    update_finish,
    update_prepare,
    workspace,
)
from fcc_env.physics import njit_kernel

__all__ = ["linear_filter"]


@njit_kernel
def _matvec(M: np.ndarray, z: np.ndarray, out: np.ndarray) -> None:
    for i in range(M.shape[0]):
        s = 0.0
        for j in range(M.shape[1]):
            s += M[i, j] * z[j]
        out[i] = s


@njit_kernel
def _linear_run(A, C, q, r_abs, r_rel, w, m, P, Y, INNOV, STDZ, WHITE, S, POST, POST_SD, STATUS):
    n, ny = m.shape[0], C.shape[0]
    ws = workspace(n, ny, 1)
    X, FX, HY = ws[1], ws[2], ws[3]
    gate_idx = np.zeros((0, 2), dtype=np.int64)
    gate_lin = np.zeros((0, 3))
    jumps = np.zeros(0, dtype=np.bool_)
    for k in range(Y.shape[0]):
        y = Y[k]
        st = update_prepare(m, P, y, r_abs, r_rel, gate_idx, gate_lin, np.inf, w, ws, jumps)
        if st & STATUS_SKIPPED:
            skip_outputs(INNOV[k], STDZ[k], WHITE[k], S[k])
        else:
            for i in range(X.shape[0]):
                _matvec(C, X[i], HY[i])
            st |= update_finish(m, P, y, w, ws, INNOV[k], STDZ[k], WHITE[k], S[k])
        posterior(m, P, POST[k], POST_SD[k])
        st |= predict_prepare(m, P, w, ws)
        for i in range(X.shape[0]):
            _matvec(A, X[i], FX[i])
        predict_finish(m, P, q, w, ws)
        STATUS[k] = st


def linear_filter(
    A: np.ndarray,
    C: np.ndarray,
    q: np.ndarray,
    r_abs: np.ndarray,
    r_rel: np.ndarray,
    m0: np.ndarray,
    P0: np.ndarray,
    Y: np.ndarray,
    alpha: float = 1.0,
    beta: float = 2.0,
    kappa: float = 0.0,
) -> dict[str, np.ndarray]:
    """Filter ``Y`` (T, n_y) on the linear model (``Q = diag(q)``, ``R_k = diag((r_abs +
    r_rel |y_k|)²)``, prior ``m0``, ``P0`` of the first sample).

    Returns ``innovations``, ``standardized``, ``whitened`` (T, n_y), ``innovation_cov``
    (T, n_y, n_y), ``states``, ``state_std`` (T, n) (posterior) and ``status`` (T,).
    """
    A, C = np.ascontiguousarray(A, dtype=float), np.ascontiguousarray(C, dtype=float)
    Y = np.ascontiguousarray(Y, dtype=float)
    T, ny, n = Y.shape[0], C.shape[0], A.shape[0]
    out = {
        "innovations": np.empty((T, ny)),
        "standardized": np.empty((T, ny)),
        "whitened": np.empty((T, ny)),
        "innovation_cov": np.empty((T, ny, ny)),
        "states": np.empty((T, n)),
        "state_std": np.empty((T, n)),
        "status": np.empty(T, dtype=np.int8),
    }
    _linear_run(
        A,
        C,
        np.asarray(q, float),
        np.asarray(r_abs, float),
        np.asarray(r_rel, float),
        sigma_weights(n, alpha, beta, kappa),
        np.array(m0, dtype=float),
        np.array(P0, dtype=float),
        Y,
        *out.values(),
    )
    return out
