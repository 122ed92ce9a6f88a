"""Locally recurrent globally feed-forward (LRGF) network with IIR-filter neurons.

This is the dynamic network of Section 2 of the paper (eqs (1)-(8)): ``v`` hidden neurons, each a
weighted sum of the ``n`` inputs followed by an ``r``-th order IIR filter in companion state-space
form and a sloped, biased tanh; a linear output layer maps the ``v`` neuron outputs to ``m``
outputs.

Each neuron is a linear SISO filter followed by a static nonlinearity, so the network is evaluated
without any per-time-step Python loop: :class:`IIRFilterFunction` runs ``scipy.signal.lfilter``
over whole sequences and back-propagates with ``lfilter`` on time-reversed signals (the dynoNet
approach). Stability holds for every parameter value because the filter denominators are built
from reflection coefficients ``|k_j| < 1`` (Levinson/Schur step-up recursion).

Tensors are batch-first, ``(batch, time, channels)``. Filtering is done in float64 internally
whatever the module dtype; outputs come back in the input's dtype.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from enum import StrEnum
from typing import Any

import numpy as np
import torch
from scipy import signal as sps
from torch import nn
from torch.nn import functional as F

__all__ = [
    "LRGF",
    "IIRFilterFunction",
    "InitialState",
    "LRGFStepper",
    "NeuronFilters",
    "denominator_from_reflection",
    "iir_filter",
    "lrgf_activation",
    "numerator_from_state_space",
    "reflection_from_denominator",
]


class InitialState(StrEnum):
    """How the neuron filters start at ``k = 0``.

    ``ZERO``: ``x_i(0) = 0`` (the paper's implicit choice). With standardised inputs this is the
    state of a process that sat at the *training-mean* input forever.
    ``STEADY``: the filters start in the steady state of a constant input equal to the first sample
    ``u(0)``, i.e. the process sat at ``u(0)`` forever. No start-up transient for plants that begin
    at rest; recommended for FCC episodes, which start at the nominal operating point.

    With ``steady_window = W > 1`` (:class:`LRGF`) the steady level is the running mean of the
    first ``W`` inputs instead of ``u(0)`` alone: for ``k < W`` the network outputs its steady
    response to ``mean(u(0..k))``, and from ``k = W`` it filters from the steady state of
    ``mean(u(0..W-1))``. This is causal, so streaming and batch evaluation agree. Why: measured
    inputs are noisy, and slow filters with a large static gain turn the noise of one sample into
    a start-up error that decays over hundreds of samples (FCC: T_rg1 from a 0.5 % noisy air flow,
    a residual of 1.6 °C RMS over the first 200 samples of every episode with ``W = 1``).
    """

    ZERO = "zero"
    STEADY = "steady"


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
def _lfilter_channels(num: np.ndarray, den_full: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``lfilter`` along axis 1 of ``x`` (B, T, C) with per-channel coefficients (C, .)."""
    out = np.empty_like(x)
    for c in range(x.shape[2]):
        out[:, :, c] = sps.lfilter(num[c], den_full[c], x[:, :, c], axis=1)
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
        g_rev = grad_y.detach().cpu().numpy().astype(np.float64)[:, ::-1]
        grad_x = grad_num = grad_den = None
        if need_x:
            gx = _lfilter_channels(nn_, den_full, np.ascontiguousarray(g_rev))[:, ::-1]
            grad_x = torch.from_numpy(gx.copy()).to(dtype=x.dtype, device=x.device)
        if need_num or need_den:
            ones = np.ones((dn.shape[0], 1))
            g_a = _lfilter_channels(ones, den_full, np.ascontiguousarray(g_rev))[:, ::-1]
            if need_num:
                xn = x.detach().cpu().numpy().astype(np.float64)
                gn = _lagged_sums(g_a, xn, nn_.shape[1], first_lag=0)
                grad_num = torch.from_numpy(gn).to(dtype=num.dtype, device=num.device)
            if need_den:
                yn = y.detach().cpu().numpy().astype(np.float64)
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


def lrgf_activation(z: torch.Tensor, g1: torch.Tensor, g2: torch.Tensor) -> torch.Tensor:
    """Eq. (5): ``f(z) = (1 - exp(-g2 (z - g1))) / (1 + exp(-g2 (z - g1))) = tanh(g2 (z - g1) / 2)``."""
    return torch.tanh(0.5 * g2 * (z - g1))


_MAX_REFLECTION = 0.999


def _inverse_softplus(y: float) -> float:
    return y + math.log(-math.expm1(-y))


# ---- the network -------------------------------------------------------------------------------
@torch.no_grad()
def set_scaler_buffers(
    module: nn.Module, input_mean: Any, input_scale: Any, output_mean: Any, output_scale: Any
) -> None:
    """Copy a standardisation (physical = normalised · scale + mean) into ``module``'s buffers.

    Shared by the LRGF and the model-error model; shapes must match, scales must be positive.
    """
    for name, val in (
        ("input_mean", input_mean),
        ("input_scale", input_scale),
        ("output_mean", output_mean),
        ("output_scale", output_scale),
    ):
        buf = getattr(module, name)
        t = torch.as_tensor(np.asarray(val, dtype=np.float64), dtype=buf.dtype)
        if t.shape != buf.shape:
            raise ValueError(
                f"scaler entry must have shape {tuple(buf.shape)}, got {tuple(t.shape)}"
            )
        buf.copy_(t)
    if (module.input_scale <= 0).any() or (module.output_scale <= 0).any():
        raise ValueError("scaler scales must be positive")


class LRGF(nn.Module):
    r"""LRGF network of IIR-filter neurons, eqs. (1)-(8) of the paper, with an optional scaler.

    Neuron ``i`` (``i = 1..v``) computes

    .. math::
        s_i(k) = w_i u(k),\qquad x_i(k+1) = A_i x_i(k) + \mathbf{1}\, s_i(k),\qquad
        y_i(k) = f\big(b_i x_i(k) + b_{0,i} s_i(k);\ g_{1,i}, g_{2,i}\big)

    with ``A_i`` the companion matrix of eq. (3) and ``f(z) = tanh(g2 (z - g1) / 2)`` (eq. (5)).
    The pre-activation ``z_i = H_i(q) s_i`` with

    .. math::
        H_i(q) = b_i (qI - A_i)^{-1}\mathbf{1} + b_{0,i}
               = \frac{n_{0,i} + n_{1,i} q^{-1} + \dots + n_{r,i} q^{-r}}
                      {1 + a_{1,i} q^{-1} + \dots + a_{r,i} q^{-r}},

    and the network output is ``y(k) = C f(z(k)) (+ c_0)`` (eq. (6); eq. (6) has no output bias, so
    ``output_bias`` defaults to ``False``).

    Units: :meth:`forward` takes and returns *physical* units. It standardises the input with the
    buffers ``input_mean``/``input_scale``, runs eq. (6) (:meth:`forward_normalized`), and maps the
    output back with ``output_mean``/``output_scale``. The buffers default to the identity (0 / 1),
    in which case :meth:`forward` is exactly eq. (6); :func:`diagnosers.training.fit_lrgf` sets them.

    Args:
        n_inputs: ``n``, number of inputs.
        n_hidden: ``v``, number of dynamic neurons.
        order: ``r``, IIR filter order of every neuron (>= 1).
        n_outputs: ``m``, number of outputs.
        output_bias: add a trainable output bias ``c_0`` (not in the paper).
        initial_state: ``"zero"`` or ``"steady"``, see :class:`InitialState`.
        steady_window: ``W``, number of first samples whose running mean sets the steady start
            (only with ``initial_state="steady"``; 1 = the first sample alone), see
            :class:`InitialState`.
        max_pole_radius: ``rho``, every pole satisfies ``|p| <= rho < 1`` for any parameter value.
            ``0.999`` admits time constants up to ~1000 samples (FCC at Ts = 10 s: 2.8 h, against a
            41 min slowest plant mode) and keeps a margin that float64 root finders resolve even
            for clustered poles of order 5.
        init_pole_range: real poles of every neuron are drawn uniformly from this interval at
            initialisation (then reparametrised); choose it to match the sampling rate.
        seed: seed of the local generator used for initialisation (global RNG untouched).

    Shape:
        - Input: ``(B, T, n)``.
        - Output: ``(B, T, m)``.

    Attributes:
        weight_in: ``W`` rows ``w_i``, shape ``(v, n)`` (eq. (1)).
        reflection_raw: ``theta``, shape ``(v, r)``; reflection coefficients
            ``k = 0.999 tanh(theta)`` give a polynomial with roots in the open unit disk, which is
            then contracted, ``a_j <- rho^j a_j``, so that all poles lie within radius ``rho``.
        b: feed-forward filter parameters ``b_i``, shape ``(v, r)`` (eq. (4), matrix ``B``).
        b0: ``b0_i``, shape ``(v,)``; ``D = diag(b0) W`` (eq. (8)).
        g1: activation bias, shape ``(v,)``.
        g2_raw: ``g2 = softplus(g2_raw) > 0``, shape ``(v,)``.
        weight_out: ``C``, shape ``(m, v)``.
        bias_out: ``c_0``, shape ``(m,)``, only if ``output_bias``.
        input_mean, input_scale, output_mean, output_scale: scaler buffers, shapes ``(n,)``/``(m,)``.

    Example:
        >>> import torch
        >>> net = LRGF(n_inputs=2, n_hidden=3, order=2, n_outputs=1, seed=0)
        >>> y = net(torch.zeros(4, 100, 2))
        >>> tuple(y.shape)
        (4, 100, 1)
        >>> num, den = net.filter_coefficients()
        >>> tuple(num.shape), tuple(den.shape)
        ((3, 3), (3, 2))
    """

    def __init__(
        self,
        n_inputs: int,
        n_hidden: int,
        order: int,
        n_outputs: int = 1,
        *,
        output_bias: bool = False,
        initial_state: InitialState | str = InitialState.ZERO,
        steady_window: int = 1,
        max_pole_radius: float = 0.999,
        init_pole_range: tuple[float, float] = (0.5, 0.95),
        seed: int = 0,
    ) -> None:
        super().__init__()
        for name, val in (("n_inputs", n_inputs), ("n_hidden", n_hidden), ("order", order)):
            if isinstance(val, bool) or not isinstance(val, int) or val < 1:
                raise ValueError(f"{name}={val!r} must be a positive integer")
        if isinstance(n_outputs, bool) or not isinstance(n_outputs, int) or n_outputs < 1:
            raise ValueError(f"n_outputs={n_outputs!r} must be a positive integer")
        if (
            isinstance(steady_window, bool)
            or not isinstance(steady_window, int)
            or steady_window < 1
        ):
            raise ValueError(f"steady_window={steady_window!r} must be a positive integer")
        if not 0.0 < max_pole_radius < 1.0:
            raise ValueError(f"max_pole_radius={max_pole_radius!r} must lie in (0, 1)")
        lo, hi = (float(p) for p in init_pole_range)
        if not -max_pole_radius < lo <= hi < max_pole_radius:
            raise ValueError(
                f"init_pole_range={init_pole_range!r} must satisfy "
                f"-max_pole_radius < low <= high < max_pole_radius (= {max_pole_radius})"
            )
        try:
            self.initial_state = InitialState(initial_state)
        except ValueError:
            raise ValueError(
                f"initial_state={initial_state!r}; choose one of {[s.value for s in InitialState]}"
            ) from None
        self.n_inputs, self.n_hidden, self.order, self.n_outputs = (
            n_inputs,
            n_hidden,
            order,
            n_outputs,
        )
        self.output_bias = bool(output_bias)
        self.steady_window = steady_window
        self.max_pole_radius = float(max_pole_radius)
        self.init_pole_range = (lo, hi)
        self.seed = int(seed)

        v, n, r, m = n_hidden, n_inputs, order, n_outputs
        self.weight_in = nn.Parameter(torch.empty(v, n))
        self.reflection_raw = nn.Parameter(torch.empty(v, r))
        self.b = nn.Parameter(torch.empty(v, r))
        self.b0 = nn.Parameter(torch.empty(v))
        self.g1 = nn.Parameter(torch.empty(v))
        self.g2_raw = nn.Parameter(torch.empty(v))
        self.weight_out = nn.Parameter(torch.empty(m, v))
        self.bias_out = nn.Parameter(torch.empty(m)) if self.output_bias else None
        self.register_buffer("input_mean", torch.zeros(n))
        self.register_buffer("input_scale", torch.ones(n))
        self.register_buffer("output_mean", torch.zeros(m))
        self.register_buffer("output_scale", torch.ones(m))
        self.reset_parameters()

    # -- initialisation --------------------------------------------------------------------------
    @torch.no_grad()
    def reset_parameters(self) -> None:
        """Initialise from ``seed`` with a local RNG (global RNG untouched).

        Poles are drawn real in ``init_pole_range``; ``b, b0`` are rescaled so that each neuron's
        filter has unit static gain ``|H_i(1)| = 1``, keeping ``z`` of the order of ``s`` whatever the
        pole positions. ``g1 = 0`` and ``g2 = 2`` make ``f = tanh`` at the start.
        """
        rng = np.random.default_rng(self.seed)
        v, n, r, m = self.n_hidden, self.n_inputs, self.order, self.n_outputs
        lo, hi = self.init_pole_range
        theta = np.empty((v, r))
        for i in range(v):
            poles = rng.uniform(lo, hi, size=r)
            k = reflection_from_denominator(np.poly(poles / self.max_pole_radius)[1:])
            # clustered real poles of high order can need |k| beyond the cap: clip (still stable)
            theta[i] = np.arctanh(np.clip(k / _MAX_REFLECTION, -1 + 1e-9, 1 - 1e-9))
        b = rng.normal(size=(v, r))
        b0 = rng.normal(scale=0.5, size=v)
        a = self._denominator(torch.from_numpy(theta))
        num = numerator_from_state_space(a, torch.from_numpy(b), torch.from_numpy(b0))
        dc = (num.sum(-1) / (1.0 + a.sum(-1))).numpy()
        gain = np.where(np.abs(dc) > 1e-3, np.abs(dc), 1.0)
        dt = self.weight_in.dtype

        def put(p: torch.Tensor, x: np.ndarray) -> None:
            p.copy_(torch.as_tensor(x, dtype=dt))

        put(self.weight_in, rng.normal(scale=1.0 / math.sqrt(n), size=(v, n)))
        put(self.reflection_raw, theta)
        put(self.b, b / gain[:, None])
        put(self.b0, b0 / gain)
        put(self.g1, rng.normal(scale=0.1, size=v))
        put(self.g2_raw, np.full(v, _inverse_softplus(2.0)))
        put(self.weight_out, rng.uniform(-1.0, 1.0, size=(m, v)) / math.sqrt(v))
        if self.bias_out is not None:
            self.bias_out.zero_()

    # -- derived quantities ----------------------------------------------------------------------
    @property
    def g2(self) -> torch.Tensor:
        """Activation slopes ``g2 > 0``, shape ``(v,)``."""
        return F.softplus(self.g2_raw)

    def _denominator(self, theta: torch.Tensor) -> torch.Tensor:
        # Contracting the roots by rho gives an explicit margin: with k = tanh(theta) alone, poles
        # approach the unit circle exponentially fast in r as the |k_j| saturate. Keeping |k| below
        # 1 as well stops saturated parameters from producing exactly repeated roots, whose
        # float64 rounding would move them by ~eps**(1/r) (past the margin for r >= 6).
        a = denominator_from_reflection(_MAX_REFLECTION * torch.tanh(theta))
        powers = self.max_pole_radius ** torch.arange(1, self.order + 1, dtype=theta.dtype)
        return a * powers

    def filter_coefficients(self) -> tuple[torch.Tensor, torch.Tensor]:
        """Transfer-function coefficients of the neuron filters, always in float64.

        float64 keeps the polynomial provably stable even when the module is float32 (rounding
        coefficients to float32 could push a pole very near the unit circle outside it).

        Returns:
            ``(num, den)``: ``num = [n_0..n_r]`` of shape ``(v, r + 1)`` and ``den = [a_1..a_r]`` of
            shape ``(v, r)``; ``H_i(q) = num_i(q^-1) / (1 + den_i(q^-1))``.
        """
        a = self._denominator(self.reflection_raw.double())
        num = numerator_from_state_space(a, self.b.double(), self.b0.double())
        return num, a

    def linear_part(self, u_n: torch.Tensor) -> torch.Tensor:
        """Neuron pre-activations ``z_i = b_i x_i + b0_i s_i`` for *standardised* input ``u_n``.

        Shape: ``(B, T, n) -> (B, T, v)``.
        """
        s = u_n @ self.weight_in.T
        num, den = self.filter_coefficients()
        if self.initial_state is InitialState.STEADY:
            # by linearity: steady response to the constant s(0) plus the zero-state response to
            # the deviation s - s(0); the static gain is H(1) = sum(num) / (1 + sum(den))
            dc = (num.sum(-1) / (1.0 + den.sum(-1))).to(s.dtype)
            # w = 1 is the first-sample start: its zero input at k = 0 leaves the state at rest
            w = min(self.steady_window, s.shape[1])
            count = torch.arange(1, w + 1, dtype=s.dtype, device=s.device)[None, :, None]
            s_bar = torch.cumsum(s[:, :w, :], dim=1) / count
            s0 = s_bar[:, -1:, :]
            head = dc * s_bar
            if w == s.shape[1]:
                return head
            return torch.cat([head, iir_filter(s[:, w:, :] - s0, num, den) + dc * s0], dim=1)
        return iir_filter(s, num, den)

    def forward_normalized(self, u_n: torch.Tensor) -> torch.Tensor:
        """Eq. (6) on standardised signals, shape ``(B, T, n) -> (B, T, m)``."""
        h = lrgf_activation(self.linear_part(u_n), self.g1, self.g2)
        y = h @ self.weight_out.T
        if self.bias_out is not None:
            y = y + self.bias_out
        return y

    def forward(self, u: torch.Tensor) -> torch.Tensor:
        """Simulate the network on physical inputs, shape ``(B, T, n) -> (B, T, m)``."""
        if u.ndim != 3 or u.shape[-1] != self.n_inputs:
            raise ValueError(
                f"LRGF expects input of shape (batch, time, {self.n_inputs}); got {tuple(u.shape)}"
            )
        u_n = (u - self.input_mean) / self.input_scale
        return self.forward_normalized(u_n) * self.output_scale + self.output_mean

    @torch.no_grad()
    def predict(self, u: np.ndarray) -> np.ndarray:
        """Numpy convenience: physical ``u`` of shape ``(T, n)`` or ``(B, T, n)`` -> ``(T, m)`` / ``(B, T, m)``."""
        arr = np.asarray(u, dtype=np.float64)
        squeeze = arr.ndim == 2
        x = torch.as_tensor(arr[None] if squeeze else arr, dtype=self.weight_in.dtype)
        y = self(x).to(torch.float64).numpy()
        return y[0] if squeeze else y

    @torch.no_grad()
    def set_scaler(
        self,
        input_mean: Sequence[float] | np.ndarray,
        input_scale: Sequence[float] | np.ndarray,
        output_mean: Sequence[float] | np.ndarray,
        output_scale: Sequence[float] | np.ndarray,
    ) -> None:
        """Set the standardisation buffers (physical = normalised * scale + mean)."""
        set_scaler_buffers(self, input_mean, input_scale, output_mean, output_scale)

    def poles(self) -> np.ndarray:
        """Poles of every neuron filter, complex array of shape ``(v, r)``."""
        _, den = self.filter_coefficients()
        d = den.detach().numpy()
        return np.stack([np.roots(np.concatenate([[1.0], row])) for row in d])

    # -- persistence -----------------------------------------------------------------------------
    def get_config(self) -> dict[str, Any]:
        """JSON-serialisable constructor arguments (plus ``kind`` and ``dtype``) to rebuild the module."""
        return {
            "kind": "lrgf",
            "n_inputs": self.n_inputs,
            "n_hidden": self.n_hidden,
            "order": self.order,
            "n_outputs": self.n_outputs,
            "output_bias": self.output_bias,
            "initial_state": self.initial_state.value,
            "steady_window": self.steady_window,
            "max_pole_radius": self.max_pole_radius,
            "init_pole_range": list(self.init_pole_range),
            "seed": self.seed,
            "dtype": str(self.weight_in.dtype).removeprefix("torch."),
        }

    @classmethod
    def from_config(cls, config: dict[str, Any]) -> LRGF:
        """Rebuild an (untrained) module from :meth:`get_config`; then ``load_state_dict``."""
        cfg = dict(config)
        kind = cfg.pop("kind", "lrgf")
        if kind != "lrgf":
            raise ValueError(f"config is for a {kind!r} module, not 'lrgf'")
        dtype = getattr(torch, cfg.pop("dtype", "float32"))
        cfg["init_pole_range"] = tuple(cfg["init_pole_range"])
        n_in, n_h, order = cfg.pop("n_inputs"), cfg.pop("n_hidden"), cfg.pop("order")
        return cls(n_in, n_h, order, cfg.pop("n_outputs"), **cfg).to(dtype)

    def extra_repr(self) -> str:
        return (
            f"n={self.n_inputs}, v={self.n_hidden}, r={self.order}, m={self.n_outputs}, "
            f"initial_state={self.initial_state.value}, steady_window={self.steady_window}, "
            f"output_bias={self.output_bias}"
        )


# ---- numpy streaming -----------------------------------------------------------------------------
def filter_step(
    num: np.ndarray, den: np.ndarray, zi: np.ndarray | None, s: np.ndarray, steady: bool
) -> tuple[np.ndarray, np.ndarray]:
    """One sample of every neuron filter in transposed direct form II (as ``lfilter``).

    ``num`` (v, r+1), ``den`` (v, r) without the leading 1, ``s`` (v,) the filter inputs. ``zi``
    None starts a sequence: at the steady state of ``s`` when ``steady``, else at rest.
    Returns (filter outputs (v,), new state (v, r)).
    """
    if zi is None:
        if steady:
            y_ss = num.sum(1) / (1.0 + den.sum(1)) * s
            terms = num[:, 1:] * s[:, None] - den * y_ss[:, None]
            zi = np.cumsum(terms[:, ::-1], axis=1)[:, ::-1].copy()
        else:
            zi = np.zeros_like(den)
    z = num[:, 0] * s + zi[:, 0]
    new = num[:, 1:] * s[:, None] - den * z[:, None]
    new[:, :-1] += zi[:, 1:]
    return z, new


class NeuronFilters:
    """Streaming state of a set of neuron filters, with the start convention of :class:`LRGF`.

    ``num`` (v, r+1) and ``den`` (v, r) as :meth:`LRGF.filter_coefficients`; :meth:`step` takes the
    filter inputs ``s(k)`` (v,) and returns the filter outputs. With ``steady`` the sequence starts
    at steady state, over a running mean of the first ``steady_window`` inputs
    (see :class:`InitialState`), exactly as :meth:`LRGF.linear_part` does on a whole sequence.
    """

    def __init__(self, num: np.ndarray, den: np.ndarray, steady: bool, steady_window: int) -> None:
        self.num, self.den = num, den
        self.steady, self.steady_window = steady, steady_window
        self.reset()

    def reset(self) -> None:
        self._zi: np.ndarray | None = None
        self._k = 0
        self._s_sum = np.zeros(self.num.shape[0])

    def step(self, s: np.ndarray) -> np.ndarray:
        if self.steady and self._k < self.steady_window:
            self._k += 1
            self._s_sum = self._s_sum + s
            z, self._zi = filter_step(self.num, self.den, None, self._s_sum / self._k, True)
            return z
        z, self._zi = filter_step(self.num, self.den, self._zi, s, self.steady)
        return z


class LRGFStepper:
    """Sample-by-sample evaluation of a trained :class:`LRGF` in numpy float64.

    Each neuron filter runs in transposed direct form II (the form ``scipy.signal.lfilter`` uses),
    so :meth:`step` over a sequence equals :meth:`LRGF.forward` on it (to float64 rounding when the
    module is float64). The weights are copied at construction; later training of the module does
    not affect the stepper.

    Example:
        >>> import numpy as np
        >>> net = LRGF(2, 3, 2, 1, seed=0).double()
        >>> st = LRGFStepper(net)
        >>> y = np.stack([st.step(row) for row in np.ones((10, 2))])
        >>> bool(np.allclose(y, net.predict(np.ones((10, 2)))))
        True
    """

    def __init__(self, model: LRGF) -> None:
        with torch.no_grad():
            num, den = model.filter_coefficients()

            def np64(t: torch.Tensor) -> np.ndarray:
                return t.detach().to(torch.float64).numpy().copy()

            self.num, self.den = np64(num), np64(den)
            self.filters = NeuronFilters(
                self.num,
                self.den,
                model.initial_state is InitialState.STEADY,
                model.steady_window,
            )
            self.w = np64(model.weight_in)
            self.g1, self.g2 = np64(model.g1), np64(model.g2)
            self.c = np64(model.weight_out)
            self.c0 = (
                np64(model.bias_out) if model.bias_out is not None else np.zeros(model.n_outputs)
            )
            self.in_mean, self.in_scale = np64(model.input_mean), np64(model.input_scale)
            self.out_mean, self.out_scale = np64(model.output_mean), np64(model.output_scale)
        self.initial_state = model.initial_state
        self.n_inputs = model.n_inputs
        self.reset()

    def reset(self) -> None:
        """Start a new sequence (the next :meth:`step` is ``k = 0``)."""
        self.filters.reset()

    def step(self, u: np.ndarray) -> np.ndarray:
        """Consume ``u(k)`` (physical, shape ``(n,)``) and return ``y(k)`` (physical, shape ``(m,)``)."""
        s = self.w @ ((np.asarray(u, dtype=np.float64) - self.in_mean) / self.in_scale)
        z = self.filters.step(s)
        h = np.tanh(0.5 * self.g2 * (z - self.g1))
        return (self.c @ h + self.c0) * self.out_scale + self.out_mean
