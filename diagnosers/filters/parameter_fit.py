"""Fitting the FCC model to healthy records: the noise scale and a few identifiable parameters.

A grey-box detector knows the model's structure (the published equations, :mod:`fcc_env.physics`)
and the spec's nominal parameters (``FCCParams()``) as a prior, never the plant's own values. It
corrects the prior from the healthy records it is given, with the filter of
:class:`~diagnosers.filters.FCCStateEstimator`:

* :func:`estimate_noise_scale`: the multiplier on the spec's sensor noise, a fixed point of
  "whitened innovations of unit variance" (the normalised innovation squared's mean equals the
  number of channels when the noise model is right);
* :func:`fit_augmented`: the named parameters as random-walk states of the filter, each
  record's estimate at its end, pooled by inverse variance (one filter pass over the records);
  a between-record spread beyond the estimates' own standard deviations says the records come
  from different plants (:attr:`ParameterFit.varies`);
* :func:`fit_maximum_likelihood`: the parameters that maximise the innovations' Gaussian
  likelihood (Nelder-Mead on log multipliers, one filter pass per evaluation): the classical
  prediction-error estimate, dearer by the number of evaluations.

Which parameters are worth fitting was measured in ``lab/filter-lab.md`` (on drawn plants only
UA_2, UA_dg and UA_d1 came back closer than nominal); the comparison of the two fits is in
``lab/greybox-lab.md``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy import optimize, stats

from diagnosers.filters.state_estimator import FCCStateEstimator, FilterResult
from diagnosers.filters.ukf_config import UKFConfig
from fcc_common.validation import invalid
from fcc_env.params import FCCParams

__all__ = [
    "HOMOGENEITY_P",
    "WARM_UP",
    "ParameterFit",
    "estimate_noise_scale",
    "filter_records",
    "fit_augmented",
    "fit_maximum_likelihood",
]

#: Samples at the start of a record left out of every fit: the filter's prior (the nominal
#: steady state) settles in about as many.
WARM_UP = 100
#: The records' parameter estimates are taken to come from different plants when their
#: homogeneity test (χ² of the deviations from the pooled value) has a p-value under this.
HOMOGENEITY_P = 1e-3


def filter_records(
    est: FCCStateEstimator, records: Sequence[np.ndarray], *, innovation_cov: bool = False
) -> list[FilterResult]:
    """Filter records ``(T_i, channels)`` of possibly different lengths, those of one length
    in one batch; one :class:`FilterResult` (batch axis 1) per record, in order."""
    out: list[FilterResult | None] = [None] * len(records)
    by_length: dict[int, list[int]] = {}
    for i, y in enumerate(records):
        by_length.setdefault(y.shape[0], []).append(i)
    for idx in by_length.values():
        res = est.filter(np.stack([records[i] for i in idx]), innovation_cov=innovation_cov)
        for j, i in enumerate(idx):
            out[i] = _one(res, j)
    return [r for r in out if r is not None]


def _one(res: FilterResult, j: int) -> FilterResult:
    cov = None if res.innovation_cov is None else res.innovation_cov[j : j + 1]
    return FilterResult(
        innovations=res.innovations[j : j + 1],
        standardized=res.standardized[j : j + 1],
        whitened=res.whitened[j : j + 1],
        innovation_cov=cov,
        states=res.states[j : j + 1],
        state_std=res.state_std[j : j + 1],
        steps=res.steps[j : j + 1],
        status=res.status[j : j + 1],
        state_names=res.state_names,
        channels=res.channels,
    )


def _mean_nis(results: Sequence[FilterResult]) -> float:
    nis = np.concatenate([r.nis[0, WARM_UP:] for r in results])
    nis = nis[np.isfinite(nis)]
    if nis.size == 0:
        raise ValueError(f"no finite innovations after the first {WARM_UP} samples of any record")
    return float(np.mean(nis))


def estimate_noise_scale(
    params: FCCParams,
    config: UKFConfig,
    records: Sequence[np.ndarray],
    *,
    iterations: int = 2,
) -> float:
    """The sensor-noise multiplier that whitens ``records``' innovations to unit variance.

    Starts from ``config.noise_scale`` and multiplies it ``iterations`` times by
    ``sqrt(mean NIS / n_channels)``: exact where the measurement noise dominates the
    innovations (the temperatures: the model's one-step prediction is much surer than the
    sensors, ``lab/filter-lab.md``), so two steps suffice. Model error the filter cannot
    explain raises the estimate, which then covers it (a deliberate robustness: the limits
    are set on the same innovations).
    """
    scale = config.noise_scale
    for _ in range(iterations):
        est = FCCStateEstimator(params, config.replace(noise_scale=scale))
        results = filter_records(est, records)
        n = results[0].whitened.shape[-1]
        scale = float(np.clip(scale * np.sqrt(_mean_nis(results) / n), 1e-3, 100.0))
    return scale


@dataclass(frozen=True)
class ParameterFit:
    """A fit of named parameters: the fitted model, the per-record estimates behind it.

    Attributes:
        params: the prior with the fitted values.
        names: the fitted fields.
        values: ``(k,)`` the fitted values.
        record_values, record_std: ``(n_records, k)`` each record's estimate and its posterior
            standard deviation (the augmented fit; empty for maximum likelihood).
        homogeneity_p: ``(k,)`` the p-value of "every record has the same value" per
            parameter (NaN where not tested).
    """

    params: FCCParams
    names: tuple[str, ...]
    values: np.ndarray
    record_values: np.ndarray
    record_std: np.ndarray
    homogeneity_p: np.ndarray

    @property
    def varies(self) -> bool:
        """Whether the records' estimates differ beyond their own uncertainty
        (:data:`HOMOGENEITY_P`): the records come from plants that differ."""
        p = self.homogeneity_p[np.isfinite(self.homogeneity_p)]
        return bool(p.size and np.min(p) < HOMOGENEITY_P)


def _check_names(names: Sequence[str]) -> tuple[str, ...]:
    names = tuple(names)
    if not names:
        raise invalid("names", names, "at least one FCCParams field")
    UKFConfig(parameters=names)  # refuses unknown fields by name
    return names


def fit_augmented(
    params: FCCParams, config: UKFConfig, records: Sequence[np.ndarray], names: Sequence[str]
) -> ParameterFit:
    """``names`` estimated as random-walk states over each record; each record's estimate at
    its end, pooled by inverse variance (module docstring)."""
    names = _check_names(names)
    est = FCCStateEstimator(params, config.replace(parameters=names))
    results = filter_records(est, records)
    idx = [results[0].state_names.index(n) for n in names]
    vals = np.stack([r.states[0, -1, idx] for r in results])
    sds = np.stack([r.state_std[0, -1, idx] for r in results])
    w = 1.0 / np.maximum(sds, 1e-12) ** 2
    pooled = np.sum(w * vals, axis=0) / np.sum(w, axis=0)
    chi2 = np.sum(w * (vals - pooled) ** 2, axis=0)
    dof = len(records) - 1
    p = stats.chi2.sf(chi2, dof) if dof > 0 else np.full(len(names), np.nan)
    fitted = params.replace(**{n: float(v) for n, v in zip(names, pooled, strict=True)})
    return ParameterFit(fitted, names, pooled, vals, sds, np.asarray(p, dtype=np.float64))


def negative_log_likelihood(results: Sequence[FilterResult]) -> float:
    """The innovations' Gaussian negative log-likelihood per sample after :data:`WARM_UP`,
    ``½ (ln det S_t + e_tᵀS_t⁻¹e_t)`` averaged (constant left out)."""
    total, count = 0.0, 0
    for r in results:
        assert r.innovation_cov is not None
        S = r.innovation_cov[0, WARM_UP:]
        e = r.whitened[0, WARM_UP:]
        ok = np.isfinite(e).all(axis=1)
        sign, logdet = np.linalg.slogdet(S[ok])
        if np.any(sign <= 0):
            return float("inf")
        total += 0.5 * float(np.sum(logdet) + np.sum(e[ok] ** 2))
        count += int(ok.sum())
    return total / max(count, 1)


def fit_maximum_likelihood(
    params: FCCParams,
    config: UKFConfig,
    records: Sequence[np.ndarray],
    names: Sequence[str],
    *,
    max_evaluations: int = 60,
    start: FCCParams | None = None,
) -> ParameterFit:
    """``names`` by maximum likelihood of the innovations (module docstring), from ``start``
    (default ``params``), at most ``max_evaluations`` filter passes."""
    names = _check_names(names)
    base = params if start is None else start
    x0 = np.array([float(getattr(base, n)) for n in names])

    def nll(log_mult: np.ndarray) -> float:
        trial = params.replace(
            **{n: float(v) for n, v in zip(names, x0 * np.exp(log_mult), strict=True)}
        )
        est = FCCStateEstimator(trial, config)
        return negative_log_likelihood(filter_records(est, records, innovation_cov=True))

    res = optimize.minimize(
        nll,
        np.zeros(len(names)),
        method="Nelder-Mead",
        options={
            "maxfev": max_evaluations,
            "xatol": 1e-3,
            "fatol": 1e-6,
            "initial_simplex": np.vstack([np.zeros(len(names)), 0.02 * np.eye(len(names))]),
        },
    )
    values = x0 * np.exp(res.x)
    fitted = params.replace(**{n: float(v) for n, v in zip(names, values, strict=True)})
    empty = np.zeros((0, len(names)))
    return ParameterFit(fitted, names, values, empty, empty, np.full(len(names), np.nan))
