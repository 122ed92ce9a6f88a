"""The catalogue's oracle, the offset/limits set-point search and the sensor-correcting policy."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import fcc_env  # noqa: F401 (registers the ids)
from evaluation.control.fault_oracle import FaultOracle
from evaluation.control.sensor_policy import SensorCorrectingSupervisor
from evaluation.control.setpoints import best_setpoints, operating_point
from fcc_env.closed_loop import CLOSED_LOOP_CHANNELS
from fcc_env.control_task import EconomicReward
from fcc_env.env import SETPOINT_ACTION_SCALE
from fcc_env.params import FCCParams
from fcc_env.regulatory import ACTUATOR_LIMITS

_RX, _RG1 = CLOSED_LOOP_CHANNELS.index("T_rx"), CLOSED_LOOP_CHANNELS.index("T_rg1")
_SP = [CLOSED_LOOP_CHANNELS.index(n) for n in ("T_rx_sp", "T_rg1_sp")]


@pytest.fixture(scope="module")
def oracle() -> FaultOracle:
    return FaultOracle()


def test_reading_offset_moves_the_set_points_by_it_at_the_same_steady_state():
    z = np.array([480.0, 152.0])
    p, e = FCCParams(), EconomicReward()
    true = operating_point(p, z, e)
    read = operating_point(p, z, e, reading_offset_C=(3.0, -2.0))
    assert read.T_rx_sp == pytest.approx(true.T_rx_sp + 3.0, abs=1e-9)
    assert read.T_rg1_sp == pytest.approx(true.T_rg1_sp - 2.0, abs=1e-9)
    assert read.reward_usd_per_h == true.reward_usd_per_h  # the same plant, the same margin


def test_limits_bound_the_search_and_bad_limits_are_refused():
    limits = ACTUATOR_LIMITS.astype(np.float64)
    limits[1, 1] = 148.0  # a weak blower, below the healthy optimum's air (154 t/h)
    point = best_setpoints(limits=limits)
    assert point.R_ar <= 148.0
    with pytest.raises(ValueError, match=r"limits=.*u_F low"):
        best_setpoints(limits=[[1.0, 0.0], [0.0, 1.0]])


def _run(policy, steps: int, **make) -> tuple[list[np.ndarray], list[np.ndarray]]:
    env = gym.make("FCC-control-v0", **make)
    obs, info = env.reset(seed=5000)
    policy.reset(info)
    seen, setpoints = [obs], []
    for _ in range(steps):
        obs, _, _, _, info = env.step(policy.act(obs, info))
        seen.append(obs)
        setpoints.append(np.asarray(info["setpoints"]))
    return seen, setpoints


def test_oracle_holds_a_stuck_transmitter_at_its_frozen_reading(oracle):
    onset = 40
    seen, sps = _run(oracle, 60, scenario="sensor-stuck", fault_channel="T_rg1", fault_time=onset)
    frozen = float(seen[onset - 1][_RG1])
    assert all(float(o[_RG1]) == frozen for o in seen[onset:])  # the plant's stuck reading
    # from the sample after the onset the loop's set point is the frozen reading
    np.testing.assert_allclose([s[1] for s in sps[onset + 1 :]], frozen, atol=1e-3)


def test_oracle_corrects_a_drifting_transmitter_by_its_offset(oracle):
    onset, rate = 30, 2.0
    _, sps = _run(
        oracle,
        50,
        scenario="sensor-drift",
        fault_channel="T_rg1",
        fault_time=onset,
        fault_magnitude=rate,
    )
    healthy = best_setpoints().setpoints
    k = 49  # the set point of sample k + 1 is the target of step k
    expected = healthy[1] + rate * (k - onset + 1) * 10.0 / 3600.0
    assert sps[k][1] == pytest.approx(expected, abs=1e-3)
    assert sps[k][0] == pytest.approx(healthy[0], abs=1e-3)


def test_sensor_policy_follows_a_frozen_reading_and_releases_it():
    healthy = np.array([540.0, 690.0])
    policy = SensorCorrectingSupervisor(healthy=healthy, frozen_samples=4)
    policy.reset({})
    obs = np.zeros(len(CLOSED_LOOP_CHANNELS))
    obs[_SP] = healthy  # the program's set points, the last move 0
    rng = np.random.default_rng(0)
    actions = []
    for k in range(12):
        o = obs.copy()
        o[_RX] = 540.0 + rng.normal()
        o[_RG1] = 687.5 if 3 <= k < 9 else 690.0 + rng.normal()
        o[_SP] = healthy + (actions[-1] * SETPOINT_ACTION_SCALE if actions else 0.0)
        actions.append(np.asarray(policy.act(o, {}), dtype=np.float64))
    moves = np.array(actions) * SETPOINT_ACTION_SCALE
    np.testing.assert_allclose(moves[:6], 0.0, atol=1e-4)  # 4 equal readings: samples 3..6
    np.testing.assert_allclose(moves[6:9, 1], -2.5, atol=1e-4)  # to the frozen 687.5
    np.testing.assert_allclose(moves[9:], 0.0, atol=1e-4)  # it moves again: released
    np.testing.assert_allclose(moves[:, 0], 0.0, atol=1e-4)


def test_sensor_policy_refuses_a_short_window():
    with pytest.raises(ValueError, match="frozen_samples=1"):
        SensorCorrectingSupervisor(healthy=np.zeros(2), frozen_samples=1)
