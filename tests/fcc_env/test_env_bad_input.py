"""Bad input to the environment, the batch simulator and the dataset CLI gives one clear message
naming the value (the rest of the project's bad-input tests are in ``tests/test_bad_input.py``)."""

from __future__ import annotations

import time

import gymnasium as gym
import numpy as np
import pytest

from fcc_env import simulate_episodes
from fcc_env.generate import main
from fcc_env.simulation import DEFAULT_MEMORY_BUDGET_BYTES, batch_nbytes


# ---- item 7: memory budget -------------------------------------------------------------------
def test_simulate_refuses_a_request_over_the_memory_budget() -> None:
    with pytest.raises(ValueError) as e:
        simulate_episodes(range(10**9), 2)
    msg = str(e.value)
    assert "1000000000 episodes x 2 samples" in msg and "643 GiB" in msg and "4 GiB" in msg
    with pytest.raises(ValueError, match=r"2 episodes x 5 samples .* budget of 1e-06 GiB"):
        simulate_episodes([0, 1], 5, memory_budget_bytes=2**30 * 1e-6)
    assert DEFAULT_MEMORY_BUDGET_BYTES == 4 * 2**30
    b = simulate_episodes([0], 3)
    arrays = (b.observations, b.y_clean, b.fault_active, b.inputs, b.states, b.aux)
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
