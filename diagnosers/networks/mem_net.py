"""The neural model error model (Section 3 of the paper): an NNARX network of the residual.

The nominal model (the LRGF of :mod:`diagnosers.networks.lrgf_net`) leaves a residual ``r = y - y_m``. The
model error model (MEM) :class:`NNARXErrorModel` predicts its structured part ``y_e`` from the
process inputs alone; :mod:`diagnosers.stages.band` puts the band ``y_m + y_e ± t_α v`` of eqs. (10)-(11)
around the measurement, and :mod:`diagnosers.networks.mem_stepper` runs trained models sample by sample.

The MEM always runs in *simulation* mode: its regressor holds delayed process inputs and its *own*
delayed outputs, never the measured residual. A fault therefore cannot leak into the band: if the
MEM were fed the measured residual it would learn to follow the fault and hide it.
"""

from __future__ import annotations

import math
from enum import StrEnum
from typing import Any

import numpy as np
import torch
from torch import nn

from diagnosers.networks.lrgf_net import set_scaler_buffers

__all__ = ["NNARXErrorModel", "OutputActivation"]


class OutputActivation(StrEnum):
    """Activation of the MEM output neuron.

    ``LINEAR`` (default): the target is the *standardised* residual, which is not confined to
    ``(-1, 1)``; a tanh output would clip its tails. ``TANH``: the paper's choice.
    """

    LINEAR = "linear"
    TANH = "tanh"


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
    (identity by default; :func:`diagnosers.networks.training.fit_mem` sets them).

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
