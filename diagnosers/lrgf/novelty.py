"""How far a learned model's own prediction lies outside the range it took in training.

A network trained on a few episodes is reliable where its training data was; where the inputs
drive the plant to an operating point no training episode reached, its prediction extrapolates
and its error grows. On the FCC (``lrgf-glr``'s bank, 200 healthy validation episodes) the T_rg1
network's normalised error had a mean of +2.6 where its prediction was above every training
prediction, against 0.0 inside, and those 0.3 % of samples held 18 % of the healthy alarm
samples and most of the longest false-alarm streaks.

Only relations whose inputs are all exogenous (none is the output of a relation of the bank)
measure it: their prediction depends on the measured inputs alone, so no fault moves it, and
a band widened there cannot hide a fault's signature as a widened band on a measured
temperature would.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["NoveltyScale", "PredictionRange", "exogenous_relations", "novelty_scale"]


def exogenous_relations(relations: Sequence[tuple[str, Sequence[str]]]) -> np.ndarray:
    """Indices of the relations none of whose inputs is the output of a relation of the bank."""
    outputs = {out for out, _ in relations}
    return np.array(
        [j for j, (_, ins) in enumerate(relations) if not outputs.intersection(ins)], dtype=int
    )


@dataclass(frozen=True)
class PredictionRange:
    """Per channel the lowest and highest training prediction and its standard deviation."""

    low: np.ndarray
    high: np.ndarray
    scale: np.ndarray

    @classmethod
    def of(cls, predictions: Sequence[np.ndarray]) -> PredictionRange:
        """The range of the training predictions, records ``(T_i, c)``."""
        p = np.concatenate([np.asarray(x, dtype=np.float64) for x in predictions])
        if p.ndim != 2 or p.shape[0] < 2:
            raise ValueError(
                f"predictions must be (samples, channels) records with at least 2 samples in "
                f"all; got shape {p.shape}"
            )
        return cls(p.min(axis=0), p.max(axis=0), np.maximum(p.std(axis=0), 1e-9))

    def distance(self, prediction: np.ndarray) -> np.ndarray:
        """How far ``prediction`` ``(..., c)`` is outside the range, in training standard
        deviations, the largest over the channels: 0 inside, ``(...)``."""
        p = np.asarray(prediction, dtype=np.float64)
        beyond = np.maximum((p - self.high) / self.scale, (self.low - p) / self.scale)
        return np.maximum(beyond.max(axis=-1, initial=0.0), 0.0)

    def to_array(self) -> np.ndarray:
        """``(3, c)``: low, high and scale, for a saved state."""
        return np.stack([self.low, self.high, self.scale])

    @classmethod
    def from_array(cls, array: Any) -> PredictionRange:
        a = np.asarray(array, dtype=np.float64)
        if a.ndim != 2 or a.shape[0] != 3:
            raise ValueError(f"a prediction range is a (3, channels) array; got shape {a.shape}")
        return cls(a[0], a[1], a[2])


def novelty_scale(distance: np.ndarray, gain: float) -> np.ndarray:
    """The factor ``1 + gain * distance`` by which a residual is divided there."""
    return 1.0 + gain * np.asarray(distance, dtype=np.float64)


class NoveltyScale:
    """Divide a bank's normalised errors by ``1 + gain · d`` where its exogenous relations'
    prediction leaves their training range by ``d`` training standard deviations.

    The optional part of ``lrgf-glr`` (``novelty_gain``). Args: ``gain`` ≥ 0 (0: off),
    ``relations``: the indices of the relations with exogenous inputs only
    (:func:`exogenous_relations`), ``steady_window``: the warm-up left out of the range.

    Attributes:
        range_: the :class:`PredictionRange` of the bank's training predictions (after
            :meth:`fit`; None when no relation has exogenous inputs only).
    """

    def __init__(self, gain: float, relations: np.ndarray, steady_window: int) -> None:
        self.gain = gain
        self.relations = relations
        self.steady_window = steady_window
        self.range_: PredictionRange | None = None

    def predictions(self, bank: Any, y: np.ndarray) -> np.ndarray:
        """The outputs ``(T, c)`` of the networks of ``bank`` (``lrgf`` and ``in_idx``) of the
        relations with exogenous inputs, over a record ``y``."""
        cols = [bank.lrgf[j].predict(y[:, bank.in_idx[j]])[:, 0] for j in self.relations]
        return np.column_stack(cols) if cols else np.zeros((y.shape[0], 0))

    def training_range(self, bank: Any, train: list[np.ndarray]) -> PredictionRange | None:
        """The range of ``bank``'s predictions on its training records (None: no relation)."""
        if not len(self.relations):
            return None
        w = self.steady_window
        return PredictionRange.of([self.predictions(bank, y)[w:] for y in train])

    def fit(self, bank: Any, train: list[np.ndarray]) -> NoveltyScale:
        """Learn ``range_`` from the training records of ``bank``."""
        self.range_ = self.training_range(bank, train)
        return self

    def distances(
        self, bank: Any, train: list[np.ndarray], cal: list[np.ndarray]
    ) -> list[np.ndarray]:
        """How far ``bank``'s prediction of each record of ``cal`` leaves its range on
        ``train``, per sample (a fold bank measured against its own training range)."""
        rng = self.training_range(bank, train)
        if rng is None:
            return [np.zeros(y.shape[0]) for y in cal]
        return [rng.distance(self.predictions(bank, y)) for y in cal]

    @property
    def active(self) -> bool:
        """Whether it scales at all (a range was learned and the gain is positive)."""
        return self.range_ is not None and self.gain > 0

    def scale(self, bank: Any, y: np.ndarray) -> np.ndarray:
        """``1 + gain · d`` per sample of a record ``y`` ``(T, channels)``."""
        if self.range_ is None or self.gain == 0:
            return np.ones(y.shape[0])
        return novelty_scale(self.range_.distance(self.predictions(bank, y)), self.gain)

    def scale_step(self, y_m: np.ndarray) -> np.ndarray:
        """``1 + gain · d`` of one sample (a 0-d array) from the networks' outputs ``y_m``."""
        assert self.range_ is not None
        return novelty_scale(self.range_.distance(y_m[self.relations]), self.gain)
