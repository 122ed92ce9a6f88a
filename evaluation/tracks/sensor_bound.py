"""How well the exact model tells a bias on one sensor from a bias on another (issue 43).

The information limit of naming a biased sensor: per hypothesis "sensor c reads b too high
from the known onset on", the log-likelihood of the episode's observations from the onset over
a window, under the state estimator of the plant's *exact* parameters and noise
(:class:`diagnosers.filters.FCCStateEstimator`, :meth:`~diagnosers.filters.UKFConfig.matching`
the plant), the reading of channel c corrected by b. The size b is unknown: profiled (a GLR)
over a grid, refined at the vertex of the parabola through the grid's best point and its
neighbours (the log-likelihood is close to quadratic in an additive offset). The filter runs
once up to the onset; from there one filter per (hypothesis, size), so every hypothesis starts
from the same prior.

What this grants beyond any diagnoser: the exact parameters and the onset. What it does not:
the true inputs (R_ar, T_ar, T_fp are estimated behind their readings with the estimator's
random walks and step gate, as every filter here does), so a bias on an input reading competes
with a real step of that input, the confusion a sensor isolator meets.

``LLR(c vs c') = max_b ℓ_c(b) − max_b ℓ_c'(b)``, in nats: the evidence the window carries for
the true channel c against the rival c' (> 3: odds 20:1; < 1: not told apart).

>>> round(float(gaussian_loglik(np.zeros((1, 2)), np.eye(2)[None])[0]), 4)
-1.8379
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from diagnosers.filters import FCCStateEstimator
from diagnosers.filters.ukf_kernels import sigma_weights
from diagnosers.filters.ukf_model import fcc_filter_batch
from fcc_common.validation import Integer, check, invalid
from fcc_env.params import MEASUREMENT_NAMES

__all__ = ["BiasProfile", "bias_profiles", "gaussian_loglik"]

#: The default size grid, in each channel's unit (°C; R_ar t/h): the track's sizes U(2, 10)
#: and a rival's compensating offset either side.
DEFAULT_GRID = np.arange(-16.0, 16.0 + 1e-9, 2.0)


def gaussian_loglik(white: np.ndarray, S: np.ndarray) -> np.ndarray:
    """Per sample, the log-density of an innovation of covariance ``S`` whose whitened value
    is ``white``: ``−|white|²/2 − log det S / 2 − n log(2π)/2``. Shapes ``(..., n)``,
    ``(..., n, n)`` -> ``(...)``."""
    n = white.shape[-1]
    _, logdet = np.linalg.slogdet(S)
    return -0.5 * np.sum(white * white, axis=-1) - 0.5 * logdet - 0.5 * n * math.log(2 * math.pi)


@dataclass(frozen=True)
class BiasProfile:
    """The profiled log-likelihoods of one episode's bias hypotheses.

    ``loglik`` (H, len(windows)): per hypothesis (``channels``), the log-likelihood summed
    over the first w samples after the onset, maximised over the size; ``size`` (H,) the size
    that maximises it over the longest window; ``healthy`` (len(windows),) the b = 0 value
    (no fault).
    """

    channels: tuple[str, ...]
    windows: tuple[int, ...]
    loglik: np.ndarray
    size: np.ndarray
    healthy: np.ndarray

    def llr(self, true: str) -> dict[str, np.ndarray]:
        """Per rival channel, ``LLR(true vs rival)`` per window (nats)."""
        if true not in self.channels:
            raise invalid("true", true, f"one of {list(self.channels)}")
        i = self.channels.index(true)
        return {c: self.loglik[i] - self.loglik[j] for j, c in enumerate(self.channels) if j != i}


def _run(est: FCCStateEstimator, M: np.ndarray, P: np.ndarray, Y: np.ndarray, keep_s: bool):
    """The compiled filter over ``Y`` (B, T, n_obs) from priors ``M``, ``P`` (advanced in
    place); returns (whitened, S) with S (B, T or 1, 8, 8)."""
    m = est.filter_model
    cfg = est.config
    B, T = Y.shape[:2]
    ny, n, G = len(MEASUREMENT_NAMES), m.n, m.gate_idx.shape[0]
    innov, stdz, white = (np.empty((B, T, ny)) for _ in range(3))
    S = np.empty((B, T if keep_s else 1, ny, ny))
    post, post_sd = np.empty((B, T, n)), np.empty((B, T, n))
    jumps, status = np.empty((B, T, G), dtype=np.bool_), np.empty((B, T), dtype=np.int8)
    w = sigma_weights(n, cfg.alpha, cfg.beta, cfg.kappa)
    gate = math.inf if cfg.step_gate is None else float(cfg.step_gate)
    fcc_filter_batch(
        m.model,
        M,
        P,
        Y,
        m.q,
        m.r_abs,
        m.r_rel,
        m.gate_idx,
        m.gate_lin,
        gate,
        w,
        m.n_scratch,
        innov,
        stdz,
        white,
        S,
        post,
        post_sd,
        jumps,
        status,
    )
    return white, S


def bias_profiles(
    est: FCCStateEstimator,
    y: np.ndarray,
    onset: int,
    channels: Sequence[str] = MEASUREMENT_NAMES,
    windows: Sequence[int] = (30, 100, 300),
    grid: np.ndarray = DEFAULT_GRID,
) -> BiasProfile:
    """The bias hypotheses of ``channels`` on the observations ``y`` (T, n_obs, the
    estimator's channels) from ``onset`` over ``windows`` samples (module docstring)."""
    y = np.ascontiguousarray(y, dtype=np.float64)
    W = max(check("windows", w, Integer(1)) for w in windows)
    if not 1 <= onset <= y.shape[0] - W:
        raise invalid("onset", onset, f"an integer in [1, {y.shape[0] - W}] (samples)")
    idx = [MEASUREMENT_NAMES.index(str(c)) for c in channels]
    grid = np.asarray(grid, dtype=np.float64)
    M0, P0 = est.initial_prior(1)
    _run(est, M0, P0, y[None, :onset], keep_s=False)
    seg = y[onset : onset + W]

    def loglik(sizes: np.ndarray) -> np.ndarray:
        """Cumulative log-likelihood (H, len(sizes), W) of each hypothesis at each size."""
        H, K = len(idx), sizes.shape[-1]
        Y = np.tile(seg, (H * K, 1, 1))
        for h, c in enumerate(idx):
            Y[h * K : (h + 1) * K, :, c] -= sizes.reshape(H, K)[h][:, None]
        M = np.repeat(M0, H * K, axis=0)
        P = np.repeat(P0, H * K, axis=0)
        white, S = _run(est, M, P, Y, keep_s=True)
        ll = np.nan_to_num(gaussian_loglik(white, S), nan=0.0)  # a skipped sample adds nothing
        return np.cumsum(ll, axis=1).reshape(H, K, W)

    coarse = loglik(np.tile(grid, (len(idx), 1)))
    at = np.array(windows) - 1
    best = np.argmax(coarse[:, :, -1], axis=1)
    vertex = np.empty(len(idx))
    for h, i in enumerate(best):
        i = int(np.clip(i, 1, grid.size - 2))
        l0, l1, l2 = coarse[h, i - 1 : i + 2, -1]
        curv = l0 - 2 * l1 + l2
        step = grid[i + 1] - grid[i]
        shift = 0.5 * (l0 - l2) / curv if curv < 0 else 0.0
        vertex[h] = grid[i] + step * float(np.clip(shift, -1.0, 1.0))
    fine = loglik(vertex[:, None])
    both = np.concatenate([coarse[:, :, at], fine[:, :, at]], axis=1)  # (H, K + 1, windows)
    top = np.where(fine[:, 0, -1] >= coarse[np.arange(len(idx)), best, -1], vertex, grid[best])
    zero = int(np.argmin(np.abs(grid)))
    healthy = coarse[0, zero, at] if grid[zero] == 0.0 else np.full(len(at), np.nan)
    return BiasProfile(
        channels=tuple(str(c) for c in channels),
        windows=tuple(int(w) for w in windows),
        loglik=both.max(axis=1),
        size=top,
        healthy=healthy,
    )
