"""LRGF + model-error-model diagnosers on FCC data: configuration, bands, alarm statistics."""

from __future__ import annotations

import numpy as np
import pytest

import diagnosers
import fcc_env
from diagnosers import Episode
from diagnosers.mem import t_alpha

FAST = {"max_epochs": 300, "mem_max_epochs": 20}


def _episodes(seeds, n=2000, scenario="nominal", **kw):
    b = fcc_env.simulate_episodes(seeds, n, scenario=scenario, **kw)
    return [
        Episode(b.observations[i].astype(float), fcc_env.MEASUREMENT_NAMES, 10.0, b.fault_onsets[i])
        for i in range(len(seeds))
    ]


@pytest.fixture(scope="module")
def residual_band():
    d = diagnosers.make("lrgf-mem-paper", band_definition="residual", **FAST)
    return d.fit(_episodes([1000, 1001, 1002]))


def test_paper_configuration():
    p = diagnosers.make("lrgf-mem-paper").get_params()
    assert p["relations"] is None  # the class default: T_rx = s1(T_rg2, T_fp)
    assert (p["n_hidden"], p["order"]) == (3, 2)
    assert (p["mem_hidden"], p["mem_input_delays"], p["mem_output_delays"]) == (5, 15, 15)
    assert p["mem_output_activation"] == "tanh" and p["alpha"] == 0.01
    assert p["band_definition"] == "paper" and p["alarm_filter"] == "none"
    assert t_alpha(0.01) == pytest.approx(2.5758, abs=1e-4)


def test_residual_band_covers_healthy_held_out_data(residual_band):
    d = residual_band
    inside = []
    for ep in _episodes([7000, 7001]):
        det = d.detect(ep)
        inside.append(~det.alarm)
        # the band is y_m + y_e ± t_α v around the centre the residual is measured from
        half = (det.upper - det.lower) / 2
        np.testing.assert_allclose(half, t_alpha(0.01) * d.v_residual_[0])
        np.testing.assert_allclose(det.signal - (det.upper + det.lower) / 2, det.residual)
    coverage = np.concatenate(inside).mean()
    assert 0.97 <= coverage <= 1.0, coverage


def test_band_detects_a_large_fault(residual_band):
    ep = _episodes([7002], scenario="f1", fault_time=1000)[0]
    det = residual_band.detect(ep)
    assert det.alarm[1000:1100].mean() > 0.9


def test_ewma_t2_statistic_matches_definition():
    d = diagnosers.make(
        "lrgf-mem",
        relations=[["T_rx", ["T_rg2", "T_fp"]], ["T_rg2", ["T_rg1", "T_ar", "R_ar"]]],
        **FAST,
    ).fit(_episodes([1000, 1001, 1002]))
    ep = _episodes([7003], n=600)[0]
    det = d.detect(ep)
    e = det.residual / d.v_residual_
    z = np.zeros(2)
    t2 = []
    for row in e:
        z = d.ewma_lambda * row + (1 - d.ewma_lambda) * z
        t2.append(z @ d.s_inv_ @ z)
    np.testing.assert_allclose(det.signal[:, 0], t2, rtol=1e-9, atol=1e-12)
    assert np.all(det.upper == d.h_[0]) and d.signal_names_ == ("T2[ewma]",)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"alpha": 0.7}, r"alpha=0.7 outside the allowed range \(0, 0.5\)"),
        ({"n_hidden": 0}, r"n_hidden=0 outside the allowed range \[1, 64\]"),
        ({"band_definition": "wide"}, r"band_definition='wide'; allowed"),
        ({"alarm_filter": "cusum"}, r"alarm_filter='cusum'; allowed"),
        ({"relations": [["T_rx"]]}, r"each relation must be \[output, \[inputs...\]\]"),
        ({"relations": [["T_xx", ["T_fp"]]]}, r"relation channel 'T_xx' is not in"),
        ({"method": "lbfgs"}, r"method='lbfgs'; allowed"),
    ],
)
def test_bad_hyperparameters(kwargs, match):
    with pytest.raises(ValueError, match=match):
        diagnosers.make("lrgf-mem", **kwargs).fit(_episodes([1000], n=200))
