"""Hyperparameter search in the style of scikit-learn's ``GridSearchCV``: :func:`grid_search`.

Every combination of a parameter grid (:class:`sklearn.model_selection.ParameterGrid`) is set on
a clone (:func:`sklearn.base.clone`) of the diagnoser, fitted on the healthy training episodes
and scored on validation episodes (healthy and faulty). There is no cross-validation: the
validation episodes are a held-out set, and the best candidate, already fitted on all of
``train``, is returned as it is (no refit). scikit-learn is needed only when
:func:`grid_search` runs (``pip install scikit-learn``, or the package's ``test`` extra).

The default scorer is :class:`diagnosers.tuning.scorer.DetectionScorer` (the share of faulty episodes
detected, less penalties for false detections and late detection). scikit-learn's own
``GridSearchCV`` works on a diagnoser too, with cross-validation: ``scoring=``
:func:`diagnosers.tuning.scorer.make_scorer` and ``y=`` :func:`diagnosers.tuning.scorer.episode_labels`
(the protocol is in :mod:`diagnosers.tuning.scorer`).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from diagnosers.contract import DiagnoserContract
from diagnosers.episode.record import Episode
from diagnosers.tuning.scorer import DetectionScorer

__all__ = ["DetectionScorer", "Scorer", "SearchResult", "grid_search"]

#: a scorer: ``scorer(fitted_diagnoser, validation_episodes)``, higher is better; a float or a
#: mapping with a ``"score"`` entry (the other entries go to the results table)
Scorer = Callable[[DiagnoserContract, Sequence[Episode]], float | Mapping[str, float]]


def _sklearn() -> tuple[Any, Any]:
    """``(clone, ParameterGrid)`` from scikit-learn, or an ImportError that says how to get it."""
    try:
        from sklearn.base import clone
        from sklearn.model_selection import ParameterGrid
    except ImportError as e:
        raise ImportError(
            "diagnosers.tuning.grid_search.grid_search needs scikit-learn (>= 1.4), which is not "
            "installed: pip install scikit-learn (or the package's 'test' extra, "
            "pip install 'fcc-fault-diagnosis[test]')"
        ) from e
    return clone, ParameterGrid


@dataclass(frozen=True)
class SearchResult:
    """What :func:`grid_search` found.

    ``results`` has one row (a dict) per grid point, in the grid's order: ``"params"`` (the
    hyperparameters set on the clone), ``"score"``, the scorer's other entries, ``"fit_time_s"``
    and ``"rank"`` (1 = best; ties share the lower rank, as ``GridSearchCV``'s
    ``rank_test_score``). ``best_diagnoser`` is the fitted clone of the first row of rank 1.
    """

    results: list[dict[str, Any]]
    best_params: dict[str, Any]
    best_score: float
    best_diagnoser: DiagnoserContract


def _as_scores(value: float | Mapping[str, float]) -> dict[str, float]:
    if isinstance(value, Mapping):
        if "score" not in value:
            raise ValueError(
                f"a scorer that returns a mapping must include a 'score' entry; got keys "
                f"{sorted(value)}"
            )
        return {k: float(v) for k, v in value.items()}
    return {"score": float(value)}


def grid_search(
    diagnoser: DiagnoserContract,
    param_grid: Mapping[str, Sequence[Any]] | Sequence[Mapping[str, Sequence[Any]]],
    train: Iterable[Episode],
    validation: Iterable[Episode],
    *,
    scorer: Scorer | None = None,
) -> SearchResult:
    """Fit a clone of ``diagnoser`` per point of ``param_grid``; keep the best on ``validation``.

    Args:
        diagnoser: an unfitted (or fitted: it is cloned, never changed) diagnoser whose other
            hyperparameters every candidate keeps.
        param_grid: ``{name: [values...]}`` or a list of such grids, as for
            :class:`sklearn.model_selection.ParameterGrid`; names are checked against the
            diagnoser's hyperparameters before anything is fitted.
        train: the episodes every candidate is fitted on (healthy ones; an isolating
            diagnoser also labelled faulty ones).
        validation: the episodes it is scored on: faulty (``fault_onset`` set) and healthy.
        scorer: ``scorer(fitted, validation) -> float | {"score": ..., ...}``, higher is
            better; default :class:`DetectionScorer()`.

    Returns:
        A :class:`SearchResult`: the table of every candidate, the best parameters, score and
        fitted diagnoser.

    Raises:
        ImportError: scikit-learn is not installed (the message says how to install it).
        ValueError: an unknown hyperparameter name, an empty grid, or no episodes.
    """
    clone, parameter_grid = _sklearn()
    grid = list(parameter_grid(param_grid))
    if not grid:
        raise ValueError(f"param_grid={param_grid!r} has no point: give at least one value")
    for point in grid:
        diagnoser.check_param_names(point)
    train, validation = list(train), list(validation)
    if not train or not validation:
        raise ValueError(
            f"grid_search needs training and validation episodes, got {len(train)} and "
            f"{len(validation)}"
        )
    score_with = DetectionScorer() if scorer is None else scorer
    rows: list[dict[str, Any]] = []
    best: tuple[float, int, DiagnoserContract] | None = None
    for i, point in enumerate(grid):
        candidate = clone(diagnoser).set_params(**point)
        start = time.perf_counter()
        candidate.fit(train)
        fit_time = time.perf_counter() - start
        scores = _as_scores(score_with(candidate, validation))
        rows.append({"params": dict(point), **scores, "fit_time_s": fit_time})
        # strictly greater: the first of equal scores wins, as in GridSearchCV; NaN never wins
        if best is None or scores["score"] > best[0] or np.isnan(best[0]):
            best = (scores["score"], i, candidate)
    assert best is not None
    for row in rows:
        row["rank"] = 1 + sum(other["score"] > row["score"] for other in rows)
    score, index, fitted = best
    return SearchResult(rows, dict(grid[index]), score, fitted)
