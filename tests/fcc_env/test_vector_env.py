"""The native vector env (:class:`fcc_env.vector_env.FCCVectorEnv`) against ``SyncVectorEnv``.

Gymnasium (1.4) ships no checker for vector envs (``gymnasium.utils`` has ``env_checker`` for
single envs only), so the spaces are checked on every step here.
"""

from __future__ import annotations

import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

import fcc_env
from fcc_env.vector_env import VECTOR_ENTRY_POINT, FCCVectorEnv

N_ENVS = 4
#: Short episodes so that a few hundred steps cross several autoresets.
SHORT = 120
#: A plant effect that ends f1 episodes by afterburn after about 50 samples (terminations).
HOT_LOSS = {"scenario": "f1", "fault_time": 5, "plant_effects": ["heat_loss:stage1,extra_ua_kw_per_k=50"]}  # fmt: skip


def make_pair(env_id: str, **kwargs: object) -> tuple[gym.vector.VectorEnv, gym.vector.VectorEnv]:
    native = gym.make_vec(env_id, N_ENVS, vectorization_mode="vector_entry_point", **kwargs)
    sync = gym.make_vec(env_id, N_ENVS, vectorization_mode="sync", **kwargs)
    return native, sync


def assert_same(where: str, native: tuple, sync: tuple) -> None:
    """Observations, rewards, flags and every info key (values, dtypes and masks) equal."""
    names = ("obs", "reward", "terminated", "truncated")
    for name, a, b in zip(names, native[:-1], sync[:-1], strict=False):
        assert a.dtype == b.dtype and np.array_equal(a, b), f"{where}: {name} {a} != {b}"
    info_a, info_b = native[-1], sync[-1]
    assert info_a.keys() == info_b.keys(), f"{where}: info keys {info_a.keys() ^ info_b.keys()}"
    for key, b in info_b.items():
        a = info_a[key]
        same = a.tolist() == b.tolist() if b.dtype == object else np.array_equal(a, b)
        assert a.dtype == b.dtype and same, f"{where}: info[{key!r}] {a} != {b}"


def run_both(env_id: str, steps: int, seed: int | list, action_high: float = 1.2, **kwargs):
    """Step both vector envs with the same random actions; returns the native flags seen."""
    native, sync = make_pair(env_id, **kwargs)
    assert_same("reset", native.reset(seed=seed), sync.reset(seed=seed))
    rng = np.random.default_rng(7)
    seen = {"terminated": 0, "truncated": 0}
    for t in range(steps):
        a = rng.uniform(-action_high, action_high, native.action_space.shape).astype(np.float32)
        out = native.step(a)
        assert_same(f"step {t}", out, sync.step(a))
        assert native.observation_space.contains(out[0]), f"step {t}: obs outside the space"
        seen["terminated"] += int(out[2].sum())
        seen["truncated"] += int(out[3].sum())
    return seen


def test_open_loop_fault_matches_sync_across_autoresets():
    seen = run_both(fcc_env.ENV_ID, 300, 3, scenario="f1", fault_time=50, max_episode_steps=SHORT)
    assert seen["truncated"] == 2 * N_ENVS  # two truncations per env, each then autoreset


def test_closed_loop_matches_sync_across_autoresets():
    seen = run_both(fcc_env.CLOSED_LOOP_ENV_ID, 300, [11, 5, 2, 9], max_episode_steps=SHORT)
    assert seen["truncated"] == 2 * N_ENVS


@pytest.mark.parametrize("env_id", [fcc_env.ENV_ID, fcc_env.CLOSED_LOOP_ENV_ID])
def test_terminations_and_parameter_effects_match_sync(env_id):
    seen = run_both(env_id, 150, 0, **HOT_LOSS)
    assert seen["terminated"] >= N_ENVS


def test_random_scenarios_incipient_faults_and_chunk_boundaries_match_sync():
    # 600 steps cross the first 512-sample chunk; random faults give differing multipliers.
    # Seed 0 gives env 0 a nominal episode, whose info has no fault_time (masked in both)
    seen = run_both(
        fcc_env.ENV_ID, 600, 0, scenario="random", fault_time=40, fault_profile="incipient",
        ramp_samples=30, noise_scale=2.0, rk4_substeps=2,
    )  # fmt: skip
    assert seen["truncated"] == 0


@pytest.mark.parametrize("seed", [0, 16])
def test_sync_takes_random_episodes_whichever_env_is_healthy(seed):
    # seed 16 gives env 0 a fault and env 3 a healthy episode: a None fault_time there
    # used to break SyncVectorEnv, which types a key by the first env that reports it
    native, sync = make_pair(fcc_env.ENV_ID, scenario="random")
    out_n, out_s = native.reset(seed=seed), sync.reset(seed=seed)
    assert_same("reset", out_n, out_s)
    scenarios = out_s[1]["scenario"]
    assert "nominal" in scenarios.tolist() and set(scenarios) != {"nominal"}
    assert out_s[1]["_fault_time"].tolist() == [sc != "nominal" for sc in scenarios]


def test_reset_options_and_reset_mask_match_sync():
    native, sync = make_pair(fcc_env.ENV_ID, scenario="f2", fault_time=20)
    assert_same("reset", native.reset(seed=1), sync.reset(seed=1))
    zero = np.zeros((N_ENVS, 2), np.float32)
    for _ in range(5):
        assert_same("step", native.step(zero), sync.step(zero))
    mask = np.array([True, False, True, False])
    options = {"scenario": "f4", "fault_time": 3, "reset_mask": mask}
    out_n = native.reset(seed=[40, None, 41, None], options=dict(options))
    out_s = sync.reset(seed=[40, None, 41, None], options=dict(options))
    assert_same("masked reset", out_n, out_s)
    assert out_n[1]["_t"].tolist() == mask.tolist()
    for t in range(10):
        assert_same(f"step {t} after the masked reset", native.step(zero), sync.step(zero))


def test_vector_api_and_registration():
    envs = gym.make_vec(fcc_env.ENV_ID, 3, vectorization_mode="vector_entry_point")
    assert isinstance(envs, FCCVectorEnv)
    assert envs.metadata["autoreset_mode"] is AutoresetMode.NEXT_STEP
    assert envs.max_episode_steps == fcc_env.MAX_EPISODE_STEPS
    assert envs.observation_space.shape == (3, 8) and envs.action_space.shape == (3, 2)
    assert envs.single_observation_space == gym.make(fcc_env.ENV_ID).observation_space
    assert envs.spec.vector_entry_point == VECTOR_ENTRY_POINT
    closed = FCCVectorEnv(2, regulatory=True)
    assert closed.single_observation_space.shape == (11,)


def test_onset_after_the_time_limit_warns_and_a_reachable_one_does_not():
    with pytest.warns(UserWarning, match=r"max_episode_steps=1000\) before its f1 fault onset"):
        FCCVectorEnv(2, scenario="f1", max_episode_steps=1000).reset(seed=0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        FCCVectorEnv(2, scenario="f1").reset(seed=0)


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (
            lambda e: e.step(np.zeros((3, 2))),
            r"actions='<float64 array of shape \(3, 2\)>' .* shape \(2, 2\)",
        ),
        (lambda e: e.step(np.array([[0, 0], [np.nan, 0]])), r"actions\[1\]=\[nan, 0.0\]"),
        (lambda e: e.reset(seed=[1]), r"seed=\[1\] .* num_envs=2"),
        (lambda e: e.reset(seed=-1), r"seed=-1 is outside the allowed range"),
        (lambda e: e.reset(options={"bogus": 1}), r"Unknown reset option\(s\) \['bogus'\]"),
    ],
)
def test_bad_calls_name_the_value(call, match):
    envs = FCCVectorEnv(2)
    envs.reset(seed=0)
    with pytest.raises(ValueError, match=match):
        call(envs)


def test_step_before_reset_asks_for_a_reset():
    with pytest.raises(gym.error.ResetNeeded, match=r"call reset\(\) before step\(\)"):
        FCCVectorEnv(2).step(np.zeros((2, 2)))


def test_bad_construction_names_the_value():
    with pytest.raises(ValueError, match=r"scenario='f9' is outside the allowed range"):
        FCCVectorEnv(2, scenario="f9")
    with pytest.raises(ValueError, match=r"num_envs=0 is outside the allowed range"):
        FCCVectorEnv(0)
    with pytest.raises(ValueError, match=r"render_mode='rgb_array'.*SyncVectorEnv"):
        FCCVectorEnv(2, render_mode="rgb_array")
    with pytest.raises(ValueError, match=r"plant_effects=.*vectorization_mode='sync'"):
        FCCVectorEnv(2, plant_effects=["sensor_bias:T_rx"]).reset(seed=0)


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--envs", "0"], "--envs 0 is outside the allowed range: an integer >= 1"),
        (["--steps", "-1"], "--steps -1 is outside the allowed range"),
        (["--sync-steps", "0"], "--sync-steps 0 is outside the allowed range"),
        (["--threads", "999"], "--threads 999 is outside the allowed range: 1.."),
    ],
)
def test_vector_speed_refuses_bad_flags_by_value(argv, message, capsys):
    from bench.vector_speed import main

    with pytest.raises(SystemExit) as e:
        main(argv)
    assert e.value.code == 2 and message in capsys.readouterr().err
