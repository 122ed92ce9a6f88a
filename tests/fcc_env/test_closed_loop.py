"""The closed-loop plant (issue 31): batch = env, the env contract, the controllers' behaviour,
saturation without windup, set-point clipping, bad input and the linear stability proof."""

from __future__ import annotations

import re

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import fcc_env
from fcc_env.closed_loop import CLOSED_LOOP_CHANNELS
from fcc_env.closed_loop_analysis import (
    closed_loop_eigenvalues,
    closed_loop_map,
    closed_loop_steady_state,
    stability_cases,
)
from fcc_env.closed_loop_report import main as report_main
from fcc_env.episode_setup import CHUNK_SAMPLES
from fcc_env.params import MEASUREMENT_NAMES, NOMINAL_INPUTS
from fcc_env.plant import PlantConfig
from fcc_env.regulatory import SETPOINT_RANGES, RegulatoryLayer, SetpointProgram
from fcc_env.simulation import operating_program
from fcc_env.uncertainty import PlantUncertainty

ZERO = np.zeros(2, dtype=np.float32)
U_F_NOMINAL = float(NOMINAL_INPUTS[0])  # 416.6667 kg/s
R_AR_NOMINAL = float(NOMINAL_INPUTS[1])  # 148.4 t/h
#: Held set points and no feed-quality drift: the controllers' responses alone.
HELD = {"program": None}


class ExtraStage1Loss:
    """A user effect on the generic (numpy RK4) path: extra stage-1 heat loss as a d_state term."""

    def __init__(self, extra_ua: float) -> None:
        self.extra_ua = extra_ua

    def d_state(self, t, x, u, params):
        d = np.zeros_like(x)
        d[..., 4] = -self.extra_ua * (x[..., 4] - params.T_amb_C) / (x[..., 2] * params.cp_c)
        return d


def rollout(n, seed=0, actions=None, env_id="FCC-closedloop-v0", **kwargs):
    """An ``n``-sample episode (reset + n − 1 steps): observations and infos; stops at the end."""
    env = gym.make(env_id, max_episode_steps=n - 1, horizon=n, **kwargs)
    obs, info = env.reset(seed=seed)
    ys, infos, terminated = [obs], [info], [False]
    for k in range(n - 1):
        a = ZERO if actions is None else np.asarray(actions(k), dtype=np.float32)
        obs, _, term, _, info = env.step(a)
        ys.append(obs)
        infos.append(info)
        terminated.append(term)
        if term:
            break
    return np.array(ys), infos, np.array(terminated)


def assert_env_equals_batch(n, seeds, env_kwargs, batch_kwargs=None, per_seed_env_kwargs=None):
    keywords = dict(batch_kwargs or env_kwargs)
    batch_only = {
        k: keywords.pop(k) for k in ("plant_effects", "plant_uncertainty") if k in keywords
    }
    fault, plant = fcc_env.env_request(regulatory=True, **keywords)
    batch = fcc_env.simulate_episodes(seeds, n, fault=fault, plant=plant, **batch_only)
    assert batch.channels == CLOSED_LOOP_CHANNELS
    for b, seed in enumerate(seeds):
        kw = per_seed_env_kwargs(seed) if per_seed_env_kwargs else env_kwargs
        ys, infos, term = rollout(n, seed, **kw)
        m = len(ys)
        t = f"seed {seed}"
        np.testing.assert_array_equal(ys, batch.observations[b, :m], err_msg=t)
        np.testing.assert_array_equal([i["y_clean"] for i in infos], batch.y_clean[b, :m], t)
        np.testing.assert_array_equal([i["inputs"] for i in infos], batch.inputs[b, :m], t)
        np.testing.assert_array_equal([i["state"] for i in infos], batch.states[b, :m], t)
        np.testing.assert_array_equal([i["setpoints"] for i in infos], batch.setpoints[b, :m], t)
        # the env reports the clamp of the update made in the step that led to sample k
        sat = [i["controller_saturated"] for i in infos]
        np.testing.assert_array_equal(sat, batch.controller_saturated[b, :m], t)
        first_term = int(np.argmax(term)) if term.any() else -1
        assert first_term == batch.terminated_at[b], t
    return batch


@pytest.mark.parametrize(
    "kwargs",
    [
        {},
        {"scenario": "f1", "fault_time": 150},
        {"scenario": "random"},
        {"plant_effects": ["sensor_bias:T_rx"]},
        {"plant_effects": ["heat_loss:stage1"]},
        {"scenario": "f3", "fault_time": 100, "plant_effects": [ExtraStage1Loss(3.0)]},
    ],
    ids=["nominal", "f1-abrupt", "random", "sensor-bias", "heat-loss", "user-d_state"],
)
def test_batch_equals_env_in_closed_loop(kwargs):
    assert_env_equals_batch(400, [3, 11], kwargs)


def test_batch_equals_env_with_plant_uncertainty():
    """The env has no ``plant_uncertainty`` option: it gets each seed's drawn plant itself."""
    unc = PlantUncertainty()

    def env_kwargs(seed):
        draw = unc.draw(seed, base=PlantConfig().params)
        plant = PlantConfig(params=draw.params, regulatory=RegulatoryLayer())
        # FCC-closedloop-v0 passes regulatory=True, which a whole plant may not be given with
        return {"env_id": "FCC-v0", "plant": plant, "plant_effects": list(draw.effects)}

    assert_env_equals_batch(
        300, [4, 5], {}, batch_kwargs={"plant_uncertainty": unc}, per_seed_env_kwargs=env_kwargs
    )


def test_batch_equals_env_across_chunk_boundary():
    """Set-point program, feed-quality drift and noise streams do not depend on chunking."""
    n = CHUNK_SAMPLES + 300
    batch = assert_env_equals_batch(n, [1], {"scenario": "f2", "fault_time": 500})
    sp = batch.setpoints[0]
    assert np.ptp(sp[:CHUNK_SAMPLES], axis=0).min() > 0  # the program moves both set points
    assert np.ptp(batch.inputs[0, :, 5]) > 0  # and the feed coking factor drifts


def test_check_env_and_observation_layout():
    env = gym.make("FCC-closedloop-v0")
    check_env(env.unwrapped, skip_render_check=True)
    obs, info = env.reset(seed=7)
    env.action_space.seed(7)
    assert obs.shape == (11,) and env.observation_space.shape == (11,)
    assert CLOSED_LOOP_CHANNELS == (*MEASUREMENT_NAMES, "u_F", "T_rx_sp", "T_rg1_sp")
    for _ in range(150):
        obs, _, _, _, info = env.step(env.action_space.sample() * 0.1)
        sp = info["setpoints"]
        assert obs[9:].tolist() == sp.astype(np.float32).tolist()
        assert obs[8] == np.float32(info["inputs"][0])
        np.testing.assert_array_equal(info["y_clean"][8:], [info["inputs"][0], *sp])


def test_open_loop_is_unchanged():
    env = gym.make("FCC-v0")
    assert env.observation_space.shape == (8,)
    obs, info = env.reset(seed=0)
    assert obs.shape == (8,)
    assert not {"controller_saturated", "setpoint_clipped", "setpoints"} & info.keys()
    b = fcc_env.simulate_episodes([0], 50)
    assert b.observations.shape == (1, 50, 8) and b.channels == MEASUREMENT_NAMES
    assert b.setpoints is None and b.controller_saturated is None


def test_set_point_step_is_tracked():
    ys, infos, _ = rollout(
        301, actions=lambda k: [5 / 15, 0], excitation=False, noise_scale=0.0, regulatory=HELD
    )
    sp = infos[-1]["setpoints"]
    assert sp[0] == pytest.approx(infos[0]["setpoints"][0] + 5.0)
    assert abs(ys[-1, 3] - sp[0]) < 0.2  # T_rx settled within 300 samples (50 min)
    assert abs(ys[-1, 4] - sp[1]) < 1.0  # the air loop holds T_rg1 through the valve's move


def test_air_loop_alone_leaves_the_valve_on_the_program():
    ys, infos, _ = rollout(
        200, actions=lambda k: [0, 0.5], excitation=False, regulatory={"loops": ["T_rg1"]}
    )
    assert all(i["inputs"][0] == U_F_NOMINAL for i in infos)
    assert np.ptp([i["inputs"][1] for i in infos]) > 1.0  # the air does move


def test_saturation_is_clamped_without_windup():
    """At fixed air (valve loop alone, spec §2.7) a +15 °C set point drives the valve to its
    top limit and keeps the error positive for many samples: a position-form integral would
    wind up; the velocity form leaves the limit as soon as the set point drops."""
    drop = 300
    ys, infos, term = rollout(
        400,
        actions=lambda k: [1.0 if k < drop else -1.0, 0],
        excitation=False,
        noise_scale=0.0,
        regulatory={**HELD, "loops": ["T_rx"]},
    )
    assert not term.any()
    sat = np.array([i["controller_saturated"] for i in infos])
    u = np.array([i["inputs"] for i in infos])
    top = 1.5 * U_F_NOMINAL
    assert sat[:drop].sum() >= 50 and np.isclose(u[drop, 0], top)
    assert (ys[:drop, 3] < infos[drop - 1]["setpoints"][0]).all()  # error positive throughout
    assert (u[drop + 1 : drop + 4, 0] < top - 1.0).all()  # off the limit at once
    assert (u[:, 0] >= 0.5 * U_F_NOMINAL).all() and (u[:, 0] <= top).all()
    assert (u[:, 1] == R_AR_NOMINAL).all()


def test_air_limits_hold_under_a_large_set_point_move():
    ys, infos, _ = rollout(
        200,
        actions=lambda k: [0, 1.0 if k < 100 else -1.0],
        excitation=False,
        noise_scale=0.0,
        regulatory=HELD,
    )
    u = np.array([i["inputs"] for i in infos])
    sat = np.array([i["controller_saturated"] for i in infos])
    assert sat.any()  # the −40 °C set-point step kicks the air to its bottom limit
    assert (u[:, 1] >= 0.85 * R_AR_NOMINAL - 1e-9).all()
    assert (u[:, 1] <= 1.15 * R_AR_NOMINAL + 1e-9).all()
    assert (u[:, 0] >= 0.5 * U_F_NOMINAL).all() and (u[:, 0] <= 1.5 * U_F_NOMINAL).all()
    assert not sat[-20:].any()  # and leaves it


def test_set_point_clipping_is_flagged():
    env = gym.make("FCC-closedloop-v0", excitation=False, regulatory=HELD)
    _, info = env.reset(seed=0)
    assert info["setpoint_clipped"] is False
    start = info["setpoints"]
    _, _, _, _, info = env.step(np.array([0.2, -0.2], dtype=np.float32))
    assert info["setpoint_clipped"] is False
    np.testing.assert_allclose(info["setpoints"], start + np.array([3.0, -4.0]))
    # T_rx_sp starts a hair above 530 °C: +15 °C crosses the top of [515, 545]
    _, _, _, _, info = env.step(np.array([1.0, -1.0], dtype=np.float32))
    assert info["setpoint_clipped"] is True
    assert info["setpoints"][0] == SETPOINT_RANGES["T_rx_sp"].high
    assert info["setpoints"][1] == pytest.approx(start[1] - 20.0)


@pytest.mark.parametrize(
    ("make", "match"),
    [
        (lambda: RegulatoryLayer(T_rx_gain=-1), r"T_rx_gain=-1 .*\(0, 50\]"),
        (lambda: RegulatoryLayer(T_rg1_integral_time_s=0), r"T_rg1_integral_time_s=0 .*\[1, "),
        (lambda: RegulatoryLayer(loops=("T_rx", "P_rg")), r"'P_rg'.*\['T_rx', 'T_rg1'\]"),
        (lambda: RegulatoryLayer(loops=()), r"loops=\(\) .*non-empty"),
        (
            lambda: gym.make("FCC-closedloop-v0", regulatory={"gain": 1}),
            r"Unknown regulatory option\(s\) \['gain'\]. Allowed: \['T_rx_gain'",
        ),
        (lambda: gym.make("FCC-closedloop-v0", regulatory="yes"), r"regulatory='yes' .*True"),
        (lambda: SetpointProgram(T_rx_sp_halfrange_C=50), r"=50 .*\[0, 10\] °C"),
        (lambda: SetpointProgram(hold_min=10, hold_max=5), r"hold_max=5 .*>= hold_min=10"),
        (
            lambda: fcc_env.simulate_episodes([0], 10, plant={"regulatory": True}),
            r"plant=\{'regulatory': True\} is outside the allowed range: a PlantConfig",
        ),
        (
            lambda: fcc_env.simulate_episodes(
                [0], 10, plant=fcc_env.PlantConfig.build(regulatory=[1, 2])
            ),
            r"regulatory=\[1, 2\] .*True, False, None, a RegulatoryLayer",
        ),
        (
            lambda: RegulatoryLayer(program={"T_rx_sp_halfrange_C": 1.0}),
            r"program=\{.*\} .*a SetpointProgram or None",
        ),
        (
            lambda: gym.make("FCC-closedloop-v0", regulatory={"program": {"amplitude": 1}}),
            r"Unknown set-point program option\(s\) \['amplitude'\]. Allowed: \['T_rx_sp",
        ),
        (lambda: operating_program(-1, 10), r"seed=-1 is outside the allowed range"),
    ],
    ids=[
        "negative-gain",
        "zero-integral-time",
        "unknown-loop",
        "no-loop",
        "unknown-option",
        "not-a-layer",
        "program-halfrange",
        "hold-order",
        "plant-and-keyword",
        "not-a-layer-batch",
        "program-not-a-program",
        "unknown-program-option",
        "negative-seed",
    ],
)
def test_bad_control_options_are_refused(make, match):
    with pytest.raises(ValueError, match=match):
        make()


@pytest.mark.parametrize(
    ("argv", "match"),
    [
        (["--horizon", "2"], r"horizon=2 is outside the allowed range: an integer in \[4, inf\)"),
        (
            ["--onset", "4000"],
            r"onset=4000 is outside the allowed range: an integer in \[1, 3998\]",
        ),
        (["--seeds", "-3"], r"seeds=.*-3.* is outside the allowed range"),
        (
            ["--terminations", "-1"],
            r"terminations=-1 is outside the allowed range: an integer in \[0, 10000\]",
        ),
    ],
)
def test_report_cli_refuses_bad_values_by_name(argv, match, tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:
        report_main(["--out", str(tmp_path), *argv])
    assert exc.value.code == 2
    assert re.search(match, capsys.readouterr().err)


def test_operating_program_is_the_simulated_program():
    plant = PlantConfig(regulatory=RegulatoryLayer())
    u, sp = operating_program(7, 700, plant)
    b = fcc_env.simulate_episodes([7], 700, plant=plant)
    np.testing.assert_array_equal(u[:, 2:], b.inputs[0, :, 2:])  # all but the valve and air
    np.testing.assert_array_equal(sp, b.setpoints[0])
    u_open, sp_open = operating_program(7, 700)
    assert sp_open is None
    np.testing.assert_array_equal(u_open, fcc_env.simulate_episodes([7], 700).inputs[0])


def test_closed_loop_is_stable_at_nominal_and_the_largest_faults():
    cases = stability_cases(corners=False)
    assert [c.name.split()[0] for c in cases] == ["nominal", "f1", "f2", "f3", "f4"]
    for c in cases:
        assert c.stable and c.min_damping > 0.3, c


def test_closed_loop_is_stable_at_the_uncertain_corners():
    corners = stability_cases(corners=True)[5:]
    assert len(corners) == 16
    for c in corners:
        assert c.stable and c.min_damping > 0.3, c


def test_linearisation_predicts_the_decay_of_a_small_perturbation():
    """Oracle: the nonlinear map, started on the slowest eigenvector, decays as |λ|^n."""
    layer = RegulatoryLayer()
    config = PlantConfig(regulatory=layer)
    p, sp, ts = config.params.as_array(), config.initial_setpoints(), config.sample_time_s
    z_star = closed_loop_steady_state(p, layer, sp, ts, config.initial_state())
    n = z_star.size
    jac = np.empty((n, n))
    for j in range(n):
        h = 1e-6 * max(abs(z_star[j]), 1e-3)
        e = np.zeros(n)
        e[j] = h
        jac[:, j] = (
            closed_loop_map(z_star + e, p, layer, sp, ts)
            - closed_loop_map(z_star - e, p, layer, sp, ts)
        ) / (2 * h)
    lam, vec = np.linalg.eig(jac)
    keep = np.abs(lam - 1.0) > 1e-6  # the conserved catalyst inventory (see the module)
    lam, vec = lam[keep], vec[:, keep]
    # the analysis' own eigenvalues (same steps) agree with this Jacobian
    np.testing.assert_allclose(
        np.sort(np.abs(closed_loop_eigenvalues(p, layer, sp, ts, z_star))),
        np.sort(np.abs(lam)),
        rtol=1e-6,
    )
    real = np.flatnonzero(np.abs(lam.imag) < 1e-12)
    i = real[np.argmax(np.abs(lam[real]))]
    slowest, v = float(lam[i].real), vec[:, i].real
    assert 0.9 < slowest < 1.0
    scale = np.maximum(np.abs(z_star), 1.0)
    delta = 1e-5 * v / np.abs(v / scale).max()  # 1e-5 of each state's size at most
    z = z_star + delta
    steps = 200
    for _ in range(steps):
        z = closed_loop_map(z, p, layer, sp, ts)
    ratio = np.linalg.norm((z - z_star) / scale) / np.linalg.norm(delta / scale)
    assert ratio == pytest.approx(slowest**steps, rel=0.03)
