"""The ``limits`` detector: per-channel fixed limits ``mean ± t_α·std`` learned from healthy data."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from diagnosers.classical.channel_selection import (
    ALPHA,
    channel_indices,
    check_channel_names,
    stack_episodes,
)
from diagnosers.contract import require_varying
from diagnosers.detection import Decision, Detection
from diagnosers.diagnoser import Diagnoser
from diagnosers.episode.record import Episode
from diagnosers.registry import register
from diagnosers.stages.band import band
from fcc_common.validation import check

__all__ = ["LimitChecker"]


@register("limits")
class LimitChecker(Diagnoser):
    """Per-channel fixed limits ``mean ± t_α·std`` learned from healthy data.

    ``t_α`` is the two-sided standard normal quantile, so for a Gaussian channel each limit pair
    holds the healthy signal with probability ``1 - alpha``. An alarm is raised when any monitored
    channel leaves its limits (with ``c`` channels the healthy false-alarm rate is therefore up
    to ``1 - (1 - alpha)^c``).

    Args:
        alpha: significance level in (0, 1), default 0.01 (as in the paper): the limits are
            ``mean ± t_α·std``, so a smaller ``alpha`` widens them.
        channels: names of the monitored channels (distinct), or ``None`` (default) for all.

    Decision arrays (one entry per monitored channel, named by ``signal_names_``):
        signal = measurement [physical units], lower/upper = limits, residual = ``y - mean_``.

    Attributes:
        mean_, std_: per-channel healthy mean and standard deviation (ddof=1).
        lower_, upper_: limits.
    """

    def __init__(self, *, alpha: float = 0.01, channels: Sequence[str] | None = None) -> None:
        self.alpha = alpha
        self.channels = channels

    def _validate_params(self) -> None:
        check("alpha", self.alpha, ALPHA)
        check_channel_names("channels", self.channels, allow_none=True)

    def _fit(self, episodes: list[Episode]) -> None:
        self.channel_idx_ = channel_indices(self.channels, self.channels_, "channels")
        y = stack_episodes(episodes)[:, self.channel_idx_]
        if y.shape[0] < 2:
            raise ValueError(f"limits needs at least 2 training samples, got {y.shape[0]}")
        require_varying(y, [self.channels_[i] for i in self.channel_idx_], "limits", every=False)
        self.mean_ = y.mean(axis=0)
        self.std_ = y.std(axis=0, ddof=1)
        self._finish()

    def _finish(self) -> None:
        self.lower_, self.upper_ = band(self.mean_, 0.0, self.std_, self.alpha)
        self.signal_names_ = tuple(self.channels_[i] for i in self.channel_idx_)

    def _get_state(self) -> dict[str, np.ndarray]:
        return {"channel_idx": self.channel_idx_, "mean": self.mean_, "std": self.std_}

    def _set_state(self, state: dict[str, np.ndarray]) -> None:
        self.channel_idx_ = np.asarray(state["channel_idx"], dtype=np.int64)
        self.mean_ = np.asarray(state["mean"], dtype=np.float64)
        self.std_ = np.asarray(state["std"], dtype=np.float64)
        self._finish()

    def _reset(self) -> None:
        pass  # memoryless

    def _update(self, y: np.ndarray) -> Decision:
        s = y[self.channel_idx_]
        alarm = bool(np.any((s < self.lower_) | (s > self.upper_)))
        return Decision(alarm, s, self.lower_.copy(), self.upper_.copy(), s - self.mean_)

    def _detect(self, y: np.ndarray) -> Detection:
        s = y[:, self.channel_idx_]
        n = s.shape[0]
        return Detection(
            alarm=np.any((s < self.lower_) | (s > self.upper_), axis=1),
            signal=s,
            lower=np.broadcast_to(self.lower_, (n, s.shape[1])).copy(),
            upper=np.broadcast_to(self.upper_, (n, s.shape[1])).copy(),
            residual=s - self.mean_,
            signal_names=self.signal_names_,
        )
