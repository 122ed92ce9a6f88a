"""What a diagnoser says: a :class:`Decision` per sample, a :class:`Detection` per episode.

An isolating diagnoser also names the fault class it diagnoses: one of its trained classes,
:data:`UNKNOWN`, or :data:`NO_DIAGNOSIS` while not alarmed.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["NO_DIAGNOSIS", "UNKNOWN", "Decision", "Detection"]

#: The diagnosis of an isolating diagnoser that is alarmed but fits none of its fault classes.
UNKNOWN = "unknown"
#: The diagnosis while not alarmed (no diagnosis).
NO_DIAGNOSIS = ""


@dataclass(frozen=True)
class Decision:
    """What a diagnoser says about one sample.

    ``signal`` is what the diagnoser checks (a measured output for band detectors, a statistic such
    as Hotelling's T² for others), ``lower``/``upper`` the limits it checks it against
    (``-inf``/``inf`` when one-sided), ``residual`` the model residual (measured − predicted)
    where there is a model. All arrays have one entry per monitored quantity, named by
    :attr:`diagnosers.Diagnoser.signal_names_`.
    """

    alarm: bool
    signal: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    residual: np.ndarray
    #: isolating diagnosers (:attr:`diagnosers.Diagnoser.isolates`): one of the trained fault classes,
    #: :data:`UNKNOWN`, or :data:`NO_DIAGNOSIS` (``""``) while not alarmed
    diagnosis: str = NO_DIAGNOSIS
    #: isolating diagnosers: a score per class of :attr:`Detection.class_names` (higher = fits
    #: better), ``None`` for a diagnoser that only detects
    class_scores: np.ndarray | None = None


@dataclass(frozen=True)
class Detection:
    """Decisions over a whole episode: each array has a leading time axis of length n_samples.

    An isolating diagnoser also fills ``diagnosis`` (``(T,)`` str: a class of ``class_names``,
    :data:`UNKNOWN`, or ``""`` while not alarmed) and ``class_scores`` (``(T, C)``, one column
    per name of ``class_names``); a detector leaves them ``None`` and ``()``.
    """

    alarm: np.ndarray  # (T,) bool
    signal: np.ndarray  # (T, k)
    lower: np.ndarray  # (T, k)
    upper: np.ndarray  # (T, k)
    residual: np.ndarray  # (T, k)
    signal_names: tuple[str, ...]
    diagnosis: np.ndarray | None = None  # (T,) str, isolating diagnosers only
    class_scores: np.ndarray | None = None  # (T, C), isolating diagnosers only
    class_names: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        n = len(self.alarm)
        if self.diagnosis is not None:
            diag = np.asarray(self.diagnosis, dtype=str)
            if diag.shape != (n,):
                raise ValueError(f"Detection.diagnosis must have shape ({n},), got {diag.shape}")
            object.__setattr__(self, "diagnosis", diag)
        if self.class_scores is not None:
            cs = np.asarray(self.class_scores, dtype=np.float64)
            if cs.shape != (n, len(self.class_names)):
                raise ValueError(
                    f"Detection.class_scores must have shape ({n}, {len(self.class_names)}) for "
                    f"class_names {self.class_names}, got {cs.shape}"
                )
            object.__setattr__(self, "class_scores", cs)

    @property
    def isolates(self) -> bool:
        """Whether the detection carries a diagnosis per sample."""
        return self.diagnosis is not None

    @classmethod
    def from_decisions(
        cls,
        decisions: Sequence[Decision],
        signal_names: tuple[str, ...],
        class_names: tuple[str, ...] | None = None,
    ) -> Detection:
        """Stack per-sample decisions; with ``class_names`` also their diagnoses and scores."""
        iso: dict[str, Any] = {}
        if class_names is not None:
            scores = [d.class_scores for d in decisions]
            iso = {
                "diagnosis": np.array([d.diagnosis for d in decisions], dtype=str).reshape(-1),
                "class_scores": (
                    np.stack(scores).reshape(len(decisions), len(class_names))
                    if all(s is not None for s in scores)
                    else None
                ),
                "class_names": tuple(class_names),
            }
        return cls(
            alarm=np.array([d.alarm for d in decisions], dtype=bool),
            signal=np.stack([d.signal for d in decisions]),
            lower=np.stack([d.lower for d in decisions]),
            upper=np.stack([d.upper for d in decisions]),
            residual=np.stack([d.residual for d in decisions]),
            signal_names=signal_names,
            **iso,
        )

    def decision(self, k: int) -> Decision:
        return Decision(
            alarm=bool(self.alarm[k]),
            signal=self.signal[k],
            lower=self.lower[k],
            upper=self.upper[k],
            residual=self.residual[k],
            diagnosis=NO_DIAGNOSIS if self.diagnosis is None else str(self.diagnosis[k]),
            class_scores=None if self.class_scores is None else self.class_scores[k],
        )
