"""The members ``catalogue-isolator`` adds for the closed loop: ``stiction-ukf`` (a sticking
valve by the excess variance of the model's T_rx innovation) and ``loop-offset`` (a loop that
cannot hold its set point), ``air-deficit`` (the metered air short of the air loop's
command). Their contract on their own faults' records, and what each sees."""

from __future__ import annotations

import numpy as np
import pytest

import diagnosers
import fcc_env
from diagnosers import Episode
from diagnosers.conformance import check_diagnoser
from diagnosers.loops.air_deficit import air_commands


@pytest.fixture(scope="module")
def loop() -> dict[str, list[Episode]]:
    plant = fcc_env.PlantConfig.build(regulatory=True)

    def sim(seeds: list[int], n: int, fault=None) -> list[Episode]:
        return Episode.from_batch(fcc_env.simulate_episodes(seeds, n, fault=fault, plant=plant))

    stiction = fcc_env.FaultSpec(scenario="valve-stiction", magnitude=0.02, onset=600)
    bias = fcc_env.FaultSpec(scenario="sensor-bias", channel="T_rx", magnitude=5.0, onset=600)
    return {
        "train": sim([1000, 1001], 1500),
        "stiction": sim([5000], 2000, stiction),
        "bias": sim([5000], 2000, bias),
        "healthy": sim([5001], 2000),
        "valve-stiction": sim([11], 1500, stiction),
        "blower-capacity": sim(
            [11], 1500, fcc_env.FaultSpec(scenario="blower-capacity", onset=600)
        ),
    }


def test_a_sticking_valve_at_its_default_size_is_found_and_a_bias_is_not(loop) -> None:
    d = diagnosers.make("stiction-ukf").fit(loop["train"])
    det = d.detect(loop["stiction"][0])
    # S = 0.02 of the valve's range: the cycle's excess variance builds over a few hundred
    # samples (lab/catalogue-isolator.md)
    assert not det.alarm[:600].any() and det.alarm[1300:].mean() > 0.9
    assert set(det.diagnosis[det.alarm]) == {"valve-stiction"}
    # a 5 °C bias on the same channel moves the innovation's mean, not its variance
    assert not d.detect(loop["bias"][0]).alarm.any()
    assert not d.detect(loop["healthy"][0]).alarm.any()


def test_a_loop_held_off_its_set_point_is_flagged(loop) -> None:
    d = diagnosers.make("loop-offset").fit(loop["train"])
    assert not d.detect(loop["healthy"][0]).alarm.any()
    ep = loop["healthy"][0]
    y = ep.y.copy()
    y[1000:, ep.channels.index("T_rg1")] -= 6.0  # the air cannot lift the bed to its set point
    det = d.detect(Episode(y, channels=ep.channels, sample_time_s=ep.sample_time_s))
    assert det.alarm[1500:].all() and not det.alarm[:1000].any()
    assert set(det.diagnosis[det.alarm]) == {"blower-capacity"}


def test_the_air_command_is_the_controllers_own(loop) -> None:
    # computed again from the recorded error, it is the air the healthy process received
    plant = fcc_env.PlantConfig.build(regulatory=True)
    res = fcc_env.simulate_episodes([5001], 1500, plant=plant)
    ep = Episode.from_batch(res)[0]
    error = ep.y[:, ep.channels.index("T_rg1_sp")] - ep.y[:, ep.channels.index("T_rg1")]
    applied = res.inputs[0, :, fcc_env.INPUT_NAMES.index("R_ar")]
    assert np.allclose(air_commands(error, ep.sample_time_s), applied, rtol=0, atol=1e-3)


def test_metered_air_short_of_its_command_is_flagged(loop) -> None:
    d = diagnosers.make("air-deficit").fit(loop["train"])
    assert not d.detect(loop["healthy"][0]).alarm.any()
    ep = loop["healthy"][0]
    y = ep.y.copy()
    j = ep.channels.index("R_ar")
    # the meter shows 1 t/h (0.7 %) less air than the loop commands from sample 1000 on
    y[1000:, j] -= 1.0
    det = d.detect(Episode(y, channels=ep.channels, sample_time_s=ep.sample_time_s))
    assert det.alarm[1300:].all() and not det.alarm[:1000].any()
    assert set(det.diagnosis[det.alarm]) == {"blower-capacity"}


@pytest.mark.parametrize(
    "name, fault",
    [
        ("stiction-ukf", "valve-stiction"),
        ("loop-offset", "blower-capacity"),
        ("air-deficit", "blower-capacity"),
    ],
)
def test_the_members_keep_the_contract(name: str, fault: str, loop) -> None:
    check_diagnoser(
        diagnosers.make(name),
        train=loop["train"],
        test=loop["stiction"][0],
        faulty_train=loop[fault],
    )


@pytest.mark.parametrize(
    "name, params, match",
    [
        ("stiction-ukf", {"lam": 0.0}, "lam"),
        ("stiction-ukf", {"channel": "T_x"}, "channel"),
        ("loop-offset", {"loop": "F"}, "loop"),
        ("loop-offset", {"sign": 2}, "sign"),
        ("air-deficit", {"lam": 1.5}, "lam"),
        ("air-deficit", {"margin": 0.5}, "margin"),
    ],
)
def test_bad_settings_are_refused_by_name(name: str, params: dict, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        diagnosers.make(name, **params).validate_params()


def test_ukf_glr_takes_the_path_faults_as_directions() -> None:
    diagnosers.make("ukf-glr", faults=["valve-bias", "sensor-bias", "f1"]).validate_params()
    with pytest.raises(ValueError, match="faults"):
        diagnosers.make("ukf-glr", faults=["f9"]).validate_params()
