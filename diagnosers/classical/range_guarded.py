"""``limits-novelty`` and ``pca-novelty``: the baselines that say "new regime" instead of "fault".

``limits`` and ``pca`` learn the healthy plant where its training history went. On the
``regimes`` track, whose set points move twice as widely as in training, they alarm on half
the healthy samples (``limits`` r_fd 0.55, ``pca`` 0.34 on 40 validation episodes;
``lab/regimes-lab.md``), almost all of them while a set point is outside its training range.
These variants keep every decision of their base and add :attr:`Detection.novelty`
(:class:`~diagnosers.stages.operating_range.OperatingRange`): a sample is novel while a set
point is outside its training range and for ``novelty_hold`` samples after (the plant settles
slowly: the regenerator's time constant is about 1600 s). Their alarms are unchanged; the
scoring counts no novel sample as a false alarm and reports the novel share beside r_fd. On
open-loop episodes (no set points) nothing is flagged and they equal their base.

Streaming :meth:`update` returns the base's :class:`Decision`, which has no novelty: the flag
is a property of the episode's :meth:`detect`.
"""

from __future__ import annotations

import dataclasses
from typing import Any, ClassVar

import numpy as np

from diagnosers.classical.limit_checker import LimitChecker
from diagnosers.classical.pca_monitor import PCADetector
from diagnosers.detection import Detection
from diagnosers.episode.record import Episode
from diagnosers.presets import keyword_init
from diagnosers.registry import register
from diagnosers.stages.operating_range import OperatingRange
from fcc_common.validation import Integer, check

__all__ = ["LimitsNovelty", "PCANovelty"]

#: Samples a novelty flag lasts after the set points return inside their training range:
#: 300 (5 h at 60 s) brought the alarms flagged novel from 0.98 (limits) and 0.96 (pca) at 0 to
#: 0.99 on 40 validation episodes of the wider program (``lab/regimes_lab.py``).
NOVELTY_HOLD = 300


class _RangeGuard:
    """What both variants add: fit the operating range, flag its novel samples. It comes first
    among the bases, so its methods wrap the detector's (``super()`` is the detector)."""

    def _fit(self, episodes: list[Episode]) -> None:
        super()._fit(episodes)  # type: ignore[misc]
        self._fit_range(episodes)

    def _get_state(self) -> dict[str, np.ndarray]:
        return {**super()._get_state(), **self._range_state()}  # type: ignore[misc]

    def _set_state(self, state: dict[str, np.ndarray]) -> None:
        super()._set_state(state)  # type: ignore[misc]
        self._set_range_state(state)

    def _detect(self, y: np.ndarray) -> Detection:
        return self._flag(super()._detect(y), y)  # type: ignore[misc]

    novelty_hold: int
    channels_: tuple[str, ...]
    sample_time_s_: float

    def _fit_range(self, episodes: list[Episode]) -> None:
        check("novelty_hold", self.novelty_hold, Integer(0))
        self.range_ = OperatingRange(hold=int(self.novelty_hold)).fit(episodes)

    def _flag(self, det: Detection, y: np.ndarray) -> Detection:
        ep = Episode(y=y, channels=self.channels_, sample_time_s=self.sample_time_s_)
        return dataclasses.replace(det, novelty=self.range_.flag(ep))

    def _range_state(self) -> dict[str, np.ndarray]:
        used = [self.channels_.index(c) for c in self.range_.used]
        return {
            "range_channels": np.array(used, dtype=np.int64),
            "range_low": self.range_.low,
            "range_high": self.range_.high,
        }

    def _set_range_state(self, state: dict[str, np.ndarray]) -> None:
        rng = OperatingRange(hold=int(self.novelty_hold))
        rng.used = tuple(self.channels_[int(i)] for i in state["range_channels"])
        rng.low = np.asarray(state["range_low"], dtype=np.float64)
        rng.high = np.asarray(state["range_high"], dtype=np.float64)
        self.range_ = rng


@register("limits-novelty")
class LimitsNovelty(_RangeGuard, LimitChecker):
    """``limits`` that flags the samples outside its training set-point range as novel.

    Args:
        alpha: as :class:`~diagnosers.classical.limit_checker.LimitChecker` (default 0.01).
        channels: as :class:`~diagnosers.classical.limit_checker.LimitChecker` (default all).
        novelty_hold: samples a novelty flag lasts after the set points return (≥ 0,
            default :data:`NOVELTY_HOLD`).
    """

    DEFAULTS: ClassVar[dict[str, Any]] = {
        "alpha": 0.01,
        "channels": None,
        "novelty_hold": NOVELTY_HOLD,
    }
    __init__ = keyword_init(DEFAULTS)


@register("pca-novelty")
class PCANovelty(_RangeGuard, PCADetector):
    """``pca`` that flags the samples outside its training set-point range as novel.

    Args:
        alpha: as :class:`~diagnosers.classical.pca_monitor.PCADetector`, as are the
            following four.
        variance_explained: components kept to this share of the variance.
        n_components: or this many components.
        channels: the monitored channels.
        limits: ``"analytic"`` or ``"empirical"`` T² and SPE limits.
        novelty_hold: samples a novelty flag lasts after the set points return (≥ 0,
            default :data:`NOVELTY_HOLD`).
    """

    DEFAULTS: ClassVar[dict[str, Any]] = {**PCADetector.DEFAULTS, "novelty_hold": NOVELTY_HOLD}
    __init__ = keyword_init(DEFAULTS)
