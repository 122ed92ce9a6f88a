"""Sample-by-sample evaluation of trained model error models in numpy float64 (for streaming).

:class:`MEMStepper` steps one :class:`~diagnosers.networks.mem_net.NNARXErrorModel`; :class:`MEMBankStepper`
steps a bank of single-output ones as one, for a diagnoser that watches several relations.
"""

from __future__ import annotations

import numpy as np
import torch

from diagnosers.networks.mem_net import NNARXErrorModel, OutputActivation

__all__ = ["MEMBankStepper", "MEMStepper"]


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
