"""The LRGF network's free run as one differentiable function with a hand-written backward.

:meth:`diagnosers.networks.lrgf_net.LRGF.linear_part` followed by the activation and the output layer is
the reference: a chain of torch operations over ``(batch, time, neurons)`` tensors, each of which
autograd walks back with its own full-size temporaries (the steady start's slice and concatenation
alone allocate and zero a copy of the pre-activations). Training spends most of its time there, not
in the filters. :class:`LRGFFreeRun` computes the same eq. (6) in one pass per stage on a
neuron-major ``(v, batch * time)`` layout, so each neuron's filter input is one contiguous block for
``scipy.signal.lfilter``, and back-propagates with the same adjoint as
:class:`diagnosers.networks.iir.IIRFilterFunction`:

* ``dL/dx(t) = sum_j n_j gA(t + j)`` with ``gA`` the anti-causal ``1/A`` applied to ``dL/dz`` (one
  reverse-time ``lfilter`` per neuron instead of two: the numerator is a short FIR);
* ``dL/dn_j = sum_t gA(t) x(t - j)`` and ``dL/da_i = -sum_t gA(t) zf(t - i)``, ``zf`` the filter's
  zero-state output.

Everything runs in float64 whatever the module's dtype (as the filters always did); the results
are cast back. The reference path stays, and the tests hold this function to it (values and
gradients) and to ``torch.autograd.gradcheck``. The two agree to rounding, not bit for bit: sums
run in another order.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
from torch.autograd.function import once_differentiable

from diagnosers.networks.iir import lfilter_rows

__all__ = ["LRGFFreeRun", "lrgf_free_run"]


def _np64(t: torch.Tensor) -> np.ndarray:
    return t.detach().cpu().numpy().astype(np.float64, copy=False)


def _lagged_dots(g: np.ndarray, x: np.ndarray, n_lags: int, first_lag: int) -> np.ndarray:
    """``out[c, j] = sum_{b,t} g[c, b, t] x[c, b, t - (first_lag + j)]``, zero before ``t = 0``."""
    t_len = x.shape[-1]
    out = np.zeros((x.shape[0], n_lags))
    for j in range(n_lags):
        lag = first_lag + j
        if lag < t_len:
            out[:, j] = np.einsum("cbt,cbt->c", g[..., lag:], x[..., : t_len - lag])
    return out


class LRGFFreeRun(torch.autograd.Function):
    """``y = C tanh(g2 (H(q) W u - g1) / 2) (+ c0)``, eq. (6), over whole sequences; the last
    ``n_linear`` neurons output ``H(q) W u`` itself.

    Inputs: ``u_n`` (B, T, n) standardised inputs; ``weight_in`` (v, n); ``num`` (v, r+1) and
    ``den`` (v, r) the neuron filters (``a_0 = 1`` implied); ``g1``, ``g2`` (v,); ``weight_out``
    (m, v); ``bias_out`` (m,) or ``None``; ``steady_window`` ``W`` for the steady start
    (:class:`diagnosers.networks.lrgf_net.InitialState`), ``0`` for the zero start. Output (B, T, m) in
    ``u_n``'s dtype.

    Steady start, as :meth:`diagnosers.networks.lrgf_net.LRGF.linear_part`: with ``s = W u`` and
    ``w = min(W, T)``, ``z(t) = H(1) mean(s(0..t))`` for ``t < w``, then
    ``z = H(q)(s - s0) + H(1) s0`` from ``t = w`` on (zero state at ``w``), ``s0 = mean(s(0..w-1))``.
    """

    @staticmethod
    def forward(  # type: ignore[override]
        ctx: Any,
        u_n: torch.Tensor,
        weight_in: torch.Tensor,
        num: torch.Tensor,
        den: torch.Tensor,
        g1: torch.Tensor,
        g2: torch.Tensor,
        weight_out: torch.Tensor,
        bias_out: torch.Tensor | None,
        steady_window: int,
        n_linear: int,
    ) -> torch.Tensor:
        b_len, t_len, n_in = u_n.shape
        num_, den_ = _np64(num), _np64(den)
        g1_, g2_ = _np64(g1), _np64(g2)
        w_in, w_out = _np64(weight_in), _np64(weight_out)
        v = w_in.shape[0]
        den_full = np.concatenate([np.ones((v, 1)), den_], axis=1)
        u_rows = np.ascontiguousarray(_np64(u_n).reshape(b_len * t_len, n_in).T)  # (n, BT)
        s = (w_in @ u_rows).reshape(v, b_len, t_len)
        z = np.empty_like(s)
        w = min(steady_window, t_len) if steady_window > 0 else 0
        dc = num_.sum(1) / (1.0 + den_.sum(1))
        s_bar = s0 = None
        if w:
            count = np.arange(1, w + 1, dtype=np.float64)
            s_bar = np.cumsum(s[..., :w], axis=-1) / count
            s0 = s_bar[..., -1]  # (v, B)
            z[..., :w] = dc[:, None, None] * s_bar
        x = s[..., w:] - s0[..., None] if w else s  # the filter's input, zero state at t = w
        zf = lfilter_rows(num_, den_full, x)
        z[..., w:] = zf + dc[:, None, None] * s0[..., None] if w else zf
        centred = z - g1_[:, None, None]
        h = np.tanh((0.5 * g2_)[:, None, None] * centred)
        lin = slice(v - n_linear, v)  # the linear neurons: f(z) = z
        h[lin] = z[lin]
        y = w_out @ h.reshape(v, b_len * t_len)  # (m, BT)
        if bias_out is not None:
            y += _np64(bias_out)[:, None]
        ctx.parts = (u_rows, x, zf, centred, h, s_bar, s0, dc, w, (b_len, t_len), lin)
        ctx.coefs = (num_, den_, den_full, g2_, w_in, w_out)
        ctx.has_bias = bias_out is not None
        ctx.u_dtype = u_n.dtype
        ctx.dtypes = tuple(
            None if t is None else t.dtype
            for t in (weight_in, num, den, g1, g2, weight_out, bias_out)
        )
        out = np.ascontiguousarray(y.T).reshape(b_len, t_len, -1)
        return torch.from_numpy(out).to(dtype=u_n.dtype, device=u_n.device)

    @staticmethod
    @once_differentiable
    def backward(ctx: Any, grad_y: torch.Tensor) -> tuple:  # type: ignore[override]
        u_rows, x, zf, centred, h, s_bar, s0, dc, w, (b_len, t_len), lin = ctx.parts
        num_, den_, den_full, g2_, w_in, w_out = ctx.coefs
        v, r = den_.shape
        gy = np.ascontiguousarray(_np64(grad_y).reshape(b_len * t_len, -1).T)  # (m, BT)
        grad_w_out = gy @ h.reshape(v, -1).T
        grad_bias = gy.sum(1) if ctx.has_bias else None
        # through the activation: da = dh (1 - h^2), dz = da g2 / 2; a linear neuron's dz = dh
        dh = (w_out.T @ gy).reshape(v, b_len, t_len)
        d_lin = dh[lin].copy()
        da = dh
        da *= 1.0 - h * h
        grad_g2 = 0.5 * np.einsum("cbt,cbt->c", da, centred)
        dz = da
        dz *= (0.5 * g2_)[:, None, None]
        grad_g1 = -dz.sum(axis=(1, 2))
        dz[lin] = d_lin
        grad_g1[lin] = grad_g2[lin] = 0.0
        # through the filter (zero state at t = w): gA = anti-causal 1/A applied to dz
        dz_f = dz[..., w:]
        ones = np.ones((v, 1))
        g_a = lfilter_rows(ones, den_full, dz_f[..., ::-1])[..., ::-1]
        dx = num_[:, :1, None] * g_a
        for j in range(1, r + 1):
            if j < g_a.shape[-1]:
                dx[..., :-j] += num_[:, j, None, None] * g_a[..., j:]
        grad_num = _lagged_dots(g_a, x, r + 1, first_lag=0)
        grad_den = -_lagged_dots(g_a, zf, r, first_lag=1)
        if w:
            # z = H(1) s0 on the filtered part and H(1) s_bar on the head; s0 = s_bar[w-1], x = s - s0
            grad_dc = np.einsum("cbt,cb->c", dz_f, s0) + np.einsum("cbt,cbt->c", dz[..., :w], s_bar)
            d_s0 = dc[:, None] * dz_f.sum(-1) - dx.sum(-1)
            d_sbar = dc[:, None, None] * dz[..., :w]
            d_sbar[..., -1] += d_s0
            d_sbar /= np.arange(1, w + 1, dtype=np.float64)
            ds = np.empty((v, b_len, t_len))
            ds[..., :w] = np.cumsum(d_sbar[..., ::-1], axis=-1)[..., ::-1]
            ds[..., w:] = dx
            den_sum = 1.0 + den_.sum(1)
            grad_num += (grad_dc / den_sum)[:, None]
            grad_den -= (grad_dc * num_.sum(1) / den_sum**2)[:, None]
        else:
            ds = dx
        grad_w_in = ds.reshape(v, -1) @ u_rows.T
        grad_u = None
        if ctx.needs_input_grad[0]:
            grad_u = np.ascontiguousarray((w_in.T @ ds.reshape(v, -1)).T).reshape(b_len, t_len, -1)

        grads = (grad_w_in, grad_num, grad_den, grad_g1, grad_g2, grad_w_out, grad_bias)
        return (
            None if grad_u is None else torch.from_numpy(grad_u).to(dtype=ctx.u_dtype),
            *(
                None
                if g is None or dt is None
                else torch.from_numpy(np.ascontiguousarray(g)).to(dtype=dt)
                for g, dt in zip(grads, ctx.dtypes, strict=True)
            ),
            None,
            None,
        )


def lrgf_free_run(
    u_n: torch.Tensor,
    weight_in: torch.Tensor,
    num: torch.Tensor,
    den: torch.Tensor,
    g1: torch.Tensor,
    g2: torch.Tensor,
    weight_out: torch.Tensor,
    bias_out: torch.Tensor | None = None,
    steady_window: int = 0,
    *,
    n_linear: int = 0,
) -> torch.Tensor:
    """Eq. (6) on standardised ``u_n`` (B, T, n) -> (B, T, m); see :class:`LRGFFreeRun`.

    ``steady_window`` ``0`` is the zero start, ``W >= 1`` the steady start over ``W`` samples;
    the last ``n_linear`` neurons are linear (:class:`diagnosers.networks.lrgf_net.LRGF`).
    """
    if u_n.ndim != 3 or u_n.shape[-1] != weight_in.shape[1]:
        raise ValueError(
            f"u_n must have shape (batch, time, {weight_in.shape[1]}); got {tuple(u_n.shape)}"
        )
    v = weight_in.shape[0]
    shapes = {
        "num": (num.shape, (v, num.shape[-1])),  # its length sets the filter order r + 1
        "den": (den.shape, (v, num.shape[-1] - 1)),
        "g1": (g1.shape, (v,)),
        "g2": (g2.shape, (v,)),
        "weight_out": (weight_out.shape, (weight_out.shape[0], v)),
    }
    if bias_out is not None:
        shapes["bias_out"] = (bias_out.shape, (weight_out.shape[0],))
    for name, (got, want) in shapes.items():
        if tuple(got) != want:
            raise ValueError(
                f"{name} has shape {tuple(got)}; allowed: {want} for {v} neurons "
                f"(weight_in {tuple(weight_in.shape)})"
            )
    if isinstance(steady_window, bool) or not isinstance(steady_window, int) or steady_window < 0:
        raise ValueError(f"steady_window={steady_window!r} must be an integer >= 0")
    if isinstance(n_linear, bool) or not isinstance(n_linear, int) or not 0 <= n_linear <= v:
        raise ValueError(f"n_linear={n_linear!r}; allowed: an integer from 0 to {v} (the neurons)")
    return LRGFFreeRun.apply(
        u_n, weight_in, num, den, g1, g2, weight_out, bias_out, steady_window, n_linear
    )
