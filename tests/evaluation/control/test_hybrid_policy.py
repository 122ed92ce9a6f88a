"""The fault-blind agent overridden by the sensor-correcting supervisor on its judged loops."""

from __future__ import annotations

import numpy as np
import pytest

from evaluation.control import make_policy, rl
from evaluation.control.hybrid_policy import DiagnosisOverride
from evaluation.control.sensor_policy import (
    SOFT_SENSOR_INPUTS,
    SensorCorrectingSupervisor,
    SoftSensor,
)
from fcc_env.closed_loop import CLOSED_LOOP_CHANNELS
from fcc_env.env import SETPOINT_ACTION_SCALE

_RX, _RG1 = CLOSED_LOOP_CHANNELS.index("T_rx"), CLOSED_LOOP_CHANNELS.index("T_rg1")
_SP = [CLOSED_LOOP_CHANNELS.index(n) for n in ("T_rx_sp", "T_rg1_sp")]
AGENT = np.array([0.3, -0.2])


class _ConstantAgent:
    """A stand-in for the PPO agent: always the same action."""

    name = "constant agent"

    def reset(self, info: object) -> None:
        pass

    def act(self, obs: np.ndarray, info: object = None) -> np.ndarray:
        return AGENT.astype(np.float32)


def _supervisor() -> SensorCorrectingSupervisor:
    coef = np.zeros((len(SOFT_SENSOR_INPUTS) + 1, 2))
    coef[-1] = (545.0, 690.0)  # a soft sensor that always answers the optimum
    return SensorCorrectingSupervisor(
        healthy=np.array([545.0, 690.0]), frozen_samples=4, soft_sensor=SoftSensor(coef)
    )


def _run(policy, readings) -> np.ndarray:
    """The actions of ``policy`` fed these loop readings; the observation shows the program's
    set points plus the move applied last, as the env does."""
    obs = np.zeros(len(CLOSED_LOOP_CHANNELS))
    program, actions, move = np.array([540.0, 688.0]), [], np.zeros(2)
    for rx, rg1 in readings:
        o = obs.copy()
        o[_RX], o[_RG1] = rx, rg1
        o[_SP] = program + move
        a = np.asarray(policy.act(o, {}), dtype=np.float64)
        move = a * SETPOINT_ACTION_SCALE
        actions.append(a)
    return np.array(actions)


def test_the_agent_acts_until_a_loop_is_judged_then_the_supervisor_sets_that_loop():
    policy = DiagnosisOverride(_ConstantAgent(), _supervisor())
    policy.reset({})
    rng = np.random.default_rng(0)
    live = [(545.0 + rng.normal(), 690.0 + rng.normal()) for _ in range(6)]
    stuck = [(541.0, 690.0 + rng.normal()) for _ in range(8)]
    actions = _run(policy, live + stuck)
    # the agent's action everywhere before the stuck reading is judged (its 4th sample)
    np.testing.assert_allclose(actions[:9], np.tile(AGENT, (9, 1)), atol=1e-6)
    # then the riser loop is held at the frozen 541 °C: the program's 540 + 1 °C, on every
    # sample (the program is recovered from the move applied, not the supervisor's own)
    expected = (541.0 - 540.0) / SETPOINT_ACTION_SCALE[0]
    np.testing.assert_allclose(actions[9:, 0], expected, atol=1e-6)
    np.testing.assert_allclose(actions[9:, 1], AGENT[1], atol=1e-6)
    assert policy.supervisor.judged.tolist() == [True, False]


def test_the_hybrid_is_registered_and_loads_the_saved_agent(tmp_path):
    n_obs = len(CLOSED_LOOP_CHANNELS)
    config = {
        "format": rl.FORMAT,
        "env_id": "FCC-control-v0",
        "obs_dim": n_obs,
        "act_dim": 2,
        "hidden": [],
        "activation": "tanh",
        "obs_mean": [0.0] * n_obs,
        "obs_var": [1.0] * n_obs,
        "obs_epsilon": 1e-8,
        "obs_clip": 10.0,
        "action_low": [-1.0] * 2,
        "action_high": [1.0] * 2,
    }
    weights = {
        "layer0.weight": np.zeros((2, n_obs), np.float32),
        "layer0.bias": np.zeros(2, np.float32),
    }
    rl.save_policy(tmp_path, rl.MLPPolicy(config, weights))
    sup = _supervisor()
    kw = {"healthy": sup.healthy, "soft_sensor": sup.soft_sensor}
    policy = make_policy("ppo+sensor-correcting", directory=tmp_path, **kw)
    assert isinstance(policy, DiagnosisOverride)
    assert isinstance(policy.agent, rl.MLPPolicy) and policy.supervisor.frozen_samples == 5
    # the agent keeps the loop the supervisor cannot rebuild unless the hold is asked for
    assert policy.supervisor.hold_frozen is False
    held = make_policy("ppo+sensor-correcting", directory=tmp_path, hold_frozen=True, **kw)
    assert held.supervisor.hold_frozen is True


def test_a_supervisor_without_judgments_is_refused():
    with pytest.raises(ValueError, match="judged"):
        DiagnosisOverride(_ConstantAgent(), _ConstantAgent())  # type: ignore[arg-type]
