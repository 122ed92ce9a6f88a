"""``FCC-control-v0``'s single-env reward in Python floats (issue 44, item 5): the same bits as
before, as the array path of the vector env, and a plant identical to ``FCC-closedloop-v0``."""

from __future__ import annotations

import math
import pickle

import gymnasium as gym
import numpy as np
import pytest
from control_reference import DT_S, ECONOMICS, REFERENCE, step_info

import fcc_env
from fcc_env.control_task import (
    REWARD_TERMS,
    EconomicReward,
    reward_term_arrays,
    reward_terms,
    total_reward,
)


def _bits(values) -> np.ndarray:
    """The IEEE-754 bit patterns of ``values`` (so that 0.0 and -0.0 differ)."""
    return np.asarray(values, dtype=np.float64).view(np.int64)


def test_reward_matches_the_stored_reference_bit_for_bit():
    if not REFERENCE.exists():
        pytest.fail(f"{REFERENCE} is missing: regenerate it with python tests/control_reference.py")
    ref = np.load(REFERENCE)
    rows = {k: ref[k] for k in ("state", "inputs", "X", "coke_make", "sat", "terminated")}
    n = len(rows["X"])
    for j, e in enumerate(ECONOMICS):
        got = np.empty((n, len(REWARD_TERMS)))
        reward = np.empty(n)
        for i in range(n):
            terms = reward_terms(step_info(rows, i), bool(rows["terminated"][i]), e, DT_S)
            assert tuple(terms) == REWARD_TERMS and all(type(v) is float for v in terms.values())
            got[i] = list(terms.values())
            reward[i] = math.fsum(terms.values())
        bad = np.argwhere(_bits(got) != _bits(ref["terms"][j]))
        assert bad.size == 0, f"economics {j}: (row, term) {bad[:5].tolist()} differ"
        np.testing.assert_array_equal(_bits(reward), _bits(ref["reward"][j]))


def _edge_infos(n: int, rng: np.random.Generator) -> dict[str, np.ndarray]:
    """``n`` envs' infos with values at and across every threshold, infinities and -0.0."""
    e = EconomicReward()
    x = np.tile([4e4, 0.01, 9e4, 0.0035, 685.0, 9e4, 0.002, 719.4, 3e4, 697.2, 710.2], (n, 1))
    x *= rng.uniform(0.5, 1.5, x.shape)
    x[0, 7], x[1, 4], x[2, 8] = e.regenerator_max_C, e.regenerator_min_C, e.well_min_t * 1000
    x[3, 9] = x[3, 4] + 40.0  # the afterburn warning exactly
    x[4, 7], x[5, 4], x[6, 9] = np.inf, -np.inf, np.inf
    u = np.tile([416.7, 148.4, 200.0, 230.0, 61.111, 1.0], (n, 1)) * rng.uniform(0, 2, (n, 6))
    u[7, 4], u[8, 1] = -0.0, 0.0
    x[9, 8] = 0.0
    return {
        "state": x,
        "inputs": u,
        "X": rng.uniform(0.0, 1.0, n),
        "coke_make": np.r_[-0.0, rng.uniform(0.0, 5.0, n - 1)],
        "controller_saturated": rng.random(n) < 0.5,
    }


@pytest.mark.parametrize(
    "economics",
    [
        EconomicReward(),
        EconomicReward(trip_usd=200_000, coke_usd_per_t=np.float32(312.7), well_min_t=30),
        EconomicReward(well_min_t=-0.0),  # with an empty well: max(0, -0.0) must be +0.0
    ],
)
def test_one_env_floats_equal_the_vector_arrays_bit_for_bit(economics):
    rng = np.random.default_rng(1000)
    n = 200
    infos = _edge_infos(n, rng)
    terminated = rng.random(n) < 0.5
    arrays = reward_term_arrays(infos, terminated, economics, 10.0)
    sums = total_reward(arrays)
    for b in range(n):
        one = reward_terms({k: v[b] for k, v in infos.items()}, terminated[b], economics, 10.0)
        for name in REWARD_TERMS:
            assert _bits(one[name]) == _bits(arrays[name][b]), (b, name, one[name])
        assert _bits(math.fsum(one.values())) == _bits(sums[b]), b


def test_prices_are_stored_as_floats():
    e = EconomicReward(trip_usd=200_000, coke_usd_per_t=np.float32(312.5))
    assert type(e.trip_usd) is float and type(e.coke_usd_per_t) is float
    assert e == EconomicReward(trip_usd=200_000.0, coke_usd_per_t=312.5)


def test_the_control_env_is_the_closed_loop_env_plus_the_vector_envs_reward():
    kw = {"scenario": "f2", "fault_time": 30}
    ctrl = gym.make(fcc_env.CONTROL_ENV_ID, **kw)
    plant = gym.make(fcc_env.CLOSED_LOOP_ENV_ID, **kw)
    o1, i1 = ctrl.reset(seed=5000)
    o2, i2 = plant.reset(seed=5000)
    del i1["reward_terms"]
    assert pickle.dumps((o1, i1)) == pickle.dumps((o2, i2))
    rng = np.random.default_rng(5000)
    e = EconomicReward()
    for k in range(150):
        a = rng.uniform(-1.5, 1.5, 2).astype(np.float32)  # past the limits: clipped, flagged
        o1, r, t1, tr1, i1 = ctrl.step(a)
        o2, _, t2, tr2, i2 = plant.step(a)
        terms = i1.pop("reward_terms")
        # the plant's step, every info value with its type, bit for bit (pickle keeps -0.0)
        assert pickle.dumps((o1, t1, tr1, i1)) == pickle.dumps((o2, t2, tr2, i2)), k
        arrays = reward_term_arrays(i2, t2, e, 10.0)
        assert [_bits(v) for v in terms.values()] == [_bits(v) for v in arrays.values()], k
        assert type(r) is float and _bits(r) == _bits(total_reward(arrays)), k
