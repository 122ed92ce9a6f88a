"""The ``<name>-novelty`` variants: their base's decisions, plus the samples outside the
training set-point range flagged as novel (:mod:`diagnosers.range_guard`,
:mod:`diagnosers.classical.range_guarded`)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import diagnosers
from diagnosers import Episode
from diagnosers.stages.operating_range import OperatingRange
from evaluation.tracks.catalogue import TRACKS
from evaluation.tracks.track_data import TrackData
from fcc_env.scenarios import FaultSpec


def _brute_flag(v: np.ndarray, low: float, high: float, hold: int) -> list[bool]:
    out = (v < low) | (v > high)
    return [bool(out[max(0, k - hold) : k + 1].any()) for k in range(v.size)]


@pytest.mark.parametrize("hold", [0, 1, 5])
def test_operating_range_matches_a_brute_force_window(hold: int) -> None:
    rng = np.random.default_rng(1)
    train = Episode(y=rng.normal(size=(50, 1)), channels=("T_rx_sp",), sample_time_s=60.0)
    test = Episode(y=2 * rng.normal(size=(80, 1)), channels=("T_rx_sp",), sample_time_s=60.0)
    r = OperatingRange(hold=hold).fit([train])
    low, high = train.y.min(), train.y.max()
    assert r.flag(test).tolist() == _brute_flag(test.y[:, 0], low, high, hold)
    assert not r.flag(train).any()


def test_open_loop_episodes_flag_nothing() -> None:
    ep = Episode(y=np.arange(10.0)[:, None], channels=("T_rx",), sample_time_s=60.0)
    r = OperatingRange(hold=3).fit([ep])
    assert r.used == () and not r.flag(ep).any()


#: every registered variant and its base; the LRGF bank trains for long even at its fast
#: parameters, so its variant runs with the slow tests
VARIANTS = [
    pytest.param(n, n.removesuffix("-novelty"), marks=[pytest.mark.slow] if "lrgf" in n else [])
    for n in diagnosers.available()
    if n.endswith("-novelty")
]


def _fast(name: str, **extra: object) -> diagnosers.Diagnoser:
    return diagnosers.make(name, **{**diagnosers.diagnoser_class(name).fast_params(), **extra})


@pytest.mark.parametrize(("name", "base"), VARIANTS)
def test_novelty_variant_keeps_the_base_alarms(name: str, base: str, tmp_path) -> None:
    data = TrackData(track=TRACKS["regimes"].replace(n_samples=1500))
    train = data.train_episodes()[:3]
    test = data.simulate([5000], FaultSpec(), test=True)[0].episode
    det = _fast(name, novelty_hold=50).fit(train)
    ref = _fast(base).fit(train)
    assert set(det.result_params()) == set(ref.result_params()) | {"novelty_hold"}
    got, want = det.detect(test), ref.detect(test)
    assert np.array_equal(got.alarm, want.alarm) and np.array_equal(got.signal, want.signal)
    assert want.novelty is None
    flags = OperatingRange(hold=50).fit(train).flag(test)
    assert flags.any() and np.array_equal(got.novel, flags)
    back = diagnosers.Diagnoser.load(det.save(tmp_path / "m"))
    assert type(back) is type(det) and np.array_equal(back.detect(test).novel, flags)


def test_the_range_ignores_labelled_faulty_training_episodes() -> None:
    """A detector that learns from faults gets faulty episodes too; only the healthy ones set
    the range (a faulty one with its set point far up would otherwise widen it)."""
    data = TrackData(track=TRACKS["regimes"].replace(n_samples=1500))
    train = data.train_episodes()[:2]
    j = train[0].channels.index("T_rx_sp")
    y = train[1].y.copy()
    y[:, j] += 50.0
    faulty = dataclasses.replace(train[1], y=y, fault_onset=700, scenario="f1")
    det = _fast("n4sid-glr-novelty").fit([*train, faulty])
    ref = OperatingRange().fit(train)
    assert det.range_.used == ref.used and np.array_equal(det.range_.high, ref.high)


def test_a_bad_hold_is_refused_with_its_value() -> None:
    with pytest.raises(ValueError, match="novelty_hold"):
        diagnosers.make("cva-novelty", novelty_hold=-1).validate_params()


def test_a_scored_cell_reports_the_novel_share_beside_r_fd() -> None:
    from evaluation.metrics.detection_metrics import novelty_rate
    from evaluation.sweep.records import detect_and_score, summarize

    data = TrackData(track=TRACKS["regimes"].replace(n_samples=1500))
    train = data.train_episodes()[:3]
    loaded = data.simulate([5000], FaultSpec(), test=True)[0]
    cell, det = detect_and_score(diagnosers.make("limits-novelty").fit(train), loaded)
    n = loaded.episode.n_samples
    assert cell.novelty == novelty_rate(det.novel, n) > 0
    assert cell.r_fd == np.mean(det.alarm & ~det.novel)
    plain, _ = detect_and_score(diagnosers.make("limits").fit(train), loaded)
    assert np.isnan(plain.novelty) and plain.r_fd == np.mean(det.alarm)
    assert summarize([cell])[0].novelty == cell.novelty
