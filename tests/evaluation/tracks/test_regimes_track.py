"""The ``regimes`` track (test episodes on a wider set-point program than training) and the
scoring of novel samples (``Detection.novelty``) apart from false alarms."""

from __future__ import annotations

import numpy as np
import pytest

from diagnosers.detection import Detection
from evaluation.metrics.detection_metrics import episode_scores, novelty_rate
from evaluation.sweep.records import pack_detection, unpack_detection
from evaluation.tracks.catalogue import TRACKS
from evaluation.tracks.track import Track
from evaluation.tracks.track_data import TrackData
from fcc_env.scenarios import FaultSpec


def test_regimes_trains_like_closed_and_tests_wider() -> None:
    closed, regimes = TRACKS["closed"], TRACKS["regimes"]
    assert "test_setpoint_halfranges" not in closed.to_json()  # closed's store key unchanged
    assert regimes.to_json()["test_setpoint_halfranges"] == [8.0, 12.0]
    assert closed.test_plant == closed.plant
    assert regimes.plant == closed.plant  # training program: the closed track's
    program = regimes.test_plant.regulatory.program
    trained = regimes.plant.regulatory.program
    assert (program.T_rx_sp_halfrange_C, program.T_rg1_sp_halfrange_C) == (8.0, 12.0)
    assert (trained.T_rx_sp_halfrange_C, trained.T_rg1_sp_halfrange_C) == (4.0, 6.0)
    # equal training keys: the two tracks share their trained models
    assert TrackData(track=regimes).training_key() == TrackData(track=closed).training_key()


def test_regimes_test_episodes_leave_the_training_range() -> None:
    data = TrackData(track=TRACKS["regimes"].replace(n_samples=3000))
    seeds = [5000, 5001, 5002]
    train = [le.episode for le in data.simulate(seeds, FaultSpec())]
    test = [le.episode for le in data.simulate(seeds, FaultSpec(), test=True)]

    def spread(eps: list, name: str) -> float:
        i = eps[0].channels.index(name)
        return float(np.ptp(np.concatenate([ep.y[:, i] for ep in eps])))

    # the same seeds' APRBS levels scaled by 2 (clipping aside): about twice the spread
    for name, half in (("T_rx_sp", 4.0), ("T_rg1_sp", 6.0)):
        assert spread(train, name) <= 2 * half + 1e-6
        assert spread(test, name) > 1.5 * spread(train, name)
    assert data.load_test("nominal", 5000).episode.y.shape == test[0].y.shape


def test_test_setpoint_halfranges_is_checked() -> None:
    with pytest.raises(ValueError, match=r"test_setpoint_halfranges=.*None on an open-loop"):
        Track(name="x", description="d", test_setpoint_halfranges=(8.0, 12.0))
    with pytest.raises(ValueError, match=r"T_rg1_sp_halfrange_C=20.0 is outside"):
        Track(name="x", description="d", closed_loop=True, test_setpoint_halfranges=(8.0, 20.0))


def test_novel_samples_are_not_false_alarms() -> None:
    rng = np.random.default_rng(0)
    alarm = rng.random(200) < 0.3
    novel = rng.random(200) < 0.4
    onset, t_on = 150, 10
    plain = episode_scores(alarm, onset, t_on)
    # no novelty flagged: every figure as without the argument
    assert episode_scores(alarm, onset, t_on, novelty=np.zeros(200, bool)) == {
        **plain,
        "novelty": 0.0,
    }
    got = episode_scores(alarm, onset, t_on, novelty=novel)
    # oracle: count by hand over the fault-free window [t_on, onset)
    window = range(t_on, onset)
    assert got["r_fd"] == sum(alarm[k] and not novel[k] for k in window) / len(window)
    assert got["novelty"] == sum(novel[k] for k in window) / len(window)
    assert got["novelty"] == novelty_rate(novel, onset, t_on)
    # after the onset the alarms count as they are
    assert (got["r_td"], got["t_dt"]) == (plain["r_td"], plain["t_dt"])
    healthy = episode_scores(alarm, None, novelty=novel)
    assert healthy["r_fd"] == np.mean(alarm & ~novel)
    with pytest.raises(ValueError, match="shape"):
        episode_scores(alarm, None, novelty=novel[:5])


def test_detection_novelty_is_checked_and_kept() -> None:
    loaded = TrackData(track=TRACKS["regimes"].replace(n_samples=400)).load_test("nominal", 5000)
    n = loaded.episode.n_samples
    arrays = {k: np.zeros((n, 1)) for k in ("signal", "lower", "upper", "residual")}
    det = Detection(alarm=np.zeros(n, bool), signal_names=("s",), **arrays)
    assert det.novelty is None and not det.novel.any() and det.novel.shape == (n,)
    with pytest.raises(ValueError, match="novelty must be a bool array of shape"):
        Detection(alarm=np.zeros(n, bool), signal_names=("s",), novelty=np.zeros(n), **arrays)
    flagged = Detection(
        alarm=np.zeros(n, bool),
        signal_names=("s",),
        novelty=np.arange(n) % 3 == 0,
        **arrays,
    )
    _, _, back, _ = unpack_detection(pack_detection(loaded, flagged))
    assert np.array_equal(back.novel, flagged.novel)
    _, _, plain, _ = unpack_detection(pack_detection(loaded, det))
    assert plain.novelty is None
