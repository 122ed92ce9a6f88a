"""The modelling loop proposes a form when no library effect explains the residual (issue 46).

Hidden effects here are NOT in :mod:`fcc_env.effects` (user ``d_state``/``measure`` hooks), so
the loop cannot name them; validation seeds (5000+) only. The simulator of a corrected model is
checked against two oracles: :func:`fcc_env.simulation.simulate_inputs` (no correction, bit for
bit) and fcc_env's generic ``d_state`` integration path (a correction, bit for bit).
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

import fcc_env
from evaluation import discover as d
from evaluation.discover.corrected_sim import TermTable, simulate_corrected, with_lags
from fcc_env.params import FCCParams
from fcc_env.physics import steady_state
from fcc_env.simulation import simulate_inputs

N = 4000


class StateTerm:
    """A hidden term added to one state derivative (°C/s)."""

    def __init__(self, index, fn):
        self.index, self.fn = index, fn

    def d_state(self, t, x, u, params):
        out = np.zeros_like(x)
        out[..., self.index] = self.fn(x, u)
        return out


class Saturation:
    """A thermocouple reading that saturates: c + s·tanh((T − c)/s)."""

    def __init__(self, channel, c, s):
        self.j, self.c, self.s = fcc_env.MEASUREMENT_NAMES.index(channel), c, s

    def measure(self, t, y):
        out = np.array(y, dtype=float, copy=True)
        out[..., self.j] = self.c + self.s * np.tanh((out[..., self.j] - self.c) / self.s)
        return out


#: Four effects outside the library (also in lab/form_lab.py as its "val" set).
HIDDEN = {
    "quadratic-loss": StateTerm(4, lambda x, u: -2e-5 * (x[..., 4] - 660.0) ** 2),
    "cross-coupling": StateTerm(9, lambda x, u: 2e-4 * (x[..., 10] - x[..., 9])),
    "saturation": Saturation("T_rg2", 716.0, 10.0),
    "product": StateTerm(7, lambda x, u: 2e-5 * (u[..., 2] - 200.0) * (x[..., 7] - 716.0)),
}


def _inputs(seeds, n):
    b = fcc_env.simulate_episodes(seeds, n)
    U = b.inputs.copy()
    x0 = np.stack([steady_state(FCCParams(), U[e, :20].mean(0)) for e in range(len(seeds))])
    return b, U, x0, np.tile(FCCParams().as_array(), (len(seeds), 1))


def test_corrected_simulator_without_correction_is_simulate_inputs_bit_for_bit():
    _, U, x0, P = _inputs([5000, 5001], 600)
    terms = (d.Term((d.Factor("T_rg2", "lin", 700.0, 10.0),)),)
    Y, _ = simulate_corrected(
        U, x0, P, TermTable(terms, ["T_rg2"]), np.zeros((2, 1)), sample_time_s=10.0
    )
    np.testing.assert_array_equal(Y, simulate_inputs(U, x0=x0).y_clean)


def test_corrected_simulator_matches_fcc_env_d_state_path():
    """A term in dT_rg2/dt, against the plant simulated with the same term as a user effect."""
    eff = StateTerm(7, lambda x, u: -1e-3 * np.tanh((x[..., 7] - 700.0) / 10.0))
    b = fcc_env.simulate_episodes([5002], 600, plant_effects=[eff])
    terms = (d.Term((d.Factor("T_rg2", "tanh", 700.0, 10.0),)),)
    x0 = fcc_env.PlantConfig().initial_state()[None]
    Y, _ = simulate_corrected(
        b.inputs,
        x0,
        FCCParams().as_array()[None],
        TermTable(terms, ["T_rg2"]),
        np.array([[-1e-3]]),
        sample_time_s=10.0,
    )
    clean = fcc_env.simulate_episodes([5002], 600).y_clean
    assert np.abs(b.y_clean - clean).max() > 0.5  # the term matters
    np.testing.assert_allclose(Y, b.y_clean, rtol=0, atol=1e-9)


def test_lagged_signals_are_the_kernel_lags():
    _, U, x0, P = _inputs([5003], 400)
    terms = (d.Term((d.Factor("T_ar", "lin", 200.0, 5.0, lag_s=300.0),)),)
    table = TermTable(terms, ["T_rg1"])
    _, Z = simulate_corrected(
        U, x0, P, table, np.zeros((1, 1)), sample_time_s=10.0, keep_signals=True
    )
    ext = with_lags(table, Z[..., : d.terms.N_BASE_SIGNALS], 10.0)
    np.testing.assert_allclose(ext, Z, rtol=0, atol=1e-9)
    # and the lag is the one the loop uses for sensor lags
    ref = d.first_order_lag(Z[0, :, d.terms.SIGNALS.index("T_ar")], 300.0, 10.0)
    np.testing.assert_allclose(Z[0, :, -1], ref, rtol=0, atol=1e-9)


def test_equation_merges_a_constant_and_a_linear_term_and_names_units():
    f = d.Factor("T_rg2", "lin", 700.0, 10.0)
    two = (d.ParamInfo("c0", 1, -1, 1), d.ParamInfo("c1", 1, -1, 1))
    form = d.FormCandidate("T_rg2", (d.Term(), d.Term((f,))), two)
    # θ_lin per scaled unit −0.12 → −0.012 per °C; constant −8.26 → T_rg2 − (700 − 688.3)
    eq = d.equation(form, [-8.26, -0.12])
    assert eq["text"] == "dT_rg2/dt [°C/s] += −0.012·(T_rg2 − 11.67)"
    assert eq["enters"] == "the state equation of T_rg2"
    assert eq["terms"][0]["unit"] == "°C/s per °C"
    sq = d.FormCandidate(
        "y:T_d1", (d.Term((d.Factor("T_d1", "sq", 698.0, 8.0),)),), form.params[:1]
    )
    assert d.equation(sq, [0.64])["text"] == "T_d1 [°C] += 0.01·(T_d1 − 698)²"


def test_form_definition_round_trips_through_json_and_is_accepted_as_declared():
    data = d.from_batch(fcc_env.simulate_episodes([5004], 500))
    terms = (
        d.Term(),
        d.Term((d.Factor("T_rg1", "lin", 680.0, 10.0), d.Factor("R_ar", "lin", 148.0, 4.0))),
    )
    form = d.form_from_json(
        d.form_to_json(
            d.FormCandidate(
                "T_rg1", terms, (d.ParamInfo("c0", 1, -1, 1), d.ParamInfo("c1", 1, -1, 1))
            )
        ),
        "f",
    )
    assert form.terms == terms and form.target == "T_rg1"
    th = np.array([1e-3, -2e-3])
    m = d.PhysicsModel()
    with_form = m.predict(data, [form], th[None], 500)
    report = {
        "effects": [{"id": "f", "params": {"c0": 1e-3, "c1": -2e-3}, "form": d.form_to_json(form)}]
    }
    accepted = d.PhysicsModel(declared=d.declared_from_report(report))
    np.testing.assert_array_equal(accepted.predict(data, [], np.zeros((1, 0)), 500), with_form)
    assert np.abs(with_form - m.predict(data, [], np.zeros((1, 0)), 500)).max() > 0.1
    with pytest.raises(ValueError, match="neither a form nor a library effect"):
        d.declared_from_report({"effects": [{"id": "nope", "params": {}}]})


def test_an_unstable_correction_is_refused():
    data = d.from_batch(fcc_env.simulate_episodes([5005], 1000))
    m = d.PhysicsModel()
    m.prepare(data, 600)
    f = d.Factor("T_rg1", "lin", 680.0, 1.0)
    p = (d.ParamInfo("c0", 1, -1, 1),)
    grow = d.FormCandidate("T_rg1", (d.Term((f,)),), p)
    assert d.stability(m, data, [grow], np.array([-1e-3]), 1000)["stable"]  # a faster decay
    bad = d.stability(m, data, [grow], np.array([5e-2]), 1000)  # exp(+0.05 t): runaway
    assert bad["stable"] is False


@pytest.mark.parametrize(
    ("kw", "match"),
    [
        ({"max_terms": 0}, r"max_terms=0 is outside the allowed range: an integer in \[1, 5\]"),
        ({"optimizer": "miosr"}, r"optimizer='miosr' .*\['stlsq', 'sr3'\]"),
        ({"targets": ("T_xx",)}, "target='T_xx'"),
    ],
)
def test_form_search_settings_refuse_bad_values(kw, match):
    with pytest.raises(ValueError, match=match):
        d.FormSearch(**kw)


def test_discover_refuses_a_bad_forms_mode():
    data = d.from_batch(fcc_env.simulate_episodes([5006], 200))
    with pytest.raises(ValueError, match=r"forms='sometimes' .*\['auto', 'always', 'never'\]"):
        d.discover(data, forms="sometimes")


SMALL = d.FormSearch(
    library=d.TermLibrary(signals=("T_rg1", "T_rg2", "T_ar"), lags_s=(), functions=("lin",)),
    targets=("T_rg1",),
)


def test_clean_data_gets_no_form_even_when_the_search_is_forced():
    data = d.from_batch(fcc_env.simulate_episodes([5007], 2000))
    rep = d.discover(data, max_effects=0, forms="always", form_search=SMALL, plots=False)
    assert rep.effects == ()
    assert [r["kind"] for r in rep.rounds] == ["form"]  # the search ran, and was refused


@pytest.mark.slow
def test_a_coupling_outside_the_library_is_found_as_a_form(tmp_path):
    """dT_rg1/dt += 2e-4·(T_rg2 − T_rg1): a form, at most 3 terms, error back to the floor;
    written to the report with its equation, and accepted through the CLI."""
    eff = StateTerm(4, lambda x, u: 2e-4 * (x[..., 7] - x[..., 4]))
    seed, n = 5008, 2000
    batch = fcc_env.simulate_episodes([seed], n, plant_effects=[eff])
    floor = d.heldout_rmse(d.from_batch(fcc_env.simulate_episodes([seed], n)))
    rep = d.discover(
        d.from_batch(batch), max_effects=0, form_search=SMALL, out_dir=tmp_path, plots=False
    ).to_json()
    (form,) = rep["effects"]
    assert form["equation"]["text"].startswith("dT_rg1/dt [°C/s] += ")
    assert len(form["form"]["terms"]) <= 3
    assert rep["rmse_after"]["T_rg1"] <= 1.3 * floor["T_rg1"] < rep["rmse_before"]["T_rg1"]
    assert rep["rounds"][0]["candidates"][0]["p_value"] < rep["rounds"][0]["p_threshold"]
    saved = json.loads((tmp_path / "report.json").read_text())
    model = d.PhysicsModel(declared=d.declared_from_report(saved))
    again = d.discover(d.from_batch(batch), model=model, max_effects=0, forms="never")
    assert again.rmse_before["T_rg1"] == pytest.approx(rep["rmse_after"]["T_rg1"], rel=1e-9)


@pytest.mark.slow
def test_out_of_library_effects_goal():
    """Issue 46's goal: ≥ 3 of 4 hidden effects get a form with at most 3 terms whose held-out
    RMSE on the affected channel is within 1.3× the noise floor (lab/form_lab.py val).

    Measured 2026-11-28 with fitted shapes (lab/form_lab.md): 3 of 4 (quadratic loss 1.005×,
    saturation 0.999×, product 1.003× the floor); the T_d1 coupling is explained to 1.02× the
    floor by two afterburn factors of the library, so no form is searched for it."""
    ok = []
    for name, eff in HIDDEN.items():
        seed = 5000
        data = d.from_batch(fcc_env.simulate_episodes([seed], N, plant_effects=[eff]))
        floor = d.heldout_rmse(d.from_batch(fcc_env.simulate_episodes([seed], N)))
        rep = d.discover(data, max_effects=3, plots=False).to_json()
        gap = {c: rep["rmse_before"][c] - floor[c] for c in floor}
        ch = max(gap, key=gap.get)
        forms = [e for e in rep["effects"] if "equation" in e]
        good = bool(forms) and all(len(e["form"]["terms"]) <= 3 for e in forms)
        ok.append(good and rep["rmse_after"][ch] <= 1.3 * floor[ch])
        assert math.isfinite(rep["rmse_after"][ch]), name
    assert sum(ok) >= 3, dict(zip(HIDDEN, ok, strict=True))


@pytest.mark.slow
def test_clean_data_gets_no_form_over_five_seeds():
    for seed in range(5010, 5015):
        data = d.from_batch(fcc_env.simulate_episodes([seed], N))
        assert d.discover(data, max_effects=1, forms="always", plots=False).effects == ()
