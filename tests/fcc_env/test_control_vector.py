"""The native vector env of ``FCC-control-v0`` against ``SyncVectorEnv`` over single envs."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import fcc_env
from fcc_env.control_task import REWARD_TERMS, EconomicReward, reward_term_arrays, reward_terms
from fcc_env.control_vector import FCCControlVectorEnv

N_ENVS = 4
#: f1 with a plant effect that ends episodes by afterburn after about 50 samples (trips), and
#: a short limit: 250 steps cross terminations, truncations and their autoresets.
TRIPS = {"scenario": "f1", "fault_time": 5, "max_episode_steps": 100,
         "plant_effects": ["heat_loss:stage1,extra_ua_kw_per_k=50"]}  # fmt: skip


def test_rewards_and_terms_equal_single_envs_bit_for_bit():
    kw = TRIPS
    native = gym.make_vec(fcc_env.CONTROL_ENV_ID, N_ENVS, vectorization_mode="vector_entry_point", **kw)  # fmt: skip
    sync = gym.make_vec(fcc_env.CONTROL_ENV_ID, N_ENVS, vectorization_mode="sync", **kw)
    assert isinstance(native.unwrapped, FCCControlVectorEnv)
    (oa, ia), (ob, ib) = native.reset(seed=[3, 8, 1, 4]), sync.reset(seed=[3, 8, 1, 4])
    assert np.array_equal(oa, ob) and ia["reward_terms"].keys() == ib["reward_terms"].keys()
    rng = np.random.default_rng(7)
    trips = 0
    for t in range(250):
        a = rng.uniform(-1.2, 1.2, (N_ENVS, 2)).astype(np.float32)
        out_a, out_b = native.step(a), sync.step(a)
        for i, name in enumerate(("obs", "reward", "terminated", "truncated")):
            x, y = out_a[i], out_b[i]
            assert x.dtype == y.dtype and np.array_equal(x, y), f"step {t}: {name} {x} != {y}"
        ta, tb = out_a[4]["reward_terms"], out_b[4]["reward_terms"]
        assert ta.keys() == tb.keys()
        for key, y in tb.items():
            assert ta[key].dtype == y.dtype and np.array_equal(ta[key], y), f"step {t}: {key}"
        trips += int((out_a[4]["reward_terms"]["trip"] < 0).sum())
    assert trips >= N_ENVS  # the trip term was exercised


def test_term_arrays_over_envs_equal_the_terms_of_each_env():
    rng = np.random.default_rng(0)
    n = 6
    info = {
        "state": rng.uniform(0, 800, (n, 11)), "inputs": rng.uniform(0, 500, (n, 6)),
        "X": rng.uniform(0, 1, n), "coke_make": rng.uniform(0, 5, n),
        "controller_saturated": rng.uniform(size=n) < 0.5,
    }  # fmt: skip
    done = rng.uniform(size=n) < 0.5
    e = EconomicReward()
    arrays = reward_term_arrays(info, done, e, 10.0)
    for b in range(n):
        one = reward_terms({k: v[b] for k, v in info.items()}, bool(done[b]), e, 10.0)
        assert tuple(one) == REWARD_TERMS
        assert all(one[k] == arrays[k][b] for k in REWARD_TERMS), b


def test_limit_before_the_onset_warns_and_reset_mask_clears_autoreset():
    with pytest.warns(UserWarning, match=r"before its f1 fault onset"):
        envs = gym.make_vec(fcc_env.CONTROL_ENV_ID, 2, vectorization_mode="vector_entry_point",
                            scenario="f1", max_episode_steps=10)  # fmt: skip
        envs.reset(seed=0)
    envs = FCCControlVectorEnv(2, scenario="nominal", max_episode_steps=3)
    envs.reset(seed=0)
    for _ in range(3):
        _, reward, _, truncated, _ = envs.step(np.zeros((2, 2)))
    assert truncated.all() and (reward > 0).all()
    _, info = envs.reset(options={"reset_mask": np.array([True, False])})
    assert info["_reward_terms"].tolist() == [True, False]
    _, reward, _, truncated, _ = envs.step(np.zeros((2, 2)))
    assert reward[0] > 0 and reward[1] == 0.0  # env 1 spends the step on its autoreset
