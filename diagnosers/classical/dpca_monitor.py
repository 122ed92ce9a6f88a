"""The ``dpca`` detector: dynamic PCA (Ku, Storer & Georgakis 1995), T² and Q of lagged data."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, ClassVar

import numpy as np

from diagnosers.classical.lagged_monitor import LaggedMonitor
from diagnosers.classical.subspace import lagged
from diagnosers.presets import keyword_init
from diagnosers.registry import register
from fcc_common.validation import Integer, Real, check_params, invalid

__all__ = ["DPCADetector", "pca_maps"]


def pca_maps(
    v: np.ndarray, n_components: int | None, variance_explained: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """PCA of the rows of ``v`` ``(N, d)``: ``(centre, W_s, W_r, eigenvalues)`` with ``W_s =
    Λ_k^{-1/2} P_kᵀ`` (T² of the ``k`` retained scores, whitened) and ``W_r`` the rows of the
    residual subspace (``|W_r c|² = |(I − P_k P_kᵀ) c|²``, the squared prediction error).
    ``k``: ``n_components``, else the smallest reaching ``variance_explained`` (at most
    ``d − 1``, so that a residual subspace exists)."""
    centre = v.mean(axis=0)
    _, s, vt = np.linalg.svd(v - centre, full_matrices=False)
    eig = s**2 / (v.shape[0] - 1)
    d = v.shape[1]
    if n_components is None:
        ratio = np.cumsum(eig) / eig.sum()
        k = min(int(np.searchsorted(ratio, variance_explained - 1e-12) + 1), d - 1)
    else:
        k = n_components
        if k > d - 1:
            raise invalid(
                "n_components", k, Integer(1, d - 1).describe(), f"lagged vectors of size {d}"
            )
    state = vt[:k] / np.sqrt(np.maximum(eig[:k], 1e-300))[:, None]
    return centre, state, vt[k:], eig


@register("dpca")
class DPCADetector(LaggedMonitor):
    """Dynamic PCA: PCA of the lagged vector ``[y_t; y_{t-1}; ...; y_{t-lags}]`` of the
    standardised channels, Hotelling's T² of the retained scores and the squared prediction
    error Q of the rest (Ku, Storer & Georgakis 1995). The lags let the PCA model the serial
    correlation that makes static PCA's limits wrong on dynamic data: a linear relation
    between present and past samples (an ARX model, a state equation) lies in the residual
    subspace, so a fault that breaks it shows in Q. Limits and warm-up as in
    :mod:`diagnosers.classical.lagged_monitor`.

    Args:
        false_alarm_target: share of healthy training samples allowed in alarm, in (0, 0.5),
            split equally between T² and Q; default 0.01.
        lags: past samples stacked beside the present one, in [0, 50]; default 2 (Ku et
            al.'s choice of one or two for most processes). 0 is static PCA.
        variance_explained: cumulative explained variance that fixes the number of retained
            components when ``n_components`` is None, in (0, 1]; default 0.95.
        n_components: retained components, in [1, d − 1] (``d`` the lagged vector's size), or
            None (default).
        ewma_lambda: weight of an EWMA of the projections before their squares are summed,
            in (0, 1]; default 0.1 (1: none, Ku et al.'s per-sample statistics; the EWMA
            found f1 in 14 samples instead of 150 on validation seeds, ``lab/monitors-lab.md``).
        channels: monitored channel names, or None (default) for all.

    Decision arrays, names ``("T2", "Q")``: signal = residual = the (filtered) statistics,
    upper = their limits (infinite in the first ``lags`` samples, which have no full vector).

    Attributes: besides :class:`~diagnosers.classical.lagged_monitor.LaggedMonitor`'s,
    ``n_components_``.
    """

    DEFAULTS: ClassVar[dict[str, Any]] = {
        "false_alarm_target": 0.01,
        "lags": 2,
        "variance_explained": 0.95,
        "n_components": None,
        "ewma_lambda": 0.1,
        "channels": None,
    }
    __init__ = keyword_init(DEFAULTS)
    lags: int
    variance_explained: float
    n_components: int | None
    channels: Sequence[str] | None

    @classmethod
    def fast_params(cls) -> dict[str, Any]:
        return {"lags": 1}

    def _check_family(self) -> None:
        check_params(
            self.get_params(),
            {
                "lags": Integer(0, 50),
                "variance_explained": Real(0, 1, closed="right"),
                "n_components": (Integer(1, 10_000), None),
            },
        )

    def window(self) -> int:
        return int(self.lags) + 1

    def _maps(self, z: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        v = np.concatenate([lagged(zi, self.window()) for zi in z])
        if v.shape[0] <= v.shape[1]:
            raise ValueError(
                f"dpca needs more lagged training vectors than their size {v.shape[1]}, got "
                f"{v.shape[0]}; give more training data or fewer lags"
            )
        n = None if self.n_components is None else int(self.n_components)
        centre, state, resid, _ = pca_maps(v, n, float(self.variance_explained))
        return centre, state, resid

    def _finish(self) -> None:
        super()._finish()
        self.n_components_ = int(self.state_map_.shape[0])
