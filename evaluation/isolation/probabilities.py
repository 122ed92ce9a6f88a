"""The isolation study's probability scores: each isolator's posterior, its Brier score per
episode and its reliability curve pooled over episodes (issue 42 item 5).

Which posterior (:func:`posteriors`): a probabilistic isolator's own
(:attr:`~diagnosers.Detection.posterior`); a hard isolator's implied by its decision
(:func:`~evaluation.metrics.probability_metrics.decision_posterior`); and for an isolator whose
class scores are log-probabilities up to a constant (``lrgf-lda``: LDA's discriminant
``−d²/2 + log prior``, smoothed over the alarm), also their softmax while alarmed.

Which samples (:func:`episode_truth`): a faulty episode from its onset, its fault the truth
(when the fault is one of the isolator's classes; an unknown fault has no true hypothesis and
is not scored); a healthy episode whole, ``"nominal"`` the truth.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from diagnosers.detection import Detection
from diagnosers.episode.record import Episode
from evaluation.metrics.probability_metrics import (
    NOMINAL,
    brier_samples,
    decision_posterior,
    reliability_curve,
)

__all__ = [
    "SOFTMAX_ISOLATORS",
    "ProbabilityScores",
    "episode_truth",
    "posteriors",
]

#: isolators whose class scores are log-probabilities up to a constant (their softmax is a
#: posterior over the classes)
SOFTMAX_ISOLATORS = ("lrgf-lda",)


def episode_truth(ep: Episode, classes: Sequence[str]) -> tuple[str, int] | None:
    """``(true hypothesis, first sample scored)`` of ``ep``; None for an unknown fault."""
    if ep.fault_onset is None:
        return NOMINAL, 0
    if ep.scenario in classes:
        return ep.scenario, ep.fault_onset
    return None


def _softmax_posterior(det: Detection) -> np.ndarray:
    """Nominal while not alarmed; the softmax of the class scores while alarmed."""
    assert det.class_scores is not None
    T, C = det.class_scores.shape
    post = np.zeros((T, C + 1))
    post[~det.alarm, 0] = 1.0
    s = det.class_scores[det.alarm]
    e = np.exp(s - np.max(s, axis=1, keepdims=True))
    post[det.alarm, 1:] = e / np.sum(e, axis=1, keepdims=True)
    return post


def posteriors(name: str, det: Detection) -> dict[str, tuple[np.ndarray, tuple[str, ...]]]:
    """The posteriors scored for isolator ``name``'s detection: ``{kind: (posterior, names)}``
    with kinds ``"own"``, ``"decision"`` and (:data:`SOFTMAX_ISOLATORS`) ``"softmax"``."""
    if det.posterior is not None:
        return {"own": (det.posterior, det.hypothesis_names)}
    assert det.diagnosis is not None
    out = {"decision": decision_posterior(det.diagnosis, det.class_names)}
    if name in SOFTMAX_ISOLATORS and det.class_scores is not None:
        out["softmax"] = (_softmax_posterior(det), (NOMINAL, *det.class_names))
    return out


class ProbabilityScores:
    """Brier scores per episode and the pooled reliability pairs of one isolator."""

    def __init__(self, name: str) -> None:
        self.name = name
        self.rows: list[dict[str, Any]] = []
        self._pairs: dict[str, list[tuple[np.ndarray, np.ndarray]]] = {}

    def add(self, ep: Episode, det: Detection, classes: Sequence[str]) -> None:
        truth = episode_truth(ep, classes)
        if truth is None:
            return
        label, t_from = truth
        row: dict[str, Any] = {
            "scenario": ep.scenario,
            "seed": ep.seed,
            "healthy": ep.fault_onset is None,
        }
        for kind, (post, names) in posteriors(self.name, det).items():
            row[f"brier_{kind}"] = float(np.mean(brier_samples(post, names, label, t_from)))
            onehot = np.asarray(names) == label
            p = post[t_from:]
            self._pairs.setdefault(kind, []).append((p, np.broadcast_to(onehot, p.shape)))
        row["n_samples"] = det.alarm.shape[0] - t_from
        self.rows.append(row)

    def kinds(self) -> list[str]:
        return list(self._pairs)

    def curve(self, kind: str, n_bins: int = 10) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The reliability curve of posterior ``kind``, pooled over episodes and hypotheses."""
        p = np.concatenate([a.ravel() for a, _ in self._pairs[kind]])
        o = np.concatenate([b.ravel() for _, b in self._pairs[kind]])
        return reliability_curve(np.clip(p, 0.0, 1.0), o, n_bins)

    def pooled(self, kind: str, healthy: bool) -> float:
        """The Brier score of posterior ``kind`` pooled over the samples of the faulty
        (``healthy=False``) or healthy episodes; NaN without any."""
        rs = [r for r in self.rows if r["healthy"] == healthy]
        n = sum(r["n_samples"] for r in rs)
        return sum(r[f"brier_{kind}"] * r["n_samples"] for r in rs) / n if n else float("nan")
