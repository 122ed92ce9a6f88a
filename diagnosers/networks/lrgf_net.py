"""The LRGF network: IIR-filter neurons with a sloped, biased tanh and a linear output layer.

This is the dynamic network of Section 2 of the paper (eqs (1)-(8)): ``v`` hidden neurons, each a
weighted sum of the ``n`` inputs followed by an ``r``-th order IIR filter in companion state-space
form (:mod:`diagnosers.networks.iir`) and the activation of eq. (5); a linear output layer maps the ``v``
neuron outputs to ``m`` outputs. Tensors are batch-first, ``(batch, time, channels)``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from enum import StrEnum
from typing import Any, TypeVar

import numpy as np
import torch
from torch import nn
from torch.nn import functional as F

from diagnosers.networks.iir import (
    denominator_from_reflection,
    iir_filter,
    numerator_from_state_space,
    reflection_from_denominator,
)
from diagnosers.networks.lrgf_fused import lrgf_free_run

__all__ = [
    "LRGF",
    "InitialState",
    "contracted_denominator",
    "lrgf_activation",
    "set_scaler_buffers",
]

ArrayT = TypeVar("ArrayT", torch.Tensor, np.ndarray)


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


def lrgf_activation(z: ArrayT, g1: ArrayT, g2: ArrayT, n_linear: int = 0) -> ArrayT:
    """Eq. (5): ``f(z) = (1 - exp(-g2 (z - g1))) / (1 + exp(-g2 (z - g1))) = tanh(g2 (z - g1) / 2)``.

    The last ``n_linear`` neurons (last axis of ``z``) are linear, ``f(z) = z`` (see
    :class:`LRGF`). For torch tensors (training) and numpy arrays (the streaming steppers)
    alike, so that both evaluate the one formula.
    """
    tanh = torch.tanh if isinstance(z, torch.Tensor) else np.tanh
    h = tanh(0.5 * g2 * (z - g1))
    if n_linear:
        cat = torch.cat if isinstance(z, torch.Tensor) else np.concatenate
        h = cat([h[..., :-n_linear], z[..., -n_linear:]], -1)
    return h


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


def contracted_denominator(theta: torch.Tensor, max_pole_radius: float) -> torch.Tensor:
    """Filter denominators ``[a_1..a_r]`` (rows) from the raw parameters ``theta`` ``(v, r)``.

    Reflection coefficients ``k = 0.999 tanh(theta)`` give roots in the open unit disk, which are
    then contracted, ``a_j <- rho^j a_j``, into the radius ``rho = max_pole_radius``.
    """
    # Contracting the roots by rho gives an explicit margin: with k = tanh(theta) alone, poles
    # approach the unit circle exponentially fast in r as the |k_j| saturate. Keeping |k| below
    # 1 as well stops saturated parameters from producing exactly repeated roots, whose
    # float64 rounding would move them by ~eps**(1/r) (past the margin for r >= 6).
    a = denominator_from_reflection(_MAX_REFLECTION * torch.tanh(theta))
    powers = max_pole_radius ** torch.arange(1, theta.shape[-1] + 1, dtype=theta.dtype)
    return a * powers


def _initial_values(
    seed: int,
    sizes: tuple[int, int, int, int],
    init_pole_range: tuple[float, float],
    max_pole_radius: float,
) -> dict[str, np.ndarray]:
    """Initial parameters of an :class:`LRGF` of ``sizes = (v, n, r, m)``, drawn from ``seed``.

    Poles are drawn real in ``init_pole_range``; ``b, b0`` are rescaled so that each neuron's
    filter has unit static gain ``|H_i(1)| = 1``, keeping ``z`` of the order of ``s`` whatever the
    pole positions. ``g1`` is near 0 and ``g2 = 2``, so that ``f`` starts near ``tanh``.
    """
    rng = np.random.default_rng(seed)
    v, n, r, m = sizes
    lo, hi = init_pole_range
    theta = np.empty((v, r))
    for i in range(v):
        poles = rng.uniform(lo, hi, size=r)
        k = reflection_from_denominator(np.poly(poles / max_pole_radius)[1:])
        # clustered real poles of high order can need |k| beyond the cap: clip (still stable)
        theta[i] = np.arctanh(np.clip(k / _MAX_REFLECTION, -1 + 1e-9, 1 - 1e-9))
    b = rng.normal(size=(v, r))
    b0 = rng.normal(scale=0.5, size=v)
    a = contracted_denominator(torch.from_numpy(theta), max_pole_radius)
    num = numerator_from_state_space(a, torch.from_numpy(b), torch.from_numpy(b0))
    dc = (num.sum(-1) / (1.0 + a.sum(-1))).numpy()
    gain = np.where(np.abs(dc) > 1e-3, np.abs(dc), 1.0)
    # the order of the draws is part of what a seed means: changing it changes every network
    return {
        "weight_in": rng.normal(scale=1.0 / math.sqrt(n), size=(v, n)),
        "reflection_raw": theta,
        "b": b / gain[:, None],
        "b0": b0 / gain,
        "g1": rng.normal(scale=0.1, size=v),
        "g2_raw": np.full(v, _inverse_softplus(2.0)),
        "weight_out": rng.uniform(-1.0, 1.0, size=(m, v)) / math.sqrt(v),
    }


def _check_sizes(
    n_inputs: int, n_hidden: int, order: int, n_outputs: int, n_linear: int, steady_window: int
) -> None:
    """Raise ValueError naming the first of :class:`LRGF`'s size arguments out of range."""
    for name, val in (("n_inputs", n_inputs), ("n_hidden", n_hidden), ("order", order)):
        if isinstance(val, bool) or not isinstance(val, int) or val < 1:
            raise ValueError(f"{name}={val!r} must be a positive integer")
    if isinstance(n_outputs, bool) or not isinstance(n_outputs, int) or n_outputs < 1:
        raise ValueError(f"n_outputs={n_outputs!r} must be a positive integer")
    if isinstance(n_linear, bool) or not isinstance(n_linear, int) or not 0 <= n_linear <= n_hidden:
        raise ValueError(
            f"n_linear={n_linear!r}; allowed: an integer from 0 to n_hidden={n_hidden}"
        )
    if isinstance(steady_window, bool) or not isinstance(steady_window, int) or steady_window < 1:
        raise ValueError(f"steady_window={steady_window!r} must be a positive integer")


def _check_poles(
    max_pole_radius: float, init_pole_range: tuple[float, float]
) -> tuple[float, float]:
    """Check :class:`LRGF`'s pole arguments; return ``init_pole_range`` as floats."""
    if not 0.0 < max_pole_radius < 1.0:
        raise ValueError(f"max_pole_radius={max_pole_radius!r} must lie in (0, 1)")
    lo, hi = (float(p) for p in init_pole_range)
    if not -max_pole_radius < lo <= hi < max_pole_radius:
        raise ValueError(
            f"init_pole_range={init_pole_range!r} must satisfy "
            f"-max_pole_radius < low <= high < max_pole_radius (= {max_pole_radius})"
        )
    return lo, hi


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

    **Linear neurons** (``n_linear``, not in the paper; default 0). The last ``n_linear`` neurons
    skip the activation, ``f(z) = z``: a linear dynamic path beside the tanh neurons, which
    extrapolates linearly where a sum of tanh units flattens. It is not the default because on
    the FCC it did not reliably help the fit and made a bank detect small faults later (the
    measurements are in the lab record). ``g1`` and ``g2`` of a linear neuron are unused (zero
    gradient).

    Units: :meth:`forward` takes and returns *physical* units. It standardises the input with the
    buffers ``input_mean``/``input_scale``, runs eq. (6) (:meth:`forward_normalized`), and maps the
    output back with ``output_mean``/``output_scale``. The buffers default to the identity (0 / 1),
    in which case :meth:`forward` is exactly eq. (6); :func:`diagnosers.networks.training.fit_lrgf` sets them.

    Args:
        n_inputs: ``n``, number of inputs.
        n_hidden: ``v``, number of dynamic neurons.
        order: ``r``, IIR filter order of every neuron (>= 1).
        n_outputs: ``m``, number of outputs.
        output_bias: add a trainable output bias ``c_0`` (not in the paper).
        n_linear: how many of the ``v`` neurons (the last ones) are linear, ``0 <= n_linear <= v``.
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
        n_linear: int = 0,
        initial_state: InitialState | str = InitialState.ZERO,
        steady_window: int = 1,
        max_pole_radius: float = 0.999,
        init_pole_range: tuple[float, float] = (0.5, 0.95),
        seed: int = 0,
    ) -> None:
        super().__init__()
        _check_sizes(n_inputs, n_hidden, order, n_outputs, n_linear, steady_window)
        lo, hi = _check_poles(max_pole_radius, init_pole_range)
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
        self.n_linear = n_linear
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
        values = _initial_values(
            self.seed,
            (self.n_hidden, self.n_inputs, self.order, self.n_outputs),
            self.init_pole_range,
            self.max_pole_radius,
        )
        for name, x in values.items():
            getattr(self, name).copy_(torch.as_tensor(x, dtype=self.weight_in.dtype))
        if self.bias_out is not None:
            self.bias_out.zero_()

    # -- derived quantities ----------------------------------------------------------------------
    @property
    def g2(self) -> torch.Tensor:
        """Activation slopes ``g2 > 0``, shape ``(v,)``."""
        return F.softplus(self.g2_raw)

    def filter_coefficients(self) -> tuple[torch.Tensor, torch.Tensor]:
        """Transfer-function coefficients of the neuron filters, always in float64.

        float64 keeps the polynomial provably stable even when the module is float32 (rounding
        coefficients to float32 could push a pole very near the unit circle outside it).

        Returns:
            ``(num, den)``: ``num = [n_0..n_r]`` of shape ``(v, r + 1)`` and ``den = [a_1..a_r]`` of
            shape ``(v, r)``; ``H_i(q) = num_i(q^-1) / (1 + den_i(q^-1))``.
        """
        a = contracted_denominator(self.reflection_raw.double(), self.max_pole_radius)
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
        """Eq. (6) on standardised signals, shape ``(B, T, n) -> (B, T, m)``.

        One fused function with a hand-written backward
        (:func:`diagnosers.networks.lrgf_fused.lrgf_free_run`; an Adam epoch about 1.7 times as fast);
        :meth:`forward_reference` is the same equation as a chain of torch operations, which the
        tests hold it to.
        """
        num, den = self.filter_coefficients()
        steady = self.steady_window if self.initial_state is InitialState.STEADY else 0
        return lrgf_free_run(
            u_n,
            self.weight_in,
            num,
            den,
            self.g1,
            self.g2,
            self.weight_out,
            self.bias_out,
            steady,
            n_linear=self.n_linear,
        )

    def forward_reference(self, u_n: torch.Tensor) -> torch.Tensor:
        """:meth:`forward_normalized` through :meth:`linear_part` and torch's autograd (the oracle)."""
        h = lrgf_activation(self.linear_part(u_n), self.g1, self.g2, self.n_linear)
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
            "n_linear": self.n_linear,
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
            f"output_bias={self.output_bias}, n_linear={self.n_linear}"
        )
