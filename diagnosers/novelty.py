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

__all__ = ["NoveltyScaled", "PredictionRange", "exogenous_relations", "novelty_scale"]


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


class NoveltyScaled:
    """The novelty of a bank diagnoser's records, for ``lrgf-glr`` (its networks ``lrgf_`` with
    inputs ``in_idx_``, ``steady_window``, the hyperparameter ``novelty_gain``; the learned
    ``novelty_relations_`` and ``prediction_range_``)."""

    lrgf_: list[Any]
    in_idx_: list[np.ndarray]
    steady_window: int
    novelty_gain: float
    novelty_relations_: np.ndarray
    prediction_range_: PredictionRange | None

    def _exogenous_predictions(self, y: np.ndarray) -> np.ndarray:
        """The current networks' outputs ``(T, c)`` of the relations with exogenous inputs."""
        cols = [self.lrgf_[j].predict(y[:, self.in_idx_[j]])[:, 0] for j in self.novelty_relations_]
        return np.column_stack(cols) if cols else np.zeros((y.shape[0], 0))

    def _prediction_range(self, train: list[np.ndarray]) -> PredictionRange | None:
        """The current networks' range on their training records (None: no such relation)."""
        if not len(self.novelty_relations_):
            return None
        w = self.steady_window
        return PredictionRange.of([self._exogenous_predictions(y)[w:] for y in train])

    def _novelty_records(self, train: list[np.ndarray], cal: list[np.ndarray]) -> list[np.ndarray]:
        """How far the current networks' prediction of each record of ``cal`` leaves their
        range on ``train``, per sample."""
        rng = self._prediction_range(train)
        if rng is None:
            return [np.zeros(y.shape[0]) for y in cal]
        return [rng.distance(self._exogenous_predictions(y)) for y in cal]

    def _scale_of(self, y: np.ndarray) -> np.ndarray:
        """``1 + novelty_gain · d`` per sample of a record ``y`` ``(T, channels)``."""
        if getattr(self, "prediction_range_", None) is None or self.novelty_gain == 0:
            return np.ones(y.shape[0])
        d = self.prediction_range_.distance(self._exogenous_predictions(y))
        return novelty_scale(d, self.novelty_gain)
