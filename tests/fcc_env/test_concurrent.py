"""Concurrent faults (issue 43 item 3): two registered faults with their own onsets in one
FaultSpec, passed whole; each acts from its own onset; labels for detection and isolation;
refusals by name; env = batch = vector env; determinism by seed."""

from __future__ import annotations

import json

import gymnasium as gym
import numpy as np
import pytest

import fcc_env
from fcc_env import FaultSpec, simulate_episodes
from fcc_env.faults import isolation_outcome

N = 300
CLOSED = fcc_env.PlantConfig.build(regulatory=True)


def _two(a: FaultSpec, b: FaultSpec, **kw) -> FaultSpec:
    return FaultSpec(scenario="concurrent", parts=(a, b), **kw)


F1_F2 = _two(FaultSpec(scenario="f2", onset=200), FaultSpec(scenario="f1", onset=100))


def test_resolve_orders_the_parts_by_onset_and_labels_both() -> None:
    f = F1_F2.resolve(N)
    assert (f.scenario, f.onset, f.magnitude) == ("concurrent", 100, 0.1)  # the first's
    assert f.labels == ("f1", "f2") and [p.onset for p in f.parts] == [100, 200]
    assert f.definition is None and f.active(100) and not f.active(99)
    p = fcc_env.FCCParams()
    assert f.faulty_params(p) == f.parts[1].faulty_params(f.parts[0].faulty_params(p))
    half = _two(*F1_F2.parts, magnitude_scale=0.5).resolve(N)
    assert [q.magnitude for q in half.parts] == [0.05, 0.075]


def test_each_part_acts_from_its_own_onset() -> None:
    both = simulate_episodes([3], N, fault=F1_F2)
    first = simulate_episodes([3], N, fault=FaultSpec(scenario="f1", onset=100))
    healthy = simulate_episodes([3], N)
    np.testing.assert_array_equal(both.states[0, :101], healthy.states[0, :101])
    assert not np.array_equal(both.states[0, 101:201], healthy.states[0, 101:201])
    np.testing.assert_array_equal(both.states[0, :201], first.states[0, :201])  # f2 not yet
    assert not np.array_equal(both.states[0, 201:], first.states[0, 201:])
    assert both.scenarios == ("concurrent",) and both.fault_onsets == (100,)
    assert both.fault_labels == (("f1", "f2"),) and first.fault_labels == (("f1",),)
    assert healthy.fault_labels == ((),)
    np.testing.assert_array_equal(both.fault_active[0], np.arange(N) >= 100)


def test_a_sensor_and_an_actuator_fault_in_closed_loop_env_equals_batch() -> None:
    spec = _two(
        FaultSpec(scenario="valve-stiction", onset=150, magnitude=0.03),
        FaultSpec(scenario="sensor-dropout", channel="T_rg1", onset=50, magnitude=0.5),
    )
    batch = simulate_episodes([4, 4], N, fault=spec, plant=CLOSED)
    np.testing.assert_array_equal(batch.observations[0], batch.observations[1])  # by seed
    env = gym.make("FCC-closedloop-v0", fault=spec)
    obs, info = env.reset(seed=4)
    rows, lost = [obs], [info["sensor_dropout"]]
    for _ in range(N - 1):
        obs, _, _, _, info = env.step(np.zeros(2))
        rows.append(obs)
        lost.append(info["sensor_dropout"])
    np.testing.assert_array_equal(np.array(rows), batch.observations[0])
    np.testing.assert_array_equal(np.array(lost), batch.sensor_dropout[0])
    assert batch.sensor_dropout[0, 50:].any() and not batch.sensor_dropout[0, :50].any()
    assert info["fault_labels"] == ("sensor-dropout", "valve-stiction")
    assert info["fault_times"] == (50, 150) and info["fault_time"] == 50
    # the valve sticks only from its own onset
    u = batch.inputs[0, :, 0]
    assert np.count_nonzero(np.diff(u[:150])) > 100 > np.count_nonzero(np.diff(u[150:]))


def test_the_vector_env_runs_parameter_faults_as_the_batch() -> None:
    batch = simulate_episodes([3, 4], N, fault=F1_F2)
    envs = gym.make_vec(
        "FCC-v0",
        num_envs=2,
        vectorization_mode="vector_entry_point",
        fault=F1_F2,
        max_episode_steps=N - 1,
    )
    obs, _ = envs.reset(seed=3)
    rows = [obs]
    for _ in range(N - 1):
        obs, *_ = envs.step(np.zeros((2, 2)))
        rows.append(obs)
    np.testing.assert_array_equal(np.stack(rows, axis=1), batch.observations)


def test_the_request_round_trips_and_keywords_drop_the_parts() -> None:
    spec = _two(FaultSpec(scenario="sensor-bias", channel="T_rg1", onset=10), F1_F2.parts[0])
    again = FaultSpec.from_json(json.loads(json.dumps(spec.to_json())))
    assert again == spec and "parts" not in FaultSpec(scenario="f1").to_json()
    assert spec.with_env_options({"scenario": "f3"}).parts == ()
    env = gym.make("FCC-v0", fault=spec)
    _, info = env.reset(seed=0, options={"scenario": "f1"})
    assert info["scenario"] == "f1" and "fault_labels" not in info


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({}, r"parts=\(\) .*a tuple of two FaultSpec"),
        ({"parts": (FaultSpec(scenario="f1"),)}, "a tuple of two FaultSpec"),
        ({"parts": (FaultSpec(scenario="f1"), FaultSpec(scenario="f1", onset=5))}, "two different"),
        ({"parts": (FaultSpec(scenario="f1"), FaultSpec())}, "parts scenario='nominal'"),
        ({"parts": (FaultSpec(scenario="f1"), "f2")}, "a FaultSpec of a registered fault"),
        ({"onset": 5, "parts": F1_F2.parts}, r"takes \['fault_time'\] from its parts"),
        ({"parts": F1_F2.parts, "magnitude_scale": 2.0}, r"fault_magnitude=0\.2 .*for f1"),
    ],
)
def test_bad_concurrent_requests_are_refused_by_name(kwargs, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        FaultSpec(scenario="concurrent", **kwargs)


def test_parts_belong_to_concurrent_only_and_keywords_cannot_give_them() -> None:
    with pytest.raises(ValueError, match="only scenario='concurrent' has parts"):
        FaultSpec(scenario="f1", parts=F1_F2.parts)
    with pytest.raises(ValueError, match="a tuple of two FaultSpec"):
        gym.make("FCC-v0", scenario="concurrent")
    with pytest.raises(ValueError, match="valve-stuck acts on the u_F actuator"):
        simulate_episodes(
            [0], N, fault=_two(F1_F2.parts[0], FaultSpec(scenario="valve-stuck", onset=9))
        )


def test_isolation_names_both_or_abstains() -> None:
    labels = F1_F2.resolve(N).labels
    assert isolation_outcome(["f2", "f1"], labels) == "correct"
    assert isolation_outcome("f1", labels) == "wrong"  # half an isolation is wrong
    assert isolation_outcome(["f1", "f3"], labels) == "wrong"
    assert isolation_outcome("unknown", labels) == "unknown"
    assert isolation_outcome("concurrent", labels) == "wrong"


def test_the_vector_env_reports_the_labels_as_sync_does() -> None:
    kw = {"num_envs": 2, "fault": F1_F2, "max_episode_steps": N - 1}
    native = gym.make_vec("FCC-v0", vectorization_mode="vector_entry_point", **kw)
    sync = gym.make_vec("FCC-v0", vectorization_mode="sync", **kw)
    for envs in (native, sync):
        _, info = envs.reset(seed=3)
        assert list(info["fault_labels"]) == [("f1", "f2")] * 2 and info["_fault_labels"].all()
        assert list(info["fault_times"]) == [(100, 200)] * 2
    _, info = native.reset(seed=3, options={"scenario": "f1", "fault_time": 100})
    assert "fault_labels" not in info
