"""Sensor faults on the native vector envs (:mod:`fcc_env.sensor_kernel`) against
``SyncVectorEnv`` over single envs: the same numbers, bit for bit."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import fcc_env
from fcc_env.params import MEASUREMENT_NAMES

N_ENVS = 4


def _same(where: str, native: tuple, sync: tuple) -> None:
    """Observations, rewards, flags and every info key (values, dtypes, masks) equal; the
    control env's nested ``reward_terms`` term by term."""
    for name, a, b in zip(
        ("obs", "reward", "terminated", "truncated"), native[:-1], sync[:-1], strict=False
    ):
        assert a.dtype == b.dtype and np.array_equal(a, b), f"{where}: {name} {a} != {b}"
    info_a, info_b = native[-1], sync[-1]
    assert info_a.keys() == info_b.keys(), f"{where}: info keys {info_a.keys() ^ info_b.keys()}"
    for key, b in info_b.items():
        a = info_a[key]
        if isinstance(b, dict):
            assert a.keys() == b.keys(), f"{where}: {key}"
            assert all(np.array_equal(a[t], b[t]) and a[t].dtype == b[t].dtype for t in b), key
            continue
        same = a.tolist() == b.tolist() if b.dtype == object else np.array_equal(a, b)
        assert a.dtype == b.dtype and same, f"{where}: info[{key!r}] {a} != {b}"


def _run_both(env_id: str, steps: int, seed: int, **kwargs) -> np.ndarray:
    """Both vector envs stepped with the same random actions; the native observations."""
    native = gym.make_vec(env_id, N_ENVS, vectorization_mode="vector_entry_point", **kwargs)
    sync = gym.make_vec(env_id, N_ENVS, vectorization_mode="sync", **kwargs)
    out = native.reset(seed=seed)
    _same("reset", out, sync.reset(seed=seed))
    rng = np.random.default_rng(7)
    seen = [out[0]]
    for t in range(steps):
        a = rng.uniform(-1.2, 1.2, native.action_space.shape).astype(np.float32)
        out = native.step(a)
        _same(f"step {t}", out, sync.step(a))
        seen.append(out[0])
    return np.stack(seen)


@pytest.mark.parametrize(
    ("scenario", "channel", "extra"),
    [
        ("sensor-stuck", "T_rg1", {}),  # a loop transmitter: the air loop reads a frozen bed
        ("sensor-bias", "T_rx", {"fault_profile": "incipient", "ramp_samples": 15}),
        ("sensor-drift", "T_dg", {"fault_magnitude": 2.0}),  # no loop reads it
        ("sensor-noise", "R_ar", {}),
    ],
)
def test_closed_loop_sensor_faults_match_sync_across_autoresets(scenario, channel, extra):
    kw = {"scenario": scenario, "fault_channel": channel, "fault_time": 20,
          "max_episode_steps": 70, **extra}  # fmt: skip
    obs = _run_both(fcc_env.CLOSED_LOOP_ENV_ID, 150, 11, **kw)
    healthy = _run_both(
        fcc_env.CLOSED_LOOP_ENV_ID, 150, 11, scenario="nominal", max_episode_steps=70
    )
    ch = MEASUREMENT_NAMES.index(channel)
    after = slice(22, 70)  # the first episode, after the onset (its sample k is row k)
    moved = obs[after, :, ch] != healthy[after, :, ch]
    assert moved.all(), f"{scenario} on {channel} left the reading as the healthy plant's"
    if scenario == "sensor-stuck":  # the reading and its noise draw held: the same bits
        assert (obs[after, :, ch] == obs[19, :, ch]).all()


def test_the_sensor_catalogue_matches_the_sync_control_env_bit_for_bit():
    # short episodes whose draws fall inside them (onset in the middle half of 80 samples)
    kw = {"catalogue": "sensor", "horizon": 80, "max_episode_steps": 79}
    native = gym.make_vec(fcc_env.CONTROL_ENV_ID, N_ENVS, vectorization_mode="vector_entry_point", **kw)  # fmt: skip
    sync = gym.make_vec(fcc_env.CONTROL_ENV_ID, N_ENVS, vectorization_mode="sync", **kw)
    out = native.reset(seed=[1000, 1001, 1002, 1003])
    _same("reset", out, sync.reset(seed=[1000, 1001, 1002, 1003]))
    rng = np.random.default_rng(3)
    drawn = set()
    for t in range(320):  # four episodes per env, the later ones from the continued generators
        a = rng.uniform(-1.2, 1.2, (N_ENVS, 2)).astype(np.float32)
        out = native.step(a)
        _same(f"step {t}", out, sync.step(a))
        channels = out[-1].get("fault_channel", np.full(N_ENVS, None))
        drawn |= set(zip(out[-1]["scenario"].tolist(), channels.tolist(), strict=True))
    scenarios = {s for s, _ in drawn}
    assert "nominal" in scenarios and len(scenarios) >= 3, drawn
    assert scenarios <= {"nominal", "sensor-bias", "sensor-drift", "sensor-stuck"}, drawn
    assert any(c in ("T_rx", "T_rg1") for _, c in drawn), drawn


def test_what_the_native_env_cannot_carry_is_refused_by_name():
    with pytest.raises(ValueError, match=r"catalogue='all'.*actuator fault.*catalogue='sensor'"):
        gym.make_vec(fcc_env.CONTROL_ENV_ID, 2, vectorization_mode="vector_entry_point", catalogue="all")  # fmt: skip
    with pytest.raises(ValueError, match=r"catalogue='sensor'.*\['fault_time'\] would be ignored"):
        gym.make_vec(fcc_env.CONTROL_ENV_ID, 2, vectorization_mode="vector_entry_point",
                     catalogue="sensor", fault_time=30)  # fmt: skip
    envs = gym.make_vec(fcc_env.CLOSED_LOOP_ENV_ID, 2, vectorization_mode="vector_entry_point",
                        scenario="sensor-dropout")  # fmt: skip
    with pytest.raises(ValueError, match=r"scenario='sensor-dropout'.*\['dropout'\]"):
        envs.reset(seed=0)
    envs = gym.make_vec(fcc_env.CLOSED_LOOP_ENV_ID, 2, vectorization_mode="vector_entry_point",
                        scenario="valve-stiction")  # fmt: skip
    with pytest.raises(ValueError, match=r"scenario='valve-stiction'.*actuator device"):
        envs.reset(seed=0)
