"""The native vector envs' thread policy (issue 45, item 4): ``threads=`` and its default, and
the same numbers on any number of threads."""

from __future__ import annotations

import os

import gymnasium as gym
import numba
import numpy as np
import pytest
from test_vector_env import HOT_LOSS, assert_same

import fcc_env
from fcc_env.vector_threads import MIN_ENVS_PER_THREAD, vector_threads

TWO_THREADS = pytest.mark.skipif(
    numba.config.NUMBA_NUM_THREADS < 2, reason="numba's pool has one thread on this machine"
)


def rollout(env_id: str, n: int, threads: int | None, steps: int, **kwargs: object) -> list:
    """Every step's output of ``n`` envs on ``threads`` numba threads (random actions past ±1)."""
    envs = gym.make_vec(
        env_id, n, vectorization_mode="vector_entry_point", threads=threads, **kwargs
    )
    out = [envs.reset(seed=5000)]
    rng = np.random.default_rng(5000)
    for _ in range(steps):
        out.append(envs.step(rng.uniform(-1.2, 1.2, envs.action_space.shape)))
    envs.close()
    return out


@TWO_THREADS
@pytest.mark.parametrize(
    ("env_id", "kwargs"),
    [
        (fcc_env.ENV_ID, HOT_LOSS),
        (fcc_env.CONTROL_ENV_ID, {"max_episode_steps": 60, "scenario": "f2", "fault_time": 20}),
    ],
)
def test_one_and_two_threads_give_the_same_numbers(env_id, kwargs):
    # terminations (HOT_LOSS) and truncations (60 steps) with autoresets in both
    one = rollout(env_id, 48, 1, 130, **kwargs)
    two = rollout(env_id, 48, 2, 130, **kwargs)
    for t, (a, b) in enumerate(zip(one, two, strict=True)):
        if env_id == fcc_env.CONTROL_ENV_ID:  # the reward terms are a nested dict of arrays
            ta, tb = a[-1].pop("reward_terms"), b[-1].pop("reward_terms")
            assert all(np.array_equal(ta[k], tb[k]) for k in tb), f"step {t}: reward terms"
        assert_same(f"step {t}", (a[0], a[-1]) if t == 0 else a, (b[0], b[-1]) if t == 0 else b)
    ended = sum(int(o[2].sum() + o[3].sum()) for o in one[1:])
    assert ended > 0  # the rollout crossed episode ends


def test_the_default_is_serial_below_its_threshold_and_capped_by_numba_and_the_cores():
    cap = min(numba.get_num_threads(), len(os.sched_getaffinity(0)))
    assert vector_threads(MIN_ENVS_PER_THREAD - 1) == 1
    assert vector_threads(1) == 1
    assert vector_threads(2 * MIN_ENVS_PER_THREAD) == min(2, cap)
    assert vector_threads(10**6) == cap
    assert vector_threads(10**6, threads=1) == 1  # a request wins
    before = numba.get_num_threads()
    numba.set_num_threads(1)  # as a pool worker or the RL trainer does
    try:
        assert vector_threads(10**6) == 1
    finally:
        numba.set_num_threads(before)


@pytest.mark.parametrize(
    ("threads", "match"),
    [
        (0, r"threads=0 is outside the allowed range"),
        (numba.config.NUMBA_NUM_THREADS + 1, r"NUMBA_NUM_THREADS"),
        ("2", r"threads='2'"),
        (1.5, r"threads=1.5"),
    ],
)
def test_bad_threads_are_refused_by_value(threads, match):
    for env_id in (fcc_env.CLOSED_LOOP_ENV_ID, fcc_env.CONTROL_ENV_ID):
        with pytest.raises(ValueError, match=match):
            gym.make_vec(env_id, 2, vectorization_mode="vector_entry_point", threads=threads)


def test_a_step_leaves_numbas_thread_count_as_it_was():
    before = numba.get_num_threads()
    envs = gym.make_vec(fcc_env.ENV_ID, 4, vectorization_mode="vector_entry_point", threads=1)
    envs.reset(seed=0)
    envs.step(np.zeros((4, 2)))
    assert numba.get_num_threads() == before and envs.unwrapped.threads == 1
