"""A per-episode regression baseline: the part of a relation's error that the episode's own
inputs explain, learned online while the plant is taken as healthy.

A learned relation meets a plant that is not quite the one it was trained on: another draw of
the kinetics and heat losses (the ``uncertain`` track), or, on a fixed plant, an operating
region where the network's error has a local linear trend. Within one episode that mismatch is
mostly a linear dynamic function of the relation's inputs: on 30 healthy ``uncertain``
validation episodes (``lab/plant_mismatch_lab.py``, a bank trained with ``val_fraction=0``),
a causal fit of this form brings the error of T_rx / T_rg1 / T_rg2 from 0.49 / 0.94 / 0.37 °C
RMS (each episode's mean removed) to 0.34 / 0.47 / 0.32, near the fixed plant's 0.33 / 0.40 /
0.33; on the paper track T_rg1 goes from 0.40 to 0.37 °C.

The regressors of relation ``j`` are a constant and first-order low-pass filters (one per time
constant τ, in samples: ``s ← s + (x − s) / τ``, started at the first sample) of the
relation's standardised inputs and of its network's standardised output. The coefficients are
an exponentially weighted ridge regression of the normalised error on them:

    R_k = f R_{k−1} + φ_k φ_kᵀ + (1 − f) ρ I,   b_k = f b_{k−1} + φ_k e_k,   θ_k = R_k⁻¹ b_k

with forgetting ``f = 1 − λ`` and ridge ``ρ`` (``R_0 = ρ I``), written in information form so
that ``R ≥ ρ I`` at every step however long the episode runs (the covariance form with
forgetting grows without bound along directions the inputs do not excite). With the constant
alone it is the running mean with gain ``1 / (n + ρ)`` until λ takes over. The baseline of
sample ``k`` uses ``θ_{k−1}``, so a sample never explains itself.

Relations with fewer inputs are padded with zero regressors, which never move their
coefficients; all relations then update in one stacked pass.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from scipy.signal import lfilter

from diagnosers.stages.baseline_kernels import adapt_step, filter_step, signals_step

__all__ = ["HeldBaseline", "RegressionBaseline"]


class RegressionBaseline:
    """Online ridge regression of ``k`` relations' errors on filtered copies of their signals.

    Args:
        n_signals: how many signals each relation has (its inputs and its model output).
        time_constants: the low-pass filters' time constants [samples], each ≥ 1.
        forgetting_lambda: λ in [0, 1): ``f = 1 − λ``.
        ridge: ρ > 0, the prior information on every coefficient (normalised error units).

    >>> rb = RegressionBaseline([2], (1.0,), forgetting_lambda=0.0, ridge=1e-9)
    >>> rng = np.random.default_rng(0)
    >>> x = rng.normal(size=(200, 1, 2))
    >>> e = 0.5 + x[:, 0, 0] - 2.0 * x[:, 0, 1]
    >>> phi = rb.features_batch(x)
    >>> for k in range(200):
    ...     rb.adapt(phi[k], e[k : k + 1])
    >>> np.round(rb.theta_[0], 6).tolist()
    [0.5, 1.0, -2.0]
    """

    def __init__(
        self,
        n_signals: Sequence[int],
        time_constants: Sequence[float],
        *,
        forgetting_lambda: float,
        ridge: float,
    ) -> None:
        taus = np.asarray(time_constants, dtype=np.float64)
        if taus.ndim != 1 or not len(taus) or not np.all(taus >= 1.0):
            raise ValueError(
                f"time_constants={list(time_constants)}; allowed: a non-empty list of numbers "
                ">= 1 (samples)"
            )
        if not 0.0 <= forgetting_lambda < 1.0:
            raise ValueError(f"forgetting_lambda={forgetting_lambda}; allowed: [0, 1)")
        if not ridge > 0.0:
            raise ValueError(f"ridge={ridge}; allowed: a number > 0")
        self.n_signals = tuple(int(n) for n in n_signals)
        self.n_relations = len(self.n_signals)
        self.width = max(self.n_signals)
        self.gains = 1.0 / taus  # per filter, a = 1/τ
        self.n_features = 1 + len(taus) * self.width
        self.forgetting = 1.0 - forgetting_lambda
        self.ridge = ridge
        self.reset()

    def reset(self) -> None:
        """A fresh episode: filters unset, coefficients zero, information ρ I."""
        k, p = self.n_relations, self.n_features
        # the regressors of the current sample; the filter outputs live in them, (k, n_taus, width)
        self._phi_now = np.zeros((k, p))
        self._phi_now[:, 0] = 1.0
        self._state = self._phi_now[:, 1:].reshape(k, len(self.gains), self.width)
        self._started = False
        self._info = np.broadcast_to(self.ridge * np.eye(p), (k, p, p)).copy()
        self._moment = np.zeros((k, p))
        self.theta_ = np.zeros((k, p))
        self._prior = (1.0 - self.forgetting) * self.ridge * np.eye(p)

    def pad(self, signals: Sequence[np.ndarray]) -> np.ndarray:
        """Per-relation signal arrays ``(..., n_j)`` stacked into ``(..., k, width)``."""
        first = np.asarray(signals[0])
        out = np.zeros((*first.shape[:-1], self.n_relations, self.width))
        for j, s in enumerate(signals):
            out[..., j, : self.n_signals[j]] = s
        return out

    def _phi(self, state: np.ndarray) -> np.ndarray:
        # state (..., n_taus, k, width) -> features (..., k, 1 + n_taus * width)
        moved = np.moveaxis(state, -3, -2)  # (..., k, n_taus, width)
        flat = moved.reshape(*moved.shape[:-2], -1)
        return np.concatenate([np.ones((*flat.shape[:-1], 1)), flat], axis=-1)

    def features(self, x: np.ndarray) -> np.ndarray:
        """Regressors ``(k, p)`` of one sample's padded signals ``x`` ``(k, width)``."""
        x = np.asarray(x, dtype=np.float64)
        if x.shape != (self.n_relations, self.width):  # the kernel does not check its indices
            raise ValueError(
                f"x has shape {x.shape}; allowed: ({self.n_relations}, {self.width}) (relations, "
                "padded signals)"
            )
        filter_step(x, self.gains, self._state, self._started)
        self._started = True
        return self._phi_now.copy()

    def features_batch(self, x: np.ndarray) -> np.ndarray:
        """Regressors ``(T, k, p)`` of a record of padded signals ``x`` ``(T, k, width)``: the
        same filters as :meth:`features` from a fresh start (it leaves the streaming state
        alone)."""
        x = np.asarray(x, dtype=np.float64)
        state = np.empty((x.shape[0], len(self.gains), *x.shape[1:]))
        for i, a in enumerate(self.gains):
            # s_t = s_{t-1} + a (x_t - s_{t-1}), s_0 = x_0: zi makes the first output x_0
            state[:, i] = lfilter([a], [1.0, a - 1.0], x, axis=0, zi=((1.0 - a) * x[:1]))[0]
        return self._phi(state)

    def predict(self, phi: np.ndarray) -> np.ndarray:
        """The baseline ``(k,)`` of one sample's regressors ``phi`` ``(k, p)``."""
        return np.einsum("kp,kp->k", self.theta_, phi)

    def adapt(self, phi: np.ndarray, e: np.ndarray) -> None:
        """Take in one sample: regressors ``phi`` ``(k, p)``, errors ``e`` ``(k,)``."""
        phi = np.ascontiguousarray(phi, dtype=np.float64)
        e = np.ascontiguousarray(e, dtype=np.float64)
        k, p = self.n_relations, self.n_features
        if phi.shape != (k, p) or e.shape != (k,):  # the kernel does not check its indices
            raise ValueError(
                f"phi has shape {phi.shape} and e {e.shape}; allowed: ({k}, {p}) and ({k},)"
            )
        theta = np.empty_like(self.theta_)  # a fresh array: callers may hold the last one
        adapt_step(self._info, self._moment, theta, phi, e, self.forgetting, self._prior)
        self.theta_ = theta


class HeldBaseline:
    """A held baseline of each relation's normalised error: a running mean (``filters`` None)
    or a :class:`RegressionBaseline` on the relation's filtered signals.

    The optional part of ``lrgf-glr``'s alarm stage (:class:`diagnosers.stages.directional_stage.
    DirectionalStage`) that removes a unit's own slow offset (or gains) from the error before
    the statistics, learning only while the stage says the plant looks healthy.

    Args:
        lam: the gain λ in (0, 1) (the running mean's ``1/n`` until λ takes over; the
            regression's forgetting).
        hold: learn after the settling only while every statistic is below ``hold`` × its
            limit, in (0, 1].
        settle: samples after the warm-up during which it always learns.
        filters: the regression's low-pass time constants [samples]; None: the running mean.
        ridge: the regression's ridge ρ > 0.

    :meth:`bind` gives it the bank's layout (inputs, outputs and the networks' scalers) before
    use; :meth:`reset` starts an episode.
    """

    def __init__(
        self,
        *,
        lam: float,
        hold: float,
        settle: int,
        filters: Sequence[float] | None = None,
        ridge: float = 1.0,
    ) -> None:
        self.lam = lam
        self.hold = hold
        self.settle = settle
        self.filters = filters
        self.ridge = ridge
        self._layout: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None

    @property
    def regression(self) -> bool:
        """Whether the baseline is a regression (``filters``) rather than a running mean."""
        return bool(self.filters)

    def bind(
        self, in_idx: Sequence[np.ndarray], out_idx: np.ndarray, networks: Sequence[Any]
    ) -> None:
        """Take the bank's layout: each relation's input channels ``in_idx``, output channels
        ``out_idx`` and networks (their input and output scalers standardise the signals)."""
        self._in_idx, self._out_idx, self._networks = list(in_idx), out_idx, list(networks)
        self._layout = None

    def reset(self) -> None:
        """A fresh episode: the running mean at zero, or a fresh regression."""
        self._b = np.zeros(len(self._out_idx))
        self._n_seen = self._n_adapted = 0
        self._reg: RegressionBaseline | None = None
        if self.regression:
            assert self.filters is not None
            self._reg = RegressionBaseline(
                [len(i) + 1 for i in self._in_idx],
                self.filters,
                forgetting_lambda=self.lam,
                ridge=self.ridge,
            )
            if self._layout is None:
                self._layout = self._signal_layout()

    def _signal_layout(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Where each relation's padded signals come from in ``[y, y_m, 0]`` and the networks'
        own input and output scalers: ``(k, width)`` index, mean and scale."""
        assert self._reg is not None
        n_ch = 1 + max(int(i.max()) for i in self._in_idx if len(i))
        n_ch = max(n_ch, 1 + int(self._out_idx.max()))
        k, width = self._reg.n_relations, self._reg.width
        zero = n_ch + k  # the padding reads a constant 0
        gather = np.full((k, width), zero)
        mean, scale = np.zeros((k, width)), np.ones((k, width))
        for j, net in enumerate(self._networks):
            n = len(self._in_idx[j])
            gather[j, :n] = self._in_idx[j]
            gather[j, n] = n_ch + j
            mean[j, :n] = np.asarray(net.input_mean, dtype=np.float64)
            scale[j, :n] = np.asarray(net.input_scale, dtype=np.float64)
            mean[j, n] = float(np.asarray(net.output_mean, dtype=np.float64).ravel()[0])
            scale[j, n] = float(np.asarray(net.output_scale, dtype=np.float64).ravel()[0])
        self._n_channels = n_ch
        return gather, mean, scale

    def _signals(self, y: np.ndarray, y_m: np.ndarray) -> np.ndarray:
        """Padded standardised signals ``(..., k, width)`` of measurements ``y`` ``(..., c)``
        and network outputs ``y_m`` ``(..., k)``."""
        assert self._layout is not None
        gather, mean, scale = self._layout
        y = np.asarray(y, dtype=np.float64)[..., : self._n_channels]
        ext = np.concatenate([y, y_m, np.zeros((*y.shape[:-1], 1))], axis=-1)
        return (ext[..., gather] - mean) / scale

    def features(self, y: np.ndarray, y_m: np.ndarray) -> np.ndarray | None:
        """Regressors ``(T, k, p)`` of a whole record ``y`` with network outputs ``y_m``
        (from a fresh start of the filters), None without the regression."""
        if self._reg is None:
            return None
        return self._reg.features_batch(self._signals(y, y_m))

    def features_step(self, y: np.ndarray, y_m: np.ndarray) -> np.ndarray | None:
        """Regressors ``(k, p)`` of one sample (advances the filters), None without them."""
        if self._reg is None:
            return None
        assert self._layout is not None
        gather, mean, scale = self._layout
        y = np.asarray(y, dtype=np.float64)
        y_m = np.asarray(y_m, dtype=np.float64)
        k = len(self._out_idx)
        if y.ndim != 1 or len(y) < self._n_channels or y_m.shape != (k,):
            raise ValueError(
                f"y has shape {y.shape} and y_m {y_m.shape}; allowed: (c,) with c >= "
                f"{self._n_channels} and ({k},)"
            )
        x = np.empty(gather.shape)
        signals_step(y[: self._n_channels], y_m, gather, mean, scale, x)
        return self._reg.features(x)

    def value(self, phi: np.ndarray | None) -> np.ndarray:
        """The baseline ``(k,)`` to subtract from this sample's normalised error."""
        if self._reg is not None:
            assert phi is not None
            return self._reg.predict(phi)
        return self._b

    def track(self, e: np.ndarray, phi: np.ndarray | None) -> np.ndarray:
        """The baseline-removed error of a normalised error record ``e`` (T, k) past its
        warm-up, the baseline learning at every sample (``phi``: its regressors with the
        regression). From a fresh :meth:`reset`."""
        self.reset()
        out = np.empty_like(e)
        for k in range(e.shape[0]):
            p = None if phi is None else phi[k]
            out[k] = e[k] - self.value(p)
            self.adapt(e[k], inside_hold=True, phi=p)
        return out

    def adapt(self, e: np.ndarray, *, inside_hold: bool, phi: np.ndarray | None = None) -> None:
        """Adapt the baseline to the normalised error ``e`` of one sample past the warm-up.

        Settling: the first ``settle`` samples always adapt (the plant is taken as healthy when
        monitoring starts, as in training), with the running mean's gain 1/n until λ takes
        over. Later the baseline follows the slow healthy error only while every statistic is
        well inside its limit (``inside_hold``), so a fault's growing error is not absorbed.
        """
        settling = self._n_seen < self.settle
        self._n_seen += 1
        if not (settling or inside_hold):
            return
        self._n_adapted += 1
        if self._reg is not None:
            assert phi is not None
            self._reg.adapt(phi, e)
            return
        self._b += max(self.lam, 1.0 / self._n_adapted) * (e - self._b)
