"""``FCC-control-v0``'s catalogue keyword: the default draw unchanged, ``"all"`` over every class."""

from __future__ import annotations

import collections

import gymnasium as gym
import numpy as np
import pytest

import fcc_env  # noqa: F401 (registers the envs)
from fcc_env.control_draws import (
    LEFT_OUT,
    LOOP_CHANNELS,
    FaultClass,
    class_scenarios,
    draw_catalogue_fault,
    fault_class,
)
from fcc_env.scenarios import fault_definition

# FCC-control-v0's random draw on seeds 0-7 before the catalogue keyword existed (main at
# d9393ee): scenario and onset. The default must keep them, bit for bit below.
PINNED = [
    ("nominal", -1),
    ("f3", 2222),
    ("f1", 1063),
    ("f4", 2565),
    ("f2", 2110),
    ("f2", 1329),
    ("f1", 1266),
    ("f4", 2716),
]


def test_default_draw_is_unchanged():
    default = gym.make("FCC-control-v0")
    paper = gym.make("FCC-control-v0", catalogue="paper")
    plant = gym.make("FCC-closedloop-v0", scenario="random")  # never passes the new code
    for seed, (scenario, onset) in enumerate(PINNED):
        obs = [env.reset(seed=seed)[0] for env in (default, paper, plant)]
        assert default.unwrapped.plant.fault.scenario == scenario, seed
        assert default.unwrapped.plant.fault.onset == onset, seed
        np.testing.assert_array_equal(obs[0], obs[1])
        np.testing.assert_array_equal(obs[0], obs[2])
    for _ in range(20):  # a few steps too: the same plant, the same noise
        steps = [env.step(np.array([0.3, -0.2]))[0] for env in (default, plant)]
        np.testing.assert_array_equal(steps[0], steps[1])


def test_all_draws_every_class_within_sizes():
    env = gym.make("FCC-control-v0", catalogue="all")
    seen = collections.Counter()
    channels = collections.Counter()
    for seed in range(5000, 5160):
        _, info = env.reset(seed=seed)
        fault = env.unwrapped.plant.fault
        seen[fault_class(fault.scenario)] += 1
        assert fault.scenario not in LEFT_OUT
        if not fault.nominal:
            d = fault_definition(fault.scenario)
            assert 0.5 * d.default_magnitude - 1e-12 <= fault.magnitude <= d.max_magnitude
            assert 4000 // 4 <= fault.onset < 3 * 4000 // 4
        if fault.channel is not None:
            channels[fault.channel in LOOP_CHANNELS] += 1
    assert set(seen) == set(FaultClass)
    # each class a quarter: 40 of 160 expected, binomial sd 5.5
    assert all(20 <= n <= 60 for n in seen.values()), seen
    assert channels[True] >= 10 and channels[False] >= 10, channels


def test_all_draw_is_reproducible_and_keeps_the_plants_noise():
    env = gym.make("FCC-control-v0", catalogue="all")
    obs_a, info_a = env.reset(seed=5007)
    fault = env.unwrapped.plant.fault
    obs_b, _ = env.reset(seed=5007)
    np.testing.assert_array_equal(obs_a, obs_b)
    assert env.unwrapped.plant.fault == fault
    # the same fault fixed by keywords: the same noise (the draw has its own stream)
    fixed = gym.make(
        "FCC-control-v0",
        scenario=fault.scenario,
        fault_time=None if fault.nominal else fault.onset,
        fault_magnitude=None if fault.nominal else fault.magnitude,
        fault_channel=fault.channel,
    )
    obs_c, _ = fixed.reset(seed=5007)
    np.testing.assert_array_equal(obs_a, obs_c)


def test_draw_consumes_a_fixed_count():
    a, b = np.random.default_rng(1), np.random.default_rng(1)
    for _ in range(30):
        draw_catalogue_fault(a, 4000)
        b.random(5)
        b.integers(1000, 3000)
    assert a.random() == b.random()


def test_class_scenarios_cover_the_registry():
    by_class = class_scenarios()
    assert by_class[FaultClass.HEALTHY] == ("nominal",)
    assert by_class[FaultClass.PROCESS][:4] == ("f1", "f2", "f3", "f4")
    assert set(by_class[FaultClass.SENSOR]) == {"sensor-bias", "sensor-drift", "sensor-stuck"}
    assert set(by_class[FaultClass.ACTUATOR]) >= {"valve-stiction", "blower-capacity"}


def test_bad_catalogue_is_refused():
    with pytest.raises(ValueError, match=r"catalogue='everything'.*paper"):
        gym.make("FCC-control-v0", catalogue="everything")
    with pytest.raises(ValueError, match="fault_time"):
        gym.make("FCC-control-v0", catalogue="all", fault_time=1500)


def test_the_native_vector_env_refuses_the_whole_catalogue_by_name():
    with pytest.raises(ValueError, match="vectorization_mode='sync'"):
        gym.make_vec("FCC-control-v0", 2, vectorization_mode="vector_entry_point", catalogue="all")
    sync = gym.make_vec("FCC-control-v0", 2, vectorization_mode="sync", catalogue="all")
    sync.reset(seed=[5000, 5003])
    assert sync.envs[1].unwrapped.plant.fault.scenario == "f2"  # seed 5003's draw
