"""Stable IIR filters as differentiable torch functions (the functional half of the LRGF neurons).

Filter denominators are built from reflection coefficients ``|k_j| < 1`` (Levinson/Schur step-up
recursion), so every parameter value gives a stable filter. :class:`IIRFilterFunction` runs
``scipy.signal.lfilter`` over whole sequences and back-propagates with ``lfilter`` on
time-reversed signals (the dynoNet approach), so no per-time-step Python loop is needed.
Layers built on these functions live in :mod:`diagnosers.networks.lrgf_net`.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
from scipy import signal as sps

__all__ = [
    "IIRFilterFunction",
    "denominator_from_reflection",
    "iir_filter",
    "numerator_from_state_space",
    "reflection_from_denominator",
]


# ---- stable denominators -----------------------------------------------------------------------
def denominator_from_reflection(k: torch.Tensor) -> torch.Tensor:
    """Step-up (Levinson/Schur) recursion: reflection coefficients -> denominator coefficients.

    Args:
        k: reflection coefficients, shape ``(..., r)``; all ``|k_j| < 1`` gives a stable filter.

    Returns:
        ``a = [a_1, ..., a_r]``, shape ``(..., r)``, of ``A(q) = 1 + a_1 q^-1 + ... + a_r q^-r``.
        ``|k_j| < 1`` for all ``j`` if and only if every root of ``z^r + a_1 z^(r-1) + ... + a_r``
        lies strictly inside the unit circle, so any real parameter mapped into ``(-1, 1)`` gives a
        stable filter; no clipping or projection is ever needed.
    """
    r = k.shape[-1]
    a = k.new_zeros((*k.shape[:-1], 0))
    for m in range(r):
        km = k[..., m : m + 1]
        # a^(m+1)_i = a^(m)_i + k_{m+1} a^(m)_{m+1-i}, i = 1..m;  a^(m+1)_{m+1} = k_{m+1}
        a = torch.cat([a + km * a.flip(-1), km], dim=-1)
    return a


def reflection_from_denominator(a: np.ndarray) -> np.ndarray:
    """Step-down recursion, the inverse of :func:`denominator_from_reflection` (numpy, float64).

    Args:
        a: ``[a_1, ..., a_r]`` of a stable denominator, shape ``(r,)``.

    Returns:
        reflection coefficients ``k``, shape ``(r,)``. Raises ``ValueError`` if the polynomial is not
        stable (some ``|k_j| >= 1``).
    """
    a = np.asarray(a, dtype=np.float64).copy()
    r = a.shape[0]
    k = np.zeros(r)
    for m in range(r, 0, -1):
        km = a[m - 1]
        if abs(km) >= 1.0:
            raise ValueError(
                f"denominator {a} is not stable: reflection coefficient {km} at order {m}"
            )
        k[m - 1] = km
        # a^(m-1)_i = (a^(m)_i - k_m a^(m)_{m-i}) / (1 - k_m^2), i = 1..m-1
        a = (a[: m - 1] - km * a[: m - 1][::-1]) / (1.0 - km * km)
    return k


def numerator_from_state_space(a: torch.Tensor, b: torch.Tensor, b0: torch.Tensor) -> torch.Tensor:
    """Numerator of the neuron filter from ``s_i = w_i u`` to ``z_i = b_i x_i + b0_i s_i``.

    The neuron state follows eq. (2), ``x(k+1) = A x(k) + 1 s(k)`` with ``A`` the companion matrix
    of eq. (3) (first row ``-a_1..-a_r``, ones on the sub-diagonal) and ``1`` the vector of ones.
    Its transfer function is

    .. math::
        H(q) = b (qI - A)^{-1} \\mathbf{1} + b_0 = \\frac{N(q^{-1})}{A(q^{-1})},\\quad
        A(q^{-1}) = 1 + \\sum_{j=1}^r a_j q^{-j}.

    With the Markov parameters ``h_k = b A^{k-1} 1`` (``k = 1..r``), ``N = b0 A + n`` where
    ``n_0 = 0`` and ``n_k = sum_{j=0}^{k-1} a_j h_{k-j}`` (``a_0 = 1``): the product of ``A`` and the
    impulse response truncates at degree ``r`` by Cayley-Hamilton. Differentiable in ``a, b, b0``.

    Args:
        a: denominator coefficients ``[a_1..a_r]``, shape ``(v, r)``.
        b: state-output weights ``b_i``, shape ``(v, r)``.
        b0: direct feed-through ``b0_i``, shape ``(v,)``.

    Returns:
        ``N = [n_0, ..., n_r]``, shape ``(v, r + 1)``.
    """
    r = a.shape[1]
    vec = torch.ones_like(a)  # A^{k-1} 1, starting with k = 1
    markov = []
    for _ in range(r):
        markov.append((b * vec).sum(-1))
        # companion matrix times vec: first entry -a·vec, the rest shift down
        vec = torch.cat([-(a * vec).sum(-1, keepdim=True), vec[:, :-1]], dim=-1)
    h = torch.stack(markov, dim=-1)  # (v, r): h_1..h_r
    a_full = torch.cat([torch.ones_like(a[:, :1]), a], dim=-1)  # (v, r+1): a_0..a_r
    n = [torch.zeros_like(b0)]
    for kk in range(1, r + 1):
        n.append((a_full[:, :kk] * h[:, :kk].flip(-1)).sum(-1))
    return b0[:, None] * a_full + torch.stack(n, dim=-1)


# ---- differentiable lfilter --------------------------------------------------------------------
def lfilter_rows(num: np.ndarray, den_full: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``lfilter`` along the last axis of ``x`` (C, ..., T), row block ``c`` with its own
    coefficients ``num[c]``, ``den_full[c]`` (``a_0`` included)."""
    out = np.empty(x.shape)
    if x.shape[-1] == 0:  # nothing to filter (e.g. a steady window as long as the sequence)
        return out
    for c in range(x.shape[0]):
        out[c] = sps.lfilter(num[c], den_full[c], x[c], axis=-1)
    return out


def _lfilter_channels(num: np.ndarray, den_full: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``lfilter`` along axis 1 of ``x`` (B, T, C) with per-channel coefficients (C, .)."""
    # each channel's (B, T) block contiguous for lfilter; the output keeps x's layout, on which
    # the einsum order of the gradients (and so their last bits) depends
    rows = lfilter_rows(num, den_full, np.ascontiguousarray(np.moveaxis(x, 2, 0)))
    out = np.empty(x.shape)
    out[...] = np.moveaxis(rows, 0, 2)
    return out


def _lagged_sums(g: np.ndarray, x: np.ndarray, n_lags: int, first_lag: int) -> np.ndarray:
    """``out[c, j] = sum_{b,t} g[b, t, c] x[b, t - (first_lag + j), c]`` for ``j < n_lags``."""
    t_len = x.shape[1]
    out = np.zeros((x.shape[2], n_lags))
    for j in range(n_lags):
        lag = first_lag + j
        if lag < t_len:
            out[:, j] = np.einsum("btc,btc->c", g[:, lag:], x[:, : t_len - lag])
    return out


class IIRFilterFunction(torch.autograd.Function):
    """``y = N(q^-1)/A(q^-1) x`` per channel with zero initial state, via ``scipy.signal.lfilter``.

    Inputs: ``x`` (B, T, C), ``num`` (C, nb) = ``[n_0..n_{nb-1}]``, ``den`` (C, na) =
    ``[a_1..a_na]`` (``a_0 = 1`` implied). Output ``y`` (B, T, C) in ``x``'s dtype.

    Backward (zero initial state, so the adjoint of a causal filter is the same filter run
    backwards in time):

    * ``dL/dx = flip(lfilter(N, A, flip(g)))``;
    * ``dy(t)/dn_j = (x/A)(t - j)``, so ``dL/dn_j = sum_t gA(t) x(t - j)`` where
      ``gA = flip(lfilter(1, A, flip(g)))`` is the adjoint of ``1/A`` applied to ``g``;
    * ``dy(t)/da_i = -(y/A)(t - i)``, so ``dL/da_i = -sum_t gA(t) y(t - i)``.
    """

    @staticmethod
    def forward(x: torch.Tensor, num: torch.Tensor, den: torch.Tensor) -> torch.Tensor:  # type: ignore[override]
        xn = x.detach().cpu().numpy().astype(np.float64, copy=False)
        nn_ = num.detach().cpu().numpy().astype(np.float64, copy=False)
        dn = den.detach().cpu().numpy().astype(np.float64, copy=False)
        den_full = np.concatenate([np.ones((dn.shape[0], 1)), dn], axis=1)
        y = _lfilter_channels(nn_, den_full, xn)
        return torch.from_numpy(y).to(dtype=x.dtype, device=x.device)

    @staticmethod
    def setup_context(ctx: Any, inputs: tuple, output: torch.Tensor) -> None:
        x, num, den = inputs
        ctx.save_for_backward(x, num, den, output)

    @staticmethod
    def backward(ctx: Any, grad_y: torch.Tensor) -> tuple:  # type: ignore[override]
        x, num, den, y = ctx.saved_tensors
        need_x, need_num, need_den = ctx.needs_input_grad
        nn_ = num.detach().cpu().numpy().astype(np.float64)
        dn = den.detach().cpu().numpy().astype(np.float64)
        den_full = np.concatenate([np.ones((dn.shape[0], 1)), dn], axis=1)
        g_rev = grad_y.detach().cpu().numpy().astype(np.float64, copy=False)[:, ::-1]
        grad_x = grad_num = grad_den = None
        if need_x:
            gx = _lfilter_channels(nn_, den_full, g_rev)[:, ::-1]
            grad_x = torch.from_numpy(gx.copy()).to(dtype=x.dtype, device=x.device)
        if need_num or need_den:
            ones = np.ones((dn.shape[0], 1))
            g_a = _lfilter_channels(ones, den_full, g_rev)[:, ::-1]
            if need_num:
                xn = x.detach().cpu().numpy().astype(np.float64, copy=False)
                gn = _lagged_sums(g_a, xn, nn_.shape[1], first_lag=0)
                grad_num = torch.from_numpy(gn).to(dtype=num.dtype, device=num.device)
            if need_den:
                yn = y.detach().cpu().numpy().astype(np.float64, copy=False)
                gd = -_lagged_sums(g_a, yn, dn.shape[1], first_lag=1)
                grad_den = torch.from_numpy(gd).to(dtype=den.dtype, device=den.device)
        return grad_x, grad_num, grad_den


def iir_filter(x: torch.Tensor, num: torch.Tensor, den: torch.Tensor) -> torch.Tensor:
    """Differentiable per-channel IIR filter, see :class:`IIRFilterFunction`.

    Shape: ``x`` (B, T, C), ``num`` (C, nb), ``den`` (C, na) without the leading 1 -> (B, T, C).
    """
    if x.ndim != 3 or num.ndim != 2 or den.ndim != 2:
        raise ValueError(
            f"iir_filter expects x (B, T, C), num (C, nb), den (C, na); got {tuple(x.shape)}, "
            f"{tuple(num.shape)}, {tuple(den.shape)}"
        )
    if not num.shape[0] == den.shape[0] == x.shape[2]:
        raise ValueError(
            f"channel counts differ: x has {x.shape[2]}, num {num.shape[0]}, den {den.shape[0]}"
        )
    return IIRFilterFunction.apply(x, num, den)
