"""The GLR bank of bias hypotheses (``diagnosers.sensors.glr_bank``) in ``sensor-validation``.

The oracle is the fault's own definition: the plant is simulated with a bias of a known size on
a known channel (``FCC-closedloop-v0``); the expectations (the channel, the size) are that
fault's, never the diagnoser's output.
"""

from __future__ import annotations

import copy

import numpy as np
import pytest

import diagnosers
import fcc_env
from diagnosers import Episode
from diagnosers.sensors import sensor_validation as sv
from diagnosers.sensors.sensor_validation import SensorValidation

N, ONSET, WINDOW = 900, 500, 200
PLANT = fcc_env.PlantConfig.build(regulatory=True)


def _sim(seeds: list[int], fault: fcc_env.FaultSpec | None = None) -> list[Episode]:
    return Episode.from_batch(fcc_env.simulate_episodes(seeds, N, plant=PLANT, fault=fault))


@pytest.fixture(scope="module")
def fitted() -> SensorValidation:
    labelled = _sim([1005], fcc_env.FaultSpec(scenario="sensor-bias", onset=ONSET))
    d = diagnosers.make("sensor-validation", warmup=100, glr_window=WINDOW, glr_settle=50)
    assert isinstance(d, SensorValidation)
    return d.fit(_sim([1000, 1001, 1002]) + labelled)


def _bias(channel: str, size: float) -> Episode:
    fault = fcc_env.FaultSpec(scenario="sensor-bias", channel=channel, magnitude=size, onset=ONSET)
    return _sim([5002], fault)[0]


def test_a_feed_temperature_bias_is_named_from_the_first_samples(fitted) -> None:
    """The pair the leave-out filters name late (T_rx first, lab/sensor-validation.md): the
    bank names T_fp within the window, its size to within a fifth."""
    ep = _bias("T_fp", 5.0)
    det = fitted.detect(ep)
    after = det.alarm[ONSET:]
    assert after[:50].any()
    first = np.flatnonzero(after)[0] + ONSET
    named = fitted.sensors(ep)[first : first + WINDOW][det.alarm[first : first + WINDOW]]
    assert np.mean(named == "T_fp") >= 0.9, np.unique(named, return_counts=True)
    fitted.reset()
    fitted._checks(np.asarray(ep.y[: first + WINDOW], dtype=np.float64))
    b = fitted._glr["bank"]
    assert b is not None and fitted._glr["left"] == 0
    acc = b["acc"][fcc_env.MEASUREMENT_NAMES.index("T_fp")]
    assert -fitted.glr_offset * acc[0] / acc[1] == pytest.approx(5.0, rel=0.2)


def test_glr_names_kind_takes_the_banks_kind_and_the_slow_rules_sensor(fitted) -> None:
    """``glr_names="kind"``: the sensor named is the slow rule's (the bank off), sample for
    sample, the kind the bank's (``"both"``), on a T_fp bias where the two rules name
    different sensors early (the slow rule T_rx, lab/sensor-validation.md)."""
    ep = _bias("T_fp", 5.0)
    kind_only, slow = copy.deepcopy(fitted), copy.deepcopy(fitted)
    kind_only.glr_names, slow.glr_window = "kind", 0
    both_named = fitted.sensors(ep)
    named = kind_only.sensors(ep)
    assert not np.array_equal(both_named, slow.sensors(ep))  # else the test tells nothing
    np.testing.assert_array_equal(named, slow.sensors(ep))
    np.testing.assert_array_equal(kind_only.detect(ep).diagnosis, fitted.detect(ep).diagnosis)
    kind_only.reset()
    streamed = [(kind_only.update(y), kind_only.named_sensor)[1] for y in np.asarray(ep.y)]
    assert streamed == list(named)


def test_an_alarm_after_a_quiet_spell_restarts_the_bank(fitted, monkeypatch) -> None:
    """``glr_restart``: an alarm that starts after that many quiet samples starts the bank
    afresh within its window (its age counts from there); one after fewer does not, and the
    quiet samples carry across calls."""
    alarm = np.zeros(14, dtype=bool)
    alarm[[1, 2, 9, 12]] = True
    starts = alarm & ~np.concatenate([[False], alarm[:-1]])
    restart, quiet = sv._restarts(alarm, starts, 0, 5)  # 6 quiet samples before 9, 2 before 12
    assert np.flatnonzero(restart).tolist() == [9] and quiet == 1
    later = np.zeros(5, dtype=bool)
    later[4] = True  # 1 quiet sample at the end of the last call, 4 in this one
    assert np.flatnonzero(sv._restarts(later, later, quiet, 5)[0]).tolist() == [4]
    assert not sv._restarts(later, later, 0, 5)[0].any()  # 4 quiet only
    assert not sv._restarts(alarm, starts, 0, 0)[0].any()  # 0: never
    # the bank's loop starts afresh where a restart is said
    ep = _bias("T_fp", 5.0)
    det = fitted.detect(ep)
    first = int(np.flatnonzero(det.alarm[ONSET:])[0]) + ONSET
    Y = np.asarray(ep.y[: first + 100], dtype=np.float64)
    d = copy.deepcopy(fitted)
    d.glr_restart = 1
    monkeypatch.setattr(sv, "_restarts", lambda a, s, q, m: (np.arange(a.size) == first + 50, 0))
    d._reset()
    d._checks(Y)
    assert d._glr["bank"]["age"][0] == 50 and d._glr["left"] == WINDOW - 50
    monkeypatch.undo()
    fitted.reset()
    fitted._checks(Y)
    assert fitted._glr["bank"]["age"][0] == 100


def test_streaming_names_as_the_whole_record_does(fitted) -> None:
    """``update`` sample by sample carries the bank across calls: the same sensor per sample
    as :meth:`sensors` on the whole record (the contract's detect = reset + updates)."""
    ep = _bias("T_rx", 4.0)
    whole = fitted.sensors(ep)
    fitted.reset()
    streamed = [(fitted.update(y), fitted.named_sensor)[1] for y in np.asarray(ep.y)]
    assert list(whole) == streamed


def test_the_window_must_be_a_count_of_samples() -> None:
    with pytest.raises(ValueError, match="glr_window"):
        diagnosers.make("sensor-validation", glr_window=-1).fit(_sim([1000]))
    with pytest.raises(ValueError, match="glr_offset"):
        diagnosers.make("sensor-validation", glr_offset=0.0).fit(_sim([1000]))


@pytest.mark.parametrize(
    ("key", "value"), [("glr_ramp", -1.0), ("glr_ratio", 0.5), ("glr_settle", -1)]
)
def test_bad_bank_settings_name_the_value_and_the_range(key: str, value: float) -> None:
    with pytest.raises(ValueError, match=rf"{key}={value}.*allowed range"):
        diagnosers.make("sensor-validation", **{key: value}).validate_params()
