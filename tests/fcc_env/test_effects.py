"""Undeclared plant effects: library, env/batch plumbing, exactness, signatures."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import fcc_env
from fcc_env import effects
from fcc_env.simulation import simulate_inputs

ZERO = np.zeros(2, dtype=np.float32)


def env_rollout(n, seed, **kwargs):
    env = gym.make("FCC-v0", max_episode_steps=n - 1, horizon=n, **kwargs)
    obs, info = env.reset(seed=seed)
    ys, infos = [obs], [info]
    for _ in range(n - 1):
        obs, _, term, trunc, info = env.step(ZERO)
        ys.append(obs)
        infos.append(info)
    return np.array(ys), infos


class ExtraStage1Loss:
    """A user effect: the same physics as heat_loss:stage1, written as a derivative term."""

    def __init__(self, extra_ua):
        self.extra_ua = extra_ua

    def d_state(self, t, x, u, params):
        d = np.zeros_like(x)
        d[..., 4] = -self.extra_ua * (x[..., 4] - params.T_amb_C) / (x[..., 2] * params.cp_c)
        return d


class Offset:
    def measure(self, t, y):
        y = np.array(y, copy=True)
        y[..., 6] += 2.0 + 0.001 * t
        return y


def test_library_lists_every_kind_with_targets():
    ids = effects.available()
    for unit in ("stage1", "stage2", "dilute1", "dilute_general"):
        assert f"heat_loss:{unit}" in ids
    for ch in fcc_env.MEASUREMENT_NAMES:
        for kind in ("sensor_lag", "sensor_bias", "sensor_drift"):
            assert f"{kind}:{ch}" in ids
    for eid in ("catalyst_deactivation", "feed_coking_drift", "air_split", "afterburn:dilute1"):
        assert eid in ids
    e = effects.make("sensor_lag:T_rx", tau_s=45)
    assert e.describe() == {"id": "sensor_lag:T_rx", "params": {"tau_s": 45.0}}


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: effects.make("heat_loss:reactor"), r"Unknown plant effect 'heat_loss:reactor'"),
        (
            lambda: effects.make("sensor_bias:T_rx", offset=1),
            r"Unknown parameter\(s\) \['offset'\]",
        ),
        (
            lambda: effects.make("sensor_lag:T_rx", tau_s=0),
            r"tau_s=0 is outside the allowed range: a number in \[1, 1800\] s",
        ),
        (lambda: effects.parse("sensor_bias:T_fp,bias"), r"use name=value"),
        (lambda: effects.resolve([object()]), r"neither a library id"),
    ],
)
def test_bad_effects(call, match):
    with pytest.raises(ValueError, match=match):
        call()


@pytest.mark.parametrize(
    "plant_effects",
    [
        ["heat_loss:stage1"],
        ["feed_coking_drift,rise_per_day=0.5", "sensor_lag:T_rg2,tau_s=90"],
        ["catalyst_deactivation", "sensor_drift:T_dg"],
        [ExtraStage1Loss(4.0), Offset()],
    ],
    ids=["param", "input+lag", "deactivation+drift", "user-d_state+measure"],
)
def test_env_equals_batch_with_effects(plant_effects):
    n = 120
    batch = fcc_env.simulate_episodes(
        [2, 9], n, fault=fcc_env.FaultSpec(scenario="f1", onset=60), plant_effects=plant_effects
    )
    for b, seed in enumerate((2, 9)):
        ys, infos = env_rollout(n, seed, scenario="f1", fault_time=60, plant_effects=plant_effects)
        np.testing.assert_array_equal(ys, batch.observations[b])
        np.testing.assert_array_equal([i["state"] for i in infos], batch.states[b])


def test_effects_are_not_declared_in_info():
    _, with_fx = env_rollout(5, 0, plant_effects=["heat_loss:stage1"])
    _, without = env_rollout(5, 0)
    assert with_fx[-1].keys() == without[-1].keys()
    assert "plant_effects" not in with_fx[-1]


def test_reset_option_overrides_make_kwarg():
    env = gym.make("FCC-v0", plant_effects=["sensor_bias:T_rx,bias=5"], noise_scale=0.0)
    a, _ = env.reset(seed=0)
    b, _ = env.reset(seed=0, options={"plant_effects": []})
    assert a[3] - b[3] == pytest.approx(5.0, abs=1e-3)


def test_parameter_path_equals_derivative_path():
    """heat_loss:stage1 through the model's UA equals the same physics as a d_state term."""
    kw = dict(n_samples=300, plant=fcc_env.PlantConfig(noise_scale=0.0))
    lib = fcc_env.simulate_episodes(
        [4], plant_effects=["heat_loss:stage1,extra_ua_kw_per_k=6"], **kw
    )
    user = fcc_env.simulate_episodes([4], plant_effects=[ExtraStage1Loss(6.0)], **kw)
    np.testing.assert_allclose(lib.y_clean, user.y_clean, atol=1e-8)
    base = fcc_env.simulate_episodes([4], **kw)
    assert (lib.y_clean[0, -1, 4] - base.y_clean[0, -1, 4]) < -1.0  # stage 1 runs cooler


def test_sensor_effects_transform_the_noise_free_measurement():
    kw = dict(n_samples=400, plant=fcc_env.PlantConfig(noise_scale=0.0))
    base = fcc_env.simulate_episodes([1], **kw).y_clean[0]
    bias = fcc_env.simulate_episodes([1], plant_effects=["sensor_bias:T_rg1,bias=3"], **kw)
    np.testing.assert_allclose(bias.y_clean[0, :, 4] - base[:, 4], 3.0, atol=1e-9)
    drift = fcc_env.simulate_episodes([1], plant_effects=["sensor_drift:T_d1,rate_per_h=1"], **kw)
    t_h = np.arange(400) * 10 / 3600
    np.testing.assert_allclose(drift.y_clean[0, :, 6] - base[:, 6], t_h, atol=1e-9)
    lag = fcc_env.simulate_episodes([1], plant_effects=["sensor_lag:T_rx,tau_s=60"], **kw)
    a = np.exp(-10 / 60)
    expect = np.empty(400)
    expect[0] = base[0, 3]
    for k in range(1, 400):
        expect[k] = (1 - a) * base[k, 3] + a * expect[k - 1]
    np.testing.assert_allclose(lag.y_clean[0, :, 3], expect, atol=1e-9)


def test_feed_temperature_sensor_bias_signature():
    """A +4 °C T_fp sensor bias, seen by a model driven by the measured inputs (spec §4 gains).

    T_fp +5 °C moves T_rx by +1.3 °C within 10 s and by +4.4 °C after an hour, so the model's
    T_rx runs ahead of the plant's by about 1 °C at once and 3–4 °C after 1.7 h.
    """
    b = fcc_env.simulate_episodes(
        [3],
        600,
        plant=fcc_env.PlantConfig.build(noise_scale=0.0, excitation=False),
        plant_effects=["sensor_bias:T_fp,bias=4"],
    )
    u_measured = b.inputs[0].copy()
    u_measured[:, 3] = b.y_clean[0, :, 2]  # what the sensor reports: true T_fp + 4
    model = simulate_inputs(u_measured, x0=b.states[0, 0])
    gap = model.y_clean[:, 3] - b.y_clean[0, :, 3]
    assert 0.8 < gap[0] < 1.3
    assert 3.0 < gap[-1] < 4.6


def test_catalyst_deactivation_shows_in_the_dilute_phases():
    """Spec §5 [V]: less activity → less coke → more O2 slip: T_d1 and T_dg rise."""
    kw = dict(n_samples=2000, plant=fcc_env.PlantConfig(noise_scale=0.0, excitation=None))
    base = fcc_env.simulate_episodes([0], **kw).y_clean[0]
    deact = fcc_env.simulate_episodes(
        [0], plant_effects=["catalyst_deactivation,loss_per_day=0.5"], **kw
    ).y_clean[0]
    assert deact[-1, 6] - base[-1, 6] > 1.0 and deact[-1, 7] - base[-1, 7] > 1.0


def test_library_effects_take_only_the_path_of_the_hook_they_use():
    """A process effect is not filed as a measurement effect (it would force the slower path)."""
    for eid in effects.available():
        e = effects.make(eid)
        assert len(e.hooks) == 1, eid
        assert effects.has_hook(e, "measure") == eid.startswith("sensor_"), eid
        assert effects.has_hook(e, "d_state") is False
    assert effects.has_hook(Offset(), "measure") and not effects.has_hook(Offset(), "d_state")
    assert effects.has_hook(ExtraStage1Loss(1.0), "d_state")
