"""The PPO agent's plumbing (issue 35): the SB3 adapter, safe saving, refusals."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

from evaluation.control import rl
from fcc_env.control_vector import FCCControlVectorEnv

SMALL = rl.PPOSettings(minutes=1, envs=4, n_steps=32, batch_size=64, n_epochs=1,
                       hidden=(8, 8), max_env_steps=128)  # fmt: skip


def test_adapter_resets_ended_envs_in_the_same_step_with_their_terminal_observation():
    pytest.importorskip("stable_baselines3")
    plain = FCCControlVectorEnv(2, scenario="nominal", max_episode_steps=5)
    adapted = rl.sb3_vec_env(FCCControlVectorEnv(2, scenario="nominal", max_episode_steps=5), 16.0)
    adapted.seed(1000)
    obs = adapted.reset()
    assert np.array_equal(obs, plain.reset(seed=1000)[0])
    zero = np.zeros((2, 2), np.float32)
    for k in range(1, 6):
        obs, reward, done, infos = adapted.step(zero)
        p_obs, p_reward, _, p_trunc, _ = plain.step(zero)
        assert np.array_equal(reward, (p_reward / 16.0).astype(np.float32))
        assert done.tolist() == p_trunc.tolist() == [k == 5] * 2
    for b in range(2):
        assert np.array_equal(infos[b]["terminal_observation"], p_obs[b])
        assert infos[b]["TimeLimit.truncated"] is True
        assert infos[b]["episode"]["l"] == 5
    # the plain env spends its next step on the autoreset; the adapter already did it
    restart_obs, restart_reward, *_ = plain.step(zero)
    assert np.array_equal(obs, restart_obs) and (restart_reward == 0).all()
    obs, reward, done, infos = adapted.step(zero)
    p_obs, p_reward, *_ = plain.step(zero)
    assert np.array_equal(obs, p_obs) and not done.any() and infos == [{}, {}]


def test_exported_actor_acts_as_sb3_and_reloads_identically_without_pickle(tmp_path):
    pytest.importorskip("stable_baselines3")
    state = np.random.get_state()  # SB3 seeds the global generator: training restores it
    policy, log = rl.train(SMALL)
    assert np.array_equal(np.random.get_state()[1], state[1])
    assert log["env_steps"] >= 128
    rl.save_policy(tmp_path, policy)
    with np.load(tmp_path / "policy.npz", allow_pickle=False) as data:
        assert sorted(data.files) == sorted(policy.weights)
    again = rl.load_policy(tmp_path)
    env = FCCControlVectorEnv(8, scenario="f2", fault_time=3)
    obs, _ = env.reset(seed=5000)
    for _ in range(5):
        a = again.act(obs)
        assert a.shape == (8, 2) and np.array_equal(a, policy.act(obs))
        assert np.all(np.abs(a) <= 1.0)
        obs, *_ = env.step(a)


def test_actor_matches_sb3_predict():
    pytest.importorskip("stable_baselines3")
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import VecNormalize

    env = VecNormalize(rl.sb3_vec_env(FCCControlVectorEnv(4, scenario="nominal")), norm_reward=False)  # fmt: skip
    model = PPO("MlpPolicy", env, policy_kwargs={"net_arch": [8, 8]}, device="cpu")
    env.obs_rms.mean, env.obs_rms.var = env.obs_rms.mean + 500.0, env.obs_rms.var * 40.0
    policy = rl.export_policy(model, env, rl.PPOSettings(hidden=(8, 8)))
    raw = env.venv.reset()
    expected, _ = model.predict(env.normalize_obs(raw), deterministic=True)
    np.testing.assert_allclose(policy.act(raw), expected, atol=1e-5)


def test_config_whose_shapes_disagree_with_the_weights_is_refused(tmp_path):
    weights = {"layer0.weight": np.zeros((8, 11), np.float32), "layer0.bias": np.zeros(8, np.float32),
               "layer1.weight": np.zeros((2, 8), np.float32), "layer1.bias": np.zeros(2, np.float32)}  # fmt: skip
    config = {"format": rl.FORMAT, "env_id": "FCC-control-v0", "activation": "tanh",
              "obs_dim": 11, "act_dim": 2, "hidden": [8],
              "obs_mean": [0.0] * 11, "obs_var": [1.0] * 11, "obs_epsilon": 1e-8, "obs_clip": 10.0,
              "action_low": [-1.0, -1.0], "action_high": [1.0, 1.0]}  # fmt: skip
    rl.save_policy(tmp_path, rl.MLPPolicy(config, weights))
    assert rl.load_policy(tmp_path).act(np.zeros(11)).shape == (2,)
    (tmp_path / "policy.json").write_text(json.dumps({**config, "hidden": [16]}))
    with pytest.raises(ValueError, match=r"policy.npz\['layer0.weight'\].shape=\(8, 11\) .*\(16, 11\)"):  # fmt: skip
        rl.load_policy(tmp_path)
    (tmp_path / "policy.json").write_text(json.dumps({**config, "obs_mean": [0.0] * 3}))
    with pytest.raises(ValueError, match=r"policy.json obs_mean='length 3'.*a list of 11 "):
        rl.load_policy(tmp_path)
    (tmp_path / "policy.npz").unlink()
    with pytest.raises(FileNotFoundError, match=r"no policy.npz there"):
        rl.load_policy(tmp_path)


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["train", "--minutes", "0", "--out", "x"], r"--minutes=0.0 is outside .*> 0"),
        (["train", "--envs", "0", "--out", "x"], r"--envs=0 is outside .*>= 1"),
        (["train", "--seed", "7", "--out", "x"], r"--seed=7 is outside .*1000\.\."),
        (["evaluate", "--policy", "nowhere"], r"--policy 'nowhere': no policy.json"),
    ],
)
def test_bad_values_are_refused_by_name(argv, message, capsys):
    with pytest.raises(SystemExit) as exit_info:
        rl.main(argv)
    assert exit_info.value.code == 2
    assert re.search(message, capsys.readouterr().err)
