"""Residual diagnostics: each test rejects the structure it is for and passes white noise."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from evaluation.discover import residual_tests as rt

N = 2000


def white(seed: int, n: int = N, scale: float = 1.0) -> np.ndarray:
    return scale * np.random.default_rng(seed).standard_normal(n)


def test_ccf_matches_direct_formula_and_sign_of_lag():
    rng = np.random.default_rng(0)
    u = rng.standard_normal(500)
    e = np.roll(u, 3) + 0.1 * rng.standard_normal(500)  # e(k) = u(k-3): u leads by 3
    lags, vals = rt.ccf(u, e, 5)
    assert lags[np.argmax(vals)] == 3
    uc, ec = u - u.mean(), e - e.mean()
    direct = np.dot(uc[:-3], ec[3:]) / np.sqrt(np.dot(uc, uc) * np.dot(ec, ec))
    assert vals[lags == 3][0] == pytest.approx(direct)


def test_ljung_box_size_on_white_noise_and_power_on_ar1():
    rejections = sum(not rt.ljung_box(white(s)).passed for s in range(200))
    assert 2 <= rejections <= 20  # nominal 5 % of 200 = 10
    ar = signal.lfilter([1.0], [1.0, -0.5], white(1))
    res = rt.ljung_box(ar)
    assert not res.passed and res.p_value < 1e-10
    assert not rt.autocorrelation(ar).passed
    assert rt.autocorrelation(white(2)).passed


def test_bias_test_is_robust_to_autocorrelation():
    # strongly coloured zero-mean noise: a naive sigma/sqrt(N) test would reject far too often
    rej = 0
    for s in range(100):
        e = signal.lfilter([1.0], [1.0, -0.9], white(s))
        rej += not rt.bias_test(e).passed
    assert rej <= 15
    biased = signal.lfilter([1.0], [1.0, -0.9], white(5)) + 1.5
    res = rt.bias_test(biased)
    assert not res.passed and res.estimate == pytest.approx(1.5, abs=0.6)


def test_drift_test_estimates_slope_per_hour():
    t_h = np.arange(N) * 10.0 / 3600.0
    e = 0.5 * t_h + white(3, scale=0.3)
    res = rt.drift_test(e, sample_time_s=10.0)
    assert not res.passed and res.estimate == pytest.approx(0.5, rel=0.05)
    assert rt.drift_test(white(4), sample_time_s=10.0).p_value > 0.01


def test_cross_correlation_flags_a_missing_input():
    u = white(6)
    e = 0.5 * np.roll(u, 2) + white(7)
    res = rt.cross_correlation(u, e, 10)
    assert not res.passed and res.lags[np.argmax(np.abs(res.values))] == 2
    assert rt.cross_correlation(u, white(8), 10).passed


def test_billings_voon_detect_quadratic_terms_that_linear_tests_miss():
    u = white(9)
    e = 0.6 * (u**2 - 1.0) + white(10, scale=0.5)  # even nonlinearity: uncorrelated with u
    assert rt.cross_correlation(u, e, 10).passed  # the linear test is blind to it
    bv = rt.billings_voon(u, e, 10)
    assert not bv["phi_u2_xi"].passed
    assert bv["phi_u2_xi"].lags[np.argmax(np.abs(bv["phi_u2_xi"].values))] == 0
    w = white(11)
    e2 = w + 0.8 * (np.roll(w, 1) ** 2 - 1.0)  # residual with a nonlinear self-term
    assert not rt.billings_voon(u, e2, 10)["phi_xi_xi2"].passed
    clean = rt.billings_voon(u, white(12), 10)
    assert sum(r.passed for r in clean.values()) >= 3


def test_robust_noise_std_ignores_slow_structure():
    t = np.arange(N)
    e = 3.0 * np.sin(2 * np.pi * t / 700) + 0.02 * t + white(13, scale=0.3)
    assert rt.robust_noise_std(e) == pytest.approx(0.3, rel=0.1)
    assert rt.diagnose(e, {"u": white(14)}, sample_time_s=10.0)["ljung_box"]["passed"] is False


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: rt.ccf(np.ones(20), np.ones(21), 3), "differ in length"),
        (lambda: rt.ccf(np.ones(20), np.ones(20), 20), r"max_lag=20 outside .*\[1, 19\]"),
        (lambda: rt.autocorrelation(np.array([1.0, np.nan] * 10)), "NaN"),
        (lambda: rt.ljung_box(np.ones((4, 4))), "one-dimensional"),
        (lambda: rt.ccf(np.ones(20), np.ones(20), 3, lags="x"), "lags must be"),
    ],
)
def test_bad_input_errors_name_the_problem(call, match):
    with pytest.raises(ValueError, match=match):
        call()
