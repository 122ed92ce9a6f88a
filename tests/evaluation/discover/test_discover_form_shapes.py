"""A selected form's shape parameters are fitted with its coefficients (issue 46).

The oracle is the hidden effect itself: a thermocouple saturating as 716 + 10·tanh((T − 716)/10)
is exactly ``−1·(T − 716) + 10·tanh((T − 716)/10)`` added to the model's reading, so a form that
starts from wrong shapes must come back to centre 716 °C and scale 10 °C. Validation seeds only.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import fcc_env
from evaluation import discover as d
from evaluation.discover.corrected_sim import TermTable, simulate_corrected, term_values
from fcc_env.params import FCCParams


class Saturation:
    """A thermocouple reading that saturates: c + s·tanh((T − c)/s)."""

    def __init__(self, channel, c, s):
        self.j, self.c, self.s = fcc_env.MEASUREMENT_NAMES.index(channel), c, s

    def measure(self, t, y):
        out = np.array(y, dtype=float, copy=True)
        out[..., self.j] = self.c + self.s * np.tanh((out[..., self.j] - self.c) / self.s)
        return out


class StateTerm:
    def __init__(self, index, fn):
        self.index, self.fn = index, fn

    def d_state(self, t, x, u, params):
        out = np.zeros_like(x)
        out[..., self.index] = self.fn(x, u)
        return out


def _coef(k):
    return tuple(d.ParamInfo(f"c{i}", 1.0, -math.inf, math.inf) for i in range(k))


def _form(target, *terms):
    return d.FormCandidate(target, tuple(d.Term(t) for t in terms), _coef(len(terms)))


def test_shape_slots_name_the_nonlinear_parameters():
    lin = d.Factor("T_rg2", "lin", 716.0, 12.0)
    tanh = d.Factor("T_rg2", "tanh", 717.0, 9.4)
    # no constant: the linear term's centre is the offset; a tanh has a centre and a scale
    assert d.shape_slots(_form("y:T_rg2", (lin,), (tanh,))) == [
        (0, 0, "center"),
        (1, 0, "center"),
        (1, 0, "scale"),
    ]
    # a constant term is the offset: the linear centre is then not a parameter
    assert d.shape_slots(_form("y:T_rg2", (), (lin,))) == []
    prod = (d.Factor("T_ar", "lin", 200.0, 6.0), d.Factor("T_rg2", "lin", 716.0, 12.0))
    lag = d.Factor("T_ar", "lin", 200.0, 6.0, lag_s=300.0)
    ex = d.Factor("T_rg1", "exp", 680.0, 12.0)
    assert d.shape_slots(_form("T_rg2", (), prod, (lag,), (ex,))) == [
        (1, 0, "center"),
        (1, 1, "center"),
        (2, 0, "lag_s"),
        (3, 0, "scale"),
    ]


def test_equation_shows_the_shape_values_with_units():
    f = _form("y:T_rg2", (d.Factor("T_rg2", "tanh", 716.0, 10.12),))
    eq = d.equation(f, [10.2])
    assert eq["text"] == "T_rg2 [°C] += 10.2·tanh((T_rg2 − 716 °C)/10.12 °C)"
    assert eq["shapes"] == [
        {
            "term": "tanh((T_rg2 − 716 °C)/10.12 °C)",
            "signal": "T_rg2",
            "parameter": "centre",
            "value": 716.0,
            "unit": "°C",
        },
        {
            "term": "tanh((T_rg2 − 716 °C)/10.12 °C)",
            "signal": "T_rg2",
            "parameter": "scale",
            "value": 10.12,
            "unit": "°C",
        },
    ]
    lag = _form("T_rg1", (d.Factor("T_ar", "lin", 200.0, 6.0, lag_s=412.0),))
    assert d.equation(lag, [6e-4])["shapes"][-1]["unit"] == "s"


def test_exp_factor_in_the_kernel_is_numpy_exp():
    """The compiled exp factor against numpy on the kernel's own signals."""
    b = fcc_env.simulate_episodes([5020], 300)
    x0 = fcc_env.PlantConfig().initial_state()[None]
    terms = (d.Term((d.Factor("T_rg2", "exp", 716.0, 12.0),)),)
    table = TermTable(terms, ["T_rg2"])
    Y, Z = simulate_corrected(
        b.inputs,
        x0,
        FCCParams().as_array()[None],
        table,
        np.array([[-2e-3]]),
        sample_time_s=10.0,
        keep_signals=True,
    )
    ref = np.exp((Z[..., d.terms.SIGNALS.index("T_rg2")] - 716.0) / 12.0)
    np.testing.assert_allclose(term_values(table, Z)[..., 0], ref, rtol=1e-12)
    # and the term is the plant's own exponential loss, integrated by fcc_env's d_state path
    eff = StateTerm(7, lambda x, u: -2e-3 * np.exp((x[..., 7] - 716.0) / 12.0))
    np.testing.assert_allclose(
        Y, fcc_env.simulate_episodes([5020], 300, plant_effects=[eff]).y_clean, rtol=0, atol=1e-9
    )


def test_refined_shapes_recover_a_saturation_from_wrong_starting_shapes():
    data = d.from_batch(
        fcc_env.simulate_episodes([5021], 1500, plant_effects=[Saturation("T_rg2", 716.0, 10.0)])
    )
    m = d.PhysicsModel()
    n_train = 900
    m.prepare(data, n_train)
    Y = data.stack(m.output_channels)
    sqrt_w = np.full(len(m.output_channels), 1 / 0.3)
    # wrong shapes: centre 2 °C off, scale 30 % short; the linear term's centre is the offset
    form = _form(
        "y:T_rg2",
        (d.Factor("T_rg2", "lin", 718.0, 12.0),),
        (d.Factor("T_rg2", "tanh", 718.0, 7.0),),
    )
    fixed = d.fit_effects(
        m, data, [form], np.ones(2), np.ones(2, bool), Y, n_train, sqrt_w, grid=False
    )
    out = d.refine_shapes(m, data, [], np.zeros(0), form, fixed.theta, Y, n_train, sqrt_w)
    assert out is not None
    fitted, fit, info = out
    values = {(s["term"][:4], s["parameter"]): s["value"] for s in info["shapes"]}
    assert values[("tanh", "centre")] == pytest.approx(716.0, abs=0.3)
    assert values[("tanh", "scale")] == pytest.approx(10.0, rel=0.05)
    natural = [t["coefficient"] for t in d.equation(fitted, fit.theta)["terms"]]
    assert natural == pytest.approx([-1.0, 10.0], rel=0.1)  # per °C, and in °C
    assert fit.cost < 0.9 * fixed.cost
    assert info["cost_after"] == pytest.approx(fit.cost)
    # deterministic: the same call gives the same shapes, bit for bit
    again = d.refine_shapes(m, data, [], np.zeros(0), form, fixed.theta, Y, n_train, sqrt_w)
    assert again is not None and again[0] == fitted


def test_a_form_without_shape_parameters_is_left_alone():
    data = d.from_batch(fcc_env.simulate_episodes([5022], 300))
    m = d.PhysicsModel()
    m.prepare(data, 200)
    form = _form("T_rg1", (), (d.Factor("T_rg1", "lin", 680.0, 12.0),))
    Y = data.stack(m.output_channels)
    assert d.refine_shapes(m, data, [], np.zeros(0), form, np.zeros(2), Y, 200, np.ones(8)) is None


def test_form_search_refuses_a_non_bool_fit_shapes():
    with pytest.raises(ValueError, match="fit_shapes='yes'"):
        d.FormSearch(fit_shapes="yes")
