"""Issue 45 item 6: scikit-learn's ``GridSearchCV`` on a diagnoser.

The protocol (``diagnosers.tuning.scorer``): ``X`` a list of episodes, ``y = episode_labels(X)``;
``fit(X, y)`` trains a detector on the healthy episodes only; ``StratifiedKFold`` deals both
kinds over the folds; ``scoring=make_scorer(...)`` is :class:`DetectionScorer` on each fold.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from sklearn.base import is_classifier
from sklearn.model_selection import GridSearchCV, StratifiedKFold, cross_val_score
from sklearn.utils import get_tags

import diagnosers
import fcc_env
from diagnosers import Episode
from diagnosers.tuning.scorer import SCORER_METRICS, DetectionScorer, EpisodeScorer

ROOT = Path(__file__).resolve().parents[2]
N = 900


@pytest.fixture(scope="module")
def labelled() -> tuple[list[Episode], np.ndarray]:
    f1 = fcc_env.FaultSpec(scenario="f1", onset=N // 2)
    healthy = Episode.from_batch(fcc_env.simulate_episodes(range(5000, 5006), N))
    faulty = Episode.from_batch(fcc_env.simulate_episodes(range(5006, 5009), N, fault=f1))
    X = healthy + faulty
    return X, diagnosers.episode_labels(X)


def _split_scores(search: GridSearchCV, n_splits: int) -> np.ndarray:
    r = search.cv_results_
    return np.array([r[f"split{k}_test_score"] for k in range(n_splits)]).T


@pytest.mark.parametrize(("name", "grid"), [("limits", [1e-3, 1e-2]), ("pca", [1e-4, 1e-2])])
def test_grid_search_cv_on_a_registered_diagnoser_scores_each_fold_as_by_hand(
    name: str, grid: list[float], labelled
) -> None:
    X, y = labelled
    scorer = diagnosers.make_scorer(false_detection_target=0.25)
    cv = StratifiedKFold(n_splits=3)
    search = GridSearchCV(
        diagnosers.make(name), {"alpha": grid}, scoring=scorer, cv=cv, error_score="raise"
    )
    search.fit(X, y)
    # by hand: fit on the healthy part of each split's training episodes, score its test fold
    expected = np.empty((len(grid), 3))
    for k, (train, test) in enumerate(cv.split(X, y)):
        healthy = [X[i] for i in train if y[i] == 0]
        for j, alpha in enumerate(grid):
            d = diagnosers.make(name, alpha=alpha).fit(healthy)
            expected[j, k] = DetectionScorer(0.25)(d, [X[i] for i in test])["score"]
    np.testing.assert_array_equal(_split_scores(search, 3), expected)
    assert search.best_params_ == {"alpha": grid[int(np.argmax(expected.mean(axis=1)))]}
    # the refit trains on the healthy episodes of X only
    refit = diagnosers.make(name, **search.best_params_).fit(X[:6])  # the healthy ones
    for ep in X:
        np.testing.assert_array_equal(
            search.best_estimator_.detect(ep).alarm, refit.detect(ep).alarm
        )


def test_grid_search_cv_on_an_lrgf_detector_with_fast_params(labelled) -> None:
    X, y = labelled
    cls = diagnosers.diagnoser_class("lrgf-glr")
    search = GridSearchCV(
        cls(**{**cls.fast_params(), "n_jobs": 1}),
        {"on_delay": [1, 3]},
        scoring=diagnosers.make_scorer(),
        cv=StratifiedKFold(n_splits=2),
        error_score="raise",
    )
    search.fit(X[:4] + X[6:8], y[:4].tolist() + y[6:8].tolist())
    assert np.isfinite(search.cv_results_["mean_test_score"]).all()
    search.best_estimator_.check_is_fitted()


def test_without_scoring_the_diagnosers_score_is_used(labelled) -> None:
    X, y = labelled
    d = diagnosers.make("limits", alpha=1e-3).fit(X[:4])
    assert d.score(X) == diagnosers.make_scorer()(d, X) == DetectionScorer()(d, X)["score"]
    cv = StratifiedKFold(n_splits=3)
    default = cross_val_score(diagnosers.make("limits"), X, y, cv=cv)
    explicit = cross_val_score(diagnosers.make("limits"), X, y, cv=cv, scoring=EpisodeScorer())
    np.testing.assert_array_equal(default, explicit)


def test_scorer_metrics_are_detection_scorer_entries_higher_is_better(labelled) -> None:
    X, _ = labelled
    d = diagnosers.make("limits", alpha=1e-2).fit(X[:4])
    entries = DetectionScorer()(d, X)
    for metric, sign in SCORER_METRICS.items():
        value = diagnosers.make_scorer(metric)(d, X)
        assert value == sign * entries[metric.removeprefix("neg_")], metric
    assert diagnosers.make_scorer("neg_false_detection_rate")(d, X) <= 0.0
    with pytest.raises(ValueError, match=r"metric='f1' is not a scorer metric\. Allowed: \["):
        diagnosers.make_scorer("f1")
    with pytest.raises(ValueError, match=r"Unknown scorer setting\(s\) \['penalty'\]"):
        diagnosers.make_scorer(penalty=2.0)
    with pytest.raises(ValueError, match=r"false_detection_target=2\.0 is outside"):
        diagnosers.make_scorer(false_detection_target=2.0)


def test_fit_with_labels_trains_a_detector_on_the_healthy_episodes_only(labelled) -> None:
    X, y = labelled
    with_labels = diagnosers.make("limits").fit(X, y)
    healthy_only = diagnosers.make("limits").fit(X[:6])
    everything = diagnosers.make("limits").fit(X)
    assert with_labels.get_params() == healthy_only.get_params()
    for ep in X:
        np.testing.assert_array_equal(with_labels.detect(ep).upper, healthy_only.detect(ep).upper)
    assert not np.array_equal(everything.detect(X[0]).upper, healthy_only.detect(X[0]).upper)
    # labels may be a list, bools or ints; an object array of episodes is a list of them
    diagnosers.make("limits").fit(np.array(X, dtype=object), [bool(v) for v in y])


def test_labels_that_contradict_the_episodes_are_refused_by_name(labelled) -> None:
    X, y = labelled
    flipped = y.copy()
    flipped[7] = 0
    with pytest.raises(
        ValueError, match=r"y\[7\]=.*contradicts episode 7 \(seed 5007, fault_onset=450"
    ):
        diagnosers.make("limits").fit(X, flipped)
    with pytest.raises(ValueError, match=r"9 labels, 1 for a faulty episode.*shape \(8,\)"):
        diagnosers.make("limits").fit(X, y[:8])
    with pytest.raises(ValueError, match="9 labels"):
        diagnosers.make("limits").fit(X, ["nominal"] * 6 + ["f1"] * 3)
    with pytest.raises(ValueError, match=r"y marks none of the 3 episodes healthy"):
        diagnosers.make("limits").fit(X[6:], y[6:])
    d = diagnosers.make("limits").fit(X[:6])
    with pytest.raises(ValueError, match=r"contradicts episode 0"):
        diagnosers.make_scorer()(d, X, 1 - y)


def test_estimator_tags_say_neither_classifier_nor_regressor() -> None:
    d = diagnosers.make("pca")
    tags = get_tags(d)
    assert tags.estimator_type is None and not is_classifier(d)
    assert tags.target_tags.required is False


def test_the_documented_cross_validation_example_runs_as_written() -> None:
    text = (ROOT / "docs" / "diagnosers.md").read_text()
    section = text.split("### Cross-validation with `GridSearchCV`", 1)[1].split("\n### ", 1)[0]
    [code] = re.findall(r"```python\n(.*?)```", section, flags=re.S)
    namespace: dict[str, object] = {"__name__": "docs_example"}
    exec(compile(code, "docs/diagnosers.md cross-validation example", "exec"), namespace)
    search = namespace["cv_search"]
    assert search.best_params_ == {"alpha": 1e-5}  # type: ignore[attr-defined]
    assert len(search.cv_results_["params"]) == 3  # type: ignore[attr-defined]
    namespace["best"].check_is_fitted()  # type: ignore[attr-defined]
