"""Neural model error modelling (Section 3 of the paper): an NNARX model of the residual and bands.

The nominal model (the LRGF of :mod:`diagnosers.lrgf`) leaves a residual ``r = y - y_m``. The
model error model (MEM) :class:`NNARXErrorModel` predicts its structured part ``y_e`` from the
process inputs alone, and eqs. (10)-(11) put a band ``y_m + y_e ± t_α v`` around the measurement.

The MEM always runs in *simulation* mode: its regressor holds delayed process inputs and its *own*
delayed outputs, never the measured residual. A fault therefore cannot leak into the band: if the
MEM were fed the measured residual it would learn to follow the fault and hide it.

Two definitions of the band half-width scale ``v`` are offered by :func:`band_scale`:

* ``"paper"``: ``v = std(y_e)``, the paper's literal text ("v is the standard deviation of y_e").
  It measures how much the error model *moves*, not how wrong the corrected model is, so its
  coverage is not controlled.
* ``"residual"``: ``v = std(y - y_m - y_e)`` on held-out healthy data: the spread of what the
  corrected model still misses. Under the paper's own normality assumption this gives a band with
  coverage ``1 - α``. Recommended.
"""

from __future__ import annotations

import math
from enum import StrEnum
from typing import Any

import numpy as np
import torch
from torch import nn

from diagnosers.alarm import two_sided_normal_quantile
from diagnosers.lrgf import set_scaler_buffers

__all__ = [
    "BandScale",
    "MEMBankStepper",
    "MEMStepper",
    "NNARXErrorModel",
    "OutputActivation",
    "band",
    "band_scale",
    "t_alpha",
]


class OutputActivation(StrEnum):
    """Activation of the MEM output neuron.

    ``LINEAR`` (default): the target is the *standardised* residual, which is not confined to
    ``(-1, 1)``; a tanh output would clip its tails. ``TANH``: the paper's choice.
    """

    LINEAR = "linear"
    TANH = "tanh"


class BandScale(StrEnum):
    """Definition of ``v`` in eqs. (10)-(11); see the module docstring."""

    PAPER = "paper"
    RESIDUAL = "residual"


class NNARXErrorModel(nn.Module):
    r"""NNARX multilayer perceptron run in simulation mode: the neural model error model.

    .. math::
        \varphi(k) = [u(k-1), \dots, u(k-n_b),\ \hat y_e(k-1), \dots, \hat y_e(k-n_a)],\qquad
        \hat y_e(k) = g\big(W_2 \tanh(W_1 \varphi(k) + c_1) + c_2\big)

    on standardised signals, ``g`` the output activation. The past outputs are the model's own
    (simulation / output-error form), so the model is driven by the process inputs only.

    Start of a sequence: delayed inputs before ``k = 0`` equal ``u(0)`` (the process sat at its first
    input), delayed outputs before ``k = 0`` are 0 in standardised units (the training-mean residual).
    :meth:`simulate` and :class:`MEMStepper` share this convention exactly.

    Units: :meth:`simulate` takes physical inputs and returns the residual estimate in physical
    units, through the scaler buffers ``input_mean/input_scale`` and ``output_mean/output_scale``
    (identity by default; :func:`diagnosers.training.fit_mem` sets them).

    Args:
        n_inputs: number of process inputs.
        n_outputs: number of residual channels modelled jointly.
        n_hidden: hidden tanh neurons (paper: 5).
        input_delays: ``n_b`` (paper: 15).
        output_delays: ``n_a`` (paper: 15); 0 gives a non-recurrent NFIR model.
        output_activation: ``"linear"`` (default) or ``"tanh"`` (paper), see :class:`OutputActivation`.
        seed: seed of the local generator used for initialisation.

    Shape:
        - Input ``u``: ``(B, T, n_inputs)``.
        - Output ``y_e``: ``(B, T, n_outputs)``.

    Attributes:
        hidden: ``nn.Linear(n_b * n_inputs + n_a * n_outputs, n_hidden)``; input columns ordered
            delay-major: ``[u(k-1) (all channels), ..., u(k-n_b), y_e(k-1), ..., y_e(k-n_a)]``.
        out: ``nn.Linear(n_hidden, n_outputs)``.
        input_mean, input_scale, output_mean, output_scale: scaler buffers.

    Example:
        >>> import torch
        >>> mem = NNARXErrorModel(n_inputs=2, n_hidden=5, input_delays=3, output_delays=3)
        >>> tuple(mem.simulate(torch.zeros(1, 50, 2)).shape)
        (1, 50, 1)
    """

    def __init__(
        self,
        n_inputs: int,
        n_outputs: int = 1,
        *,
        n_hidden: int = 5,
        input_delays: int = 15,
        output_delays: int = 15,
        output_activation: OutputActivation | str = OutputActivation.LINEAR,
        seed: int = 0,
    ) -> None:
        super().__init__()
        for name, val, low in (
            ("n_inputs", n_inputs, 1),
            ("n_outputs", n_outputs, 1),
            ("n_hidden", n_hidden, 1),
            ("input_delays", input_delays, 1),
            ("output_delays", output_delays, 0),
        ):
            if isinstance(val, bool) or not isinstance(val, int) or val < low:
                raise ValueError(f"{name}={val!r} must be an integer >= {low}")
        try:
            self.output_activation = OutputActivation(output_activation)
        except ValueError:
            raise ValueError(
                f"output_activation={output_activation!r}; choose one of "
                f"{[a.value for a in OutputActivation]}"
            ) from None
        self.n_inputs, self.n_outputs, self.n_hidden = n_inputs, n_outputs, n_hidden
        self.input_delays, self.output_delays = input_delays, output_delays
        self.seed = int(seed)
        # skip_init: nn.Linear's own initialisation would draw from the global torch RNG
        n_reg = input_delays * n_inputs + output_delays * n_outputs
        self.hidden = nn.utils.skip_init(nn.Linear, n_reg, n_hidden)
        self.out = nn.utils.skip_init(nn.Linear, n_hidden, n_outputs)
        self.register_buffer("input_mean", torch.zeros(n_inputs))
        self.register_buffer("input_scale", torch.ones(n_inputs))
        self.register_buffer("output_mean", torch.zeros(n_outputs))
        self.register_buffer("output_scale", torch.ones(n_outputs))
        self.reset_parameters()

    @torch.no_grad()
    def reset_parameters(self) -> None:
        """Initialise from ``seed`` with a local RNG (global RNG untouched).

        Uniform ``±1/sqrt(fan_in)`` as ``nn.Linear`` does, except that the output-feedback columns
        start 10x smaller: the untrained model is then nearly an NFIR model and its free run cannot
        wander off before training has shaped the feedback.
        """
        rng = np.random.default_rng(self.seed)
        dt = self.hidden.weight.dtype
        fan_in = self.hidden.in_features
        w1 = rng.uniform(-1.0, 1.0, size=self.hidden.weight.shape) / math.sqrt(fan_in)
        w1[:, self.input_delays * self.n_inputs :] *= 0.1
        self.hidden.weight.copy_(torch.as_tensor(w1, dtype=dt))
        self.hidden.bias.copy_(
            torch.as_tensor(rng.uniform(-1, 1, self.n_hidden) / math.sqrt(fan_in), dtype=dt)
        )
        bound = 1.0 / math.sqrt(self.n_hidden)
        self.out.weight.copy_(
            torch.as_tensor(rng.uniform(-bound, bound, self.out.weight.shape), dtype=dt)
        )
        self.out.bias.zero_()

    # -- simulation ------------------------------------------------------------------------------
    def lagged_inputs(self, u_n: torch.Tensor) -> torch.Tensor:
        """The input regressor ``[u(k-1)..u(k-n_b)]`` for every ``k`` (``u(<0) = u(0)``).

        It does not depend on the parameters, so training builds it once per episode group and
        passes it to :meth:`input_drive`. Shape: ``(B, T, n) -> (B, T, n_b n)``.
        """
        nb, t_len = self.input_delays, u_n.shape[1]
        pad = u_n[:, :1].expand(-1, nb, -1)
        u_pad = torch.cat([pad, u_n], dim=1)  # u_pad[:, j] = u(j - nb), u(<0) = u(0)
        lagged = torch.stack([u_pad[:, nb - d : nb - d + t_len] for d in range(1, nb + 1)], dim=2)
        return lagged.flatten(2)

    def input_drive(self, u_n: torch.Tensor, lagged: torch.Tensor | None = None) -> torch.Tensor:
        """Input part of the hidden pre-activation, ``W_1u [u(k-1)..u(k-n_b)] + c_1``.

        The inputs are known in advance, so this is computed for all ``k`` at once; only the
        output feedback has to be stepped. ``lagged`` is :meth:`lagged_inputs` of ``u_n`` when
        the caller has it already. Shape: ``(B, T, n) -> (B, T, n_hidden)``.
        """
        if lagged is None:
            lagged = self.lagged_inputs(u_n)
        w_u = self.hidden.weight[:, : self.input_delays * self.n_inputs]
        return lagged @ w_u.T + self.hidden.bias

    def run_normalized(
        self, drive: torch.Tensor, y_past: torch.Tensor | None = None
    ) -> torch.Tensor:
        """Free-run the output recursion given the input drive (standardised units).

        Args:
            drive: :meth:`input_drive` (or a window of it), shape ``(B, T, n_hidden)``.
            y_past: initial output delays ``[y_e(-1), ..., y_e(-n_a)]``, shape ``(B, n_a, m)``;
                zeros if ``None``.

        Returns:
            ``y_e`` in standardised units, shape ``(B, T, m)``.
        """
        bsz, t_len, _ = drive.shape
        na, m = self.output_delays, self.n_outputs
        w_y = self.hidden.weight[:, self.input_delays * self.n_inputs :]
        tanh_out = self.output_activation is OutputActivation.TANH
        if na == 0:
            y = self.out(torch.tanh(drive))
            return torch.tanh(y) if tanh_out else y
        buf = drive.new_zeros((bsz, na * m)) if y_past is None else y_past.flatten(1)
        steps = drive.transpose(0, 1)  # (T, B, H): a contiguous-time view per step
        w_y_t, w_out_t, b_out = w_y.T, self.out.weight.T, self.out.bias
        outs = []
        # few, fused ops per step: this loop dominates the cost of training and validation
        for k in range(t_len):
            h = torch.tanh(torch.addmm(steps[k], buf, w_y_t))
            y = torch.addmm(b_out, h, w_out_t)
            if tanh_out:
                y = torch.tanh(y)
            outs.append(y)
            buf = torch.cat([y, buf[:, : (na - 1) * m]], dim=1)
        return torch.stack(outs, dim=1)

    def lagged_outputs(self, y_meas: torch.Tensor) -> torch.Tensor:
        """The measured output regressor ``[y(k-1)..y(k-n_a)]`` (``y(<0) = 0``) of
        :meth:`one_step_normalized`. Shape: ``(B, T, m) -> (B, T, n_a m)``."""
        na, t_len = self.output_delays, y_meas.shape[1]
        y_pad = torch.cat([y_meas.new_zeros((y_meas.shape[0], na, self.n_outputs)), y_meas], 1)
        return torch.stack(
            [y_pad[:, na - d : na - d + t_len] for d in range(1, na + 1)], 2
        ).flatten(2)

    def one_step_normalized(
        self, drive: torch.Tensor, y_meas: torch.Tensor, lagged: torch.Tensor | None = None
    ) -> torch.Tensor:
        """One-step-ahead (series-parallel) prediction from *measured* past outputs.

        For training warm-starts only: with measured residuals in the regressor a fault would leak
        into the prediction, so detection never uses this. Past outputs before ``k = 0`` are 0.
        ``lagged`` is :meth:`lagged_outputs` of ``y_meas`` when the caller has it already.
        Shape: ``drive`` ``(B, T, n_hidden)``, ``y_meas`` ``(B, T, m)`` -> ``(B, T, m)``.
        """
        pre = drive
        if self.output_delays:
            if lagged is None:
                lagged = self.lagged_outputs(y_meas)
            pre = pre + lagged @ self.hidden.weight[:, self.input_delays * self.n_inputs :].T
        y = self.out(torch.tanh(pre))
        return torch.tanh(y) if self.output_activation is OutputActivation.TANH else y

    def simulate(self, u: torch.Tensor) -> torch.Tensor:
        """Simulate the MEM on physical inputs: ``(B, T, n) -> y_e (B, T, m)`` physical units."""
        if u.ndim != 3 or u.shape[-1] != self.n_inputs:
            raise ValueError(
                f"NNARXErrorModel expects input of shape (batch, time, {self.n_inputs}); "
                f"got {tuple(u.shape)}"
            )
        u_n = (u - self.input_mean) / self.input_scale
        ye_n = self.run_normalized(self.input_drive(u_n))
        return ye_n * self.output_scale + self.output_mean

    forward = simulate

    @torch.no_grad()
    def predict(self, u: np.ndarray) -> np.ndarray:
        """Numpy convenience: ``(T, n)`` or ``(B, T, n)`` physical inputs -> ``(T, m)`` / ``(B, T, m)``."""
        arr = np.asarray(u, dtype=np.float64)
        squeeze = arr.ndim == 2
        x = torch.as_tensor(arr[None] if squeeze else arr, dtype=self.hidden.weight.dtype)
        y = self.simulate(x).to(torch.float64).numpy()
        return y[0] if squeeze else y

    @torch.no_grad()
    def set_scaler(
        self, input_mean: Any, input_scale: Any, output_mean: Any, output_scale: Any
    ) -> None:
        """Set the standardisation buffers (physical = normalised * scale + mean)."""
        set_scaler_buffers(self, input_mean, input_scale, output_mean, output_scale)

    # -- persistence -----------------------------------------------------------------------------
    def get_config(self) -> dict[str, Any]:
        """JSON-serialisable constructor arguments (plus ``kind`` and ``dtype``)."""
        return {
            "kind": "nnarx_mem",
            "n_inputs": self.n_inputs,
            "n_outputs": self.n_outputs,
            "n_hidden": self.n_hidden,
            "input_delays": self.input_delays,
            "output_delays": self.output_delays,
            "output_activation": self.output_activation.value,
            "seed": self.seed,
            "dtype": str(self.hidden.weight.dtype).removeprefix("torch."),
        }

    @classmethod
    def from_config(cls, config: dict[str, Any]) -> NNARXErrorModel:
        """Rebuild an (untrained) module from :meth:`get_config`; then ``load_state_dict``."""
        cfg = dict(config)
        kind = cfg.pop("kind", "nnarx_mem")
        if kind != "nnarx_mem":
            raise ValueError(f"config is for a {kind!r} module, not 'nnarx_mem'")
        dtype = getattr(torch, cfg.pop("dtype", "float32"))
        return cls(cfg.pop("n_inputs"), cfg.pop("n_outputs"), **cfg).to(dtype)

    def extra_repr(self) -> str:
        return (
            f"n_b={self.input_delays}, n_a={self.output_delays}, "
            f"output_activation={self.output_activation.value}"
        )


class MEMStepper:
    """Streaming evaluation of a trained :class:`NNARXErrorModel` in numpy float64.

    Keeps the delayed inputs and the model's own delayed outputs in small shift buffers; equals
    :meth:`NNARXErrorModel.simulate` sample by sample (to float64 rounding for a float64 module).
    Driven by process inputs only. Weights are copied at construction.

    Example:
        >>> import numpy as np
        >>> mem = NNARXErrorModel(1, input_delays=2, output_delays=2).double()
        >>> st = MEMStepper(mem)
        >>> ye = np.stack([st.step(row) for row in np.ones((20, 1))])
        >>> bool(np.allclose(ye, mem.predict(np.ones((20, 1)))))
        True
    """

    def __init__(self, model: NNARXErrorModel) -> None:
        def np64(t: torch.Tensor) -> np.ndarray:
            return t.detach().to(torch.float64).numpy().copy()

        nbn = model.input_delays * model.n_inputs
        w1 = np64(model.hidden.weight)
        self.w_u, self.w_y = w1[:, :nbn].copy(), w1[:, nbn:].copy()
        self.c1 = np64(model.hidden.bias)
        self.w2, self.c2 = np64(model.out.weight), np64(model.out.bias)
        self.in_mean, self.in_scale = np64(model.input_mean), np64(model.input_scale)
        self.out_mean, self.out_scale = np64(model.output_mean), np64(model.output_scale)
        self.tanh_out = model.output_activation is OutputActivation.TANH
        self.n_inputs, self.n_outputs = model.n_inputs, model.n_outputs
        self.input_delays, self.output_delays = model.input_delays, model.output_delays
        self.reset()

    def reset(self) -> None:
        """Start a new sequence (the next :meth:`step` is ``k = 0``)."""
        # flat, most recent first: [u(k-1) channels..., u(k-2) ...]; same layout as the weights
        self._u_buf = np.zeros(self.input_delays * self.n_inputs)
        self._y_buf = np.zeros(self.output_delays * self.n_outputs)
        self._started = False

    def step(self, u: np.ndarray) -> np.ndarray:
        """Consume ``u(k)`` (physical, shape ``(n,)``) and return ``y_e(k)`` (physical, ``(m,)``)."""
        u_n = (np.asarray(u, dtype=np.float64) - self.in_mean) / self.in_scale
        n, m = self.n_inputs, self.n_outputs
        if not self._started:
            self._u_buf[:] = np.tile(u_n, self.input_delays)
            self._started = True
        pre = self.c1 + self.w_u @ self._u_buf
        if self.output_delays:
            pre += self.w_y @ self._y_buf
        y = self.w2 @ np.tanh(pre) + self.c2
        if self.tanh_out:
            y = np.tanh(y)
        # shift the delay lines (numpy copies overlapping slices safely)
        self._u_buf[n:] = self._u_buf[:-n]
        self._u_buf[:n] = u_n
        if self.output_delays:
            self._y_buf[m:] = self._y_buf[:-m]
            self._y_buf[:m] = y
        return y * self.out_scale + self.out_mean


class MEMBankStepper:
    """Several single-output error models, each on its own channels, stepped as one.

    Mathematically :class:`MEMStepper` per model (same delay lines, same start), with the models
    stacked: one delay line holds every model's past inputs and outputs, and one block-diagonal
    matrix (zero-padded to the largest model) maps it to every hidden neuron, so that one sample
    costs two matrix-vector products instead of one pass per model. ``in_idx[j]`` are the
    channels of a measurement vector that model ``j`` reads (its inputs, in order). Weights are
    copied at construction.

    Example:
        >>> import numpy as np
        >>> mems = [NNARXErrorModel(n, input_delays=2, output_delays=3, seed=n).double() for n in (1, 2)]
        >>> idx = [np.array([0]), np.array([2, 1])]
        >>> bank, y = MEMBankStepper(mems, idx), np.random.default_rng(0).normal(size=(20, 3))
        >>> ye = np.stack([bank.step(row) for row in y])
        >>> bool(np.allclose(ye, np.column_stack([m.predict(y[:, i])[:, 0] for m, i in zip(mems, idx)])))
        True
    """

    def __init__(self, models: list[NNARXErrorModel], in_idx: list[np.ndarray]) -> None:
        if any(m.n_outputs != 1 for m in models):
            raise ValueError("MEMBankStepper steps single-output error models")
        steppers = [MEMStepper(m) for m in models]
        k = len(steppers)
        n = max((st.n_inputs for st in steppers), default=1)
        lags = max((max(st.input_delays, st.output_delays) for st in steppers), default=1)
        hs = np.cumsum([0, *(st.c1.shape[0] for st in steppers)])  # hidden rows of each model
        # delay line (lags, k n + k): row d = [u(t-1-d) of every model | y_e(t-1-d) of every
        # model], model j's inputs in columns j n .. j n + n_j; padded entries: channel 0, mean 0,
        # scale 1, weight 0 (they add exact zeros)
        self._kn, width = k * n, k * n + k
        self.idx = np.zeros(k * n, dtype=int)
        self.in_mean, self.in_scale = np.zeros(k * n), np.ones(k * n)
        w1 = np.zeros((hs[-1], lags, width))
        self.c1, self.w2 = np.zeros(hs[-1]), np.zeros((k, hs[-1]))
        self.c2, self.out_mean, self.out_scale = np.zeros(k), np.zeros(k), np.ones(k)
        for j, st in enumerate(steppers):
            rows, cols = slice(hs[j], hs[j + 1]), slice(j * n, j * n + st.n_inputs)
            self.idx[cols] = np.asarray(in_idx[j])
            self.in_mean[cols], self.in_scale[cols] = st.in_mean, st.in_scale
            w1[rows, : st.input_delays, cols] = st.w_u.reshape(-1, st.input_delays, st.n_inputs)
            w1[rows, : st.output_delays, self._kn + j] = st.w_y
            self.c1[rows], self.w2[j, rows] = st.c1, st.w2[0]
            self.c2[j], self.out_mean[j], self.out_scale[j] = (
                st.c2[0],
                st.out_mean[0],
                st.out_scale[0],
            )
        self.w1 = w1.reshape(hs[-1], lags * width)
        self.tanh_out = np.array([st.tanh_out for st in steppers], dtype=bool)
        self._any_tanh = bool(self.tanh_out.any())
        self._shape = (lags, width)
        self.reset()

    def reset(self) -> None:
        """Start a new sequence (the next :meth:`step` is ``k = 0``)."""
        self._x = np.zeros(self._shape)
        self._flat = self._x.reshape(-1)  # a view: the regressor of every hidden neuron
        self._started = False

    def step(self, y: np.ndarray) -> np.ndarray:
        """Consume a measurement vector (physical, indexed by ``in_idx``); ``y_e(k)`` of each model."""
        u_n = (y[self.idx] - self.in_mean) / self.in_scale
        x, kn = self._x, self._kn
        if not self._started:  # the inputs' past is the first input (as MEMStepper)
            x[:, :kn] = u_n
            self._started = True
        ye = self.w2 @ np.tanh(self.w1 @ self._flat + self.c1) + self.c2
        if self._any_tanh:
            ye[self.tanh_out] = np.tanh(ye[self.tanh_out])
        x[1:] = x[:-1]  # shift the delay line (numpy copies overlapping slices safely)
        x[0, :kn] = u_n
        x[0, kn:] = ye
        return ye * self.out_scale + self.out_mean


# ---- bands (10)-(11) ---------------------------------------------------------------------------
#: Two-sided standard normal quantile ``t_α = Φ^{-1}(1 - α/2)`` (α = 0.01 -> 2.5758); the paper's
#: name for :func:`diagnosers.alarm.two_sided_normal_quantile`.
t_alpha = two_sided_normal_quantile


def band(
    y_m: np.ndarray, y_e: np.ndarray, v: np.ndarray | float, alpha: float = 0.01
) -> tuple[np.ndarray, np.ndarray]:
    """Uncertainty band of eqs. (10)-(11): ``y_m + y_e ∓ t_α v``.

    Args:
        y_m: nominal model output, shape ``(T, m)`` (or broadcastable), physical units.
        y_e: model-error-model output, same shape.
        v: band scale per output, shape ``(m,)`` or scalar (see :func:`band_scale`).
        alpha: significance level; the band has nominal coverage ``1 - α`` for Gaussian errors.

    Returns:
        ``(lower, upper)``, each of the broadcast shape of the inputs.
    """
    centre = np.asarray(y_m, dtype=np.float64) + np.asarray(y_e, dtype=np.float64)
    half = t_alpha(alpha) * np.asarray(v, dtype=np.float64)
    if np.any(half < 0):
        raise ValueError("band scale v must be non-negative")
    return centre - half, centre + half


def band_scale(
    y_e: np.ndarray,
    *,
    definition: BandScale | str = BandScale.RESIDUAL,
    y: np.ndarray | None = None,
    y_m: np.ndarray | None = None,
    ddof: int = 1,
) -> np.ndarray:
    """Band scale ``v`` per output channel.

    Args:
        y_e: MEM output on (held-out, healthy) data, shape ``(T, m)``.
        definition: ``"paper"`` -> ``std(y_e)``; ``"residual"`` -> ``std(y - y_m - y_e)``, which needs
            ``y`` and ``y_m``; see the module docstring for why ``"residual"`` is recommended.
        y: measured outputs, shape ``(T, m)`` (``"residual"`` only).
        y_m: nominal model outputs, shape ``(T, m)`` (``"residual"`` only).
        ddof: delta degrees of freedom of the standard deviation.

    Returns:
        ``v``, shape ``(m,)``.
    """
    try:
        definition = BandScale(definition)
    except ValueError:
        raise ValueError(
            f"definition={definition!r}; choose one of {[d.value for d in BandScale]}"
        ) from None
    ye = np.asarray(y_e, dtype=np.float64)
    ye = ye[:, None] if ye.ndim == 1 else ye
    if definition is BandScale.PAPER:
        return ye.std(axis=0, ddof=ddof)
    if y is None or y_m is None:
        raise ValueError('definition="residual" needs the measured y and the nominal y_m')
    yy = np.asarray(y, dtype=np.float64).reshape(ye.shape)
    ym = np.asarray(y_m, dtype=np.float64).reshape(ye.shape)
    return (yy - ym - ye).std(axis=0, ddof=ddof)
