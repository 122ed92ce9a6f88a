"""What the classical detectors share: the channels they watch and their significance level."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from diagnosers.episode.record import Episode
from fcc_common.validation import Real, invalid

__all__ = ["ALPHA", "channel_indices", "check_channel_names", "stack_episodes"]

#: significance level of every classical detector
ALPHA = Real(0, 1, closed="neither")


def check_channel_names(name: str, value: object, *, allow_none: bool) -> None:
    """Raise ValueError unless ``value`` is a non-empty list of distinct names (or None if allowed)."""
    if value is None and allow_none:
        return
    if (
        isinstance(value, str)
        or not isinstance(value, Sequence)
        or len(value) == 0
        or not all(isinstance(v, str) for v in value)
        or len(set(value)) != len(value)
    ):
        allowed = "None or " if allow_none else ""
        raise invalid(name, value, f"{allowed}a non-empty list of distinct channel names")


def channel_indices(
    names: Sequence[str] | None, channels: tuple[str, ...], param: str
) -> np.ndarray:
    """Column indices of ``names`` in ``channels`` (all columns when ``names`` is None)."""
    if names is None:
        return np.arange(len(channels))
    unknown = [n for n in names if n not in channels]
    if unknown:
        raise ValueError(f"{param}: unknown channel(s) {unknown}. Available: {list(channels)}")
    return np.array([channels.index(n) for n in names], dtype=np.int64)


def stack_episodes(episodes: list[Episode]) -> np.ndarray:
    """The measurements of all ``episodes``, one after the other: ``(sum T_i, n_channels)``."""
    return np.concatenate([ep.y for ep in episodes], axis=0)
