"""The reachable-bound row: the optimal filter on the exact model, measured channels."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from diagnosers.stages.innovation_stage import union_limits
from evaluation.tracks import TRACKS
from evaluation.tracks.filter_bound import FILTER_LABEL, FilterBound
from evaluation.tracks.optimal import CUSUM_LABEL
from evaluation.tracks.oracle import REFERENCE_LABELS, REFERENCE_TARGET, OracleConfig
from evaluation.tracks.track_data import TrackData

TINY = TRACKS["paper"].replace(n_healthy=2, n_faulty=1, n_train=2, n_validation=6)
#: fresh seeds: neither test, training nor calibration seeds
FRESH = 6000


@pytest.fixture(scope="module")
def bound() -> FilterBound:
    data = TrackData(track=TINY)
    healthy = [data.load_test("nominal", s).episode for s in TINY.validation_seeds]
    row = FilterBound(data, false_alarm_target=REFERENCE_TARGET, signature_seeds=2)
    return row.fit(healthy)


def test_false_alarm_rate_near_its_target(bound: FilterBound) -> None:
    data = bound.data
    calib = [data.load_test("nominal", s).episode for s in TINY.validation_seeds]
    share = np.mean(np.concatenate([bound.detect(ep).alarm for ep in calib]))
    assert 0.5 * REFERENCE_TARGET <= share <= REFERENCE_TARGET
    fresh = [data.load_test("nominal", s).episode for s in range(FRESH, FRESH + 3)]
    assert np.mean(np.concatenate([bound.detect(ep).alarm for ep in fresh])) < 0.01


def test_detects_a_paper_size_f1_at_once_without_the_clean_output(bound: FilterBound) -> None:
    loaded = bound.data.load_test("f1", FRESH)
    ep = dataclasses.replace(loaded.episode, y_clean=None)  # what a detector reads
    det = bound.detect(ep)
    onset = ep.fault_onset
    assert onset is not None
    assert det.alarm[onset : onset + 3].any()
    assert np.array_equal(det.alarm, bound.detect(loaded.episode).alarm)


def test_signatures_are_unit_directions_that_tell_f3_from_f1(bound: FilterBound) -> None:
    d = bound.directions_
    assert np.allclose(np.linalg.norm(d, axis=1), 1.0)
    f1, f3 = bound.faults.index("f1"), bound.faults.index("f3")  # windows (30, 300)
    assert d[2 * f1 + 1] @ d[2 * f3 + 1] < 0.5  # f3 heats the dilute phases, f1 cools the riser


def test_union_limits_hold_the_share() -> None:
    z = np.random.default_rng(1).normal(size=(20_000, 4))
    h = union_limits(z, 0.002)
    assert np.mean((z > h).any(axis=1)) <= 0.002
    assert np.allclose(h, h.mean(), atol=0.3)  # one tail for all: equal limits here


def test_the_row_sits_between_the_perfect_models_and_the_optimal_cusum() -> None:
    order = list(REFERENCE_LABELS.values())
    assert order.index(FILTER_LABEL) == order.index(CUSUM_LABEL) - 1
    assert OracleConfig(inputs="measured", stage="filter").label == FILTER_LABEL
    with pytest.raises(ValueError, match="inputs='measured'"):
        OracleConfig(stage="filter")
