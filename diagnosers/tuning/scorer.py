"""Scoring a fitted diagnoser on labelled episodes, for model selection.

:class:`DetectionScorer` is a small, self-contained version of the benchmark's detection metrics
(``evaluation`` holds the full ones; ``diagnosers`` does not import it): the share of faulty
episodes detected, less a penalty for healthy episodes with any alarm beyond a target share, less
a small term for late detection. :func:`diagnosers.tuning.grid_search.grid_search` uses it by default.

For scikit-learn (``GridSearchCV``, ``cross_val_score``) the same score is a scorer,
:func:`make_scorer` (``scoring=diagnosers.make_scorer()``), and every diagnoser's ``score``
method. The protocol (docs: *Tuning with scikit-learn*):

* ``X`` is a list of :class:`~diagnosers.episode.record.Episode`: healthy ones
  (``fault_onset=None``) and faulty ones with their onset (and, for an isolating diagnoser, their
  ``scenario``);
* ``y`` is :func:`episode_labels` of ``X``: 1 for a faulty episode, 0 for a healthy one. With it,
  ``fit(X, y)`` trains a detector on the healthy episodes only (an isolating diagnoser on all of
  them), so every split's training part, and the refit on all of ``X``, stay healthy;
* ``cv=StratifiedKFold(k)`` deals the healthy and the faulty episodes evenly over the folds, so
  each fold is scored on both: its healthy episodes give the false detections, its faulty ones
  the detections and their delays.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from diagnosers.detection import Detection
from diagnosers.episode.record import Episode

__all__ = [
    "SCORER_METRICS",
    "DetectionScorer",
    "EpisodeScorer",
    "check_episode_labels",
    "episode_labels",
    "make_scorer",
]


class Detects(Protocol):
    """What a scorer needs of a fitted diagnoser."""

    def detect(self, episode: Episode) -> Detection: ...


@dataclass(frozen=True)
class DetectionScorer:
    """Episode-level detection score of a fitted diagnoser on validation episodes.

    A faulty episode (``fault_onset`` set) is *detected* when some alarm falls at or after
    its onset; its delay is the samples from the onset to that first alarm, as a share of the
    samples from the onset to the end (1 when missed). A healthy episode (``fault_onset``
    ``None``) is a *false detection* when it has any alarm. The score is::

        true_detection_rate
        − false_alarm_penalty · max(0, false_detection_rate − false_detection_target)
        − delay_weight · mean_delay_share

    with ``true_detection_rate`` over the faulty episodes (0 when there are none) and
    ``false_detection_rate`` over the healthy ones (0 when there are none). The best score
    is 1 (every fault detected at its onset, few enough healthy episodes alarmed).

    Args:
        false_detection_target: the share of healthy episodes with an alarm that costs
            nothing, in [0, 1]; default 0.1.
        false_alarm_penalty: score lost per unit of false-detection rate above the target,
            ≥ 0; default 5.0 (one healthy episode in ten over the target costs half of the
            true-detection rate's range).
        delay_weight: score lost at the largest mean delay share (1), ≥ 0; default 0.1, so
            that it breaks ties between settings that detect alike.

    Calling it returns ``{"score", "true_detection_rate", "false_detection_rate",
    "mean_delay_share"}``.
    """

    false_detection_target: float = 0.1
    false_alarm_penalty: float = 5.0
    delay_weight: float = 0.1

    def __post_init__(self) -> None:
        if not 0.0 <= self.false_detection_target <= 1.0:
            raise ValueError(
                f"false_detection_target={self.false_detection_target!r} is outside the "
                "allowed range [0, 1]"
            )
        for name in ("false_alarm_penalty", "delay_weight"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0.0):
                raise ValueError(f"{name}={value!r} is outside the allowed range [0, inf)")

    def __call__(self, diagnoser: Detects, episodes: Sequence[Episode]) -> dict[str, float]:
        """Detect every episode with the fitted ``diagnoser`` and score (see the class)."""
        detected: list[bool] = []
        delays: list[float] = []
        false_alarms: list[bool] = []
        for ep in episodes:
            alarm = diagnoser.detect(ep).alarm
            if ep.fault_onset is None:
                false_alarms.append(bool(alarm.any()))
                continue
            after = np.flatnonzero(alarm[ep.fault_onset :])
            detected.append(after.size > 0)
            span = max(ep.n_samples - ep.fault_onset, 1)
            delays.append(float(after[0]) / span if after.size else 1.0)
        tdr = float(np.mean(detected)) if detected else 0.0
        fdr = float(np.mean(false_alarms)) if false_alarms else 0.0
        delay = float(np.mean(delays)) if delays else 1.0
        excess = max(0.0, fdr - self.false_detection_target)
        score = tdr - self.false_alarm_penalty * excess - self.delay_weight * delay
        return {
            "score": score,
            "true_detection_rate": tdr,
            "false_detection_rate": fdr,
            "mean_delay_share": delay,
        }


#: What a scikit-learn scorer may report, each higher-is-better as scikit-learn wants: the
#: entries of :class:`DetectionScorer`, with the sign by which each is multiplied (scikit-learn's
#: ``neg_`` names for the two where lower is better).
SCORER_METRICS: dict[str, float] = {
    "score": 1.0,
    "true_detection_rate": 1.0,
    "neg_false_detection_rate": -1.0,
    "neg_mean_delay_share": -1.0,
}


def episode_labels(episodes: Sequence[Episode]) -> np.ndarray:
    """scikit-learn's ``y`` for ``episodes``: 1 for a faulty episode (``fault_onset`` set), 0
    for a healthy one (int8, one per episode).

    >>> import numpy as np, diagnosers
    >>> y = np.zeros((10, 1))
    >>> eps = [diagnosers.Episode(y, channels=("T_rx",), sample_time_s=10.0),
    ...        diagnosers.Episode(y, channels=("T_rx",), sample_time_s=10.0, fault_onset=5)]
    >>> episode_labels(eps).tolist()
    [0, 1]
    """
    return np.array([ep.fault_onset is not None for ep in episodes], dtype=np.int8)


def check_episode_labels(episodes: Sequence[Episode], y: Any) -> None:
    """Refuse a ``y`` that is not :func:`episode_labels` of ``episodes`` (a label is the
    episode's own: a ``y`` that disagrees would train or score on the wrong episodes)."""
    labels = episode_labels(episodes)
    given = np.asarray(y)
    if given.shape != labels.shape or given.dtype.kind not in "biuf":
        raise ValueError(
            f"y must be diagnosers.episode_labels(X): {labels.size} labels, 1 for a faulty "
            f"episode and 0 for a healthy one; got {given.dtype} of shape {given.shape}"
        )
    wrong = np.flatnonzero(given != labels)
    if wrong.size:
        i = int(wrong[0])
        raise ValueError(
            f"y[{i}]={given[i]!r} contradicts episode {i} (seed {episodes[i].seed}, fault_onset="
            f"{episodes[i].fault_onset!r}, label {labels[i]}); pass y=diagnosers.episode_labels(X)"
        )


@dataclass(frozen=True)
class EpisodeScorer:
    """A scikit-learn scorer (``scoring=``): ``scorer(fitted, X, y=None) -> float``.

    Scores the fitted diagnoser on the episodes ``X`` with ``detection`` (a
    :class:`DetectionScorer`) and reports its entry ``metric`` (:data:`SCORER_METRICS`: higher
    is better). ``y``, when given, must be :func:`episode_labels` of ``X``. Build it with
    :func:`make_scorer`.
    """

    detection: DetectionScorer = DetectionScorer()
    metric: str = "score"

    def __post_init__(self) -> None:
        if self.metric not in SCORER_METRICS:
            raise ValueError(
                f"metric={self.metric!r} is not a scorer metric. Allowed: {list(SCORER_METRICS)}"
            )

    def __call__(self, estimator: Detects, X: Sequence[Episode], y: Any = None) -> float:
        episodes = list(X)
        if y is not None:
            check_episode_labels(episodes, y)
        entry = self.metric.removeprefix("neg_")
        return SCORER_METRICS[self.metric] * self.detection(estimator, episodes)[entry]


def make_scorer(metric: str = "score", **params: float) -> EpisodeScorer:
    """The detection score as a scikit-learn scorer, for ``GridSearchCV(..., scoring=...)``.

    Args:
        metric: which entry of :class:`DetectionScorer` to report (:data:`SCORER_METRICS`):
            ``"score"`` (default), ``"true_detection_rate"``, ``"neg_false_detection_rate"``
            or ``"neg_mean_delay_share"``.
        **params: :class:`DetectionScorer`'s settings (``false_detection_target``,
            ``false_alarm_penalty``, ``delay_weight``).

    >>> make_scorer(false_detection_target=0.25).detection.false_detection_target
    0.25
    """
    fields = [f.name for f in dataclasses.fields(DetectionScorer)]
    unknown = sorted(set(params) - set(fields))
    if unknown:
        raise ValueError(f"Unknown scorer setting(s) {unknown}. Allowed: {fields}")
    return EpisodeScorer(DetectionScorer(**params), metric)
