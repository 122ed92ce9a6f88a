"""The distributions a track draws a fault's magnitude, onset and ramp from.

Each is a frozen, validated dataclass with ``low``/``high`` (its support), ``sample`` (a float),
``sample_int`` (a sample index) and ``to_json`` (hashed into the track's store key).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from fcc_common.validation import Integer, Real, check, invalid

__all__ = ["Choice", "Distribution", "Fixed", "Uniform", "check_distribution"]

# ---- distributions -----------------------------------------------------------------------------
_NUMBER = Real()


@dataclass(frozen=True)
class Fixed:
    """Always ``value``."""

    value: float

    def __post_init__(self) -> None:
        object.__setattr__(self, "value", check("value", self.value, Integer(), _NUMBER))

    @property
    def low(self) -> float:
        return self.value

    @property
    def high(self) -> float:
        return self.value

    def sample(self, rng: np.random.Generator) -> float:
        return self.value

    def sample_int(self, rng: np.random.Generator) -> int:
        return int(self.value)

    def to_json(self) -> dict[str, Any]:
        return {"kind": "fixed", "value": self.value}


@dataclass(frozen=True)
class Uniform:
    """Uniform in ``[low, high]`` (integers ``ceil(low)..floor(high)`` for sample indices)."""

    low: float
    high: float

    def __post_init__(self) -> None:
        low = check("low", self.low, _NUMBER)
        high = check("high", self.high, Real(low, why="high >= low"))
        object.__setattr__(self, "low", low)
        object.__setattr__(self, "high", high)

    def sample(self, rng: np.random.Generator) -> float:
        return float(rng.uniform(self.low, self.high))

    def sample_int(self, rng: np.random.Generator) -> int:
        lo, hi = math.ceil(self.low), math.floor(self.high)
        if lo > hi:
            raise invalid("Uniform", self, "bounds holding an integer")
        return int(rng.integers(lo, hi, endpoint=True))

    def to_json(self) -> dict[str, Any]:
        return {"kind": "uniform", "low": self.low, "high": self.high}


@dataclass(frozen=True)
class Choice:
    """One of ``values`` with equal probability."""

    values: tuple[float, ...]

    def __post_init__(self) -> None:
        vals = self.values
        if isinstance(vals, str | bytes) or not isinstance(vals, tuple | list) or not vals:
            raise invalid("values", vals, "a non-empty tuple of numbers")
        object.__setattr__(
            self, "values", tuple(check("values", v, Integer(), _NUMBER) for v in vals)
        )

    @property
    def low(self) -> float:
        return min(self.values)

    @property
    def high(self) -> float:
        return max(self.values)

    def sample(self, rng: np.random.Generator) -> float:
        return self.values[int(rng.integers(len(self.values)))]

    def sample_int(self, rng: np.random.Generator) -> int:
        return int(self.sample(rng))

    def at_most(self, limit: float) -> Choice:
        """The values ``<= limit`` (the caller ensures one remains)."""
        return Choice(tuple(v for v in self.values if v <= limit))

    def to_json(self) -> dict[str, Any]:
        return {"kind": "choice", "values": list(self.values)}


Distribution = Fixed | Uniform | Choice
_DISTRIBUTIONS = (Fixed, Uniform, Choice)


def check_distribution(name: str, value: Any, low: float, high: float, what: str) -> Distribution:
    """``value`` if it is a distribution with support in ``[low, high]``; else ``ValueError``
    naming ``name``, the allowed support and ``what`` (why the support is bounded)."""
    if not isinstance(value, _DISTRIBUTIONS):
        raise invalid(name, value, "a Fixed, Uniform or Choice distribution")
    if not (low <= value.low and value.high <= high):
        raise invalid(name, value, f"a distribution with support in [{low:g}, {high:g}]", what)
    return value
