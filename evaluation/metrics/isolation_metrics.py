"""Fault-isolation performance indexes (after DAMADICS and the DX competitions); pure functions.

They score one episode's per-sample diagnosis (``(T,)`` str array as in
:attr:`diagnosers.Detection.diagnosis`): a fault class, ``"unknown"``, or ``""`` while the
diagnoser is not alarmed. An alarmed sample is one whose diagnosis is not ``""``. ``truth`` is
the fault's label: the fault class, or ``"unknown"`` for a fault the diagnoser was not trained on
(then calling it ``"unknown"`` is the right answer). Windows start at the fault onset ``t_from``
and end at the episode's horizon ``t_hor = len(diagnosis)``.

* :func:`t_it` - isolation time: samples from ``t_from`` to the first sample ``k`` from which the
  right label holds for ``persistence`` samples in a row (``[k, k + persistence)``, cut at the
  horizon; ``persistence=None``: until the horizon). ``nan`` when that never happens.
* :func:`r_ti` - true isolation rate: share of ``[t_from, t_hor)`` with the right label.
* :func:`r_fi` - false isolation rate: share of ``[t_from, t_hor)`` with a *wrong fault* label
  (neither the right label, nor ``""``, nor ``"unknown"``; for an unknown fault every fault label
  is wrong).
* :func:`cdr` - correct diagnosis rate: share of the alarmed samples of ``[t_from, t_hor)`` with
  the right label (``nan`` when none is alarmed). For an unknown fault it is the share of its
  alarmed samples called ``"unknown"``.
* :func:`episode_label` - the episode's diagnosis: the most frequent label among the alarmed
  samples of ``[t_from, t_hor)`` (ties: the alphabetically first), ``"missed"`` when none is
  alarmed. :func:`confusion_matrix` counts true labels against these.

Relations (property-tested): ``r_ti = r_td · cdr`` when some sample is alarmed, ``t_it >= t_dt``,
``r_ti + r_fi <= r_td``.

>>> import numpy as np
>>> d = np.array(["", "", "f2", "f1", "f1", "f1"])
>>> t_it(d, "f1", t_from=1, persistence=2), r_ti(d, "f1", 1), r_fi(d, "f1", 1), cdr(d, "f1", 1)
(2.0, 0.6, 0.2, 0.75)
>>> episode_label(d, t_from=1)
'f1'
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Sequence

import numpy as np

from evaluation.metrics.detection_metrics import check_sample_index

__all__ = [
    "DEFAULT_PERSISTENCE",
    "MISSED",
    "NONE",
    "UNKNOWN",
    "cdr",
    "confusion_matrix",
    "episode_label",
    "isolation_scores",
    "r_fi",
    "r_ti",
    "t_it",
]

#: no diagnosis (not alarmed)
NONE = ""
#: alarmed, but none of the trained fault classes fits
UNKNOWN = "unknown"
#: the episode label of a fault that was never alarmed on
MISSED = "missed"
#: samples the right label must hold for :func:`t_it` (100 samples = 1000 s at 10 s)
DEFAULT_PERSISTENCE = 100


def _check_diagnosis(diagnosis: np.ndarray) -> np.ndarray:
    d = np.asarray(diagnosis)
    if d.dtype.kind != "U":
        raise ValueError(
            f"diagnosis must be a string array (one label per sample, '' = no diagnosis), got "
            f"dtype {d.dtype}"
        )
    if d.ndim != 1:
        raise ValueError(f"diagnosis must be 1-D (one label per sample), got shape {d.shape}")
    if d.size == 0:
        raise ValueError("diagnosis is empty; an episode needs at least one sample")
    return d


def _check_truth(truth: object) -> str:
    if not isinstance(truth, str) or truth in (NONE, MISSED):
        raise ValueError(
            f"truth must be a fault label or {UNKNOWN!r} (not '' or {MISSED!r}), got {truth!r}"
        )
    return truth


def _window(diagnosis: np.ndarray, t_from: object) -> np.ndarray:
    d = _check_diagnosis(diagnosis)
    t = check_sample_index("t_from", t_from)
    if not 0 <= t < d.size:
        raise ValueError(f"t_from={t} outside the allowed range 0 <= t_from < {d.size} (t_hor)")
    return d[t:]


def t_it(
    diagnosis: np.ndarray,
    truth: str,
    t_from: int,
    persistence: int | None = DEFAULT_PERSISTENCE,
) -> float:
    """Isolation time [samples]: from ``t_from`` to the first sample from which ``truth`` holds.

    Args:
        diagnosis: str, shape ``(t_hor,)``.
        truth: the right label (fault class or ``"unknown"``).
        t_from: fault onset, ``0 <= t_from < t_hor``.
        persistence: samples in a row the label must hold (``>= 1``; cut at the horizon, so a
            correct run that reaches the end counts), or ``None``: until the horizon.

    Returns:
        Delay in samples, ``nan`` when the right label never holds long enough.
    """
    w = _window(diagnosis, t_from) == _check_truth(truth)
    if persistence is not None:
        persistence = check_sample_index("persistence", persistence)
        if persistence < 1:
            raise ValueError(f"persistence={persistence} outside the allowed range >= 1 (or None)")
    n = w.size
    # run[k]: length of the run of right labels starting at k (0 where wrong)
    run = np.zeros(n + 1, dtype=np.int64)
    for k in range(n - 1, -1, -1):
        run[k] = run[k + 1] + 1 if w[k] else 0
    need = np.arange(n, 0, -1) if persistence is None else np.minimum(persistence, n - np.arange(n))
    hits = np.flatnonzero(run[:n] >= need)
    return float(hits[0]) if hits.size else float("nan")


def r_ti(diagnosis: np.ndarray, truth: str, t_from: int) -> float:
    """True isolation rate: share of ``[t_from, t_hor)`` diagnosed ``truth``."""
    w = _window(diagnosis, t_from)
    return float(np.count_nonzero(w == _check_truth(truth)) / w.size)


def r_fi(diagnosis: np.ndarray, truth: str, t_from: int) -> float:
    """False isolation rate: share of ``[t_from, t_hor)`` given a wrong fault label."""
    w = _window(diagnosis, t_from)
    truth = _check_truth(truth)
    wrong = (w != truth) & (w != NONE) & (w != UNKNOWN)
    return float(np.count_nonzero(wrong) / w.size)


def cdr(diagnosis: np.ndarray, truth: str, t_from: int) -> float:
    """Correct diagnosis rate: share of the alarmed samples of ``[t_from, t_hor)`` diagnosed
    ``truth``; ``nan`` when none is alarmed."""
    w = _window(diagnosis, t_from)
    truth = _check_truth(truth)
    alarmed = np.count_nonzero(w != NONE)
    return float(np.count_nonzero(w == truth) / alarmed) if alarmed else float("nan")


def episode_label(diagnosis: np.ndarray, t_from: int) -> str:
    """Majority label of the alarmed samples of ``[t_from, t_hor)``; ``"missed"`` if none."""
    w = _window(diagnosis, t_from)
    counts = Counter(str(x) for x in w[w != NONE])
    if not counts:
        return MISSED
    top = max(counts.values())
    return min(k for k, v in counts.items() if v == top)


def isolation_scores(
    diagnosis: np.ndarray,
    truth: str,
    fault_onset: int,
    persistence: int | None = DEFAULT_PERSISTENCE,
) -> dict[str, float | str]:
    """All indexes of one faulty episode: ``t_it``, ``r_ti``, ``r_fi``, ``cdr``, ``label``."""
    return {
        "t_it": t_it(diagnosis, truth, fault_onset, persistence),
        "r_ti": r_ti(diagnosis, truth, fault_onset),
        "r_fi": r_fi(diagnosis, truth, fault_onset),
        "cdr": cdr(diagnosis, truth, fault_onset),
        "label": episode_label(diagnosis, fault_onset),
    }


def confusion_matrix(
    truths: Sequence[str], labels: Sequence[str], classes: Sequence[str] | None = None
) -> tuple[list[str], list[str], np.ndarray]:
    """Counts of episodes by true label (rows) and episode diagnosis (columns).

    Args:
        truths: true label of each episode (fault class or ``"unknown"``).
        labels: :func:`episode_label` of each episode.
        classes: the diagnoser's fault classes (row and column order); default: the sorted
            labels seen. ``"unknown"`` and ``"missed"`` columns always come last.

    Returns:
        ``(row names, column names, counts (rows, columns) int)``.
    """
    truths, labels = list(truths), list(labels)
    if len(truths) != len(labels):
        raise ValueError(
            f"truths and labels must have one entry per episode; got {len(truths)} and "
            f"{len(labels)}"
        )
    for t in truths:
        _check_truth(t)
    special = (UNKNOWN, MISSED)
    if classes is None:
        classes = sorted({x for x in (*truths, *labels) if x not in special})
    classes = list(classes)
    rows = classes + sorted({t for t in truths if t not in classes})
    cols = classes + sorted({x for x in labels if x not in classes and x not in special})
    cols += list(special)
    counts = np.zeros((len(rows), len(cols)), dtype=np.int64)
    for t, lab in zip(truths, labels, strict=True):
        if lab == NONE:
            raise ValueError("an episode label is '' (use episode_label: 'missed' when no alarm)")
        counts[rows.index(t), cols.index(lab)] += 1
    return rows, cols, counts


def nanmean(values: Sequence[float]) -> float:
    """Mean of the finite values (``nan`` when there are none): for per-episode index lists."""
    v = [x for x in values if not math.isnan(x)]
    return float(np.mean(v)) if v else float("nan")
