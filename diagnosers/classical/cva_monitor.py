"""The ``cva`` detector: canonical variate analysis (Russell, Chiang & Braatz 2000)."""

from __future__ import annotations

from collections.abc import Sequence
from enum import StrEnum
from typing import Any, ClassVar

import numpy as np

from diagnosers.classical.lagged_monitor import LaggedMonitor
from diagnosers.classical.subspace import (
    aic_order,
    canonical_variates,
    inverse_sqrt,
    lagged,
    past_future,
)
from diagnosers.presets import keyword_init
from diagnosers.registry import register
from fcc_common.validation import Integer, Options, check_params, invalid

__all__ = ["CVADetector", "Residual"]


class Residual(StrEnum):
    """What :class:`CVADetector`'s second statistic measures."""

    PAST = "past"
    PREDICTION = "prediction"


@register("cva")
class CVADetector(LaggedMonitor):
    """Canonical variate analysis: the states of a stochastic realisation of the healthy
    process, with a T² on the retained states and one on the rest (Russell, Chiang & Braatz
    2000; Chiang, Russell & Braatz 2001, ch. 7).

    The past vector ``p_t = [y_{t-1}; ...; y_{t-past}]`` and the future ``f_t = [y_t; ...;
    y_{t+future-1}]`` of the standardised channels give the scaled Hankel covariance
    ``H = Σ_ff^{-1/2} Σ_fp Σ_pp^{-1/2} = U S Vᵀ`` (:func:`~diagnosers.classical.subspace.
    canonical_variates`). ``J = Vᵀ Σ_pp^{-1/2}`` maps a past vector to canonical variates of
    unit variance; the first ``k`` are the states (those of the past that best predict the
    future), the rest the residual. At sample ``t`` the monitor reads ``p_{t+1}``, the past
    ending with ``y_t`` (all known at ``t``): ``T²_s = |J_k p|²`` and ``T²_r = |J_r p|²``;
    with a future as long as the past ``V`` is square and ``T²_r`` equals Russell et al.'s Q,
    ``|(I − V_k V_kᵀ) Σ_pp^{-1/2} p|²``. Limits and warm-up as in
    :mod:`diagnosers.classical.lagged_monitor` (empirical quantiles).

    ``residual="prediction"`` replaces ``T²_r`` by the T² of the states' one-step prediction
    error, ``ε_t = y_t − C x_t`` with ``x_t = J_k p_t`` and ``C`` the least-squares output
    map, whitened by its healthy covariance (the residual of the CVA state-space model, as in
    Negiz & Çinar 1997): the residual space of the past mixes the process's whole variation
    into ``T²_r``, the prediction error keeps only what the past cannot explain.

    Args:
        false_alarm_target: share of healthy training samples allowed in alarm, in (0, 0.5),
            split equally between the two statistics; default 0.01.
        past: lags in the past vector, in [1, 50]; default 10.
        future: lags in the future vector, in [1, 50], or None (default: ``past``).
        n_states: retained states, in [1, m·past] (``m·past − 1`` with ``residual="past"``), or None (default): the minimiser of
            Larimore's AIC (:func:`~diagnosers.classical.subspace.aic_order`), capped at
            ``max_states``.
        max_states: the largest order the AIC may choose, in [1, 500]; default 30.
        residual: ``"prediction"`` (default, above) or ``"past"`` (Russell et al.'s ``T²_r``).
        ewma_lambda: weight of an EWMA of the projections before their squares are summed,
            in (0, 1]; default 0.1 (1: none, the classical per-sample statistics).
        channels: monitored channel names, or None (default) for all.

    Russell et al.'s monitor as published is ``residual="past", ewma_lambda=1``; the defaults
    are the variant that detected most on validation seeds (``lab/monitors-lab.md``).

    Decision arrays, names ``("T2s", "T2e")`` (``("T2s", "T2r")`` with ``residual="past"``):
    signal = residual = the (filtered)
    statistics, upper = their limits (infinite in the first ``past − 1`` samples).

    Attributes: besides :class:`~diagnosers.classical.lagged_monitor.LaggedMonitor`'s,
    ``n_states_`` and ``correlations_`` (canonical correlations, descending).
    """

    SIGNALS = ("T2s", "T2r")
    DEFAULTS: ClassVar[dict[str, Any]] = {
        "false_alarm_target": 0.01,
        "past": 10,
        "future": None,
        "n_states": None,
        "max_states": 30,
        "residual": "prediction",
        "ewma_lambda": 0.1,
        "channels": None,
    }
    __init__ = keyword_init(DEFAULTS)
    past: int
    future: int | None
    n_states: int | None
    max_states: int
    residual: str
    channels: Sequence[str] | None

    @classmethod
    def fast_params(cls) -> dict[str, Any]:
        return {"past": 2}

    def _check_family(self) -> None:
        check_params(
            self.get_params(),
            {
                "past": Integer(1, 50),
                "future": (Integer(1, 50), None),
                "n_states": (Integer(1, 10_000), None),
                "max_states": Integer(1, 500),
                "residual": Options(Residual),
            },
        )

    def window(self) -> int:
        return int(self.past) + (self.residual == Residual.PREDICTION)

    def _maps(self, z: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        past = int(self.past)
        future = past if self.future is None else int(self.future)
        parts = [past_future(zi, past, future) for zi in z]
        p = np.concatenate([a for a, _ in parts])
        f = np.concatenate([b for _, b in parts])
        dp = p.shape[1]
        if p.shape[0] <= dp + f.shape[1]:
            raise ValueError(
                f"cva needs more past/future pairs than their size {dp + f.shape[1]}, got "
                f"{p.shape[0]}; give more training data or a shorter past/future"
            )
        cv = canonical_variates(p, f)
        # the past residual needs one variate left over; the prediction error does not
        top = dp - 1 if self.residual == Residual.PAST else dp
        if self.n_states is None:
            cap = min(int(self.max_states), top, cv.correlations.size)
            k = aic_order(cv.correlations, p.shape[0], z[0].shape[1], cap)
        else:
            k = int(self.n_states)
            if k > top:
                raise invalid(
                    "n_states", k, Integer(1, top).describe(), f"a past vector of size {dp}"
                )
        self.correlations_ = cv.correlations
        if self.residual == Residual.PAST:
            return cv.mean, cv.past_weights[:k], cv.past_weights[k:]
        return prediction_maps([lagged(zi, past + 1) for zi in z], cv.past_weights[:k])

    def _get_state(self) -> dict[str, np.ndarray]:
        return super()._get_state() | {"correlations": self.correlations_}

    def _set_state(self, state: dict[str, np.ndarray]) -> None:
        self.correlations_ = np.asarray(state["correlations"], dtype=np.float64)
        super()._set_state(state)

    def _finish(self) -> None:
        super()._finish()
        if self.residual == Residual.PREDICTION:
            self.signal_names_ = ("T2s", "T2e")
        self.n_states_ = int(self.state_map_.shape[0])


def prediction_maps(
    lagged_records: list[np.ndarray], states: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(centre, W_s, W_r)`` on the vectors ``[y_t; p_t]`` (``lagged_records``, ``(N_i, m +
    dp)`` each) of the CVA ``states`` ``J_k`` ``(k, dp)``: ``W_s = [J_k, 0]`` the states of
    ``p_{t+1}`` (the newest ``dp`` entries), ``W_r = Σ_ε^{-1/2} [I, −Cᵀ J_k]`` the whitened
    one-step prediction error ``ε_t = y_t − Cᵀ x_t`` of ``x_t = J_k p_t``, ``C`` by least
    squares."""
    v = np.concatenate(lagged_records)
    centre = v.mean(axis=0)
    c = v - centre
    k, dp = states.shape
    m = v.shape[1] - dp
    x = c[:, m:] @ states.T
    cmat = np.linalg.lstsq(x, c[:, :m], rcond=None)[0]  # (k, m)
    eps = c[:, :m] - x @ cmat
    pred = np.concatenate([np.eye(m), -cmat.T @ states], axis=1)
    state_map = np.concatenate([states, np.zeros((k, m))], axis=1)
    return centre, state_map, inverse_sqrt(np.atleast_2d(np.cov(eps.T))) @ pred
