"""The declared model's own simulator with a form's correction added to its state equations.

:func:`simulate_corrected` integrates :func:`fcc_env.physics.rhs_core` (the declared right-hand
side) with the stage arithmetic of :mod:`fcc_env.integrator` (classic RK4, inputs and
parameters held over each sample, per-sample parameter multipliers of library effects), and adds
``Σ_k θ_k·term_k(z)`` to the target state's derivative at every RK4 stage, ``z`` the stage's
signals (:data:`evaluation.discover.terms.SIGNALS`). Lagged signals are first-order lags of
the sampled signal, updated once per sample and held over the step (as
:func:`evaluation.discover.physics_model.first_order_lag` filters a sampled channel).

With every θ zero it reproduces :func:`fcc_env.simulate_inputs` bit for bit (tested), so a form
is fitted by the model's own simulation, as library effects are; the compiled kernel of
:mod:`fcc_env` has no state-dependent hook, which is why this one exists (numba ``prange`` over
parameter rows × episodes).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numba
import numpy as np
from scipy import signal

from evaluation.discover.terms import FUNCTIONS, N_BASE_SIGNALS, SIGNALS, STATE_TARGETS, Term
from fcc_env.params import N_MEASUREMENTS, N_STATES
from fcc_env.physics import N_AUX, measurements_into, njit_kernel, rhs_core

__all__ = ["TermTable", "factor_value", "simulate_corrected", "term_values", "with_lags"]


@njit_kernel
def factor_value(fn: int, v: float) -> float:
    """Function ``fn`` (a code of :data:`~evaluation.discover.terms.FUNCTIONS`) of ``v``."""
    if fn == 0:
        return v
    if fn == 1:
        return v * v
    if fn == 2:
        return v * v * v
    if fn == 3:
        return math.tanh(v)
    if fn == 4:
        return max(v, 0.0)
    if fn == 6:
        return math.exp(v)
    return abs(v)


class TermTable:
    """Terms packed for the kernel: factor signal codes, function codes, centres, scales, the
    target state of each term, and the lagged signals (source code, time constant)."""

    def __init__(self, terms: Sequence[Term], targets: Sequence[str | None]) -> None:
        lags: list[tuple[str, float]] = []
        for t in terms:
            for lag in t.lags:
                if lag not in lags:
                    lags.append(lag)
        K = len(terms)
        self.sig = np.full((K, 3), -1, np.int64)
        self.fn = np.zeros((K, 3), np.int64)
        self.c = np.zeros((K, 3))
        self.s = np.ones((K, 3))
        # a measurement term (target None) is never added to a derivative
        self.target = np.array(
            [-1 if g is None else STATE_TARGETS[g] for g in targets], np.int64
        ).reshape(K)
        for k, t in enumerate(terms):
            for j, f in enumerate(t.factors):
                code = SIGNALS.index(f.signal)
                if f.lag_s > 0:
                    code = N_BASE_SIGNALS + lags.index((f.signal, f.lag_s))
                self.sig[k, j] = code
                self.fn[k, j] = FUNCTIONS[f.fn]
                self.c[k, j] = f.center
                self.s[k, j] = f.scale
        self.lag_src = np.array([SIGNALS.index(s) for s, _ in lags], np.int64)
        self.lag_tau = np.array([tau for _, tau in lags], np.float64)

    @property
    def n_signals(self) -> int:
        return N_BASE_SIGNALS + self.lag_src.size


@njit_kernel
def _signals(x, u, t_rx, lag, z):
    for i in range(N_STATES):
        z[i] = x[i]
    for i in range(u.shape[0]):
        z[N_STATES + i] = u[i]
    z[N_BASE_SIGNALS - 1] = t_rx
    for i in range(lag.shape[0]):
        z[N_BASE_SIGNALS + i] = lag[i]


@njit_kernel
def _add_correction(dx, z, theta, sig, fn, c, s, target):
    for k in range(theta.shape[0]):
        if theta[k] == 0.0 or target[k] < 0:
            continue
        v = theta[k]
        for j in range(3):
            if sig[k, j] >= 0:
                v *= factor_value(fn[k, j], (z[sig[k, j]] - c[k, j]) / s[k, j])
        dx[target[k]] += v


@njit_kernel
def _rhs(x, u, p, dx, aux, z, lag, theta, sig, fn, c, s, target):
    rhs_core(x, u, p, dx, aux)
    _signals(x, u, aux[0], lag, z)
    _add_correction(dx, z, theta, sig, fn, c, s, target)


@numba.njit(cache=True, nogil=True, parallel=True, error_model="numpy")
def _kernel(x0, U, p_base, pidx, PM, h, substeps, theta, sig, fn, c, s, target, lsrc, ltau, Y, Z):
    B, T = U.shape[0], U.shape[1]
    keep_z = Z.shape[1] == T
    nz = N_BASE_SIGNALS + lsrc.shape[0]
    for b in numba.prange(B):
        x = x0[b].copy()
        p = np.empty_like(p_base[b])
        k1 = np.empty(N_STATES)
        k2 = np.empty(N_STATES)
        k3 = np.empty(N_STATES)
        k4 = np.empty(N_STATES)
        xt = np.empty(N_STATES)
        aux = np.empty(N_AUX)
        z = np.empty(nz)
        lag = np.zeros(lsrc.shape[0])
        a = np.exp(-h * substeps / ltau)
        th = theta[b]
        for k in range(T):
            u = U[b, k]
            for j in range(p.shape[0]):
                p[j] = p_base[b, j]
            for j in range(pidx.shape[1]):
                if pidx[b, j] >= 0:
                    p[pidx[b, j]] = p[pidx[b, j]] * PM[b, k, j]
            rhs_core(x, u, p, k1, aux)
            measurements_into(x, u, aux[0], Y[b, k])
            _signals(x, u, aux[0], lag, z)
            for i in range(lsrc.shape[0]):
                v = z[lsrc[i]]
                lag[i] = v if k == 0 else a[i] * lag[i] + (1.0 - a[i]) * v
                z[N_BASE_SIGNALS + i] = lag[i]
            if keep_z:
                for i in range(nz):
                    Z[b, k, i] = z[i]
            if k + 1 == T:
                break
            _add_correction(k1, z, th, sig, fn, c, s, target)
            for step in range(substeps):
                if step > 0:
                    _rhs(x, u, p, k1, aux, z, lag, th, sig, fn, c, s, target)
                for i in range(N_STATES):
                    xt[i] = x[i] + 0.5 * h * k1[i]
                _rhs(xt, u, p, k2, aux, z, lag, th, sig, fn, c, s, target)
                for i in range(N_STATES):
                    xt[i] = x[i] + 0.5 * h * k2[i]
                _rhs(xt, u, p, k3, aux, z, lag, th, sig, fn, c, s, target)
                for i in range(N_STATES):
                    xt[i] = x[i] + h * k3[i]
                _rhs(xt, u, p, k4, aux, z, lag, th, sig, fn, c, s, target)
                for i in range(N_STATES):
                    x[i] = x[i] + h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])


def simulate_corrected(
    U: np.ndarray,
    x0: np.ndarray,
    p_base: np.ndarray,
    table: TermTable,
    theta: np.ndarray,
    *,
    sample_time_s: float,
    rk4_substeps: int = 1,
    pidx: np.ndarray | None = None,
    PM: np.ndarray | None = None,
    keep_signals: bool = False,
) -> tuple[np.ndarray, np.ndarray | None]:
    """Simulate B rows: outputs (B, T, 8) and, with ``keep_signals``, signals (B, T, n_z).

    ``U`` (B, T, 6) inputs held over each sample, ``x0`` (B, 11), ``p_base`` (B, n_params)
    packed parameters, ``theta`` (B, K) coefficients of ``table``'s K terms per row; ``pidx``
    (B, J) / ``PM`` (B, T, J): parameter slots scaled per sample (as :func:`fcc_env.simulate_inputs`'
    ``param_multipliers``).
    """
    U = np.ascontiguousarray(U, np.float64)
    B, T = U.shape[:2]
    if pidx is None or PM is None:
        pidx = np.full((B, 1), -1, np.int64)
        PM = np.ones((B, T, 1))
    theta = np.ascontiguousarray(np.atleast_2d(theta), np.float64).reshape(B, -1)
    if theta.shape[1] != table.target.size:
        raise ValueError(f"theta has {theta.shape[1]} columns for {table.target.size} terms")
    Y = np.empty((B, T, N_MEASUREMENTS))
    Z = np.empty((B, T if keep_signals else 0, table.n_signals))
    with np.errstate(all="ignore"):
        _kernel(
            np.ascontiguousarray(x0, np.float64),
            U,
            np.ascontiguousarray(p_base, np.float64),
            np.ascontiguousarray(pidx, np.int64),
            np.ascontiguousarray(PM, np.float64),
            sample_time_s / rk4_substeps,
            rk4_substeps,
            theta,
            table.sig,
            table.fn,
            table.c,
            table.s,
            table.target,
            table.lag_src,
            table.lag_tau if table.lag_tau.size else np.ones(0),
            Y,
            Z,
        )
    return Y, (Z if keep_signals else None)


def term_values(table: TermTable, Z: np.ndarray) -> np.ndarray:
    """The K terms of ``table`` on signals ``Z`` (..., n_z): (..., K) (numpy, for measurement
    forms and the regression)."""
    out = np.ones((*Z.shape[:-1], table.target.size))
    for k in range(table.target.size):
        for j in range(3):
            code = table.sig[k, j]
            if code < 0:
                continue
            v = (Z[..., code] - table.c[k, j]) / table.s[k, j]
            out[..., k] *= _np_fn(int(table.fn[k, j]), v)
    return out


def _np_fn(fn: int, v: np.ndarray) -> np.ndarray:
    return [
        lambda a: a,
        lambda a: a * a,
        lambda a: a * a * a,
        np.tanh,
        lambda a: np.maximum(a, 0.0),
        np.abs,
        np.exp,
    ][fn](v)


def with_lags(table: TermTable, Z: np.ndarray, sample_time_s: float) -> np.ndarray:
    """Base signals ``Z`` (..., T, n_base) extended by ``table``'s lagged signals, filtered as
    the kernel filters them (lag[0] = z[0], lag[k] = a·lag[k−1] + (1 − a)·z[k])."""
    out = [Z[..., :N_BASE_SIGNALS]]
    for src, tau in zip(table.lag_src, table.lag_tau, strict=True):
        a = math.exp(-sample_time_s / tau)
        z = Z[..., int(src)]
        lag, _ = signal.lfilter([1.0 - a], [1.0, -a], z, axis=-1, zi=a * z[..., :1])
        out.append(lag[..., None])
    return np.concatenate(out, axis=-1)
