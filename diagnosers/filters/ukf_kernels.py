"""The unscented Kalman filter's algebra, compiled, for any model: one sample in phases
around the model's two functions.

A model owns a compiled *sample function* that calls, in order, :func:`update_prepare`; its
``measure`` on each sigma point; :func:`update_finish` (or :func:`skip_outputs`);
:func:`posterior`; :func:`predict_prepare`; its ``transition`` on each sigma point;
:func:`predict_finish` (the FCC model's: :func:`diagnosers.filters.ukf_model.fcc_sample`; a
linear-Gaussian model's, on which the algebra must equal the exact Kalman filter:
:mod:`diagnosers.filters.ukf_linear`). The model functions are called by name, not passed: a
compiled function that takes another as an argument cannot be cached by numba, and the FCC
filter would compile for 10 s in every process.

The order of one sample ``k`` (prior mean ``m`` and covariance ``P`` of the state at ``k``):

1. measurement noise variances from the readings, ``r_i = (a_i + b_i |y_i|)²`` (the plant's
   noise model: absolute, and relative to the value for the air flow);
2. **steps**: a channel that reads a state directly (``y = offset + gain · z``) whose
   innovation exceeds ``gate`` standard deviations adds a step variance to that state's prior
   variance: a piecewise-constant input has stepped, which a random walk alone would follow
   only slowly;
3. sigma points of ``(m, P)`` through ``measure``; innovation ``ν = y − ŷ``, its covariance
   ``S``, the Cholesky-whitened ``L_S⁻¹ ν`` and the per-channel ``ν_i / √S_ii``;
4. update in square-root form: ``U = P_xy L_S⁻ᵀ``, ``m ← m + U L_S⁻¹ ν``, ``P ← P − U Uᵀ``;
5. sigma points of the posterior through ``transition`` (which reads the inputs held over the
   sample from the observation row); the prior of ``k + 1`` with ``+ Q``.

A sample with a non-finite reading is skipped (no update; its innovations are NaN). Sigma
points are the scaled set of van der Merwe (``alpha``, ``beta``, ``kappa``). The loops fix the
order of every floating-point operation (no fast-math), so a stream and a batch that run the
same sample function agree bit for bit; sums run over the sigma points in the outer loop, so
the inner loops carry independent sums that the compiler can vectorise.

Why not filterpy (issue 42 asks for a well-kept library where it costs no speed): its
``UnscentedKalmanFilter`` calls the model once per sigma point from Python and does its algebra
in NumPy per sample. On the same compiled FCC model it ran 2,400 samples per CPU second, one
episode; this filter runs 12,700 batched over episodes (5.3x) and 7,900 streaming (3.3x;
``python -m bench.filter_speed --filterpy``, 2026-11-27, a shared 2-core machine). It also propagates the
sigma points of the prior without ``Q`` into the measurement (the random-walk inputs reach
T_rx at once, so their process noise belongs in ``S`` and ``P_xy``), and has no place for the
step test on the prior covariance.

numba's cache checks only a compiled function's own file: after editing this module, delete
``diagnosers/filters/__pycache__`` so that the sample functions that call it recompile.
"""

from __future__ import annotations

import math

import numba
import numpy as np

__all__ = [
    "STATUS_REPAIRED",
    "STATUS_SKIPPED",
    "posterior",
    "predict_finish",
    "predict_prepare",
    "sigma_weights",
    "skip_outputs",
    "update_finish",
    "update_prepare",
    "workspace",
]

#: Status bits of a sample: the sample was skipped (a non-finite reading), a covariance needed
#: a pivot floor in its Cholesky factor (it had lost positive definiteness).
STATUS_SKIPPED = 1
STATUS_REPAIRED = 2

#: Smallest pivot a Cholesky factor keeps, relative to its diagonal entry (absolute floor
#: below): a covariance that rounding pushed to semi-definite is repaired, not propagated as NaN.
_PIVOT_FLOOR_REL = 1e-12
_PIVOT_FLOOR_ABS = 1e-300

_kernel = numba.njit(cache=True, nogil=True, error_model="numpy")


def sigma_weights(n: int, alpha: float, beta: float, kappa: float) -> np.ndarray:
    """``[w_m0, w_c0, w_i, c]`` of van der Merwe's scaled sigma points for an ``n``-state:
    centre mean and covariance weights, the weight of each of the ``2n`` others, and their
    spread ``c = √(n + λ)``, ``λ = α² (n + κ) − n``."""
    lam = alpha * alpha * (n + kappa) - n
    w_m0 = lam / (n + lam)
    return np.array([w_m0, w_m0 + 1.0 - alpha * alpha + beta, 0.5 / (n + lam), math.sqrt(n + lam)])


@_kernel
def _cholesky(A: np.ndarray, L: np.ndarray) -> bool:
    """Lower ``L`` with ``A = L Lᵀ`` (``A`` symmetric, only its lower triangle read); True if a
    pivot needed the floor."""
    n = A.shape[0]
    repaired = False
    for j in range(n):
        d = A[j, j]
        for k in range(j):
            d -= L[j, k] * L[j, k]
        floor = max(_PIVOT_FLOOR_REL * abs(A[j, j]), _PIVOT_FLOOR_ABS)
        if not d > floor:  # also catches NaN
            repaired = repaired or not math.isnan(d)
            d = floor if not math.isnan(d) else d
        ljj = math.sqrt(d)
        L[j, j] = ljj
        for i in range(j + 1, n):
            s = A[i, j]
            for k in range(j):
                s -= L[i, k] * L[j, k]
            L[i, j] = s / ljj
        for i in range(j):
            L[i, j] = 0.0
    return repaired


@_kernel
def _sigma_points(m: np.ndarray, L: np.ndarray, c: float, X: np.ndarray) -> None:
    """Rows of ``X`` (2n + 1, n): ``m``, then ``m ± c L[:, i]``."""
    n = m.shape[0]
    for j in range(n):
        X[0, j] = m[j]
    for i in range(n):
        for j in range(n):
            X[1 + i, j] = m[j] + c * L[j, i]
            X[1 + n + i, j] = m[j] - c * L[j, i]


@_kernel
def _weighted_mean(V: np.ndarray, w: np.ndarray, out: np.ndarray) -> None:
    """``out = w_m0 V[0] + w_i Σ_{i≥1} V[i]`` (``w = sigma_weights``)."""
    n = V.shape[1]
    for j in range(n):
        out[j] = 0.0
    for i in range(1, V.shape[0]):  # row by row: the inner loop has independent sums
        for j in range(n):
            out[j] += V[i, j]
    for j in range(n):
        out[j] = w[0] * V[0, j] + w[2] * out[j]


@_kernel
def _deviations(A: np.ndarray, a: np.ndarray, D: np.ndarray) -> None:
    """``D[i] = A[i] − a``."""
    for i in range(A.shape[0]):
        for j in range(A.shape[1]):
            D[i, j] = A[i, j] - a[j]


@_kernel
def _weighted_cross(DA: np.ndarray, DB: np.ndarray, w: np.ndarray, out: np.ndarray) -> None:
    """``out = Σ w_ci DA[i] DB[i]ᵀ`` of deviations from the means (centre weight ``w_c0``, the
    others ``w_i``); exactly symmetric when ``DA`` is ``DB``."""
    na, nb = DA.shape[1], DB.shape[1]
    for r in range(na):
        for c in range(nb):
            out[r, c] = 0.0
    for i in range(1, DA.shape[0]):  # rank-one terms in turn: the inner loop vectorises
        for r in range(na):
            d = DA[i, r]
            for c in range(nb):
                out[r, c] += d * DB[i, c]
    for r in range(na):
        for c in range(nb):
            out[r, c] = w[1] * DA[0, r] * DB[0, c] + w[2] * out[r, c]


@_kernel
def _symmetrise(P: np.ndarray) -> None:
    n = P.shape[0]
    for i in range(n):
        for j in range(i):
            v = 0.5 * (P[i, j] + P[j, i])
            P[i, j] = v
            P[j, i] = v


@_kernel
def _forward(L: np.ndarray, b: np.ndarray, out: np.ndarray) -> None:
    """``out = L⁻¹ b`` for lower-triangular ``L``."""
    for i in range(L.shape[0]):
        s = b[i]
        for k in range(i):
            s -= L[i, k] * out[k]
        out[i] = s / L[i, i]


@_kernel
def update_prepare(
    m: np.ndarray,  # (n,) prior mean of this sample
    P: np.ndarray,  # (n, n) its covariance (a declared step adds to it)
    y: np.ndarray,  # (n_obs,) the observation row (the first n_y channels are measured)
    r_abs: np.ndarray,  # (n_y,) measurement-noise std, absolute
    r_rel: np.ndarray,  # (n_y,) ... and relative to the reading
    gate_idx: np.ndarray,  # (G, 2) int: (state, channel) read directly
    gate_lin: np.ndarray,  # (G, 3): offset, gain, step variance
    gate: float,  # steps are declared beyond this many standard deviations (inf: never)
    w: np.ndarray,  # sigma_weights
    ws,  # workspace (workspace())
    jumps: np.ndarray,  # (G,) bool out: a step was declared
) -> int:
    """Steps 1-2 and the sigma points of step 3 (into ``ws``'s ``X``); returns status bits
    (:data:`STATUS_SKIPPED`: a reading is not finite, the caller skips the update)."""
    L, X, r = ws[0], ws[1], ws[8]
    ny = r_abs.shape[0]
    for g in range(gate_idx.shape[0]):
        jumps[g] = False
    for i in range(ny):
        if not math.isfinite(y[i]):
            return STATUS_SKIPPED
    for i in range(ny):
        sd = r_abs[i] + r_rel[i] * abs(y[i])
        r[i] = sd * sd
    for g in range(gate_idx.shape[0]):
        s, ch = gate_idx[g, 0], gate_idx[g, 1]
        gain = gate_lin[g, 1]
        nu = y[ch] - (gate_lin[g, 0] + gain * m[s])
        if nu * nu > gate * gate * (gain * gain * P[s, s] + r[ch]):
            P[s, s] += gate_lin[g, 2]
            jumps[g] = True
    status = STATUS_REPAIRED if _cholesky(P, L) else 0
    _sigma_points(m, L, w[3], X)
    return status


@_kernel
def update_finish(
    m: np.ndarray,
    P: np.ndarray,
    y: np.ndarray,
    w: np.ndarray,
    ws,  # with HY: the sigma points' measurements
    innov: np.ndarray,  # (n_y,) out: innovation
    stdz: np.ndarray,  # (n_y,) out: innovation / √S_ii
    white: np.ndarray,  # (n_y,) out: L_S⁻¹ innovation
    S: np.ndarray,  # (n_y, n_y) out: innovation covariance
) -> int:
    """Steps 3-4: innovation and its covariance, the update of ``m``, ``P`` in place."""
    _, X, DX, HY, yhat, Ls, Pxy, U, r, _, DY = ws
    n, ny = m.shape[0], r.shape[0]
    _weighted_mean(HY, w, yhat)
    _deviations(HY, yhat, DY)
    _deviations(X, m, DX)
    _weighted_cross(DY, DY, w, S)
    _weighted_cross(DX, DY, w, Pxy)
    for i in range(ny):
        S[i, i] += r[i]
        innov[i] = y[i] - yhat[i]
    status = STATUS_REPAIRED if _cholesky(S, Ls) else 0
    _forward(Ls, innov, white)
    for i in range(ny):
        stdz[i] = innov[i] / math.sqrt(S[i, i])
    for j in range(n):  # row j of U = P_xy L_S⁻ᵀ solves L_S U[j]ᵀ = P_xy[j]ᵀ
        _forward(Ls, Pxy[j], U[j])
    for j in range(n):
        s = 0.0
        for i in range(ny):
            s += U[j, i] * white[i]
        m[j] += s
    for i in range(ny):  # P ← P − U Uᵀ, one rank-one term at a time
        for a in range(n):
            d = U[a, i]
            for b in range(n):
                P[a, b] -= d * U[b, i]
    return status


@_kernel
def skip_outputs(innov: np.ndarray, stdz: np.ndarray, white: np.ndarray, S: np.ndarray) -> None:
    """A skipped sample's innovations: NaN."""
    for i in range(innov.shape[0]):
        innov[i] = stdz[i] = white[i] = np.nan
        for j in range(innov.shape[0]):
            S[i, j] = np.nan


@_kernel
def posterior(m: np.ndarray, P: np.ndarray, post: np.ndarray, post_sd: np.ndarray) -> None:
    """The posterior mean and standard deviations, out."""
    for j in range(m.shape[0]):
        post[j] = m[j]
        post_sd[j] = math.sqrt(max(P[j, j], 0.0))


@_kernel
def predict_prepare(m: np.ndarray, P: np.ndarray, w: np.ndarray, ws) -> int:
    """Step 5's sigma points of the posterior (into ``ws``'s ``X``); returns status bits."""
    L, X = ws[0], ws[1]
    status = STATUS_REPAIRED if _cholesky(P, L) else 0
    _sigma_points(m, L, w[3], X)
    return status


@_kernel
def predict_finish(m: np.ndarray, P: np.ndarray, q: np.ndarray, w: np.ndarray, ws) -> None:
    """Step 5: the next sample's prior from the propagated sigma points ``FX``, in place."""
    FX = ws[2]
    _weighted_mean(FX, w, m)
    _deviations(FX, m, FX)  # FX is not needed after: its deviations replace it
    _weighted_cross(FX, FX, w, P)
    for j in range(m.shape[0]):
        P[j, j] += q[j]
    _symmetrise(P)


@_kernel
def workspace(n: int, ny: int, n_scratch: int):
    """The arrays one sample works in (one set per thread): ``L, X, FX, HY, yhat, Ls, Pxy, U,
    r, scratch, DY``; a model's sample function fills ``HY`` (``measure`` of the rows of ``X``)
    and ``FX`` (``transition`` of them), ``scratch`` is the model's. ``FX`` also holds the
    state deviations of the update (it is free until the prediction)."""
    N = 2 * n + 1
    return (
        np.empty((n, n)),
        np.empty((N, n)),
        np.empty((N, n)),
        np.empty((N, ny)),
        np.empty(ny),
        np.empty((ny, ny)),
        np.empty((n, ny)),
        np.empty((n, ny)),
        np.empty(ny),
        np.empty(n_scratch),
        np.empty((N, ny)),
    )
