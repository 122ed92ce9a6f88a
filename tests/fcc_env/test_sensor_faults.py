"""Sensor faults on any measured channel (issue 43 item 1): each kind's effect on the reading,
env = batch in open and closed loop, dropouts held with a flag, the controllers steering the
true process to a biased reading, refusals by name, the request's JSON with its channel."""

from __future__ import annotations

import json

import gymnasium as gym
import numpy as np
import pytest

import diagnosers
import fcc_env
from fcc_env import FaultSpec, simulate_episodes
from fcc_env.params import MEASUREMENT_NAMES
from fcc_env.physics import AUX_NAMES

N, ONSET = 300, 100
CLOSED = fcc_env.PlantConfig.build(regulatory=True)
SIZES = {"bias": 3.0, "drift": 2.0, "stuck": 1.0, "noise": 3.0, "dropout": 0.5}


def _spec(kind: str, channel: str = "T_rg2", **kw) -> FaultSpec:
    return FaultSpec(
        scenario=f"sensor-{kind}", channel=channel, onset=ONSET, magnitude=SIZES[kind], **kw
    )


@pytest.fixture(scope="module")
def healthy():
    return simulate_episodes([3], N)


def _pair(kind: str, channel: str = "T_rg2"):
    return simulate_episodes([3], N, fault=_spec(kind, channel)), MEASUREMENT_NAMES.index(channel)


def test_the_registry_holds_them_apart_from_the_catalogue_lists() -> None:
    kinds = tuple(f"sensor-{k}" for k in SIZES)
    assert fcc_env.fault_names() == fcc_env.PAPER_FAULTS  # the tracks, random, the studies
    every = fcc_env.fault_names(include_path_faults=True)
    assert every[:4] == fcc_env.PAPER_FAULTS and tuple(n for n in every if n in kinds) == kinds
    assert set(every) == {*fcc_env.PAPER_FAULTS, *kinds, *fcc_env.ACTUATOR_FAULTS}
    assert fcc_env.scenario_names(include_path_faults=True)[1:] == every
    rng = np.random.default_rng(0)
    drawn = {FaultSpec(scenario="random").resolve(1000, rng).scenario for _ in range(100)}
    assert drawn == {"nominal", *fcc_env.PAPER_FAULTS}


def test_bias_is_an_exact_offset_on_its_channel_only(healthy) -> None:
    b, ch = _pair("bias")
    delta = b.y_clean[0] - healthy.y_clean[0]
    np.testing.assert_allclose(delta[:, ch], np.where(np.arange(N) >= ONSET, 3.0, 0.0), atol=1e-9)
    assert not np.delete(delta, ch, axis=1).any()
    np.testing.assert_array_equal(b.states, healthy.states)  # open loop: the process untouched
    assert b.scenarios == ("sensor-bias",) and b.fault_channels == ("T_rg2",)


def test_drift_is_a_ramp_of_its_rate_per_hour(healthy) -> None:
    b, ch = _pair("drift")
    delta = (b.y_clean[0] - healthy.y_clean[0])[:, ch]
    assert not delta[:ONSET].any()
    slope = np.polyfit(np.arange(ONSET, N) * 10.0 / 3600.0, delta[ONSET:], 1)[0]
    assert slope == pytest.approx(2.0, rel=1e-9)


def test_stuck_holds_the_reading_before_the_onset(healthy) -> None:
    b, ch = _pair("stuck")
    obs, clean = b.observations[0, :, ch], b.y_clean[0, :, ch]
    assert (obs[ONSET:] == obs[ONSET - 1]).all() and (clean[ONSET:] == clean[ONSET - 1]).all()
    np.testing.assert_array_equal(b.observations[0, :ONSET], healthy.observations[0, :ONSET])
    assert np.ptp(healthy.observations[0, ONSET:, ch]) > 0  # the process moves meanwhile


def test_noise_grows_by_its_multiple(healthy) -> None:
    b, ch = _pair("noise")
    noise = b.observations[0, ONSET:, ch] - b.y_clean[0, ONSET:, ch]
    base = healthy.observations[0, ONSET:, ch] - healthy.y_clean[0, ONSET:, ch]
    assert noise.std() / base.std() == pytest.approx(4.0, rel=1e-3)  # std × (1 + 3)
    np.testing.assert_array_equal(b.y_clean, healthy.y_clean)


def test_a_dropout_holds_the_last_good_value_and_flags_it(healthy) -> None:
    b, ch = _pair("dropout")
    lost = b.sensor_dropout[0]
    assert not lost[:ONSET].any() and 0.3 < lost[ONSET:].mean() < 0.7
    obs = b.observations[0, :, ch]
    for k in np.flatnonzero(lost):
        assert obs[k] == obs[k - 1]  # the DCS holds the last value it received
    good = ~lost
    np.testing.assert_array_equal(b.observations[0, good], healthy.observations[0, good])
    assert np.isfinite(b.observations).all()
    # every diagnoser's input path takes it (diagnosers.Episode refuses NaN)
    [ep] = diagnosers.Episode.from_batch(b)
    assert ep.scenario == "sensor-dropout" and ep.fault_onset == ONSET
    diagnosers.make("limits").fit(diagnosers.Episode.from_batch(healthy)).fit([ep])


@pytest.mark.parametrize("closed", [False, True], ids=["FCC-v0", "FCC-closedloop-v0"])
@pytest.mark.parametrize("kind", list(SIZES))
def test_env_and_batch_read_the_same_transmitter(kind: str, closed: bool) -> None:
    spec = _spec(kind, "T_rx" if closed else "T_rg2")
    env_id = "FCC-closedloop-v0" if closed else "FCC-v0"
    batch = simulate_episodes([9, 3], N, fault=spec, plant=CLOSED if closed else None)
    env = gym.make(env_id, fault=spec, max_episode_steps=N - 1, horizon=N)
    obs, info = env.reset(seed=3)
    ys, lost = [obs], [info["sensor_dropout"]]
    for _ in range(N - 1):
        obs, _, _, _, info = env.step(np.zeros(2, dtype=np.float32))
        ys.append(obs)
        lost.append(info["sensor_dropout"])
    np.testing.assert_array_equal(np.array(ys), batch.observations[1])
    np.testing.assert_array_equal(lost, batch.sensor_dropout[1])
    assert info["fault_channel"] == spec.channel and info["scenario"] == spec.scenario


def test_the_env_keyword_and_the_reset_option_name_the_channel() -> None:
    env = gym.make("FCC-v0", scenario="sensor-bias", fault_channel="T_ar", fault_time=50, horizon=N)
    _, info = env.reset(seed=0)
    assert info["fault_channel"] == "T_ar" and info["fault_magnitude"] == 5.0
    opts = {"scenario": "sensor-noise", "fault_channel": "R_ar", "fault_time": 50}
    _, info = env.reset(seed=0, options=opts)
    assert (info["scenario"], info["fault_channel"]) == ("sensor-noise", "R_ar")
    _, info = env.reset(seed=0, options={"scenario": "f1", "fault_magnitude": None})
    assert info["scenario"] == "f1" and "fault_channel" not in info
    _, info = gym.make("FCC-v0", scenario="sensor-stuck").reset(seed=0)
    assert info["fault_channel"] == "T_rx"  # the default channel
    assert "fault_channel" not in gym.make("FCC-v0", scenario="f1").reset(seed=0)[1]
    fault, _ = fcc_env.env_request(scenario="sensor-drift", fault_channel="T_d1")
    assert fault.channel == "T_d1"


def test_closed_loop_bias_moves_the_true_process_by_minus_the_bias() -> None:
    n = 1200
    seeds = [1000, 1001]
    healthy = simulate_episodes(seeds, n, plant=CLOSED)
    for channel in ("T_rx", "T_rg1"):
        spec = FaultSpec(scenario="sensor-bias", channel=channel, magnitude=4.0, onset=300)
        b = simulate_episodes(seeds, n, fault=spec, plant=CLOSED)
        if channel == "T_rx":
            true = b.aux[..., AUX_NAMES.index("T_rx")] - healthy.aux[..., AUX_NAMES.index("T_rx")]
        else:
            true = b.states[..., fcc_env.STATE_NAMES.index("T1")] - healthy.states[..., 4]
        assert not true[:, :300].any()
        assert true[:, 900:].mean() == pytest.approx(-4.0, abs=0.3)  # the loop follows the reading


def test_refusals_name_the_value_and_the_allowed_ones() -> None:
    with pytest.raises(ValueError, match=r"fault_channel='u_F' .*'R_ar', 'T_ar'.*'T_dg'"):
        FaultSpec(scenario="sensor-bias", channel="u_F")
    with pytest.raises(ValueError, match=r"fault_channel='T_rx' .*'f1' acts on no chosen channel"):
        FaultSpec(scenario="f1", channel="T_rx")
    with pytest.raises(ValueError, match=r"fault_channel='T_rx' .*'random'"):
        FaultSpec(scenario="random", channel="T_rx")
    with pytest.raises(ValueError, match=r"fault_magnitude=12\.0 .*\[0, 10\].*sensor-bias.*°C"):
        FaultSpec(scenario="sensor-bias", magnitude=12.0)
    with pytest.raises(ValueError, match=r"fault_magnitude=0\.95 .*\[0, 0\.9\].*probability"):
        FaultSpec(scenario="sensor-dropout", magnitude=0.95)
    with pytest.raises(ValueError, match=r"fault_magnitude=3\.0 .*\[0, 2\]"):
        gym.make("FCC-v0", scenario="sensor-drift", fault_magnitude=3.0)
    # a dropout draws per sample (bias, drift, stuck and noise run natively: test_vector_sensor)
    with pytest.raises(ValueError, match="vectorization_mode='sync'"):
        envs = gym.make_vec(
            "FCC-v0", 2, vectorization_mode="vector_entry_point", scenario="sensor-dropout"
        )
        envs.reset(seed=0)


def test_the_request_round_trips_through_json_with_its_channel() -> None:
    spec = FaultSpec(scenario="sensor-drift", channel="T_rg1", magnitude=1.5, profile="incipient")
    data = json.loads(json.dumps(spec.to_json()))
    assert data["channel"] == "T_rg1" and FaultSpec.from_json(data) == spec
    assert "channel" not in FaultSpec(scenario="f2").to_json()  # the paper's store keys stay
    assert FaultSpec.from_json(FaultSpec(scenario="f2").to_json()) == FaultSpec(scenario="f2")


def test_a_dataset_carries_the_dropout_flag_and_the_channel(tmp_path) -> None:
    from fcc_env.generate import main

    out = tmp_path / "d.csv"
    argv = ["--scenario", "sensor-dropout", "--fault-channel", "T_rg1", "--seeds", "3"]
    main([*argv, "--samples", str(N), "--fault-time", str(ONSET), "--out", str(out)])
    meta = json.loads(out.with_suffix(".json").read_text())
    assert meta["fault"]["channel"] == "T_rg1" and meta["fault_channels"] == ["T_rg1"]
    table = np.genfromtxt(out, delimiter=",", names=True)
    spec = FaultSpec(scenario="sensor-dropout", channel="T_rg1", onset=ONSET)
    lost = simulate_episodes([3], N, fault=spec).sensor_dropout[0]
    np.testing.assert_array_equal(table["sensor_dropout"], lost.astype(float))
    # the command's chunked simulation joins the channels per episode
    from fcc_env.generate import PROGRESS_CHUNK, simulate_in_chunks

    seeds = list(range(PROGRESS_CHUNK + 1))
    joined = simulate_in_chunks(seeds, 120, progress=False, fault=_spec("dropout"))
    assert joined.fault_channels == ("T_rg2",) * len(seeds)
    assert joined.sensor_dropout.shape == (len(seeds), 120) and joined.sensor_dropout.any()
