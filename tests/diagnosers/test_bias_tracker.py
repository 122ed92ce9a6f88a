"""The innovation stage's bias tracker (``bias_memory``): white stays white, a constant bias
goes, a step passes, streaming equals filtering, and ``ukf-glr`` refuses a bad memory."""

from __future__ import annotations

import numpy as np
import pytest

import diagnosers
from diagnosers.stages.innovation_stage import BiasTracker, InnovationStage


def test_white_innovations_stay_white_of_unit_variance() -> None:
    e = np.random.default_rng(0).normal(size=(20_000, 8))
    out = BiasTracker(200).filter(e)
    assert np.abs(out.mean(axis=0)).max() < 0.03
    assert np.allclose(out.var(axis=0), 1.0, atol=0.04)
    lag1 = np.mean(out[1:] * out[:-1], axis=0)
    assert np.abs(lag1).max() < 0.03  # the recursive residuals are uncorrelated


def test_a_constant_bias_goes_and_a_step_passes_at_once() -> None:
    rng = np.random.default_rng(1)
    e = rng.normal(size=(3000, 2)) + np.array([0.5, -0.3])
    out = BiasTracker(200).filter(e)
    assert np.abs(out[1000:].mean(axis=0)).max() < 0.05  # the plant's bias is learnt
    e[2000:, 0] += 2.0  # a fault's step
    out = BiasTracker(200).filter(e)
    assert out[2000:2010, 0].mean() > 1.5  # passes at once...
    assert abs(out[2900:, 0].mean()) < 0.3  # ...and fades over the memory


def test_a_skipped_sample_passes_as_nan_and_teaches_nothing() -> None:
    e = np.ones((4, 1))
    e[1] = np.nan
    out = BiasTracker(10).filter(e)
    assert np.isnan(out[1, 0]) and out[0, 0] == 1.0 and out[2, 0] == 0.0


def test_the_stage_with_a_bias_memory_streams_as_it_filters_and_ignores_a_bias() -> None:
    rng = np.random.default_rng(2)
    d = np.linalg.qr(rng.normal(size=(8, 2)))[0].T
    train = [rng.normal(size=(5000, 8)) for _ in range(4)]
    plain = InnovationStage(d, window=300).fit(train, 0.01)
    tracked = InnovationStage(d, window=300, bias_memory=300).fit(train, 0.01)
    e = rng.normal(size=(3000, 8)) + 0.25 * d[0]  # another plant: a bias along direction 0
    e[2500:] += 1.0 * d[1]  # then a fault along direction 1
    e[7] = np.nan
    batch = tracked.statistics(e)
    tracked.reset()
    assert np.allclose(np.array([tracked.step(x) for x in e]), batch, rtol=1e-12, atol=1e-9)
    assert plain.alarm(plain.statistics(e))[1000:2500].mean() > 0.5  # the bias alone alarms
    alarm = tracked.alarm(batch)
    assert alarm[1000:2500].mean() < 0.05 and alarm[2500:2530].any()


def test_ukf_glr_refuses_a_bias_memory_out_of_range_by_name() -> None:
    with pytest.raises(ValueError, match=r"bias_memory=0"):
        diagnosers.make("ukf-glr", bias_memory=0).validate_params()
