"""The FCC state-and-disturbance estimator (:class:`FCCStateEstimator`): an unscented Kalman
filter on the model's compiled step, for a batch of recorded episodes (:meth:`filter`) or
sample by sample (:meth:`update`), with the same numbers either way.

Its innovations are what a residual should be: white, zero-mean and of known covariance while
the model is right (the whitened ones standard normal), so a fault shows as a departure from
that, and tests built on them (CUSUM, GLR along a fault's signature) are the optimal ones.

>>> import fcc_env
>>> from diagnosers.filters import FCCStateEstimator
>>> b = fcc_env.simulate_episodes([1000], 300)
>>> est = FCCStateEstimator(fcc_env.FCCParams())
>>> out = est.filter(b.observations)
>>> out.whitened.shape, out.states.shape, out.state_names[11:]
((1, 300, 8), (1, 300, 14), ('R_ar', 'T_ar', 'T_fp'))
>>> est.reset()
>>> step = est.update(b.observations[0, 0])
>>> bool((step.innovation == out.innovations[0, 0]).all())
True
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, fields

import numpy as np

from diagnosers.filters.ukf_config import UKFConfig
from diagnosers.filters.ukf_kernels import sigma_weights
from diagnosers.filters.ukf_model import (
    ESTIMATED_INPUTS,
    FCCFilterModel,
    fcc_filter_batch,
    fcc_filter_streams,
)
from fcc_common.validation import invalid
from fcc_env.closed_loop import CLOSED_LOOP_CHANNELS
from fcc_env.params import MEASUREMENT_NAMES, FCCParams

__all__ = ["FCCStateEstimator", "FilterResult", "FilterStep"]


@dataclass(frozen=True)
class FilterResult:
    """What :meth:`FCCStateEstimator.filter` returns; leading axes ``(n_episodes, n_samples)``.

    The innovation of sample k is its observation less the prediction from samples before k;
    states are the posterior means after sample k, in physical units.
    """

    innovations: np.ndarray  # (B, T, 8) y − ŷ, the channels' units
    standardized: np.ndarray  # (B, T, 8) innovation / √S_ii, per channel
    whitened: np.ndarray  # (B, T, 8) L_S⁻¹ innovation (S = L_S L_Sᵀ, channel order)
    innovation_cov: np.ndarray | None  # (B, T, 8, 8) S (None: not kept)
    states: np.ndarray  # (B, T, n) posterior means
    state_std: np.ndarray  # (B, T, n) posterior standard deviations
    steps: np.ndarray  # (B, T, 3) bool: a step of R_ar, T_ar, T_fp was declared
    status: np.ndarray  # (B, T) int8 bits: 1 skipped (non-finite reading), 2 repaired covariance
    state_names: tuple[str, ...]
    channels: tuple[str, ...] = MEASUREMENT_NAMES

    @property
    def nis(self) -> np.ndarray:
        """(B, T) normalised innovation squared, χ²(8) while the model is right."""
        return np.sum(self.whitened**2, axis=-1)

    def state(self, name: str) -> np.ndarray:
        """(B, T) posterior mean of the augmented state ``name``."""
        if name not in self.state_names:
            raise invalid("name", name, f"one of {list(self.state_names)}")
        return self.states[..., self.state_names.index(name)]


@dataclass(frozen=True)
class FilterStep:
    """One sample of :meth:`FCCStateEstimator.update`: the arrays of :class:`FilterResult` at
    one sample (a leading stream axis when several streams run)."""

    innovation: np.ndarray
    standardized: np.ndarray
    whitened: np.ndarray
    innovation_cov: np.ndarray
    state: np.ndarray
    state_std: np.ndarray
    steps: np.ndarray
    status: np.ndarray


class FCCStateEstimator:
    """An unscented Kalman filter of the FCC model with augmented random-walk states.

    Args:
        params: the model's parameters. The estimator reads no others: a grey-box detector
            passes what it fitted, a reference row the plant's.
        config: plant side and tuning (:class:`UKFConfig`; default: the paper's open-loop plant).

    Attributes:
        state_names: the augmented state (:mod:`diagnosers.filters.ukf_model`).
        channels: the observation channels expected (Table 1, or the closed-loop ones).
    """

    def __init__(self, params: FCCParams, config: UKFConfig | None = None) -> None:
        if not isinstance(params, FCCParams):
            raise invalid("params", params, "an FCCParams instance")
        config = UKFConfig() if config is None else config
        if not isinstance(config, UKFConfig):
            raise invalid("config", config, "a UKFConfig or None")
        self.params = params
        self.config = config
        self._model = FCCFilterModel.build(params, config)
        m = self._model
        self.state_names = m.names
        self.channels = CLOSED_LOOP_CHANNELS if config.closed_loop else MEASUREMENT_NAMES
        self._w = sigma_weights(m.n, config.alpha, config.beta, config.kappa)
        gate = config.step_gate
        self._gate = np.inf if gate is None else float(gate)
        self._M = np.empty((0, m.n))
        self._P = np.empty((0, m.n, m.n))
        self._single = True

    @property
    def n_states(self) -> int:
        return self._model.n

    @property
    def filter_model(self) -> FCCFilterModel:
        """The model as the compiled filter reads it (coordinates, noise, the model tuple)."""
        return self._model

    @property
    def input_names(self) -> tuple[str, ...]:
        """The inputs estimated behind their readings."""
        return ESTIMATED_INPUTS

    def initial_prior(self, n: int = 1) -> tuple[np.ndarray, np.ndarray]:
        """Prior mean (n, n_states) and covariance (n, n_states, n_states), filter units."""
        m = self._model
        return np.zeros((n, m.n)), np.tile(np.diag(m.p0), (n, 1, 1))

    def _observations(self, Y: np.ndarray, ndim: int) -> np.ndarray:
        arr = np.asarray(Y)
        n_ch = len(self.channels)
        if arr.ndim != ndim or arr.shape[-1] != n_ch:
            mode = "closed-loop" if self.config.closed_loop else "open-loop"
            raise ValueError(
                f"observations of shape {arr.shape} do not fit: expected {ndim} axes, the last "
                f"with the {n_ch} {mode} channels {list(self.channels)}"
            )
        return np.ascontiguousarray(arr, dtype=np.float64)

    def _args(self) -> tuple:
        m = self._model
        return (m.q, m.r_abs, m.r_rel, m.gate_idx, m.gate_lin, self._gate, self._w, m.n_scratch)

    def filter(self, Y: np.ndarray, *, innovation_cov: bool = True) -> FilterResult:
        """Filter whole episodes: ``Y`` (B, T, channels), e.g. ``BatchResult.observations``.

        Each episode starts from the initial prior (the steady state of ``params`` at the
        nominal inputs); the streaming state of :meth:`update` is left alone. With
        ``innovation_cov=False`` the result's ``innovation_cov`` is None: 512 bytes a sample
        (400 MB for 200 episodes of 4000 samples) not kept.
        """
        Yf = self._observations(Y, 3)
        B, T = Yf.shape[:2]
        m = self._model
        n, ny, G = m.n, len(MEASUREMENT_NAMES), m.gate_idx.shape[0]
        M, P = self.initial_prior(B)
        out = _outputs((B, T), n, ny, G)
        if not innovation_cov:
            out = (*out[:3], np.empty((B, 1, ny, ny)), *out[4:])
        fcc_filter_batch(m.model, M, P, Yf, *self._args(), *out)
        result = self._result(out)
        return result if innovation_cov else dataclasses.replace(result, innovation_cov=None)

    def reset(self, n_streams: int | None = None) -> None:
        """Start ``n_streams`` streams (default 1, each a one-sample ``update`` without a
        stream axis) from the initial prior."""
        self._single = n_streams is None
        n = 1 if n_streams is None else int(n_streams)
        if n < 1:
            raise invalid("n_streams", n_streams, "an integer >= 1 or None")
        self._M, self._P = self.initial_prior(n)

    def update(self, y: np.ndarray) -> FilterStep:
        """One sample: ``y`` (channels,) after ``reset()``, or (n_streams, channels) after
        ``reset(n_streams)``. Equals the same sample of :meth:`filter` bit for bit."""
        if self._M.shape[0] == 0:
            raise RuntimeError("call reset() before update()")
        Yk = self._observations(y, 1 if self._single else 2)
        Yk = Yk.reshape(-1, Yk.shape[-1])
        if Yk.shape[0] != self._M.shape[0]:
            raise ValueError(f"got {Yk.shape[0]} streams' observations for {self._M.shape[0]}")
        m = self._model
        out = _outputs((Yk.shape[0],), m.n, len(MEASUREMENT_NAMES), m.gate_idx.shape[0])
        fcc_filter_streams(m.model, self._M, self._P, Yk, *self._args(), *out)
        r = self._result(out)
        step = FilterStep(
            r.innovations,
            r.standardized,
            r.whitened,
            r.innovation_cov,
            r.states,
            r.state_std,
            r.steps,
            r.status,
        )
        if self._single:
            step = FilterStep(*(getattr(step, f.name)[0] for f in fields(FilterStep)))
        return step

    def _result(self, out: tuple[np.ndarray, ...]) -> FilterResult:
        innov, stdz, white, S, post, post_sd, jumps, status = out
        m = self._model
        return FilterResult(
            innovations=innov,
            standardized=stdz,
            whitened=white,
            innovation_cov=S,
            states=m.ref + m.scale * post,
            state_std=m.scale * post_sd,
            steps=jumps,
            status=status,
            state_names=self.state_names,
        )


def _outputs(lead: tuple[int, ...], n: int, ny: int, G: int) -> tuple[np.ndarray, ...]:
    """The kernels' output arrays with leading axes ``lead``."""
    return (
        np.empty((*lead, ny)),
        np.empty((*lead, ny)),
        np.empty((*lead, ny)),
        np.empty((*lead, ny, ny)),
        np.empty((*lead, n)),
        np.empty((*lead, n)),
        np.empty((*lead, G), dtype=np.bool_),
        np.empty(lead, dtype=np.int8),
    )
