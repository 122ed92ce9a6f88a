"""The catalogue's oracle, the offset/limits set-point search and the sensor-correcting policy."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import fcc_env  # noqa: F401 (registers the ids)
from diagnosers.detection import Decision
from evaluation.control.fault_oracle import FaultOracle
from evaluation.control.sensor_policy import (
    SOFT_SENSOR_INPUTS,
    SensorCorrectingSupervisor,
    SoftSensor,
    fit_sensor_diagnoser,
)
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


def _run(policy, steps: int, **make) -> tuple[list[np.ndarray], list[np.ndarray], list]:
    env = gym.make("FCC-control-v0", **make)
    obs, info = env.reset(seed=5000)
    policy.reset(info)
    seen, setpoints, infos = [obs], [], [info]
    for _ in range(steps):
        obs, _, _, _, info = env.step(policy.act(obs, info))
        seen.append(obs)
        setpoints.append(np.asarray(info["setpoints"]))
        infos.append(info)
    return seen, setpoints, infos


def test_oracle_runs_a_stuck_loop_on_the_true_temperature(oracle):
    onset = 40
    seen, sps, infos = _run(
        oracle, 60, scenario="sensor-stuck", fault_channel="T_rg1", fault_time=onset
    )
    assert all(float(o[_RG1]) == float(seen[onset - 1][_RG1]) for o in seen[onset:])
    healthy = oracle.healthy
    for i in range(60):  # the set point of step i: from the info the oracle read at step i
        error = infos[i]["y_clean"][4] - infos[i]["state"][4] if i >= onset else 0.0
        assert sps[i][1] == pytest.approx(healthy[1] + error, abs=1e-3), i
    assert abs(infos[59]["y_clean"][4] - infos[59]["state"][4]) > 1e-3  # it did move


def test_oracle_corrects_a_drifting_transmitter_by_its_offset(oracle):
    onset, rate = 30, 2.0
    _, sps, _ = _run(
        oracle,
        50,
        scenario="sensor-drift",
        fault_channel="T_rg1",
        fault_time=onset,
        fault_magnitude=rate,
    )
    healthy = oracle.healthy
    k = 49  # the set point of step k: the drift's offset at sample k
    expected = healthy[1] + rate * (k - onset + 1) * 10.0 / 3600.0
    assert sps[k][1] == pytest.approx(expected, abs=1e-3)
    assert sps[k][0] == pytest.approx(healthy[0], abs=1e-3)


def _feed(policy, readings: list[tuple[float, float]]) -> np.ndarray:
    """The moves (°C) of ``policy`` fed observations with these loop readings."""
    healthy = policy.healthy
    obs = np.zeros(len(CLOSED_LOOP_CHANNELS))
    moves = []
    for rx, rg1 in readings:
        o = obs.copy()
        o[_RX], o[_RG1] = rx, rg1
        o[_SP] = healthy + (moves[-1] if moves else 0.0)
        moves.append(np.asarray(policy.act(o, {}), dtype=np.float64) * SETPOINT_ACTION_SCALE)
    return np.array(moves)


def _flat_sensor(value: tuple[float, float]) -> SoftSensor:
    """A soft sensor that always answers ``value`` (intercept only)."""
    coef = np.zeros((len(SOFT_SENSOR_INPUTS) + 1, 2))
    coef[-1] = value
    return SoftSensor(coef)


def test_sensor_policy_judges_a_frozen_reading_and_releases_it():
    healthy = np.array([540.0, 690.0])
    policy = SensorCorrectingSupervisor(
        healthy=healthy, frozen_samples=4, soft_sensor=_flat_sensor((540.0, 690.0))
    )
    policy.reset({})
    rng = np.random.default_rng(0)
    judged = []
    readings = []
    for k in range(12):
        rg1 = 687.5 if 3 <= k < 9 else 690.0 + rng.normal()
        readings.append((540.0 + rng.normal(), rg1))
    for r in readings:
        _feed(policy, [r])
        judged.append(policy.judged.copy())
    judged = np.array(judged)
    # four equal readings from sample 3: judged at samples 6, 7, 8, released at 9
    assert judged[:, 1].tolist() == [False] * 6 + [True] * 3 + [False] * 3
    assert not judged[:, 0].any()


def test_sensor_policy_takes_a_bias_out_through_the_set_point():
    healthy = np.array([540.0, 690.0])
    policy = SensorCorrectingSupervisor(
        healthy=healthy,
        arm_after=0,
        window=10,
        limit_C=3.0,
        soft_sensor=_flat_sensor((540.0, 690.0)),
    )
    policy.reset({})
    rng = np.random.default_rng(1)
    readings = [(540.0 + 0.1 * rng.normal(), 695.0 + 0.1 * rng.normal()) for _ in range(40)]
    moves = _feed(policy, readings)
    assert policy.judged.tolist() == [False, True]
    # the T_rg1 loop's set point is the optimum plus the reading's error (5 °C)
    assert moves[-1][1] == pytest.approx(5.0, abs=0.3)
    assert abs(moves[-1][0]) < 0.3


@pytest.mark.parametrize(
    ("hold", "stuck_at", "judged", "move"),
    [(True, 541.0, True, -4.0), (True, 546.5, True, 0.0), (False, 541.0, False, 0.0)],
)
def test_a_frozen_loop_without_set_point_room_is_held_at_its_reading(hold, stuck_at, judged, move):
    """The riser's optimum on its range's top (545 °C) leaves no room to rebuild the loop; its
    frozen reading becomes its set point instead (clipped to the range), the PI error zero."""
    healthy = np.array([545.0, 690.0])
    policy = SensorCorrectingSupervisor(
        healthy=healthy,
        frozen_samples=4,
        soft_sensor=_flat_sensor((545.0, 690.0)),
        hold_frozen=hold,
    )
    policy.reset({})
    rng = np.random.default_rng(4)
    live = [(545.0 + rng.normal(), 690.0 + rng.normal()) for _ in range(5)]
    stuck = [(stuck_at, 690.0 + rng.normal()) for _ in range(4)]
    moves = _feed(policy, live + stuck[:3])
    assert not policy.judged.any() and np.abs(moves).max() < 1e-5
    moves = _feed(policy, stuck[3:])
    assert policy.judged.tolist() == [judged, False]
    assert moves[-1][0] == pytest.approx(move, abs=1e-5)
    assert moves[-1][1] == pytest.approx(0.0, abs=1e-5)


def test_sensor_policy_refuses_a_short_window():
    with pytest.raises(ValueError, match="frozen_samples=1"):
        SensorCorrectingSupervisor(
            healthy=np.zeros(2), frozen_samples=1, soft_sensor=_flat_sensor((0.0, 0.0))
        )


def test_sensor_policy_refuses_a_hold_that_is_not_a_bool():
    with pytest.raises(ValueError, match=r"hold_frozen='no': allowed: True or False"):
        SensorCorrectingSupervisor(
            healthy=np.zeros(2), hold_frozen="no", soft_sensor=_flat_sensor((0.0, 0.0))
        )


def test_soft_sensor_tracks_the_true_temperatures():
    sensor = SoftSensor.fit(seeds=[1000], n_steps=1500)
    env = gym.make("FCC-control-v0", scenario="nominal")
    obs, info = env.reset(seed=5001)
    errors = []
    for _ in range(600):
        obs, _, _, _, info = env.step(np.zeros(2))
        errors.append(sensor.estimate(obs) - (info["T_rx"], info["state"][4]))
    rms = np.sqrt(np.mean(np.square(errors), axis=0))
    assert rms[0] < 4.0 and rms[1] < 3.0, rms  # 1.7 and 1.0 °C fitted on 4 episodes


class _NamesSensorBias:
    """A stand-in diagnoser: alarms from its third sample, naming ``sensor-bias``."""

    def __init__(self) -> None:
        self.n = 0

    def reset(self) -> None:
        self.n = 0

    def update(self, y: np.ndarray) -> Decision:
        self.n += 1
        z = np.zeros(1)
        name = "sensor-bias" if self.n >= 3 else ""
        return Decision(self.n >= 3, z, z - 1.0, z + 1.0, z, diagnosis=name)


def test_a_diagnosis_of_a_sensor_fault_latches_the_loop_of_the_larger_residual():
    healthy = np.array([540.0, 690.0])
    policy = SensorCorrectingSupervisor(
        healthy=healthy,
        diagnoser=_NamesSensorBias(),
        arm_after=0,
        window=50,
        limit_C=10.0,  # the residual test alone would not judge a 2 °C bias
        soft_sensor=_flat_sensor((540.0, 690.0)),
    )
    policy.reset({})
    rng = np.random.default_rng(2)
    noisy = [(542.0 + 0.01 * rng.normal(), 690.0 + 0.01 * rng.normal()) for _ in range(32)]
    _feed(policy, noisy[:2])
    assert not policy.judged.any()  # no diagnosis yet
    moves = _feed(policy, noisy[2:])
    assert policy.judged.tolist() == [True, False]
    assert moves[-1][0] == pytest.approx(2.0, abs=0.05)  # T_rx's error taken out
    assert abs(moves[-1][1]) < 0.05


class _NamesSensor(_NamesSensorBias):
    """A stand-in that also names the sensor while streaming (as ``sensor-validation``)."""

    def __init__(self, sensor: str) -> None:
        super().__init__()
        self.sensor = sensor

    @property
    def named_sensor(self) -> str:
        return self.sensor if self.n >= 3 else ""


@pytest.mark.parametrize(("sensor", "judged"), [("T_rg1", [False, True]), ("T_ar", [False, False])])
def test_a_named_sensor_is_taken_at_its_word_over_the_larger_residual(sensor, judged):
    healthy = np.array([540.0, 690.0])
    policy = SensorCorrectingSupervisor(
        healthy=healthy,
        diagnoser=_NamesSensor(sensor),
        arm_after=0,
        window=50,
        limit_C=10.0,
        soft_sensor=_flat_sensor((540.0, 690.0)),
    )
    policy.reset({})
    rng = np.random.default_rng(3)
    # T_rx's residual is the larger (2 °C against 0.5 °C): the named channel decides
    _feed(policy, [(542.0 + 0.01 * rng.normal(), 690.5 + 0.01 * rng.normal()) for _ in range(20)])
    assert policy.judged.tolist() == judged


@pytest.mark.slow
def test_sensor_validation_judges_a_stuck_t_rg1_transmitter_in_the_loop():
    """The real diagnoser, its frozen and residual checks off: the judgment is the diagnosis."""
    diagnoser = fit_sensor_diagnoser("sensor-validation", seeds=range(1000, 1001))
    policy = SensorCorrectingSupervisor(
        diagnoser=diagnoser,
        frozen_samples=10**9,
        limit_C=1e9,
        soft_sensor=_flat_sensor((540.0, 690.0)),
    )
    env = gym.make("FCC-control-v0", scenario="sensor-stuck", fault_channel="T_rg1")
    obs, info = env.reset(seed=5220)
    policy.reset(info)
    onset = env.unwrapped.plant.fault.onset
    judged = []
    for _ in range(onset + 200):
        obs, _, terminated, truncated, info = env.step(policy.act(obs, info))
        judged.append(policy.judged)
        assert not (terminated or truncated)
    env.close()
    judged = np.array(judged)
    assert not judged[: onset - 1].any()  # no false judgment before the fault
    assert judged[-1].tolist() == [False, True]
    assert diagnoser.named_sensor == "T_rg1"


def test_correctable_loops_need_room_on_both_sides_of_the_range():
    from evaluation.control.setpoints import correctable_loops

    assert correctable_loops(np.array([544.9, 682.8])).tolist() == [False, True]
    assert correctable_loops(np.array([530.0, 665.5])).tolist() == [True, False]
    assert correctable_loops(np.array([530.0, 700.0]), min_room_C=6.0).tolist() == [True, False]


def test_a_closed_loop_reading_out_of_range_ends_the_episode_inside_the_space():
    """Seed 5226's stuck T_rx at the best fixed set points drives a reading out of range at
    sample 3590: the closed-loop observation (11 channels) is clipped to its own space, not to
    the open loop's 8 bounds (which raised a broadcast error)."""
    from evaluation.control.policies import fixed_setpoints

    policy = fixed_setpoints()
    env = gym.make("FCC-control-v0", scenario="sensor-stuck", fault_channel="T_rx")
    obs, info = env.reset(seed=5226)
    policy.reset(info)
    for _ in range(3999):
        obs, _, terminated, truncated, info = env.step(policy.act(obs, info))
        if terminated or truncated:
            break
    env.close()
    assert terminated and info["termination_reason"] == "measurement_out_of_range"
    assert env.observation_space.contains(np.asarray(obs, dtype=np.float32))
