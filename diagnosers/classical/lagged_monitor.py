"""What ``dpca`` and ``cva`` share: a linear monitor of the lagged vector of standardised
channels, with a T² of its retained variates and a residual statistic.

Both monitors read, at sample ``t``, the stacked vector ``z_t = [y_t; y_{t-1}; ...;
y_{t-L+1}]`` of the standardised channels (``L`` samples: ``lags + 1`` for DPCA, the past
horizon for CVA, whose past vector of ``t + 1`` is exactly what is known at ``t``). A family
learns two linear maps of the centred ``z_t`` on healthy data, ``W_s`` (the retained
variates, whitened, so ``T² = |W_s z|²``) and ``W_r`` (the residual, ``Q = |W_r z|²``), in
:meth:`LaggedMonitor._maps`; everything else is here: the warm-up (the first ``L − 1``
samples carry no full vector: no statistic, no alarm), an optional EWMA of the projections
``W_s z`` and ``W_r z`` before their squares are summed (a multivariate EWMA, Lowry et al.
1992: a small persistent shift builds up in it, where it drowns in a single sample's T²), the
limits and the streaming buffer.

**Limits**: each statistic's empirical ``1 − false_alarm_target/2`` quantile on the healthy
training samples (after their warm-up), so the union alarms on at most ``false_alarm_target``
of them (Bonferroni). Empirical rather than the F / χ² limits of the original papers because
the lagged vectors are autocorrelated and the process is not Gaussian (the operating program
moves in steps); the quantiles are in-sample, which with tens of thousands of samples and a
few hundred parameters costs little (measured on validation seeds, ``lab/monitors-lab.md``).
"""

from __future__ import annotations

from abc import abstractmethod
from collections.abc import Sequence
from typing import Any, ClassVar

import numpy as np

from diagnosers.classical.channel_selection import (
    channel_indices,
    check_channel_names,
    stack_episodes,
)
from diagnosers.classical.subspace import lagged
from diagnosers.contract import require_varying
from diagnosers.detection import Decision, Detection
from diagnosers.diagnoser import Diagnoser
from diagnosers.episode.record import Episode
from diagnosers.stages.alarm import EWMA, calibrate_limit
from fcc_common.validation import Real, check_params

__all__ = ["LAGGED_CONSTRAINTS", "LaggedMonitor"]

#: the constraints every lagged monitor shares
LAGGED_CONSTRAINTS: dict[str, Any] = {
    "false_alarm_target": Real(0, 0.5, closed="neither"),
    "ewma_lambda": Real(0, 1, closed="right"),
}


class LaggedMonitor(Diagnoser):
    """A T² and a residual statistic of the lagged standardised channels (module docstring).

    Subclasses set :attr:`DEFAULTS` (with ``false_alarm_target``, ``ewma_lambda`` and
    ``channels``), :attr:`SIGNALS`, :meth:`window` and :meth:`_maps`.

    Attributes (fitted): ``channel_idx_``, ``mean_``/``scale_`` the standardisation,
    ``centre_`` the lagged vector's mean, ``state_map_`` ``W_s`` ``(k, d)``, ``resid_map_``
    ``W_r`` ``(r, d)``, ``limits_`` ``(2,)``.
    """

    #: the names of the two statistics
    SIGNALS: ClassVar[tuple[str, str]] = ("T2", "Q")
    false_alarm_target: float
    ewma_lambda: float
    channels: Sequence[str] | None

    @abstractmethod
    def window(self) -> int:
        """``L``, the samples in one lagged vector."""

    @abstractmethod
    def _maps(self, z: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(centre (d,), W_s (k, d), W_r (r, d))`` from the healthy standardised records
        ``z`` (``(T_i, m)`` each, whole: a family builds its own lagged vectors)."""

    def _check_family(self) -> None:
        """The family's own hyperparameters (beside :data:`LAGGED_CONSTRAINTS`)."""

    def _validate_params(self) -> None:
        params = self.get_params()
        check_params({k: params[k] for k in LAGGED_CONSTRAINTS}, LAGGED_CONSTRAINTS)
        check_channel_names("channels", self.channels, allow_none=True)
        self._check_family()

    # ---- fitting -------------------------------------------------------------------------------
    def _fit(self, episodes: list[Episode]) -> None:
        idx = channel_indices(self.channels, self.channels_, "channels")
        x = stack_episodes(episodes)[:, idx]
        require_varying(x, [self.channels_[i] for i in idx], self.name, every=False)
        L = self.window()
        if not any(ep.n_samples >= 2 * L + 1 for ep in episodes):
            raise ValueError(
                f"{self.name} needs training episodes of at least {2 * L + 1} samples for "
                f"{L}-sample lagged vectors, got at most {max(ep.n_samples for ep in episodes)}"
            )
        mean = x.mean(axis=0)
        scale = x.std(axis=0, ddof=1)
        self.channel_idx_ = idx
        self.mean_ = mean
        # a constant channel keeps scale 1: any change of it shows up in the residual
        self.scale_ = np.where(scale > 1e-9 * np.abs(mean), scale, 1.0)
        z = [self._standardise(ep.y) for ep in episodes]
        self.centre_, self.state_map_, self.resid_map_ = self._maps(z)
        self._finish()
        stats = np.concatenate([self._statistics(zi)[L - 1 :] for zi in z])
        self.limits_ = calibrate_limit(stats, 0.5 * self.false_alarm_target, method="empirical")
        self._finish()

    def _standardise(self, y: np.ndarray) -> np.ndarray:
        return (np.atleast_2d(y)[:, self.channel_idx_] - self.mean_) / self.scale_

    def _finish(self) -> None:
        self.signal_names_ = self.SIGNALS
        self._maps_t = np.ascontiguousarray(np.concatenate([self.state_map_, self.resid_map_]).T)
        self._lower = np.full(2, -np.inf)
        self._no_limit = np.full(2, np.inf)

    # ---- statistics ----------------------------------------------------------------------------
    def _projected(self, v: np.ndarray) -> np.ndarray:
        """``[W_s c, W_r c]`` of lagged vectors ``v`` ``(N, d) -> (N, k + r)``, ``c = v − centre``."""
        return (v - self.centre_) @ self._maps_t

    def _squares(self, w: np.ndarray) -> np.ndarray:
        """``[T², Q]`` ``(N, 2)`` of (filtered) projections ``w`` ``(N, k + r)``."""
        k = self.state_map_.shape[0]
        return np.column_stack([np.sum(w[:, :k] ** 2, axis=1), np.sum(w[:, k:] ** 2, axis=1)])

    def _statistics(self, z: np.ndarray) -> np.ndarray:
        """The statistics ``(T, 2)`` of a standardised record ``z``; zero in the warm-up, the
        EWMA of the projections starting at the first full vector."""
        L = self.window()
        out = np.zeros((z.shape[0], 2))
        if z.shape[0] >= L:
            w = EWMA(self.ewma_lambda).filter(self._projected(lagged(z, L)))
            out[L - 1 :] = self._squares(w)
        return out

    def statistics(self, y: np.ndarray) -> np.ndarray:
        """``[T², Q]`` ``(T, 2)`` of a record ``y`` ``(T, n_channels)`` (after the EWMA; zero
        in the first ``window() − 1`` samples)."""
        self._check_fitted()
        return self._statistics(self._standardise(y))

    # ---- running -------------------------------------------------------------------------------
    def _reset(self) -> None:
        self._buf = np.zeros((self.window(), self.channel_idx_.size))  # newest first
        self._t = 0
        self._ewma = EWMA(self.ewma_lambda)

    def _update(self, y: np.ndarray) -> Decision:
        self._buf = np.roll(self._buf, 1, axis=0)
        self._buf[0] = self._standardise(y)[0]
        self._t += 1
        if self._t < self.window():
            st = np.zeros(2)
            return Decision(False, st, self._lower.copy(), self._no_limit.copy(), st.copy())
        w = self._ewma.update(self._projected(self._buf.reshape(1, -1))[0])
        st = self._squares(w[None])[0]
        alarm = bool(np.any(st > self.limits_))
        return Decision(alarm, st, self._lower.copy(), self.limits_.copy(), st.copy())

    def _detect(self, y: np.ndarray) -> Detection:
        st = self.statistics(y)
        n, L = st.shape[0], self.window()
        upper = np.tile(self.limits_, (n, 1))
        upper[: L - 1] = np.inf
        return Detection(
            alarm=np.any(st > upper, axis=1),
            signal=st,
            lower=np.full((n, 2), -np.inf),
            upper=upper,
            residual=st.copy(),
            signal_names=self.signal_names_,
        )

    # ---- state ---------------------------------------------------------------------------------
    def _get_state(self) -> dict[str, np.ndarray]:
        return {
            "channel_idx": self.channel_idx_,
            "mean": self.mean_,
            "scale": self.scale_,
            "centre": self.centre_,
            "state_map": self.state_map_,
            "resid_map": self.resid_map_,
            "limits": self.limits_,
        }

    def _set_state(self, state: dict[str, np.ndarray]) -> None:
        self.channel_idx_ = np.asarray(state["channel_idx"], dtype=np.int64)
        for key in ("mean", "scale", "centre", "state_map", "resid_map", "limits"):
            setattr(self, f"{key}_", np.asarray(state[key], dtype=np.float64))
        d = self.channel_idx_.size * self.window()
        if self.centre_.shape != (d,) or self.state_map_.shape[1] != d:
            raise ValueError(
                f"the saved maps are for {self.centre_.size}-dimensional lagged vectors; "
                f"these hyperparameters make {d}"
            )
        self._finish()
