"""The probability metrics: the Brier score against its definition, the reliability curve on
calibrated and miscalibrated draws, the posterior a hard decision implies."""

from __future__ import annotations

import numpy as np
import pytest

from evaluation.metrics.probability_metrics import (
    brier_samples,
    brier_score,
    decision_posterior,
    reliability_curve,
)

NAMES = ("nominal", "f1", "f2")


def test_brier_against_its_definition() -> None:
    rng = np.random.default_rng(1)
    post = rng.dirichlet(np.ones(3), size=50)
    got = brier_samples(post, NAMES, "f2", t_from=10)
    oracle = [sum((post[k, h] - (h == 2)) ** 2 for h in range(3)) for k in range(10, 50)]
    np.testing.assert_allclose(got, oracle, rtol=1e-12)
    assert brier_score(post, NAMES, "f2", 10) == pytest.approx(np.mean(oracle))
    # the bounds: sure and right 0, sure and wrong 2, uniform 1 − 1/H
    sure = np.tile([0.0, 1.0, 0.0], (4, 1))
    assert brier_score(sure, NAMES, "f1") == 0.0
    assert brier_score(sure, NAMES, "nominal") == 2.0
    assert brier_score(np.full((4, 3), 1 / 3), NAMES, "f1") == pytest.approx(2 / 3)


def test_brier_errors() -> None:
    post = np.full((3, 3), 1 / 3)
    with pytest.raises(ValueError, match="truth 'f9' is not one of"):
        brier_score(post, NAMES, "f9")
    with pytest.raises(ValueError, match=r"shape \(n_samples >= 1, 3\)"):
        brier_score(post[:, :2], NAMES, "f1")
    with pytest.raises(ValueError, match="summing to 1"):
        brier_score(post * 2, NAMES, "f1")
    with pytest.raises(ValueError, match="t_from=3 outside"):
        brier_score(post, NAMES, "f1", t_from=3)


def test_reliability_curve_is_diagonal_when_calibrated() -> None:
    rng = np.random.default_rng(2)
    p = rng.uniform(size=200_000)
    o = rng.uniform(size=p.size) < p  # calibrated by construction
    mean_p, freq, count = reliability_curve(p, o, n_bins=10)
    assert count.sum() == p.size
    np.testing.assert_allclose(freq, mean_p, atol=0.01)
    np.testing.assert_allclose(mean_p, np.arange(10) / 10 + 0.05, atol=0.01)
    # over-confident: the event happens half as often as said
    _, freq2, _ = reliability_curve(p, rng.uniform(size=p.size) < p / 2, n_bins=10)
    np.testing.assert_allclose(freq2, mean_p / 2, atol=0.01)
    # an empty bin is NaN
    mp, fr, c = reliability_curve(np.array([0.05, 0.95]), np.array([False, True]), n_bins=4)
    assert c.tolist() == [1, 0, 0, 1] and np.isnan(mp[1]) and fr[3] == 1.0
    with pytest.raises(ValueError, match="outcomes bool"):
        reliability_curve(p[:3], np.array([0, 1, 1]))


def test_decision_posterior() -> None:
    post, names = decision_posterior(np.array(["", "f2", "unknown", "f1"]), ("f1", "f2"))
    assert names == ("nominal", "f1", "f2")
    np.testing.assert_array_equal(post, [[1, 0, 0], [0, 0, 1], [0, 0.5, 0.5], [0, 1, 0]])
    with pytest.raises(ValueError, match=r"'f7' .* is neither"):
        decision_posterior(np.array(["", "f7"]), ("f1", "f2"))
