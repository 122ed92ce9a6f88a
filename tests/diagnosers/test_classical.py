"""Behaviour of the classical baselines (limits, pca, arx-band) against known answers."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats
from synthetic import CHANNELS, inject_step_fault, make_episode

from diagnosers import Episode, make
from diagnosers.classical import ARXBand, fit_percent, hotelling_t2_limit, spe_limit
from diagnosers.stages.alarm import two_sided_normal_quantile
from evaluation.metrics import episode_scores

ALPHA = 0.01
Z = 2.5758293035489004  # Φ⁻¹(1 - 0.01/2), tabulated


@pytest.fixture(scope="module")
def steady() -> list[Episode]:
    """Constant inputs: every channel is nominal + iid Gaussian noise (σ = 0.2)."""
    return [make_episode(10_000, seed=s, step_scale=0.0) for s in (11, 12)]


@pytest.fixture(scope="module")
def stepped_train() -> list[Episode]:
    return [make_episode(3000, seed=s) for s in (21, 22, 23)]


@pytest.fixture(scope="module")
def stepped_test() -> list[Episode]:
    return [make_episode(4000, seed=s) for s in (31, 32, 33)]


def test_two_sided_normal_quantile() -> None:
    assert two_sided_normal_quantile(ALPHA) == pytest.approx(Z, rel=1e-12)
    assert two_sided_normal_quantile(0.05) == pytest.approx(1.959963984540054, rel=1e-12)


def test_fit_percent() -> None:
    y = np.array([1.0, 2.0, 3.0, 4.0])
    assert fit_percent(y, y) == 100.0
    assert fit_percent(y, np.full(4, y.mean())) == pytest.approx(0.0)
    assert fit_percent(y, y + 1.0) == pytest.approx(100 * (1 - 2 / np.sqrt(5)))
    with pytest.raises(ValueError, match="constant"):
        fit_percent(np.ones(3), np.ones(3))
    with pytest.raises(ValueError, match="same length"):
        fit_percent(y, y[:3])


# ---- limits ------------------------------------------------------------------------------------
def test_limits_are_mean_plus_minus_z_std(steady: list[Episode]) -> None:
    d = make("limits", channels=["T_rx", "T_fp"]).fit(steady)
    y = np.concatenate([ep.y for ep in steady])[:, [3, 2]]
    np.testing.assert_allclose(d.lower_, y.mean(0) - Z * y.std(0, ddof=1), rtol=1e-12)
    np.testing.assert_allclose(d.upper_, y.mean(0) + Z * y.std(0, ddof=1), rtol=1e-12)
    assert d.signal_names_ == ("T_rx", "T_fp")
    det = d.detect(steady[0])
    np.testing.assert_allclose(det.residual, steady[0].y[:, [3, 2]] - d.mean_)


def test_limits_false_alarm_rate_close_to_alpha(steady: list[Episode]) -> None:
    held_out = [make_episode(20_000, seed=s, step_scale=0.0) for s in (13, 14)]
    one = make("limits", channels=["T_rx"]).fit(steady)
    rate = np.mean([episode_scores(one.detect(ep).alarm, None)["r_fd"] for ep in held_out])
    # 40 000 samples: binomial sd ≈ 0.0005, plus the error of the estimated limits.
    assert rate == pytest.approx(ALPHA, abs=0.003)
    # All 8 independent channels: any of them alarms with probability 1 - (1 - α)^8 ≈ 0.077.
    every = make("limits").fit(steady)
    rate8 = np.mean([episode_scores(every.detect(ep).alarm, None)["r_fd"] for ep in held_out])
    assert rate8 == pytest.approx(1 - (1 - ALPHA) ** 8, abs=0.01)


def test_limits_detect_a_step_on_a_steady_plant(steady: list[Episode]) -> None:
    d = make("limits", channels=["T_rx"]).fit(steady)
    faulty = inject_step_fault(make_episode(3000, seed=15, step_scale=0.0), onset=1000)
    s = episode_scores(d.detect(faulty).alarm, faulty.fault_onset)
    assert s["r_td"] > 0.99 and s["t_dt"] <= 2 and s["r_fd"] < 0.03


# ---- pca ---------------------------------------------------------------------------------------
def test_pca_t2_limit_matches_f_formula(stepped_train: list[Episode]) -> None:
    d = make("pca", n_components=3).fit(stepped_train)
    n, k = 9000, 3
    expected = k * (n - 1) * (n + 1) / (n * (n - k)) * stats.f.ppf(1 - ALPHA, k, n - k)
    assert d.n_samples_ == n
    assert d.t2_limit_ == pytest.approx(expected, rel=1e-12)
    assert hotelling_t2_limit(k, n, ALPHA) == pytest.approx(expected, rel=1e-12)
    np.testing.assert_array_equal(d.detect(stepped_train[0]).upper[0], [d.t2_limit_, d.q_limit_])


def test_pca_spe_limit_formula_and_monte_carlo() -> None:
    lam = np.array([0.5, 0.3, 0.1])
    t1, t2, t3 = lam.sum(), (lam**2).sum(), (lam**3).sum()
    h0 = 1 - 2 * t1 * t3 / (3 * t2**2)
    c = stats.norm.ppf(1 - ALPHA)
    jm = t1 * (c * np.sqrt(2 * t2 * h0**2) / t1 + 1 + t2 * h0 * (h0 - 1) / t1**2) ** (1 / h0)
    assert spe_limit(lam, ALPHA) == pytest.approx(jm, rel=1e-12)
    rng = np.random.default_rng(0)
    # Q = Σ λ_j z_j² for Gaussian scores; its 99 % quantile is what the limit approximates.
    # The second spectrum (one large, many small eigenvalues) makes h0 < 0 and needs Box's form.
    for spectrum in (lam, np.r_[1.0, np.full(30, 0.05)]):
        q = (rng.standard_normal((200_000, spectrum.size)) ** 2) @ spectrum
        assert spe_limit(spectrum, ALPHA) == pytest.approx(np.quantile(q, 1 - ALPHA), rel=0.15)


def test_pca_chooses_smallest_k_reaching_variance(stepped_train: list[Episode]) -> None:
    for target in (0.5, 0.8, 0.95):
        d = make("pca", variance_explained=target).fit(stepped_train)
        ratio = np.cumsum(d.eigenvalues_) / d.eigenvalues_.sum()
        k = d.n_components_
        assert ratio[k - 1] >= target - 1e-12 or k == len(CHANNELS) - 1
        assert k == 1 or ratio[k - 2] < target
    # Asking for all the variance still leaves one dimension for SPE.
    assert make("pca", variance_explained=1.0).fit(stepped_train).n_components_ == 7


def test_pca_false_alarms_and_detection_on_iid_data(steady: list[Episode]) -> None:
    d = make("pca", n_components=4).fit(steady)
    held_out = make_episode(20_000, seed=16, step_scale=0.0)
    st = d.detect(held_out).signal
    # Each statistic alone exceeds its limit with probability ≈ α on iid Gaussian data.
    assert np.mean(st[:, 0] > d.t2_limit_) == pytest.approx(ALPHA, abs=0.004)
    assert np.mean(st[:, 1] > d.q_limit_) == pytest.approx(ALPHA, abs=0.004)
    faulty = inject_step_fault(make_episode(3000, seed=17, step_scale=0.0), onset=1000)
    s = episode_scores(d.detect(faulty).alarm, faulty.fault_onset)
    assert s["r_td"] > 0.99 and s["t_dt"] <= 2


def test_pca_n_components_too_large_for_the_data(steady: list[Episode]) -> None:
    with pytest.raises(
        ValueError, match=r"n_components=8 is outside the allowed range: an integer in \[1, 7\]"
    ):
        make("pca", n_components=8).fit(steady)
    with pytest.raises(ValueError, match="at least 2 monitored channels"):
        make("pca", channels=["T_rx"]).fit(steady)


# ---- arx-band ----------------------------------------------------------------------------------
def test_arx_recovers_an_exact_first_order_system() -> None:
    # Noise-free data from y(t) = a y(t-1) + (1-a)(0.6 u1(t-1) + 0.4 u2(t-1)) in deviations
    # (tests/synthetic.py), so a (na=1, nb=1, nk=1) ARX model is exact.
    clean = [make_episode(2000, seed=s, noise_std=0.0) for s in (41, 42)]
    d = make("arx-band", na=1, nb=1, nk=1).fit(clean)
    a = np.exp(-1 / 4)
    b = (1 - a) * np.array([0.6, 0.4])
    np.testing.assert_allclose(d.a_, [a], rtol=1e-8)
    np.testing.assert_allclose(d.b_[:, 0], b, rtol=1e-7)
    assert d.c_ == pytest.approx(520 - a * 520 - b @ [700.0, 220.0], abs=1e-6)
    assert d.sigma_ < 1e-8
    assert d.train_fit_percent_ > 99.999


def test_arx_simulation_residual_small_on_held_out_data(
    stepped_train: list[Episode], stepped_test: list[Episode]
) -> None:
    d = make("arx-band").fit(stepped_train)
    assert isinstance(d, ARXBand)
    # Free-run residual ≈ measurement noise (σ = 0.2 °C) plus propagated input noise.
    assert d.sigma_ < 0.3
    assert d.train_fit_percent_ > 90
    n0 = d.n_warmup_
    for ep in stepped_test:
        y = ep.channel("T_rx")
        u = np.column_stack([ep.channel("T_rg2"), ep.channel("T_fp")])
        y_m = d.simulate(u, y[:n0])
        assert fit_percent(y[n0:], y_m[n0:]) > 90
        assert np.sqrt(np.mean((y - y_m)[n0:] ** 2)) < 0.3
        # The detector's band is centred on the same free-run simulation.
        det = d.detect(ep)
        np.testing.assert_allclose((det.lower + det.upper)[:, 0] / 2, y_m, rtol=1e-12)
        np.testing.assert_allclose(det.upper - det.lower, 2 * Z * d.sigma_, rtol=1e-9)


def test_arx_band_coverage_near_confidence_level(
    stepped_train: list[Episode], stepped_test: list[Episode]
) -> None:
    d = make("arx-band").fit(stepped_train)
    n0 = d.n_warmup_
    inside = np.concatenate([~d.detect(ep).alarm[n0:] for ep in stepped_test])
    assert inside.mean() == pytest.approx(1 - ALPHA, abs=0.007)


def test_arx_detects_a_3_degree_step_on_t_rx(
    stepped_train: list[Episode], stepped_test: list[Episode]
) -> None:
    d = make("arx-band").fit(stepped_train)
    faulty = inject_step_fault(stepped_test[0], onset=2000, magnitude=3.0)
    s = episode_scores(d.detect(faulty).alarm, faulty.fault_onset)
    assert s["r_td"] > 0.95
    assert s["t_dt"] <= 3
    assert s["r_fd"] < 0.03
    # Simulation mode: the fault is not absorbed, the residual stays near +3 °C to the end.
    resid = d.detect(faulty).residual[-500:, 0]
    assert resid.mean() == pytest.approx(3.0, abs=0.2)


def test_arx_warm_up_follows_measurement(stepped_test: list[Episode]) -> None:
    d = make("arx-band", na=3, nb=4, nk=2).fit(stepped_test)
    assert d.n_warmup_ == 5
    det = d.detect(stepped_test[0])
    np.testing.assert_array_equal(det.residual[:5, 0], 0.0)
    assert not det.alarm[:5].any()
    assert np.any(det.residual[5:, 0] != 0.0)
    # A short episode made only of warm-up samples is fine too.
    short = Episode(stepped_test[0].y[:3], CHANNELS, 10.0)
    assert not d.detect(short).alarm.any()


def test_arx_simulate_validates_inputs(stepped_train: list[Episode]) -> None:
    d = make("arx-band").fit(stepped_train)
    with pytest.raises(ValueError, match=r"u must have shape \(T, 2\)"):
        d.simulate(np.zeros((10, 3)), 520.0)
    with pytest.raises(ValueError, match="y0 needs at least 9 warm-up outputs"):
        d.simulate(np.zeros((10, 2)), np.zeros(4))
    assert d.simulate(np.zeros((10, 2)), 520.0).shape == (10,)


def test_arx_needs_enough_data() -> None:
    with pytest.raises(ValueError, match="regression rows"):
        make("arx-band").fit([make_episode(20, seed=1)])


# ---- hyperparameter validation -----------------------------------------------------------------
@pytest.mark.parametrize(
    ("name", "params", "match"),
    [
        (
            "limits",
            {"alpha": 0.0},
            r"alpha=0\.0 is outside the allowed range: a number in \(0, 1\)",
        ),
        (
            "limits",
            {"alpha": 1.5},
            r"alpha=1\.5 is outside the allowed range: a number in \(0, 1\)",
        ),
        (
            "limits",
            {"alpha": "0.01"},
            r"alpha='0\.01' is outside the allowed range: a number in \(0, 1\)",
        ),
        (
            "limits",
            {"alpha": True},
            r"alpha=True is outside the allowed range: a number in \(0, 1\)",
        ),
        (
            "limits",
            {"channels": "T_rx"},
            r"channels='T_rx' is outside the allowed range: None or a non-empty list",
        ),
        (
            "limits",
            {"channels": []},
            r"channels=\[\] is outside the allowed range: None or a non-empty list",
        ),
        (
            "limits",
            {"channels": ["T_rx", "T_rx"]},
            r"channels=.* is outside the allowed range: .*distinct channel names",
        ),
        ("pca", {"alpha": -0.1}, r"alpha=-0\.1 is outside the allowed range: a number in \(0, 1\)"),
        (
            "pca",
            {"variance_explained": 0.0},
            r"variance_explained=0\.0 is outside the allowed range: a number in \(0, 1\]",
        ),
        (
            "pca",
            {"variance_explained": 1.2},
            r"variance_explained=1\.2 is outside the allowed range: a number in \(0, 1\]",
        ),
        (
            "pca",
            {"n_components": 0},
            r"n_components=0 is outside the allowed range: an integer in \[1, 10000\] or None",
        ),
        (
            "pca",
            {"n_components": 2.0},
            r"n_components=2\.0 is outside the allowed range: an integer in \[1, 10000\] or None",
        ),
        (
            "pca",
            {"channels": [1, 2]},
            r"channels=\[1, 2\] is outside the allowed range: None or a non-empty list",
        ),
        ("arx-band", {"output": 3}, r"output=3 is outside the allowed range: a channel name"),
        ("arx-band", {"inputs": []}, r"inputs=\[\] is outside the allowed range: a non-empty list"),
        ("arx-band", {"inputs": ("T_rx",)}, r"output='T_rx' must not also be one of inputs"),
        ("arx-band", {"na": -1}, r"na=-1 is outside the allowed range: an integer in \[0, 50\]"),
        ("arx-band", {"na": 2.5}, r"na=2\.5 is outside the allowed range: an integer in \[0, 50\]"),
        ("arx-band", {"nb": 0}, r"nb=0 is outside the allowed range: an integer in \[1, 200\]"),
        ("arx-band", {"nk": 101}, r"nk=101 is outside the allowed range: an integer in \[0, 100\]"),
        (
            "arx-band",
            {"alpha": 1.0},
            r"alpha=1\.0 is outside the allowed range: a number in \(0, 1\)",
        ),
    ],
)
def test_bad_hyperparameters_raise_on_fit(name: str, params: dict, match: str) -> None:
    d = make(name, **params)  # __init__ stores verbatim and never validates
    assert all(getattr(d, k) is v for k, v in params.items())
    with pytest.raises(ValueError, match=match):
        d.fit([make_episode(200, seed=0)])
    assert not getattr(d, "_fitted_", False)


@pytest.mark.parametrize(
    ("name", "params", "match"),
    [
        ("limits", {"channels": ["T_rx", "T_nope"]}, r"unknown channel\(s\) \['T_nope'\]"),
        ("pca", {"channels": ["Xx", "T_rx"]}, r"unknown channel\(s\) \['Xx'\]. Available"),
        ("arx-band", {"output": "T_x"}, r"output: unknown channel\(s\) \['T_x'\]"),
        ("arx-band", {"inputs": ["T_fp", "u9"]}, r"inputs: unknown channel\(s\) \['u9'\]"),
    ],
)
def test_unknown_channels_raise_on_fit(name: str, params: dict, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        make(name, **params).fit([make_episode(200, seed=0)])
