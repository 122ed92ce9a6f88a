"""Bad input to the environment, the batch simulator and the dataset CLI gives one clear message
naming the value (the rest of the project's bad-input tests are in ``tests/test_bad_input.py``)."""

from __future__ import annotations

import re
import time

import gymnasium as gym
import numpy as np
import pytest

import fcc_env
from fcc_env import simulate_episodes
from fcc_env.generate import main
from fcc_env.simulation import DEFAULT_MEMORY_BUDGET_BYTES, batch_nbytes


# ---- item 7: memory budget -------------------------------------------------------------------
def test_simulate_refuses_a_request_over_the_memory_budget() -> None:
    with pytest.raises(ValueError) as e:
        simulate_episodes(range(10**9), 2)
    msg = str(e.value)
    assert "1000000000 episodes x 2 samples" in msg and "644 GiB" in msg and "4 GiB" in msg
    with pytest.raises(ValueError, match=r"2 episodes x 5 samples .* budget of 1e-06 GiB"):
        simulate_episodes([0, 1], 5, memory_budget_bytes=2**30 * 1e-6)
    assert DEFAULT_MEMORY_BUDGET_BYTES == 4 * 2**30
    b = simulate_episodes([0], 3)
    arrays = (
        b.observations,
        b.y_clean,
        b.fault_active,
        b.inputs,
        b.states,
        b.aux,
        b.sensor_dropout,
    )
    assert sum(a.nbytes for a in arrays) == batch_nbytes(1, 3)


def test_generate_cli_refuses_before_building_the_seed_list(tmp_path, capsys) -> None:
    t0 = time.perf_counter()
    with pytest.raises(SystemExit) as e:
        main(["--seeds", "0-999999999", "--samples", "2", "--out", str(tmp_path / "x.csv")])
    assert e.value.code == 2 and time.perf_counter() - t0 < 5
    err = capsys.readouterr().err
    assert "--seeds 0-999999999 --samples 2" in err and "GiB" in err and "budget of 4 GiB" in err
    with pytest.raises(SystemExit):
        main(["--seeds", "0", "--out", str(tmp_path / "y.csv"), "--memory-budget-gib", "-1"])
    assert "--memory-budget-gib=-1.0" in capsys.readouterr().err
    assert not list(tmp_path.iterdir())


# ---- items 9-10: the environment and the batch simulator -------------------------------------
ENV_ID = "fcc/FCC-v0" if "fcc/FCC-v0" in gym.registry else "FCC-v0"


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda env: env.reset(options="f1"), r"options='f1' is outside .* a dict"),
        (lambda env: env.reset(seed=1.5), r"seed=1\.5 is outside the allowed range"),
        (lambda env: env.step(["a", "b"]), r"action=\['a', 'b'\] is outside .*dtype <U1"),
        (lambda env: env.step(np.array([1j, 0])), r"action=array\(\[0\.\+1\.j.*complex128"),
        (lambda env: env.step(None), r"action=None is outside"),
    ],
)
def test_env_bad_calls(call, match) -> None:
    env = gym.make(ENV_ID, horizon=10)
    env.reset(seed=0)
    with pytest.raises(ValueError, match=match):
        call(env)


def test_random_scenario_with_an_onset_beyond_the_horizon_fails_at_make() -> None:
    with pytest.raises(ValueError, match=r"fault_time=50 is outside .* \[0, 20\)"):
        gym.make(ENV_ID, scenario="random", fault_time=50, horizon=20)


@pytest.mark.parametrize(
    ("seeds", "match"),
    [
        ([1.5], r"seeds=\[1\.5\] .* \(1\.5 is not\)"),
        (3, r"seeds=3 is outside"),
        ("12", r"seeds='12' is outside"),
        (None, r"seeds=None is outside"),
    ],
)
def test_simulate_bad_seeds(seeds, match) -> None:
    with pytest.raises(ValueError, match=match):
        simulate_episodes(seeds, 3)


# ---- issue 45: each id takes exactly the keywords its docstring lists ---------------------------
CLOSED_IDS = (fcc_env.CLOSED_LOOP_ENV_ID, fcc_env.CONTROL_ENV_ID)


def _closed(env) -> bool:
    inner = env.unwrapped
    return getattr(inner, "plant", inner).closed_loop


@pytest.mark.parametrize("env_id", CLOSED_IDS)
@pytest.mark.parametrize("value", [False, None, "yes", 1, np.True_])
def test_a_closed_loop_id_refuses_an_open_loop_or_a_wrong_type(env_id, value) -> None:
    """``regulatory=False`` once built the open-loop plant under the closed-loop id; on the
    control id it raised ``TypeError: got multiple values``."""
    match = re.escape(
        f"regulatory={value!r} is outside the allowed range: True, a RegulatoryLayer or a "
        f"mapping of its fields ({env_id} is the plant under its regulatory layer; the "
        "open-loop plant is FCC-v0)"
    )
    with pytest.raises(ValueError, match=match):
        gym.make(env_id, regulatory=value)
    with pytest.raises(ValueError, match=match):
        gym.make_vec(env_id, 2, vectorization_mode="vector_entry_point", regulatory=value)


@pytest.mark.parametrize("env_id", CLOSED_IDS)
@pytest.mark.parametrize("value", [True, fcc_env.RegulatoryLayer(), {"program": None}])
def test_a_closed_loop_id_accepts_a_consistent_layer(env_id, value) -> None:
    env = gym.make(env_id, regulatory=value, horizon=20)
    obs, _ = env.reset(seed=0)
    assert _closed(env) and obs.shape == (11,)
    envs = gym.make_vec(env_id, 2, vectorization_mode="vector_entry_point", regulatory=value)
    assert envs.single_observation_space.shape == (11,)


def test_the_open_loop_id_keeps_its_keywords() -> None:
    assert not _closed(gym.make(fcc_env.ENV_ID, regulatory=False))
    assert _closed(gym.make(fcc_env.ENV_ID, regulatory=True))  # its docstring: closed by keyword
    # a plant without a layer on the closed-loop id gets the default one, as documented
    assert _closed(gym.make(fcc_env.CLOSED_LOOP_ENV_ID, plant=fcc_env.PlantConfig()))


@pytest.mark.parametrize("value", ["cheap", [1, 2], 5, b"x"])
def test_economics_of_a_wrong_type_is_refused_by_name(value) -> None:
    """A string was read as the names of its characters."""
    match = re.escape(f"economics={value!r} is outside the allowed range: an EconomicReward, a")
    with pytest.raises(ValueError, match=match):
        gym.make(fcc_env.CONTROL_ENV_ID, economics=value)
    with pytest.raises(ValueError, match=match):
        gym.make_vec(
            fcc_env.CONTROL_ENV_ID, 2, vectorization_mode="vector_entry_point", economics=value
        )


def test_economics_keys_and_values_are_refused_by_name() -> None:
    with pytest.raises(ValueError, match=r"Unknown economics option\(s\) \['price'\]"):
        gym.make(fcc_env.CONTROL_ENV_ID, economics={"price": 1.0})
    with pytest.raises(ValueError, match=r"trip_usd=-1 is outside the allowed range"):
        gym.make(fcc_env.CONTROL_ENV_ID, economics={"trip_usd": -1})


@pytest.mark.parametrize("env_id", [fcc_env.ENV_ID, *CLOSED_IDS])
def test_a_keyword_no_docstring_lists_is_refused_by_name(env_id) -> None:
    with pytest.raises(TypeError, match=r"unexpected keyword argument 'economy'"):
        gym.make(env_id, economy=1)
    if env_id != fcc_env.CONTROL_ENV_ID:  # only the control task has a reward to price
        with pytest.raises(TypeError, match=r"unexpected keyword argument 'economics'"):
            gym.make(env_id, economics={})


def test_a_string_for_a_mapping_of_fields_is_refused_not_split() -> None:
    from fcc_common.validation import from_fields

    with pytest.raises(ValueError, match=r"regulatory='loops' is outside the allowed range"):
        from_fields(fcc_env.RegulatoryLayer, "loops", "regulatory")
    with pytest.raises(ValueError, match=r"program='ab' is outside the allowed range"):
        gym.make(fcc_env.CLOSED_LOOP_ENV_ID, regulatory={"program": "ab"}).reset(seed=0)


def test_batch_simulation_refuses_loose_or_mistyped_requests_by_name() -> None:
    # the plant and the fault travel whole: anything else is refused naming what it got
    with pytest.raises(
        ValueError, match=r"fault='f1' is outside the allowed range: a FaultSpec \(one per seed\)"
    ):
        simulate_episodes([0], 5, fault=[fcc_env.FaultSpec(), "f1"][1:])
    with pytest.raises(
        ValueError, match=r"got 3 faults for 2 seeds; allowed: one, or one per seed"
    ):
        simulate_episodes([0, 1], 5, fault=[fcc_env.FaultSpec()] * 3)
    with pytest.raises(ValueError, match=r"plant=0\.5 is outside the allowed range: a PlantConfig"):
        simulate_episodes([0], 5, plant=0.5)
    with pytest.raises(
        TypeError, match=r"unknown env keyword\(s\) \['noise'\]; allowed: .*noise_scale"
    ):
        fcc_env.env_request(noise=2.0)
    with pytest.raises(ValueError, match=r"noise_scale=-1 is outside the allowed range"):
        fcc_env.env_request(noise_scale=-1)
    fault, plant = fcc_env.env_request(scenario="f2", fault_time=10, noise_scale=0.5)
    assert (fault.scenario, fault.onset, plant.noise_scale) == ("f2", 10, 0.5)


def test_simulated_data_refuses_a_plant_that_is_not_one() -> None:
    from evaluation.sweep.sources import SimulatedData

    with pytest.raises(
        ValueError, match=r"plant=\{'noise_scale': 2\.0\} is outside the allowed range"
    ):
        SimulatedData(plant={"noise_scale": 2.0}).validate()  # type: ignore[arg-type]
