"""The isolation study's probability scores: which samples count, each isolator's posterior."""

from __future__ import annotations

import numpy as np
import pytest

from diagnosers import Detection, Episode
from evaluation.isolation.probabilities import ProbabilityScores, episode_truth, posteriors

CH = ("a",)


def _episode(onset: int | None, scenario: str) -> Episode:
    return Episode(
        np.zeros((4, 1)),
        channels=CH,
        sample_time_s=10.0,
        fault_onset=onset,
        scenario=scenario,
        seed=5000,
    )


def _det(**kw) -> Detection:
    z = np.zeros((4, 1))
    return Detection(
        alarm=kw.pop("alarm", np.array([False, False, True, True])),
        signal=z,
        lower=z - 1,
        upper=z + 1,
        residual=z,
        signal_names=("s",),
        **kw,
    )


def test_which_samples_count() -> None:
    assert episode_truth(_episode(None, "nominal"), ("f1",)) == ("nominal", 0)
    assert episode_truth(_episode(2, "f1"), ("f1",)) == ("f1", 2)
    assert episode_truth(_episode(2, "heat_loss"), ("f1",)) is None  # unknown: not scored


def test_scores_own_decision_and_softmax_posteriors() -> None:
    post = np.array([[1.0, 0.0], [0.8, 0.2], [0.4, 0.6], [0.0, 1.0]])
    own = _det(
        diagnosis=np.array(["", "", "f1", "f1"]),
        class_scores=post[:, 1:],
        class_names=("f1",),
        posterior=post,
        hypothesis_names=("nominal", "f1"),
    )
    sc = ProbabilityScores("mmae")
    sc.add(_episode(2, "f1"), own, ("f1",))
    sc.add(_episode(None, "nominal"), own, ("f1",))
    sc.add(_episode(2, "heat_loss"), own, ("f1",))
    assert sc.kinds() == ["own"] and len(sc.rows) == 2
    # faulty from onset: samples 2, 3 -> (0.4² + 0.4²) and 0
    assert sc.pooled("own", healthy=False) == pytest.approx(0.16)
    # healthy, all samples: 0, 2·0.04, 2·0.36, 2·1
    assert sc.pooled("own", healthy=True) == pytest.approx((0.08 + 0.72 + 2.0) / 4)
    mean_p, freq, count = sc.curve("own", n_bins=2)
    assert count.sum() == 2 * (2 + 4)
    lda = _det(
        diagnosis=np.array(["", "", "f2", "unknown"]),
        class_scores=np.array([[0.0, 0.0], [0.0, 0.0], [0.0, np.log(3.0)], [0.0, 0.0]]),
        class_names=("f1", "f2"),
    )
    got = posteriors("lrgf-lda", lda)
    assert set(got) == {"decision", "softmax"}
    np.testing.assert_allclose(got["softmax"][0][2], [0, 0.25, 0.75])
    np.testing.assert_allclose(got["decision"][0][3], [0, 0.5, 0.5])
    assert set(posteriors("lrgf-iso", lda)) == {"decision"}
