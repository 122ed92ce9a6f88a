"""Sample-by-sample evaluation of trained LRGF networks in numpy float64 (for streaming detection).

The neuron filters run in transposed direct form II, the form ``scipy.signal.lfilter`` uses, so a
stepped sequence equals :meth:`diagnosers.networks.lrgf_net.LRGF.forward` on it.
"""

from __future__ import annotations

import numpy as np
import torch

from diagnosers.networks.lrgf_net import LRGF, InitialState, lrgf_activation

__all__ = ["BankStepper", "LRGFStepper", "NeuronFilters", "filter_step"]


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
            self.n_linear = model.n_linear
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
        h = lrgf_activation(z, self.g1, self.g2, self.n_linear)
        return (self.c @ h + self.c0) * self.out_scale + self.out_mean


class BankStepper:
    """All relations' LRGF networks stepped together in one set of numpy arrays.

    Mathematically :class:`LRGFStepper` per relation (same transposed direct form
    II filters, same steady-state start), with the neurons of every relation stacked so that one
    sample costs one pass of small matrix products instead of one pass per relation.
    """

    def __init__(self, nets: list[LRGF], in_idx: list[np.ndarray], n_channels: int) -> None:
        steppers = [LRGFStepper(net) for net in nets]
        v = [st.w.shape[0] for st in steppers]
        self.w = np.zeros((sum(v), n_channels))
        self.b = np.zeros(sum(v))
        self.c = np.zeros((len(nets), sum(v)))
        self.d = np.zeros(len(nets))
        rows = np.cumsum([0, *v])
        for j, st in enumerate(steppers):
            sl = slice(rows[j], rows[j + 1])
            self.w[sl][:, in_idx[j]] = st.w / st.in_scale
            self.b[sl] = -st.w @ (st.in_mean / st.in_scale)
            self.c[j, sl] = st.c[0] * st.out_scale[0]
            self.d[j] = st.c0[0] * st.out_scale[0] + st.out_mean[0]
        self.g1 = np.concatenate([st.g1 for st in steppers])
        self.g2 = np.concatenate([st.g2 for st in steppers])
        # the rows of the relations' linear neurons in the stacked layout (none by default, and
        # then step() does no extra work)
        self.linear = np.flatnonzero(
            np.concatenate(
                [np.arange(st.w.shape[0]) >= st.w.shape[0] - st.n_linear for st in steppers]
            )
        )
        starts = {(net.initial_state, net.steady_window) for net in nets}
        if len(starts) != 1:
            raise ValueError("all relations must share one initial-state convention")
        ((initial_state, window),) = starts
        self.filters = NeuronFilters(
            np.concatenate([st.num for st in steppers]),
            np.concatenate([st.den for st in steppers]),
            initial_state is InitialState.STEADY,
            window,
        )

    def reset(self) -> None:
        self.filters.reset()

    def step(self, y: np.ndarray) -> np.ndarray:
        """Nominal-model outputs y_m of every relation for one measurement vector."""
        z = self.filters.step(self.w @ y + self.b)
        h = lrgf_activation(z, self.g1, self.g2)
        if self.linear.size:
            h[self.linear] = z[self.linear]
        return self.c @ h + self.d
