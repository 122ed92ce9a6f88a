"""The operating range a detector was trained on, and the samples outside it ("novel").

A detector learned from healthy history knows the plant where that history went. When operators
move a set point beyond anything in it, the plant runs at an operating point no training episode
reached: a learned band or relation extrapolates there, and its alarms say "new regime", not
"fault". :class:`OperatingRange` records, per channel of the operating program, the lowest and
highest training value, and flags a sample as novel while a channel is outside that range and
for ``hold`` samples after it returns (the plant keeps moving while it settles). The flag is the
detector's own outcome (:attr:`diagnosers.detection.Detection.novelty`), scored apart from false
alarms.

Only channels no fault moves may define the range: the set points (an operator's decision), not
the measured temperatures, through which a fault shows and which a range could then hide. On an
open-loop episode, which has no set points, nothing is flagged.

>>> import numpy as np
>>> from diagnosers.episode.record import Episode
>>> ep = Episode(y=np.array([[1.0], [2.0], [3.0]]), channels=("T_rx_sp",), sample_time_s=60.0)
>>> rng = OperatingRange(hold=1).fit([ep])
>>> wide = Episode(y=np.array([[2.0], [4.0], [2.0], [2.0]]), channels=("T_rx_sp",),
...                sample_time_s=60.0)
>>> rng.flag(wide).tolist()
[False, True, True, False]
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np

from diagnosers.detection import Detection
from diagnosers.episode.record import Episode
from fcc_common.validation import Integer, Real, check, invalid

__all__ = ["SETPOINT_CHANNELS", "OperatingRange"]

#: The operating program's set points (closed loop): what an operator moves, and no fault does.
SETPOINT_CHANNELS: tuple[str, ...] = ("T_rx_sp", "T_rg1_sp")


class OperatingRange:
    """Per channel the training range ``[low, high]``; samples outside it are novel.

    Args:
        channels: the channels that define the operating point (default the set points).
            A channel missing from the training episodes is not checked.
        margin: tolerance beyond the range, as a share of its span (≥ 0, default 0).
        hold: samples a flag lasts after the channel returns inside (≥ 0, default 0).
    """

    def __init__(
        self,
        channels: Sequence[str] = SETPOINT_CHANNELS,
        *,
        margin: float = 0.0,
        hold: int = 0,
    ) -> None:
        if isinstance(channels, str) or not all(isinstance(c, str) for c in channels):
            raise invalid("channels", channels, "a sequence of channel names")
        self.channels = tuple(channels)
        self.margin = float(check("margin", margin, Real(0.0)))
        self.hold = int(check("hold", hold, Integer(0)))
        self.low = np.zeros(0)
        self.high = np.zeros(0)
        self.used: tuple[str, ...] = ()

    def fit(self, episodes: Sequence[Episode]) -> OperatingRange:
        """Record the range of each channel over the training episodes (those that hold it)."""
        if not episodes:
            raise invalid("episodes", episodes, "at least one training episode")
        used = [c for c in self.channels if all(c in ep.channels for ep in episodes)]
        lows, highs = [], []
        for c in used:
            v = np.concatenate([ep.y[:, ep.channels.index(c)] for ep in episodes])
            lows.append(float(np.min(v)))
            highs.append(float(np.max(v)))
        self.used = tuple(used)
        self.low, self.high = np.array(lows), np.array(highs)
        return self

    def flag(self, episode: Episode) -> np.ndarray:
        """``(T,)`` bool: samples where a channel is outside its range (held ``hold`` samples)."""
        out = np.zeros(episode.n_samples, dtype=bool)
        span = self.high - self.low
        for j, c in enumerate(self.used):
            if c not in episode.channels:
                raise invalid("episode", c, f"an episode holding the channels {list(self.used)}")
            v = episode.y[:, episode.channels.index(c)]
            pad = self.margin * span[j]
            out |= (v < self.low[j] - pad) | (v > self.high[j] + pad)
        if self.hold and out.any():
            # a flag lasts `hold` samples after the last novel sample: a running maximum over
            # the window [k - hold, k]
            idx = np.where(out, np.arange(out.size), -(self.hold + 1))
            last = np.maximum.accumulate(idx)
            out = np.arange(out.size) - last <= self.hold
        return out

    def apply(self, detection: Detection, episode: Episode) -> Detection:
        """``detection`` with the novel samples of ``episode`` flagged (its ``novelty``)."""
        return dataclasses.replace(detection, novelty=self.flag(episode))
