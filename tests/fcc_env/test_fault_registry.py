"""The fault registry: a fault added in one place (``fcc_env.register_fault``) flows through the
fault request, the env, batch simulation, a track, ``lrgf-glr``'s fault directions and the
closed-loop report; faults on the measurement and actuator paths act through their hooks."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import diagnosers
import fcc_env
from evaluation.sweep.tasks import training_episodes
from evaluation.tracks import Fixed, Track
from evaluation.tracks.track_data import TrackData
from fcc_env import FaultDefinition, FaultSpec
from fcc_env.closed_loop_analysis import stability_cases
from fcc_env.closed_loop_report import ReportConfig, fault_deltas, report_faults
from fcc_env.faults import fault_width
from fcc_env.params import INPUT_NAMES, MEASUREMENT_NAMES

#: heat loss of three units at once: one parameter more than any paper fault (f2 scales two)
HEAT3 = FaultDefinition(
    ("UA_1", "UA_2", "UA_d1"),
    +1,
    0.5,
    600,
    "heat-loss coefficients of stages 1, 2 and dilute phase 1 +50 %",
    max_magnitude=0.8,
    max_reason="a test fault",
)
T_RX = MEASUREMENT_NAMES.index("T_rx")
T_AR = INPUT_NAMES.index("T_ar")


def _bias(fault, k, y):  # T_rx reads 10 °C per unit of magnitude high once the fault is in
    out = np.array(y, dtype=np.float64, copy=True)
    out[..., T_RX] += 10.0 * fault.magnitude * fault.fraction(np.asarray(k))
    return out


def _air_heater(fault, k, u):  # the air arrives 20 °C per unit of magnitude hotter
    out = np.array(u, dtype=np.float64, copy=True)
    out[..., T_AR] += 20.0 * fault.magnitude * fault.fraction(k)
    return out


BIAS = FaultDefinition(
    (),
    +1,
    0.3,
    100,
    "T_rx transmitter +3 °C",
    max_magnitude=0.9,
    max_reason="a test fault",
    measure=_bias,
)
HEATER = FaultDefinition(
    (),
    +1,
    0.5,
    100,
    "air preheater +10 °C",
    max_magnitude=0.9,
    max_reason="a test fault",
    transform_inputs=_air_heater,
)


def _registered(name: str, definition: FaultDefinition):
    fcc_env.register_fault(name, definition)
    yield name
    fcc_env.unregister_fault(name)


@pytest.fixture
def heat3():
    yield from _registered("heat3", HEAT3)


@pytest.fixture
def bias():
    yield from _registered("trx_bias", BIAS)


@pytest.fixture
def heater():
    yield from _registered("air_heater", HEATER)


def _rollout(env: gym.Env, seed: int, n: int) -> tuple[np.ndarray, list[dict]]:
    obs, info = env.reset(seed=seed)
    ys, infos = [obs], [info]
    for _ in range(n - 1):
        obs, _, _, _, info = env.step(np.zeros(2, dtype=np.float32))
        ys.append(obs)
        infos.append(info)
    return np.array(ys), infos


# ---- the registry --------------------------------------------------------------------------------
def test_register_checks_the_definition_and_the_name() -> None:
    assert fcc_env.fault_names() == fcc_env.PAPER_FAULTS == ("f1", "f2", "f3", "f4")
    bad = [
        ("f1", HEAT3, "already registered"),
        ("nominal", HEAT3, "name='nominal'"),
        ("Heat", HEAT3, "name='Heat'"),
        ("x", FaultDefinition(("rho_bb",), 1, 0.1, 10, "d", 0.2, "r"), r"x\.parameters='rho_bb'"),
        ("x", FaultDefinition((), 1, 0.1, 10, "d", 0.2, "r"), "a fault must act"),
        ("x", FaultDefinition(("rho_b",), 0, 0.1, 10, "d", 0.2, "r"), r"x\.direction=0"),
        ("x", FaultDefinition(("rho_b",), 1, 0.3, 10, "d", 0.2, "r"), r"default_magnitude=0\.3"),
        ("x", FaultDefinition(("rho_b",), 1, 0.1, 10, "d", 0.95, "r"), r"max_magnitude=0\.95"),
    ]
    for name, d, match in bad:
        with pytest.raises(ValueError, match=match):
            fcc_env.register_fault(name, d)
    assert fcc_env.fault_names() == fcc_env.PAPER_FAULTS  # nothing half-registered
    with pytest.raises(ValueError, match="the paper's faults stay"):
        fcc_env.unregister_fault("f2")


def test_a_registered_fault_is_a_scenario_and_then_is_gone(heat3) -> None:
    assert fcc_env.scenario_names()[-1] == heat3 and heat3 in fcc_env.FAULTS
    fault = FaultSpec(scenario=heat3).resolve(horizon=1000)
    assert (fault.scenario, fault.onset, fault.magnitude) == (heat3, 600, 0.5)
    with pytest.raises(ValueError, match=r"for heat3: a test fault"):
        FaultSpec(scenario=heat3, magnitude=0.85)
    # scenario="random" draws among every registered scenario, this one too
    rng = np.random.default_rng(0)
    drawn = {FaultSpec(scenario="random").resolve(1000, rng).scenario for _ in range(200)}
    assert drawn == {"nominal", *fcc_env.PAPER_FAULTS, heat3}
    fcc_env.unregister_fault(heat3)
    try:
        with pytest.raises(ValueError, match=r"scenario='heat3' is outside the allowed range"):
            FaultSpec(scenario=heat3)
    finally:
        fcc_env.register_fault(heat3, HEAT3)  # the fixture removes it


def test_a_wider_fault_widens_the_slots_and_changes_no_number() -> None:
    f1 = FaultSpec(scenario="f1", onset=150)
    before = fcc_env.simulate_episodes([0, 1], 300, fault=f1)
    assert fault_width() == 2
    fcc_env.register_fault("heat3", HEAT3)
    try:
        assert fault_width() == 3
        idx = f1.resolve(300).param_indices
        assert idx.shape == (3,) and idx[1] == idx[2] == -1  # padded, unused
        after = fcc_env.simulate_episodes([0, 1], 300, fault=f1)
        mixed = fcc_env.simulate_episodes(
            [0, 1],
            300,
            fault=[fcc_env.FaultSpec(scenario=_sc, onset=150) for _sc in ["f1", "heat3"]],
        )
    finally:
        fcc_env.unregister_fault("heat3")
    assert fault_width() == 2
    np.testing.assert_array_equal(after.observations, before.observations)
    np.testing.assert_array_equal(mixed.observations[0], before.observations[0])


# ---- the env and batch simulation ----------------------------------------------------------------
def test_env_and_batch_simulate_a_registered_fault_alike(heat3) -> None:
    n, seed = 800, 4
    env = gym.make("FCC-v0", scenario=heat3, max_episode_steps=n - 1, horizon=n)
    ys, infos = _rollout(env, seed, n)
    batch = fcc_env.simulate_episodes([seed], n, fault=FaultSpec(scenario=heat3))
    healthy = fcc_env.simulate_episodes([seed], n)
    np.testing.assert_array_equal(ys, batch.observations[0])
    assert infos[-1]["scenario"] == heat3 and batch.scenarios == (heat3,)
    assert batch.fault_onsets == (600,) and infos[600]["fault_active"]
    delta = batch.y_clean[0] - healthy.y_clean[0]
    assert not delta[:600].any()  # the same seed: identical until the onset
    assert np.abs(delta[600:, MEASUREMENT_NAMES.index("T_d1")]).max() > 0.1  # more heat lost


def test_a_measurement_fault_acts_on_the_transmitter_only(bias) -> None:
    n, seed = 400, 5
    healthy = fcc_env.simulate_episodes([seed], n)
    spec = FaultSpec(scenario=bias, profile="incipient", ramp_samples=100)
    faulty = fcc_env.simulate_episodes([seed], n, fault=spec)
    delta = faulty.y_clean[0] - healthy.y_clean[0]
    expected = np.zeros(n)
    expected[100:] = 3.0 * np.minimum(1.0, (np.arange(n)[100:] - 99) / 100)
    np.testing.assert_allclose(delta[:, T_RX], expected, rtol=0, atol=1e-9)
    assert not np.delete(delta, T_RX, axis=1).any()  # the plant is the healthy one
    np.testing.assert_array_equal(faulty.states, healthy.states)
    # the env reads the same transmitter, sample for sample
    env = gym.make("FCC-v0", fault=spec, max_episode_steps=n - 1, horizon=n)
    np.testing.assert_array_equal(_rollout(env, seed, n)[0], faulty.observations[0])
    # a batch mixing it with other faults gives each episode its own
    mixed = fcc_env.simulate_episodes(
        [seed, seed], n, fault=[fcc_env.FaultSpec(scenario=_sc) for _sc in [bias, "nominal"]]
    )
    assert mixed.y_clean[0, 200, T_RX] - mixed.y_clean[1, 200, T_RX] == pytest.approx(3.0)
    # the vector env cannot call it per sample, and says what to do
    with pytest.raises(ValueError, match="vectorization_mode='sync'"):
        envs = gym.make_vec("FCC-v0", 2, vectorization_mode="vector_entry_point", scenario=bias)
        envs.reset(seed=0)


def test_the_controllers_read_a_faulty_transmitter(bias) -> None:
    n, seed = 400, 6
    healthy = fcc_env.simulate_episodes([seed], n, plant=fcc_env.PlantConfig.build(regulatory=True))
    faulty = fcc_env.simulate_episodes(
        [seed],
        n,
        fault=fcc_env.FaultSpec(scenario=bias),
        plant=fcc_env.PlantConfig.build(regulatory=True),
    )
    valve = INPUT_NAMES.index("u_F")
    moved = faulty.inputs[0, :, valve] - healthy.inputs[0, :, valve]
    assert not moved[:100].any() and np.abs(moved[100:]).max() > 0  # the T_rx loop answers
    assert np.abs(faulty.states[0, 200:] - healthy.states[0, 200:]).max() > 0


def test_an_actuator_fault_changes_what_the_process_sees(heater) -> None:
    n, seed = 300, 7
    healthy = fcc_env.simulate_episodes([seed], n)
    faulty = fcc_env.simulate_episodes([seed], n, fault=fcc_env.FaultSpec(scenario=heater))
    d_in = faulty.inputs[0, :, T_AR] - healthy.inputs[0, :, T_AR]
    np.testing.assert_allclose(d_in, np.where(np.arange(n) >= 100, 10.0, 0.0), atol=1e-9)
    later = MEASUREMENT_NAMES.index("T_rg1")
    assert np.abs(faulty.y_clean[0, 150:, later] - healthy.y_clean[0, 150:, later]).max() > 0.1


# ---- a track, lrgf-glr's directions, the closed-loop report ------------------------------------
def test_a_track_holds_a_registered_fault_and_lrgf_glr_learns_its_direction(heat3) -> None:
    track = Track(
        name="registry-test",
        description="f1 and a registered fault",
        faults=("f1", heat3),
        onset=Fixed(600),
        n_samples=1200,
        n_healthy=1,
        n_faulty=1,
        n_train=2,
        n_train_faults=2,
    )
    assert track.magnitude(heat3) == Fixed(0.5)  # the fault's default size
    assert (heat3, track.test_seed_start) in track.test_cells()
    data = TrackData(track=track)
    faulty = data.train_fault_episodes()
    assert sorted({(e.scenario, e.seed) for e in faulty}) == [
        ("f1", 1000),
        ("f1", 1001),
        (heat3, 1000),
        (heat3, 1001),
    ]
    cls = diagnosers.diagnoser_class("lrgf-glr")
    det = cls(**{**cls.fast_params(), "n_folds": 2, "fault_seeds": None})
    episodes = training_episodes(det, data, "lrgf-glr")  # what the harness fits it on
    assert len(episodes) == 2 + len(faulty)
    det.fit(episodes)
    assert det.direction_faults_ == ("f1", heat3)
    assert f"directional[{heat3}]" in det.signal_names_
    np.testing.assert_allclose(np.linalg.norm(det.directions_, axis=1), 1.0)


def test_the_closed_loop_report_covers_a_registered_fault(heat3) -> None:
    assert report_faults() == (*fcc_env.PAPER_FAULTS, heat3)
    run = fault_deltas(heat3, "closed", ReportConfig(horizon=300, onset=150, seeds=(5000,)))
    assert run.fault == heat3 and np.abs(run.mean("T_d1")[150:]).max() > 0
    names = [c.name for c in stability_cases(corners=False)]
    assert names[-1] == f"{heat3} at 80%"
