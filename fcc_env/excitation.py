"""The operating program (spec §7.5): APRBS excitation of the plant's inputs, and the split of an
episode's generator into its independent random streams."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from fcc_common.validation import Constraint, Integer, Real, check_params, from_fields, invalid
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
            return from_fields(cls, value, "excitation")
        raise invalid(
            "excitation", value, "True, False, None, an Excitation or a mapping of its fields"
        )

    def __post_init__(self) -> None:
        check_params({name: getattr(self, name) for name in EXCITATION_RANGES}, EXCITATION_RANGES)
        if self.hold_max < self.hold_min:
            raise invalid(
                "hold_max", self.hold_max, f"an integer >= hold_min={self.hold_min}", "hold range"
            )


class APRBSChannel:
    """One channel of amplitude-modulated pseudo-random steps, streamed chunk by chunk.

    Levels are uniform in ``centre ± half`` and held an integer number of samples uniform in
    ``[hold_min, hold_max]``; the first ``warmup_samples`` stay at ``centre``. Levels and holds
    are drawn from the channel's own generator in blocks of ``_BLOCK`` (one numpy call each
    instead of two per segment), so the stream does not depend on how it is chunked.
    """

    _BLOCK = 64

    def __init__(
        self,
        centre: float,
        half: float,
        hold_min: int,
        hold_max: int,
        warmup_samples: int,
        rng: np.random.Generator,
    ) -> None:
        self.centre, self.half = float(centre), float(half)
        self.hold_min, self.hold_max, self.warmup = hold_min, hold_max, warmup_samples
        self.rng = rng
        self.k = 0
        self._level = self.centre
        self._left = 0
        self._draws: tuple[np.ndarray, np.ndarray] = (np.empty(0), np.empty(0))
        self._next = 0

    def _segment(self) -> tuple[float, int]:
        """Next (offset in [-1, 1), hold samples)."""
        if self._next >= self._draws[0].shape[0]:
            offsets = self.rng.uniform(-1.0, 1.0, size=self._BLOCK)
            holds = self.rng.integers(self.hold_min, self.hold_max, size=self._BLOCK, endpoint=True)
            self._draws = (offsets, holds)
            self._next = 0
        j = self._next
        self._next += 1
        return float(self._draws[0][j]), int(self._draws[1][j])

    def take(self, n: int, out: np.ndarray) -> None:
        """Write the next ``n`` samples into ``out`` (shape (n,); left as is during warm-up)."""
        i = max(0, min(n, self.warmup - self.k))  # warm-up samples keep out's values
        while i < n:
            if self._left == 0:
                offset, hold = self._segment()
                self._level = self.centre + self.half * offset
                self._left = hold
            m = int(min(self._left, n - i))
            out[i : i + m] = self._level
            self._left -= m
            i += m
        self.k += n


class ProgramGenerator:
    """Streams the operating program: inputs ``(n, 6)`` per sample, chunk by chunk.

    Each excited channel is an :class:`APRBSChannel` with its own generator, so the program
    does not depend on how it is chunked, and a seed gives the same program whatever the
    scenario.
    """

    _CHANNELS = (3, 2, 1)  # T_fp, T_ar, R_ar columns of the input vector

    def __init__(self, excitation: Excitation | None, rngs: list[np.random.Generator]):
        self.excitation = excitation
        self.channels: list[APRBSChannel] = []
        if excitation is not None:
            ex = excitation
            half = (
                ex.T_fp_halfrange_C,
                ex.T_ar_halfrange_C,
                ex.R_ar_halfrange_rel * NOMINAL_INPUTS[1],
            )
            self.channels = [
                APRBSChannel(
                    NOMINAL_INPUTS[col], h, ex.hold_min, ex.hold_max, ex.warmup_samples, rng
                )
                for col, h, rng in zip(self._CHANNELS, half, rngs, strict=True)
            ]

    def take(self, n: int) -> np.ndarray:
        out = np.empty((n, NOMINAL_INPUTS.shape[0]))
        out[:] = NOMINAL_INPUTS
        for col, channel in zip(self._CHANNELS, self.channels, strict=False):
            channel.take(n, out[:, col])
        return out


def episode_generators(rng: np.random.Generator, closed_loop: bool = False) -> dict[str, Any]:
    """Split an episode's generator into independent streams (program, noise, random fault;
    in closed loop also the set-point program's three streams, spawned after the open-loop
    ones so those are the same in both modes)."""
    children = rng.spawn(5)
    gens = {"program": children[:3], "noise": children[3], "fault": children[4]}
    if closed_loop:
        gens["setpoints"] = rng.spawn(3)
    return gens
