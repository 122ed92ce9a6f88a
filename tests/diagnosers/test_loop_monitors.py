"""The loop monitors ``oscillation-acf`` and ``stiction-ccf`` (diagnosers/loops): their indexes
against exact signals, both detectors against a PI loop with a sticking valve (the
Choudhury et al. 2005 model of fcc_env/stiction.py), a healthy one and one with a sinusoidal
external disturbance, and on the closed-loop plant."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import diagnosers
import fcc_env
from diagnosers import Episode
from diagnosers.conformance import check_diagnoser
from diagnosers.loops import LOOP_CHANNELS
from diagnosers.loops.loop_indexes import (
    acf_regularity,
    horch_phase,
    shape_index,
    zero_crossings,
)
from fcc_env.stiction import StictionValve

PERIOD = 50  # samples: about the plant's stiction limit cycle (lab/stiction-detection.md)
T = np.arange(500)


def test_zero_crossings_of_a_sine_are_at_its_half_periods() -> None:
    z = zero_crossings(np.sin(2 * np.pi * (T + 0.25) / PERIOD))
    expected = np.arange(1, 20) * PERIOD / 2 - 0.25
    np.testing.assert_allclose(z, expected, atol=0.05)  # linear interpolation of a sine


def test_regularity_finds_a_noisy_tone_and_not_white_noise() -> None:
    rng = np.random.default_rng(0)
    tone = np.sin(2 * np.pi * T / PERIOD) + 0.5 * rng.standard_normal(T.size)
    r, period, peak = acf_regularity(tone, 250, 6, 24.0)
    assert r > 1.0 and period == pytest.approx(PERIOD, rel=0.03)
    # one period on, the (biased) ACF of a unit sine in noise of variance 0.25 is
    # 0.5 / 0.75 · (1 − 50 / 500) = 0.6
    assert peak == pytest.approx(0.6, abs=0.08)
    r_noise, _, _ = acf_regularity(rng.standard_normal(T.size), 250, 6, 0.0)
    assert r_noise < 1.0
    # a period below min_period is not an oscillation (the noise through a PI law)
    assert acf_regularity(tone, 250, 6, 60.0)[0] == 0.0
    assert acf_regularity(np.ones(T.size), 250, 6, 0.0)[0] == 0.0


def test_horch_phase_is_a_quarter_period_for_an_odd_ccf_and_zero_for_an_even_one() -> None:
    w = 2 * np.pi * T / PERIOD
    # the CCF of cos and sin is a sine in the lag (odd), of -sin and sin a cosine (even)
    assert horch_phase(np.sin(w), np.cos(w), PERIOD) == pytest.approx(np.pi / 2, abs=0.07)
    assert horch_phase(np.sin(w), -np.sin(w), PERIOD) == pytest.approx(0.0, abs=0.07)
    # a phase shift φ between them reads |φ| (the CCF is cos(ωτ + φ))
    assert horch_phase(np.sin(w), np.sin(w + np.pi / 6), PERIOD) == pytest.approx(
        np.pi / 6, abs=0.07
    )


def test_shape_index_reads_a_triangle_as_stiction_and_a_sine_as_not() -> None:
    phase = (T % PERIOD) / PERIOD
    triangle = 1.0 - 4.0 * np.abs(phase - 0.5)
    # He et al. (2007): SI >= 0.6 stiction, SI <= 0.4 no stiction
    assert shape_index(triangle, PERIOD) > 0.6
    assert shape_index(np.sin(2 * np.pi * T / PERIOD), PERIOD) < 0.4
    assert np.isnan(shape_index(np.sin(2 * np.pi * T[:40] / PERIOD), PERIOD))


def _pi_loop(
    S: float = 0.0,
    J: float = 0.0,
    *,
    disturbance: float = 0.0,
    disturbance_period: float = 80.0,
    steps: bool = False,
    noise: float = 0.3,
    setpoint: float = 100.0,
    n: int = 3000,
    seed: int = 0,
) -> Episode:
    """A loop shaped like the plant's T_rx loop (sample 10 s): a quasi-steady process
    0.25 °C per kg/s behind a one-sample lag, a PI law integral-dominated as the plant's
    (Kc 0.26, Ts/τI 2.3), measurement noise ``noise`` °C, a valve with stiction S, J (kg/s), an
    external sinusoid on the controlled variable, and set-point steps of ±3 °C if ``steps``
    (the set point ``setpoint`` first; the loop starts at rest at 100 °C)."""
    rng = np.random.default_rng(seed)
    gain, a, kc, ki = 0.25, np.exp(-1.0), 0.26, 0.6
    valve, u, e_prev, x, v, sp = StictionValve(400.0), 400.0, 0.0, 100.0, 400.0, setpoint
    out = np.empty((n, 3))
    for k in range(n):
        if steps and k % 300 == 0:
            sp = 100.0 + rng.uniform(-3.0, 3.0)
        y = x + disturbance * np.sin(2 * np.pi * k / disturbance_period)
        y += noise * rng.standard_normal()
        e = sp - y
        out[k] = (y, sp, u)
        u += kc * (e - e_prev) + ki * e
        e_prev = e
        x = a * x + (1.0 - a) * gain * v  # the valve in force since the previous sample
        v = valve.move(u, S, J)
    return Episode(out, channels=LOOP_CHANNELS["T_rx"], sample_time_s=10.0)


@pytest.fixture(scope="module")
def fitted() -> dict[str, diagnosers.Diagnoser]:
    train = [_pi_loop(steps=True, seed=1)]
    return {n: diagnosers.make(n).fit(train) for n in ("oscillation-acf", "stiction-ccf")}


def test_a_sticking_valve_is_flagged_and_named(fitted) -> None:
    ep = _pi_loop(8.0, 4.0)
    osc = fitted["oscillation-acf"].detect(ep)
    stic = fitted["stiction-ccf"].detect(ep)
    assert osc.alarm[500:].mean() > 0.3 and stic.alarm[500:].mean() > 0.3
    assert set(stic.diagnosis[stic.alarm]) == {"valve-stiction"}
    # the period: the noise-free loop's limit cycle (started by a set-point step of 1 °C),
    # from its upward crossings of its mean
    clean = _pi_loop(8.0, 4.0, noise=0.0, setpoint=101.0).y[500:, 0]
    up = np.flatnonzero(np.diff(np.sign(clean - clean.mean())) > 0)
    period_s = float(np.diff(up).mean()) * 10.0
    assert np.median(osc.signal[osc.alarm, 3]) == pytest.approx(period_s, rel=0.15)


def test_a_healthy_loop_with_set_point_steps_is_not_flagged(fitted) -> None:
    for seed in (2, 3):
        ep = _pi_loop(steps=True, seed=seed)
        assert fitted["oscillation-acf"].detect(ep).alarm.mean() < 0.01
        assert fitted["stiction-ccf"].detect(ep).alarm.mean() < 0.01


def test_an_external_sinusoid_oscillates_but_is_not_stiction(fitted) -> None:
    ep = _pi_loop(disturbance=2.0)
    assert fitted["oscillation-acf"].detect(ep).alarm[500:].mean() > 0.9
    stic = fitted["stiction-ccf"].detect(ep)
    assert not stic.alarm.any()
    # Horch's phase alone reads it odd under this integral-dominated law (the curve fit
    # tells them apart: its index stays below He et al.'s 0.4)
    alone = diagnosers.make("stiction-ccf", shape_limit=0.0).fit([_pi_loop(steps=True, seed=1)])
    assert alone.detect(ep).alarm[500:].mean() > 0.9
    assert np.all(stic.signal[500:, 4] < 0.4)


def test_the_label_is_the_registrys_stiction_of_the_loops_valve() -> None:
    label = diagnosers.make("stiction-ccf").get_params()["label"]
    assert fcc_env.FAULTS[label].actuator_input == LOOP_CHANNELS["T_rx"][2]


@pytest.fixture(scope="module")
def plant_episodes() -> dict[str, list[Episode]]:
    plant = fcc_env.PlantConfig.build(regulatory=True)

    def sim(seeds: list[int], n: int, fault=None) -> list[Episode]:
        return Episode.from_batch(fcc_env.simulate_episodes(seeds, n, fault=fault, plant=plant))

    stiction = fcc_env.FaultSpec(scenario="valve-stiction", magnitude=0.1, onset=500)
    return {
        "train": sim([1000, 1001], 1500),
        "faulty_train": sim([11, 12], 1500, stiction),
        "test": sim([5000], 2500, stiction),
        "short": sim([5002], 1000, stiction),
        "healthy": sim([5000, 5001], 4000),
    }


def test_on_the_plant_stiction_is_found_and_healthy_loops_stay_silent(plant_episodes) -> None:
    d = diagnosers.make("stiction-ccf").fit(plant_episodes["train"])
    det = d.detect(plant_episodes["test"][0])
    # S = 0.1 of the valve's range: a third of the samples after the onset and more
    # (the window needs a few cycles; lab/stiction-detection.md)
    assert not det.alarm[:500].any() and det.alarm[500:].mean() > 0.2
    assert set(det.diagnosis[det.alarm]) == {"valve-stiction"}
    for ep in plant_episodes["healthy"]:  # validation seeds
        assert not d.detect(ep).alarm.any()
    assert d.training_index_max_ < 1.0  # the healthy training loops do not oscillate


def test_training_on_an_oscillating_loop_warns(plant_episodes, caplog) -> None:
    # a sticking valve's record passed off as healthy
    unlabelled = [dataclasses.replace(ep, fault_onset=None) for ep in plant_episodes["test"]]
    with caplog.at_level("WARNING", logger="diagnosers.loops.loop_detectors"):
        d = diagnosers.make("oscillation-acf").fit(unlabelled)
    assert d.training_index_max_ > 1.0
    assert "the training episodes already alarm" in caplog.text
    # labelled faulty episodes (what an isolating monitor also receives) do not count
    caplog.clear()
    with caplog.at_level("WARNING", logger="diagnosers.loops.loop_detectors"):
        d = diagnosers.make("stiction-ccf").fit(
            plant_episodes["train"] + plant_episodes["faulty_train"]
        )
    assert d.training_index_max_ < 1.0 and not caplog.text


@pytest.mark.parametrize("name", ["oscillation-acf", "stiction-ccf"])
def test_the_loop_monitors_keep_the_contract(name: str, plant_episodes) -> None:
    check_diagnoser(
        diagnosers.make(name),
        train=plant_episodes["train"],
        test=plant_episodes["short"][0],
        faulty_train=plant_episodes["faulty_train"],
    )


def test_bad_settings_and_records_are_refused_by_name(plant_episodes) -> None:
    train = plant_episodes["train"]
    with pytest.raises(ValueError, match=r"loop='P_rg' is outside the allowed range: one of"):
        diagnosers.make("oscillation-acf", loop="P_rg").fit(train)
    with pytest.raises(ValueError, match=r"label='unknown' is outside the allowed range"):
        diagnosers.make("stiction-ccf", label="unknown").fit(train)
    with pytest.raises(ValueError, match=r"window_s=50.0 is outside the allowed range: at least 8"):
        diagnosers.make("oscillation-acf", window_s=50.0).fit(train)
    open_loop = Episode.from_batch(fcc_env.simulate_episodes([1000], 300))
    with pytest.raises(ValueError, match=r"missing \['T_rx_sp', 'u_F'\]"):
        diagnosers.make("stiction-ccf").fit(open_loop)


def test_the_harness_runs_them_on_closed_loop_tracks_only() -> None:
    from evaluation.tracks.board import applicable, track_channels
    from evaluation.tracks.catalogue import TRACKS

    names = ["oscillation-acf", "stiction-ccf"]
    keep, skipped = applicable(names, track_channels(TRACKS["paper"]), "on track paper")
    assert keep == [] and all("no channel T_rx_sp, u_F" in s for s in skipped)
    keep, _ = applicable(names, track_channels(TRACKS["actuator"]), "on track actuator")
    assert keep == names
