"""The operating program (spec §7.5): APRBS excitation of the plant's inputs, and the split of an
episode's generator into its independent random streams."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from fcc_common.validation import Constraint, Integer, Real, check_params, invalid
from fcc_env.params import NOMINAL_INPUTS

#: Allowed values of the :class:`Excitation` fields.
EXCITATION_RANGES: dict[str, Constraint] = {
    "T_fp_halfrange_C": Real(0.0, 50.0, unit="°C"),
    "T_ar_halfrange_C": Real(0.0, 50.0, unit="°C"),
    "R_ar_halfrange_rel": Real(
        0.0, 0.07, why="larger air moves leave the hot-state envelope, spec §4"
    ),
    "hold_min": Integer(1),
    "hold_max": Integer(1),
    "warmup_samples": Integer(0),
}


@dataclass(frozen=True)
class Excitation:
    """Amplitude-modulated pseudo-random steps (APRBS) on T_fp, T_ar and R_ar (spec §7.5).

    Each new level is uniform in nominal ± half-range and is held for an integer number of samples
    drawn uniformly from ``[hold_min, hold_max]``; the first ``warmup_samples`` stay at nominal.
    The catalyst valve is held (exciting it would make the T_rx relation unidentifiable, spec §5).
    """

    T_fp_halfrange_C: float = 10.0
    T_ar_halfrange_C: float = 10.0
    R_ar_halfrange_rel: float = 0.05
    hold_min: int = 20
    hold_max: int = 200
    warmup_samples: int = 100

    @classmethod
    def from_option(cls, value: Any) -> Excitation | None:
        """``True``/``None`` → defaults, ``False`` → no excitation, a mapping → overrides."""
        if value is None or value is True:
            return cls()
        if value is False:
            return None
        if isinstance(value, Excitation):
            return value
        if isinstance(value, Mapping):
            allowed = set(cls.__dataclass_fields__)
            unknown = sorted(set(value) - allowed)
            if unknown:
                raise ValueError(
                    f"Unknown excitation option(s) {unknown}. Allowed: {sorted(allowed)}"
                )
            return cls(**value)
        raise invalid(
            "excitation", value, "True, False, None, an Excitation or a mapping of its fields"
        )

    def __post_init__(self) -> None:
        check_params({name: getattr(self, name) for name in EXCITATION_RANGES}, EXCITATION_RANGES)
        if self.hold_max < self.hold_min:
            raise invalid(
                "hold_max", self.hold_max, f"an integer >= hold_min={self.hold_min}", "hold range"
            )


class ProgramGenerator:
    """Streams the operating program: inputs ``(n, 6)`` per sample, chunk by chunk.

    Each excited channel draws from its own generator, in blocks of ``_BLOCK`` levels and hold
    times (one numpy call each instead of two per segment), so the program does not depend on
    how it is chunked, and a seed gives the same program whatever the scenario.
    """

    _CHANNELS = (3, 2, 1)  # T_fp, T_ar, R_ar columns of the input vector
    _BLOCK = 64

    def __init__(self, excitation: Excitation | None, rngs: list[np.random.Generator]):
        self.excitation = excitation
        self.rngs = rngs
        self.k = 0
        self._level = NOMINAL_INPUTS[list(self._CHANNELS)].copy()
        self._left = np.zeros(3, dtype=np.int64)
        self._draws: list[tuple[np.ndarray, np.ndarray]] = [(np.empty(0), np.empty(0))] * 3
        self._next = [0, 0, 0]

    def _segment(self, c: int) -> tuple[float, int]:
        """Next (offset in [-1, 1), hold samples) of channel c."""
        ex = self.excitation
        assert ex is not None
        if self._next[c] >= self._draws[c][0].shape[0]:
            rng = self.rngs[c]
            offsets = rng.uniform(-1.0, 1.0, size=self._BLOCK)
            holds = rng.integers(ex.hold_min, ex.hold_max, size=self._BLOCK, endpoint=True)
            self._draws[c] = (offsets, holds)
            self._next[c] = 0
        j = self._next[c]
        self._next[c] += 1
        return float(self._draws[c][0][j]), int(self._draws[c][1][j])

    def take(self, n: int) -> np.ndarray:
        out = np.empty((n, NOMINAL_INPUTS.shape[0]))
        out[:] = NOMINAL_INPUTS
        ex = self.excitation
        if ex is None:
            self.k += n
            return out
        half = (
            ex.T_fp_halfrange_C,
            ex.T_ar_halfrange_C,
            ex.R_ar_halfrange_rel * NOMINAL_INPUTS[1],
        )
        for c, col in enumerate(self._CHANNELS):
            centre = NOMINAL_INPUTS[col]
            i = max(0, min(n, ex.warmup_samples - self.k))  # warm-up samples stay at nominal
            while i < n:
                if self._left[c] == 0:
                    offset, hold = self._segment(c)
                    self._level[c] = centre + half[c] * offset
                    self._left[c] = hold
                m = int(min(self._left[c], n - i))
                out[i : i + m, col] = self._level[c]
                self._left[c] -= m
                i += m
        self.k += n
        return out


def episode_generators(rng: np.random.Generator) -> dict[str, Any]:
    """Split an episode's generator into independent streams (program, noise, random fault)."""
    children = rng.spawn(5)
    return {"program": children[:3], "noise": children[3], "fault": children[4]}
