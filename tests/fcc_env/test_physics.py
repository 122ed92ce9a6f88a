"""Physics: steady state, balances, golden trajectories, integrator accuracy, fault signatures."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import fcc_env
from fcc_env.params import MEASUREMENT_NAMES, NOMINAL_INPUTS, PARAM_INDEX, STATE_NAMES, FCCParams
from fcc_env.physics import measure, rhs, rhs_aux, steady_state

REF = Path(__file__).parents[1] / "data" / "fcc-reference"
P = FCCParams()


def _simulate_keywords(seeds, n_samples, **keywords):
    """Batch simulation of the env's keywords (the plant and fault they build)."""
    fault, plant = fcc_env.env_request(**keywords)
    return fcc_env.simulate_episodes(seeds, n_samples, fault=fault, plant=plant)


def test_steady_state_matches_spec_table_2_10():
    x = steady_state()
    aux = rhs_aux(x, NOMINAL_INPUTS, P)
    assert np.abs(rhs(0.0, x, NOMINAL_INPUTS, P)).max() < 1e-10
    # §2.10 verified values, to the digits the table gives
    assert aux["T_rx"] == pytest.approx(530.00, abs=0.005)
    assert aux["X"] == pytest.approx(0.7500, abs=5e-5)
    assert 100 * x[1] == pytest.approx(1.031, abs=5e-4)
    assert 100 * x[3] == pytest.approx(0.354, abs=5e-4)
    assert 100 * x[6] == pytest.approx(0.200, abs=5e-4)
    for i, v in ((4, 685.05), (7, 719.39), (9, 697.21), (10, 710.16)):
        assert x[i] == pytest.approx(v, abs=0.005), STATE_NAMES[i]
    assert 100 * aux["y1_O2"] == pytest.approx(0.503, abs=5e-4)
    assert 100 * aux["y2_O2"] == pytest.approx(0.106, abs=5e-4)
    # and the verification run's exact steady state (meta.json) to 1e-6 relative
    import json

    meta = json.loads((REF / "meta.json").read_text())["x_nominal"]
    ref = np.array(list(meta.values()))
    np.testing.assert_allclose(x, ref, rtol=1e-7)


def test_nominal_balances_close():
    x = steady_state()
    a = rhs_aux(x, NOMINAL_INPUTS, P)
    # catalyst: circulation equal everywhere (F_12 and F_23 enter via zero bed derivatives)
    assert a["F_rc"] == pytest.approx(a["F_sc"], rel=1e-12)
    # coke: coke make = burning in both stages (§2.10: 3.465 = 2.822 + 0.643 kg/s)
    assert a["coke_make"] == pytest.approx(a["R_cb1"] + a["R_cb2"], rel=1e-9)
    assert a["R_cb1"] == pytest.approx(2.822, abs=5e-4)
    assert a["R_cb2"] == pytest.approx(0.643, abs=5e-4)
    # energy: riser 86.01 MW on both sides; combustion heat 92.93 / 21.65 MW
    F_feed, T_fp = NOMINAL_INPUTS[4], NOMINAL_INPUTS[3]
    q_cat = a["F_rc"] * P.cp_c * (x[7] - a["T_rx"])
    q_feed = F_feed * (P.cp_fe * (a["T_rx"] - T_fp) + P.dH_v + P.dH_cr * a["X"])
    assert q_cat == pytest.approx(86_010, abs=10)
    assert q_cat == pytest.approx(q_feed, rel=1e-9)
    assert a["Q_burn1_kW"] == pytest.approx(92_930, abs=10)
    assert a["Q_burn2_kW"] == pytest.approx(21_650, abs=10)


def test_total_catalyst_inventory_is_conserved_at_any_state():
    rng = np.random.default_rng(0)
    x0 = steady_state()
    for _ in range(20):
        x = x0 * (1 + 0.05 * rng.standard_normal(x0.size))
        u = NOMINAL_INPUTS * (1 + 0.03 * rng.standard_normal(NOMINAL_INPUTS.size))
        dx = rhs(0.0, x, u, P)
        # W_rx + W1 + W2 + W_sp: the weirs, level loop and valve only move catalyst around
        assert abs(dx[0] + dx[2] + dx[5] + dx[8]) < 1e-9


def test_open_loop_is_stable_with_one_conserved_direction():
    x = steady_state()
    eps = np.maximum(np.abs(x) * 1e-6, 1e-9)
    J = np.column_stack(
        [
            (rhs(0, x + e, NOMINAL_INPUTS, P) - rhs(0, x - e, NOMINAL_INPUTS, P)) / (2 * e[i])
            for i, e in enumerate(np.diag(eps))
        ]
    )
    ev = np.linalg.eigvals(J)
    ev = ev[np.argsort(np.abs(ev.real))]
    assert abs(ev[0].real) < 1e-7  # total inventory (§7.3)
    assert (ev[1:].real < 0).all()
    assert ev[1].real == pytest.approx(-4.10e-4, rel=0.02)  # slowest mode, 40.6 min


def _load_reference(name: str):
    d = np.genfromtxt(REF / f"{name}.csv", delimiter=",", names=True)
    cols = ["in_u_F", "in_R_ar", "in_T_ar", "in_T_fp", "in_F_feed", "in_f_coke"]
    U = np.stack([d[c] for c in cols], axis=1)
    Y = np.stack([d["y_" + c] for c in MEASUREMENT_NAMES], axis=1)
    xcols = ["W_rx", "C_sc", "W1", "C1", "T1", "W2", "C2", "T2", "W_sp", "T_d1", "T_dg"]
    X = np.stack([d["x_" + c] for c in xcols], axis=1)
    return U, Y, X


FAULT_SETUP = {
    "nominal": ([-1, -1], 1.0),
    "f1": ([PARAM_INDEX["rho_b"], -1], 1.10),
    "f2": ([PARAM_INDEX["K_w1"], PARAM_INDEX["K_w2"]], 0.85),
    "f3": ([PARAM_INDEX["k_sigma"], -1], 0.90),
    "f4": ([PARAM_INDEX["V_rx_sp_m3"], -1], 1.05),
}


def _simulate(U, x0, fault, onset, substeps=1):
    idx, final = fault
    k = np.arange(U.shape[0])
    mult = np.where(k >= onset, final, 1.0)
    names = [fcc_env.params.PARAM_FIELDS[i] for i in idx if i >= 0]
    sim = fcc_env.simulation.simulate_inputs(
        U, x0=x0, param_multipliers={n: mult for n in names}, rk4_substeps=substeps
    )
    return sim.y_clean, sim.states


@pytest.mark.parametrize("name", list(FAULT_SETUP))
def test_golden_trajectories(name):
    """Reproduce the spec's verification run (LSODA rtol 1e-10) to 0.01 °C on every channel."""
    U, Yref, Xref = _load_reference(name)
    Y, X = _simulate(U, Xref[0], FAULT_SETUP[name], onset=100)
    err = np.abs(Y - Yref).max(axis=0)
    if name == "f1":
        # The reference's f1 T_rx uses the nominal density in the valve law (see physics.py);
        # every other channel and all states match.
        err[3] = 0.0
    assert err.max() < 0.01, dict(zip(MEASUREMENT_NAMES, err.round(5), strict=True))
    temps = [4, 7, 9, 10]
    assert np.abs(X[:, temps] - Xref[:, temps]).max() < 0.01


def test_reference_f1_T_rx_is_the_nominal_density_riser_temperature():
    """Evidence for the correction: the reference's f1 T_rx is our riser with ρ_b unchanged."""
    U, Yref, Xref = _load_reference("f1")
    y_nominal_density = np.array([measure(Xref[k], U[k], P)[3] for k in range(len(U))])
    np.testing.assert_allclose(y_nominal_density, Yref[:, 3], atol=1e-6)
    faulty = P.replace(rho_b=660.0)
    y_true = np.array([measure(Xref[k], U[k], faulty)[3] for k in range(100, len(U))])
    assert (y_true - Yref[100:, 3]).min() > 5.0  # the density factor's +4.9 % circulation


def _lsoda_reference(U, x0, fault_param: str, fault_value: float, onset: int, n: int):
    x = x0.copy()
    out = [x.copy()]
    for k in range(n - 1):
        p = P.replace(**{fault_param: fault_value}) if k >= onset else P
        sol = solve_ivp(
            lambda t, xx, u=U[k], p=p: rhs(t, xx, u, p),
            (0.0, 10.0), x, method="LSODA", rtol=1e-10, atol=1e-10,
        )  # fmt: skip
        assert sol.success, sol.message
        x = sol.y[:, -1]
        out.append(x.copy())
    return np.array(out)


#: Stated RK4 error bounds on temperatures (°C) against LSODA rtol 1e-10, abrupt f1 (the worst
#: case, spec §7.8 measured 1.4e-3 at 1 step and 7e-5 at 2 steps per sample).
RK4_BOUND_C = {1: 2e-3, 2: 1e-4}


@pytest.mark.parametrize("substeps", [1, 2])
def test_rk4_against_lsoda(substeps):
    U, _, Xref = _load_reference("f1")
    n, onset = 160, 20
    ref = _lsoda_reference(U, Xref[0], "rho_b", 660.0, onset, n)
    _, X = _simulate(U[:n], Xref[0], FAULT_SETUP["f1"], onset=onset, substeps=substeps)
    temps = [4, 7, 9, 10]
    err = np.abs(X[:, temps] - ref[:, temps]).max()
    assert err < RK4_BOUND_C[substeps], err


SIGNATURES = {
    # spec §7.6 "final" column (mean of the last 200 samples, °C): T_rx, T_rg1, T_rg2, T_d1, T_dg
    "f1": (1.56, 12.7, 13.8, 3.3, 1.6),
    "f2": (0.25, 2.41, 2.73, 1.88, 1.67),
    "f3": (-4.28, -6.47, -5.87, 5.04, 7.36),
    "f4": (0.55, 2.59, 2.58, -1.72, -2.50),
}


@pytest.mark.parametrize("fault", list(SIGNATURES))
def test_fault_signatures_match_spec(fault):
    """Sign and rough size of each fault's noise-free effect (spec §7.6, onset 2000).

    Riser and dense beds: within ±50 % of the spec's final value in an excited run (our excitation
    differs from the spec's seed). Dilute phases: the afterburn makes their response depend on the
    excitation (the spec says so for f3; seeds here show even sign changes), so their signs are
    checked at constant inputs.
    """
    kw = dict(n_samples=4000, fault_time=2000, noise_scale=0.0)
    healthy = _simulate_keywords([7], scenario="nominal", **kw)
    faulty = _simulate_keywords([7], scenario=fault, **kw)
    d = faulty.y_clean[0] - healthy.y_clean[0]
    assert np.all(d[:2000] == 0.0)  # identical until the onset: same excitation, same noise
    assert np.all(faulty.observations[0, :2000] == healthy.observations[0, :2000])
    assert not np.all(faulty.observations[0, 2000:] == healthy.observations[0, 2000:])
    final = d[-200:, 3:6].mean(axis=0)
    for got, want, name in zip(final, SIGNATURES[fault][:3], MEASUREMENT_NAMES[3:6], strict=True):
        if abs(want) >= 1.0:
            assert np.sign(got) == np.sign(want), (name, got, want)
            assert 0.5 * abs(want) < abs(got) < 1.5 * abs(want), (name, got, want)
        else:
            assert abs(got - want) < 0.5, (name, got, want)
    kw["excitation"] = False
    d = (
        _simulate_keywords([0], scenario=fault, **kw).y_clean[0]
        - _simulate_keywords([0], scenario="nominal", **kw).y_clean[0]
    )
    dilute = d[-200:, 6:].mean(axis=0)
    assert np.all(np.sign(dilute) == np.sign(SIGNATURES[fault][3:])), dilute


@pytest.mark.parametrize(("valve_beta", "invisible"), [(0.0, True), (0.15, False), (0.3, False)])
def test_valve_hydraulics_modes(valve_beta, invisible):
    """Flow mode (β_sv = 0) hides f2 (spec §7.6: every final change < 0.6 °C); with slide-valve
    hydraulics f2 moves the regenerator by about β_sv/0.3 × 2.7 °C."""
    kw = dict(n_samples=3000, fault_time=500, noise_scale=0.0, valve_beta=valve_beta)
    d = (
        _simulate_keywords([0], scenario="f2", **kw).y_clean[0]
        - _simulate_keywords([0], scenario="nominal", **kw).y_clean[0]
    )
    final = d[-200:, 3:].mean(axis=0)
    if invisible:
        assert np.abs(final).max() < 0.6
    else:
        assert np.abs(final).max() > 1.0
        assert d[-200:, 5].mean() == pytest.approx(2.7 * valve_beta / 0.3, rel=0.5)
