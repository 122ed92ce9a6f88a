"""``lrgf-glr``'s alarm stage as a part of its own: fitted on normalised errors, no model."""

from __future__ import annotations

import numpy as np
import pytest

from diagnosers.stages.alarm import EWMA, LimitMethod, calibrate_limit
from diagnosers.stages.baseline import HeldBaseline
from diagnosers.stages.directional_stage import DirectionalStage

DIRECTIONS = np.array([[1.0, 0.0, 0.0], [0.0, -0.6, 0.8]])


def _records(n: int, seed: int, length: int = 1500) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    return [rng.standard_normal((length, 3)) for _ in range(n)]


@pytest.mark.parametrize("statistic", ["t2", "directional", "glr", "cusum"])
@pytest.mark.parametrize("with_baseline", [False, True])
def test_batch_equals_stream_and_the_target_is_split(statistic: str, with_baseline: bool) -> None:
    baseline = None
    if with_baseline:
        baseline = HeldBaseline(lam=0.01, hold=0.5, settle=50)
        baseline.bind([np.array([0]), np.array([1]), np.array([2])], np.array([3, 4, 5]), [])
    stage = DirectionalStage(
        false_alarm_target=0.02, statistic=statistic, glr_window=30, baseline=baseline
    )
    stage.fit(_records(4, 0), DIRECTIONS)
    n_dir = {"t2": 0, "directional": 4}.get(statistic, 2)  # directional: fast and slow scale
    assert stage.upper_.shape == (1 + n_dir,)
    assert len(stage.signal_names(("f1", "f2"))) == 1 + n_dir
    if not with_baseline:
        # the omnibus T² gets omnibus_share of the target (all of it with no directional test)
        z = np.concatenate([EWMA(0.3).filter(e) for e in _records(4, 0)])
        t2 = np.einsum("ti,ij,tj->t", z, stage.s_inv_, z)[:, None]
        share = 1.0 if statistic == "t2" else stage.omnibus_share
        expected = calibrate_limit(t2, 0.02 * share, method=LimitMethod.CHI2_TAIL, dof=3)
        np.testing.assert_allclose(stage.h_, expected, rtol=1e-12)
    e = _records(1, 7, 600)[0] + np.where(np.arange(600) >= 300, 1.5, 0.0)[:, None]
    stage.reset()
    batch = stage.signals(e, warm_up=0)
    stage.reset()
    stream = np.array([stage.step(row, warm=False, residual=row).signal for row in e])
    np.testing.assert_allclose(batch, stream, rtol=1e-9, atol=1e-12)
    alarms = stage.detect(e, warm_up=0, residual=e, names=()).alarm
    assert np.mean(alarms[300:]) > np.mean(alarms[:300])


def test_the_state_round_trips() -> None:
    stage = DirectionalStage(false_alarm_target=0.01).fit(_records(3, 1), DIRECTIONS)
    again = DirectionalStage(false_alarm_target=0.01)
    again.set_state({k: np.asarray(v) for k, v in stage.get_state().items()})
    e = _records(1, 2, 400)[0]
    stage.reset()
    again.reset()
    np.testing.assert_array_equal(again.signals(e, 0), stage.signals(e, 0))
    with pytest.raises(ValueError, match="lacks array 'directions'"):
        DirectionalStage(false_alarm_target=0.01).set_state({"s_inv": np.eye(3), "h": [1.0]})


def test_a_centred_t2_is_about_the_calibration_mean_and_saves_it() -> None:
    """``centered=True`` (the physical-limit rows): T² about the mean of the healthy EWMA."""
    norm = [r + np.array([0.5, -0.2, 0.0]) for r in _records(3, 3)]
    stage = DirectionalStage(statistic="t2", centered=True).fit(norm)
    z = np.concatenate([EWMA(0.3).filter(e) for e in norm])
    np.testing.assert_allclose(stage.mean_, z.mean(axis=0), rtol=1e-12)
    assert set(stage.get_state()) == {"s_inv", "h", "directions", "dir_weights", "h_dir", "mean"}
    plain = DirectionalStage(statistic="t2").fit(norm)
    assert "mean" not in plain.get_state() and not plain.mean_.any()  # a detector's: about 0
    e = norm[0]
    centred = stage.detect(e, warm_up=0, residual=e, names=("T2",)).signal[:, 0]
    d = EWMA(0.3).filter(e) - stage.mean_
    np.testing.assert_allclose(centred, np.einsum("ti,ij,tj->t", d, stage.s_inv_, d), rtol=1e-12)
