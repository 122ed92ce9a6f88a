"""Actuator faults (issue 43 item 2): each in the registry and accepted whole by FaultSpec,
gym.make and simulate_episodes; what each does to the inputs the process receives, in closed
and open loop; the command the control system records; refusals by name; env = batch;
determinism by seed."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import fcc_env
from fcc_env import FaultSpec, simulate_episodes
from fcc_env.actuator_faults import BLOWER_CAPACITY, VALVE_RANGE
from fcc_env.closed_loop import CLOSED_LOOP_CHANNELS
from fcc_env.params import NOMINAL_INPUTS
from fcc_env.physics import AUX_NAMES

N, ONSET = 300, 100
CLOSED = fcc_env.PlantConfig.build(regulatory=True)
U_F = CLOSED_LOOP_CHANNELS.index("u_F")
NAMES = ("valve-stiction", "valve-bias", "valve-stuck", "blower-capacity")


def _closed(name: str, seeds=(3,), n: int = N, **kw):
    return simulate_episodes(
        list(seeds), n, fault=FaultSpec(scenario=name, onset=ONSET, **kw), plant=CLOSED
    )


@pytest.fixture(scope="module")
def healthy():
    return simulate_episodes([3], N, plant=CLOSED)


def test_they_are_registered_scenarios_outside_the_catalogue_lists() -> None:
    assert tuple(fcc_env.ACTUATOR_FAULTS) == NAMES
    for name in NAMES:
        assert fcc_env.FAULTS[name] is fcc_env.ACTUATOR_FAULTS[name]
        assert name in fcc_env.fault_names(include_path_faults=True)
        assert name not in fcc_env.fault_names()  # random, the tracks, the studies: not yet
        d = fcc_env.FAULTS[name]
        assert d.actuator_input == ("R_ar" if name == "blower-capacity" else "u_F")
        assert FaultSpec(scenario=name).resolve(4000).magnitude == d.default_magnitude


@pytest.mark.parametrize("name", NAMES)
def test_a_size_beyond_the_largest_is_refused_with_its_reason(name: str) -> None:
    d = fcc_env.FAULTS[name]
    FaultSpec(scenario=name, magnitude=d.max_magnitude)
    with pytest.raises(ValueError, match=rf"fault_magnitude=.*for {name} \(.*\): "):
        FaultSpec(scenario=name, magnitude=d.max_magnitude + 0.01)
    with pytest.raises(ValueError, match="acts on no chosen channel"):
        FaultSpec(scenario=name, channel="T_rx")


def test_the_valve_faults_in_closed_loop(healthy) -> None:
    k = np.arange(N)
    bias = _closed("valve-bias", magnitude=0.05)
    gap = bias.inputs[0, :, 0] - bias.y_clean[0, :, U_F]  # applied − command
    np.testing.assert_allclose(gap, np.where(k >= ONSET, 0.05 * NOMINAL_INPUTS[0], 0.0), atol=1e-9)
    # the loop takes the bias out: the command drops by it, the process follows its set point
    assert bias.y_clean[0, -1, U_F] < healthy.y_clean[0, -1, U_F] - 15.0
    stuck = _closed("valve-stuck")
    u = stuck.inputs[0, :, 0]
    assert (u[ONSET:] == u[ONSET - 1]).all() and (u[:ONSET] == stuck.y_clean[0, :ONSET, U_F]).all()
    sticky = _closed("valve-stiction", magnitude=0.03)
    moves = np.flatnonzero(np.diff(sticky.inputs[0, ONSET:, 0]))
    commands = np.flatnonzero(np.diff(sticky.y_clean[0, ONSET:, U_F]))
    assert 0 < moves.size < commands.size / 5  # it sticks, then slips
    s = 0.03 * VALVE_RANGE
    # after the first breakaway each slip jumps J = S/2 at least
    slips = np.abs(np.diff(sticky.inputs[0, ONSET:, 0]))[moves[1:]]
    assert (slips >= s / 2 - 1e-9).all()
    # before the onset all three are the healthy episode
    for b in (bias, stuck, sticky):
        np.testing.assert_array_equal(b.observations[0, :ONSET], healthy.observations[0, :ONSET])


def test_the_blower_caps_the_air_in_either_mode() -> None:
    ceiling = (1 - 0.12) * BLOWER_CAPACITY
    for plant, seed in ((None, 3), (CLOSED, 4)):  # (seed 4: its air loop reaches the cap)
        spec = FaultSpec(scenario="blower-capacity", onset=ONSET)
        b = simulate_episodes([seed], N, fault=spec, plant=plant)
        h = simulate_episodes([seed], N, plant=plant)
        air, healthy_air = b.inputs[0, :, 1], h.inputs[0, :, 1]
        np.testing.assert_array_equal(air[:ONSET], healthy_air[:ONSET])
        assert air[ONSET:].max() <= ceiling + 1e-9 < healthy_air[ONSET:].max()


def test_open_loop_bias_shifts_the_valve_and_the_sticky_ones_are_refused() -> None:
    b = simulate_episodes([3], N, fault=FaultSpec(scenario="valve-bias", onset=ONSET))
    h = simulate_episodes([3], N)
    gap = (b.inputs - h.inputs)[0]
    np.testing.assert_allclose(
        gap[:, 0], np.where(np.arange(N) >= ONSET, 0.05 * NOMINAL_INPUTS[0], 0)
    )
    assert not gap[:, 1:].any()
    for name in ("valve-stiction", "valve-stuck"):
        with pytest.raises(
            ValueError, match=rf"{name} acts on the u_F actuator, which only the T_rx"
        ):
            gym.make("FCC-v0", scenario=name)
        with pytest.raises(ValueError, match="the plant runs open loop"):
            simulate_episodes([3], N, fault=FaultSpec(scenario=name, onset=ONSET))
        air_only = fcc_env.PlantConfig.build(regulatory={"loops": ("T_rg1",)})
        with pytest.raises(ValueError, match=r"loops=\('T_rg1',\)"):
            simulate_episodes([3], N, fault=FaultSpec(scenario=name, onset=ONSET), plant=air_only)


@pytest.mark.parametrize("name", ["valve-stiction", "blower-capacity"])
def test_env_equals_batch_and_records_the_command(name: str) -> None:
    spec = FaultSpec(scenario=name, onset=ONSET, magnitude=0.03 if "stiction" in name else None)
    batch = simulate_episodes([5], N, fault=spec, plant=CLOSED)
    env = gym.make("FCC-closedloop-v0", fault=spec)
    obs, info = env.reset(seed=5)
    rows, inputs = [obs], [info["inputs"]]
    for _ in range(N - 1):
        obs, _, _, _, info = env.step(np.zeros(2))
        rows.append(obs)
        inputs.append(info["inputs"])
    np.testing.assert_array_equal(np.array(rows), batch.observations[0])
    np.testing.assert_array_equal(np.array(inputs), batch.inputs[0])
    assert info["scenario"] == name and info["fault_active"]


def test_same_seed_same_episode_and_the_vector_env_refuses_them() -> None:
    a = _closed("valve-stiction", seeds=(7, 8), magnitude=0.03)
    b = _closed("valve-stiction", seeds=(7, 8), magnitude=0.03)
    np.testing.assert_array_equal(a.observations, b.observations)
    assert not np.array_equal(a.inputs[0], a.inputs[1])
    envs = gym.make_vec(
        "FCC-closedloop-v0",
        num_envs=2,
        vectorization_mode="vector_entry_point",
        scenario="valve-bias",
    )
    with pytest.raises(ValueError, match="actuator device needs Python per sample"):
        envs.reset(seed=0)


def test_an_incipient_fault_grows_over_its_ramp() -> None:
    spec = FaultSpec(
        scenario="valve-bias", onset=ONSET, magnitude=0.1, profile="incipient", ramp_samples=100
    )
    b = simulate_episodes([3], N, fault=spec, plant=CLOSED)
    gap = b.inputs[0, :, 0] - b.y_clean[0, :, U_F]
    k = np.arange(N)
    frac = np.clip((k - ONSET + 1) / 100, 0, 1) * (k >= ONSET)
    np.testing.assert_allclose(gap, 0.1 * NOMINAL_INPUTS[0] * frac, atol=1e-9)


def _crossings(e: np.ndarray, band: float = 0.2) -> int:
    """Sign changes of ``e`` past ``±band`` (a Schmitt trigger: noise inside does not count)."""
    state, n = 0, 0
    for v in e:
        new = 1 if v > band else -1 if v < -band else state
        n += bool(state and new != state)
        state = new
    return n


def test_a_sticking_valve_makes_the_t_rx_loop_cycle() -> None:
    n, seeds = 1300, (3, 4)
    sticky = _closed("valve-stiction", seeds=seeds, n=n, magnitude=0.05)
    healthy = simulate_episodes(list(seeds), n, plant=CLOSED)

    def cycling(r) -> list[int]:  # the true riser outlet about its set point, after the onset
        e = r.aux[:, 300:, AUX_NAMES.index("T_rx")] - r.setpoints[:, 300:, 0]
        return [_crossings(row) for row in e]

    # lab/actuator-faults.md: a period of about 10 min (60 samples); here 34 and 36 crossings
    # against the healthy loop's 7 and 7 (its set-point steps)
    for stuck, free in zip(cycling(sticky), cycling(healthy), strict=True):
        assert stuck > max(3 * free, 20), (stuck, free)


@pytest.mark.parametrize("name", ["valve-stuck", "valve-stiction"])
def test_a_valve_fault_from_the_first_sample_holds_the_valve_where_commanded(name: str) -> None:
    b = simulate_episodes([3], N, fault=FaultSpec(scenario=name, onset=0), plant=CLOSED)
    u = b.inputs[0, :, 0]
    assert u[0] == pytest.approx(NOMINAL_INPUTS[0]) and np.count_nonzero(np.diff(u)) < N / 10
