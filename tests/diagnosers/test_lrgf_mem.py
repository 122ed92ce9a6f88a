"""LRGF + model-error-model diagnosers on FCC data: configuration, bands, alarm statistics."""

from __future__ import annotations

import numpy as np
import pytest

import diagnosers
import fcc_env
from diagnosers import Episode
from diagnosers.lrgf.bank_detector import holdout_split
from diagnosers.stages.alarm import two_sided_normal_quantile as t_alpha
from diagnosers.stages.ewma_stage import EWMAStage

FAST = {"max_epochs": 300, "mem_max_epochs": 20}


def _episodes(seeds, n=2000, scenario="nominal", **kw):
    fault, plant = fcc_env.env_request(scenario=scenario, **kw)
    b = fcc_env.simulate_episodes(seeds, n, fault=fault, plant=plant)
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
    assert p["relations"] is None  # the preset's relations: T_rx = s1(T_rg2, T_fp)
    assert diagnosers.make("lrgf-mem-paper")._relations() == [("T_rx", ("T_rg2", "T_fp"))]
    assert (p["n_hidden"], p["order"]) == (3, 2)
    assert (p["mem_hidden"], p["mem_input_delays"], p["mem_output_delays"]) == (5, 15, 15)
    assert p["mem_output_activation"] == "tanh" and p["band_alpha"] == 0.01
    assert p["band_definition"] == "paper-record" and p["alarm_filter"] == "none"
    assert t_alpha(0.01) == pytest.approx(2.5758, abs=1e-4)


def test_residual_band_covers_healthy_held_out_data(residual_band):
    d = residual_band
    inside = []
    for ep in _episodes([7000, 7001]):
        det = d.detect(ep)
        w = d.steady_window  # no band during the warm-up
        assert np.all(np.isinf(det.lower[:w])) and not det.alarm[:w].any()
        inside.append(~det.alarm[w:])
        # the band is y_m + y_e ± t_α v around the centre the residual is measured from
        half = (det.upper[w:] - det.lower[w:]) / 2
        np.testing.assert_allclose(half, t_alpha(0.01) * d.v_residual_[0])
        np.testing.assert_allclose(
            det.signal[w:] - (det.upper[w:] + det.lower[w:]) / 2, det.residual[w:]
        )
    coverage = np.concatenate(inside).mean()
    assert 0.97 <= coverage <= 1.0, coverage


def test_band_view_is_the_detection_itself_for_the_paper_rule(residual_band):
    assert residual_band.band_view(_episodes([7005], n=300)[0]) is None


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
    w = d.steady_window
    for k, row in enumerate(e):
        if k >= w:  # silent warm-up: the EWMA starts after it
            z = d.ewma_lambda * row + (1 - d.ewma_lambda) * z
        t2.append(z @ d.stage_.s_inv_ @ z)
    np.testing.assert_allclose(det.signal[:, 0], t2, rtol=1e-9, atol=1e-12)
    assert np.all(det.upper[w:] == d.stage_.h_[0]) and np.all(np.isinf(det.upper[:w]))
    assert d.signal_names_ == ("T2[ewma]",)
    assert not det.alarm[:w].any()
    # the paper-style view of the same models: each output with y_m + y_e ± t_α v around it
    bands = d.band_view(ep)
    np.testing.assert_allclose(bands.signal, ep.y[:, d.out_idx_])
    np.testing.assert_allclose(
        bands.signal[w:] - bands.residual[w:], (bands.lower[w:] + bands.upper[w:]) / 2
    )
    np.testing.assert_allclose(
        bands.upper[w:] - bands.lower[w:], np.tile(2 * t_alpha(0.01) * d.v_, (600 - w, 1))
    )
    np.testing.assert_allclose(bands.residual, det.residual, atol=1e-9)
    assert bands.signal_names == ("T_rx", "T_rg2")


def test_warm_up_is_silent_and_too_short_data_is_refused():
    d = diagnosers.make("lrgf-mem-paper", steady_window=150, **FAST).fit(_episodes([1000, 1001]))
    ep = _episodes([7004], scenario="f1", fault_time=20)[0]  # a fault inside the warm-up
    det = d.detect(ep)
    assert not det.alarm[:150].any() and det.alarm[150:250].mean() > 0.9
    d.reset()
    streamed = [d.update(row).alarm for row in ep.y[:200]]
    np.testing.assert_array_equal(streamed, det.alarm[:200])
    with pytest.raises(
        ValueError, match=r"calibration samples after the warm-up \(steady_window=150\)"
    ):
        diagnosers.make("lrgf-mem-paper", steady_window=150, **FAST).fit(_episodes([1000], n=160))


def test_alarm_limits_follow_their_definition():
    from scipy.stats import chi2, norm

    from diagnosers.stages.alarm import TAIL_FIT_QUANTILE

    d = EWMAStage(
        alarm_filter="ewma-t2",
        ewma_lambda=0.3,
        threshold_margin=1.1,
        false_alarm_target=0.002,
        limit_method="chi2-tail",
    )
    rng = np.random.default_rng(0)
    t2 = chi2.rvs(3, size=(20000, 1), random_state=rng) * 1.5  # a tail heavier than chi2_3
    h = d.limit(t2, 3)[0]
    inflation = np.quantile(t2, TAIL_FIT_QUANTILE) / chi2.ppf(TAIL_FIT_QUANTILE, 3)
    assert inflation == pytest.approx(1.5, rel=0.05)
    assert h == pytest.approx(1.1 * inflation * chi2.ppf(0.998, 3))
    light = chi2.rvs(3, size=(20000, 1), random_state=rng) * 0.5  # lighter: no deflation
    assert d.limit(light, 3)[0] == pytest.approx(1.1 * chi2.ppf(0.998, 3))
    z = np.abs(rng.normal(scale=[1.0, 3.0], size=(20000, 2)))  # per-relation |EWMA|, target / 2
    np.testing.assert_allclose(
        d.limit(z, 0), 1.1 * np.array([1.0, 3.0]) * norm.ppf(1 - 0.0005), rtol=0.05
    )
    d.limit_method = "empirical"
    assert d.limit(t2, 3)[0] == pytest.approx(1.1 * np.quantile(t2, 0.998))


def test_learning_rate_reaches_the_trainer():
    fits = {
        lr: diagnosers.make("lrgf-mem-paper", lr=lr, max_epochs=20, mem_max_epochs=2)
        .fit(_episodes([1000, 1001], n=400))
        .bank_.train_fit_loss[0]
        for lr in (0.001, 0.05)
    }
    assert fits[0.001] != fits[0.05]


@pytest.mark.parametrize("val_fraction", [0.0, 0.25])
def test_val_fraction_reaches_each_network(val_fraction):
    """The bank's network equals one trained by ``fit_lrgf`` directly with that hold-out share
    (same seed, one thread); 0 and 0.25 train different networks."""
    from diagnosers.networks.lrgf_net import LRGF
    from diagnosers.networks.training import fit_lrgf

    eps = _episodes([1000, 1001], n=400)
    kw = {"max_epochs": 20, "mem_max_epochs": 2, "mem_input_delays": 2, "mem_output_delays": 2}
    det = diagnosers.make("lrgf-mem-paper", val_fraction=val_fraction, **kw).fit(eps)
    names = list(fcc_env.MEASUREMENT_NAMES)
    ui, yi = [names.index("T_rg2"), names.index("T_fp")], [names.index("T_rx")]
    train = holdout_split(eps)[0]  # the records the bank trains on
    p = det.get_params()
    net = LRGF(2, p["n_hidden"], p["order"], 1, initial_state="steady",
               steady_window=p["steady_window"], seed=p["seed"]).double()  # fmt: skip
    fit_lrgf(net, [y[:, ui] for y in train], [y[:, yi] for y in train], lr=p["lr"],
             max_epochs=20, patience=50, val_fraction=val_fraction, seed=p["seed"],
             num_threads=1)  # fmt: skip
    net.eval()
    u = eps[1].y[:, ui]
    np.testing.assert_array_equal(det.lrgf_[0].predict(u), net.predict(u))
    other = diagnosers.make("lrgf-mem-paper", val_fraction=0.25 - val_fraction, **kw).fit(eps)
    assert not np.array_equal(other.lrgf_[0].predict(u), net.predict(u))


def test_per_relation_network_sizes_reach_the_networks_and_survive_save_load(tmp_path):
    eps = _episodes([1000, 1001], n=400)
    kw = {"max_epochs": 5, "mem_max_epochs": 2, "mem_input_delays": 2, "mem_output_delays": 2}
    det = diagnosers.make("lrgf-mem", n_hidden=[2, 4, 3], **kw).fit(eps)
    assert [net.n_hidden for net in det.lrgf_] == [2, 4, 3]
    # one size for all is the same as that size repeated: same seeds, same networks
    same = diagnosers.make("lrgf-mem", n_hidden=[3, 3, 3], **kw).fit(eps)
    ref = diagnosers.make("lrgf-mem", n_hidden=3, **kw).fit(eps)
    np.testing.assert_array_equal(same.detect(eps[0]).signal, ref.detect(eps[0]).signal)
    det.save(tmp_path / "m")
    back = diagnosers.Diagnoser.load(tmp_path / "m")
    assert list(back.get_params()["n_hidden"]) == [2, 4, 3]
    np.testing.assert_array_equal(back.detect(eps[1]).signal, det.detect(eps[1]).signal)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        (
            {"band_alpha": 0.7},
            r"band_alpha=0.7 is outside the allowed range: a number in \(0, 0.5\)",
        ),
        ({"n_hidden": 0}, r"n_hidden=0 is outside the allowed range: an integer in \[1, 64\]"),
        (
            {"n_hidden": [5, 10]},
            r"n_hidden=\[5, 10\] is outside the allowed range: an integer in \[1, 64\] or 3 of "
            r"them, one per relation \(there are 3 relations\)",
        ),
        ({"n_hidden": [5, 0, 5]}, r"n_hidden=\[5, 0, 5\] is outside the allowed range"),
        (
            {"band_definition": "wide"},
            r"band_definition='wide' is outside the allowed range: one of \['paper', 'paper-record', 'residual'\]",
        ),
        (
            {"alarm_filter": "cusum"},
            r"alarm_filter='cusum' is outside the allowed range: one of \['none', 'ewma', 'ewma-t2'\]",
        ),
        ({"relations": [["T_rx"]]}, r"each relation must be \[output, \[inputs...\]\]"),
        ({"relations": [["T_xx", ["T_fp"]]]}, r"relation channel 'T_xx' is not in"),
        (
            {"method": "lbfgs"},
            r"method='lbfgs' is outside the allowed range: one of \['adam', 'spsa'\]",
        ),
        (
            {"limit_method": "gev"},
            r"limit_method='gev' is outside the allowed range: one of \['empirical', 'chi2-tail'\]",
        ),
        (
            {"steady_window": 0},
            r"steady_window=0 is outside the allowed range: an integer in \[1, 100000\]",
        ),
        ({"seed": "a"}, r"seed='a' is outside the allowed range: an integer in \[0, inf\)"),
        ({"seed": -1}, r"seed=-1 is outside the allowed range: an integer in \[0, inf\)"),
        ({"lr": "0.1"}, r"lr='0.1' is outside the allowed range: a number in \(0, 1\]"),
        (
            {"ewma_lambda": None},
            r"ewma_lambda=None is outside the allowed range: a number in \(0, 1\]",
        ),
        ({"progress": 1}, r"progress=1 is outside the allowed range: True or False"),
        (
            {"val_fraction": 1.0},
            r"val_fraction=1.0 is outside the allowed range: a number in \[0, 1\)",
        ),
    ],
)
def test_bad_hyperparameters(kwargs, match):
    with pytest.raises(ValueError, match=match):
        diagnosers.make("lrgf-mem", **kwargs).fit(_episodes([1000], n=200))
