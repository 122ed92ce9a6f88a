"""How good a diagnoser's probabilities are: the Brier score and the reliability curve; pure.

A probabilistic diagnoser (``mmae``) gives a posterior per sample over its hypotheses
(:attr:`diagnosers.Detection.posterior`, ``(T, H)``, the healthy one named ``"nominal"``).

**Which samples count.** The true hypothesis of sample k of an episode is ``"nominal"`` before
the fault onset (and throughout a healthy episode) and the fault's class from the onset on. The
functions take the window ``[t_from, t_hor)`` and one truth for it: the isolation study scores
a faulty episode from its onset (``t_from = onset``, truth its fault) and a healthy episode
whole (``t_from = 0``, truth ``"nominal"``), and reports the two apart and pooled over samples.
A fault that is none of the hypotheses (an unknown fault) has no true hypothesis: it is not
scored.

* :func:`brier_samples` / :func:`brier_score`: the multi-class Brier score of each sample,
  ``Σ_h (p_h − o_h)²`` with ``o`` the one-hot truth (0 perfect, 2 sure and wrong; a uniform
  posterior over H scores ``1 − 1/H``), and its mean over the window.
* :func:`reliability_curve`: the calibration of one-vs-rest probabilities: bins of predicted
  probability, the mean prediction and the observed frequency in each (a calibrated diagnoser
  lies on the diagonal).
* :func:`decision_posterior`: the posterior a diagnoser *without* one implies by its decision
  (nominal while not alarmed, its diagnosis when alarmed, ``"unknown"`` uniform over the
  faults), so a hard isolator's Brier score can stand beside a probabilistic one's.

>>> import numpy as np
>>> post = np.array([[0.9, 0.1], [0.2, 0.8], [0.5, 0.5]])
>>> brier_samples(post, ("nominal", "f1"), "f1", t_from=1).round(4).tolist()
[0.08, 0.5]
>>> round(brier_score(post, ("nominal", "f1"), "nominal"), 4)
0.6
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from evaluation.metrics.detection_metrics import check_sample_index

__all__ = [
    "NOMINAL",
    "brier_samples",
    "brier_score",
    "decision_posterior",
    "reliability_curve",
]

#: the healthy hypothesis's name (fcc_env's healthy scenario)
NOMINAL = "nominal"


def _check_posterior(posterior: np.ndarray, names: Sequence[str]) -> np.ndarray:
    p = np.asarray(posterior, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != len(names) or p.shape[0] == 0:
        raise ValueError(
            f"posterior must have shape (n_samples >= 1, {len(names)}) for hypotheses "
            f"{tuple(names)}, got {p.shape}"
        )
    if not np.all(np.isfinite(p)) or np.any(p < 0) or not np.allclose(p.sum(axis=1), 1.0):
        raise ValueError("posterior rows must be finite probabilities summing to 1")
    return p


def brier_samples(
    posterior: np.ndarray, names: Sequence[str], truth: str, t_from: int = 0
) -> np.ndarray:
    """Per-sample multi-class Brier score ``Σ_h (p_h − o_h)²`` of ``[t_from, t_hor)``.

    Args:
        posterior: ``(t_hor, H)`` probabilities, rows summing to 1.
        names: the H hypotheses' names (the columns).
        truth: the true hypothesis over the window, one of ``names``.
        t_from: first sample scored, ``0 <= t_from < t_hor``.
    """
    p = _check_posterior(posterior, names)
    if truth not in names:
        raise ValueError(f"truth {truth!r} is not one of the hypotheses {tuple(names)}")
    t = check_sample_index("t_from", t_from)
    if not 0 <= t < p.shape[0]:
        raise ValueError(f"t_from={t} outside the allowed range 0 <= t_from < {p.shape[0]}")
    onehot = np.zeros(len(names))
    onehot[list(names).index(truth)] = 1.0
    return np.sum((p[t:] - onehot) ** 2, axis=1)


def brier_score(posterior: np.ndarray, names: Sequence[str], truth: str, t_from: int = 0) -> float:
    """Mean of :func:`brier_samples` over ``[t_from, t_hor)``: 0 perfect, 2 worst."""
    return float(np.mean(brier_samples(posterior, names, truth, t_from)))


def reliability_curve(
    probabilities: np.ndarray, outcomes: np.ndarray, n_bins: int = 10
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The reliability (calibration) curve of predictions ``probabilities`` of events
    ``outcomes`` (same shape, bool), in ``n_bins`` equal bins of [0, 1].

    Returns ``(mean predicted probability, observed frequency, count)`` per bin, NaN where a
    bin is empty. One-vs-rest over a posterior: flatten ``posterior`` and its one-hot truth.
    """
    p = np.asarray(probabilities, dtype=np.float64).ravel()
    o = np.asarray(outcomes).ravel()
    if p.shape != o.shape or o.dtype != np.bool_:
        raise ValueError(
            f"probabilities and outcomes must have one entry each (outcomes bool), got "
            f"{p.shape} and {o.shape} {o.dtype}"
        )
    if np.any((p < 0) | (p > 1)) or not np.all(np.isfinite(p)):
        raise ValueError("probabilities must be finite and in [0, 1]")
    n_bins = check_sample_index("n_bins", n_bins)
    if n_bins < 1:
        raise ValueError(f"n_bins={n_bins} outside the allowed range >= 1")
    idx = np.minimum((p * n_bins).astype(np.int64), n_bins - 1)
    count = np.bincount(idx, minlength=n_bins)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean_p = np.bincount(idx, weights=p, minlength=n_bins) / count
        freq = np.bincount(idx, weights=o.astype(np.float64), minlength=n_bins) / count
    return mean_p, freq, count


def decision_posterior(
    diagnosis: np.ndarray, class_names: Sequence[str], unknown: str = "unknown"
) -> tuple[np.ndarray, tuple[str, ...]]:
    """The posterior a hard decision implies: ``(posterior (T, 1 + C), names)``.

    Not alarmed (``""``): nominal with probability 1; a class: that class with probability 1;
    ``unknown``: uniform over the C classes (it names none of them).
    """
    d = np.asarray(diagnosis)
    names = (NOMINAL, *class_names)
    post = np.zeros((d.shape[0], len(names)))
    post[d == "", 0] = 1.0
    for j, c in enumerate(class_names):
        post[d == c, j + 1] = 1.0
    if class_names:
        post[d == unknown, 1:] = 1.0 / len(class_names)
    odd = np.flatnonzero(post.sum(axis=1) == 0)
    if odd.size:
        raise ValueError(
            f"diagnosis {str(d[odd[0]])!r} (sample {odd[0]}) is neither '', {unknown!r} nor one of "
            f"{tuple(class_names)}"
        )
    return post, names
