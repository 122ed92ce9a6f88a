"""Residual diagnostics for model validation: pure functions on numpy arrays.

Every test takes a residual ``e`` (1-D, one channel, time order) and, for the correlation tests,
an input or other signal ``u`` of the same length. Confidence limits are the large-sample
95 % limits of a white, zero-mean residual: ±1.96/√N for a normalised correlation.

Tests (Ljung & Box 1978; Billings & Voon 1983, 1986; Söderström & Stoica 1989, ch. 11):

* :func:`bias_test` - mean against zero, with a batch-means standard error (robust to
  autocorrelation, unlike σ/√N);
* :func:`drift_test` - slope of a straight line in time, standard error by batch means of the
  slope's influence function;
* :func:`autocorrelation` / :func:`ljung_box` - whiteness: φ_ξξ(τ), and Q = N(N+2)Σρ²/(N−τ)
  against χ²(m);
* :func:`cross_correlation` - φ_uξ(τ) for τ in [−m, m] (a residual that follows an input, or
  that an input follows, means missing dynamics);
* :func:`billings_voon` - the higher-order correlation tests for unmodelled nonlinear structure:
  φ_ξ(ξu)(τ) (τ ≥ 0), φ_u²'ξ(τ), φ_u²'ξ²'(τ) and φ_ξ'ξ'²(τ) (τ ≥ 0), where a prime means the mean
  is removed. All are ideally zero for a model that captured the system.

Each correlation result carries the lags, values, limit, how many values lie outside it and a
``passed`` flag: passed when the count outside is within the 99 % binomial quantile of the count
expected by chance (5 % of the lags), so a long lag window is not failed by one expected excursion,
and no single value exceeds the Bonferroni limit z(1 − 0.025/n_lags)/√N (a single large spike
fails).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from scipy import stats

Z95 = 1.959963984540054


@dataclass(frozen=True)
class CorrelationResult:
    """A normalised correlation function with its 95 % white-noise limit."""

    name: str
    lags: np.ndarray
    values: np.ndarray
    limit: float
    n_outside: int
    n_allowed: int
    passed: bool

    @property
    def max_abs(self) -> float:
        return float(np.max(np.abs(self.values))) if self.values.size else 0.0

    def summary(self) -> dict[str, Any]:
        return {
            "max_abs": self.max_abs,
            "limit": self.limit,
            "n_outside": self.n_outside,
            "n_lags": int(self.lags.size),
            "passed": self.passed,
        }


@dataclass(frozen=True)
class ScalarTest:
    """A scalar statistic with its p-value (two-sided unless stated)."""

    name: str
    estimate: float
    statistic: float
    p_value: float
    passed: bool  # p_value >= alpha

    def summary(self) -> dict[str, Any]:
        return asdict(self)


def _as_1d(x: Any, name: str) -> np.ndarray:
    a = np.asarray(x, dtype=np.float64)
    if a.ndim != 1:
        raise ValueError(f"{name} must be one-dimensional, got shape {a.shape}")
    if a.size < 8:
        raise ValueError(f"{name} needs at least 8 samples, got {a.size}")
    if not np.isfinite(a).all():
        raise ValueError(f"{name} contains NaN or inf")
    return a


def _check_lags(max_lag: int, n: int) -> int:
    if isinstance(max_lag, bool) or not isinstance(max_lag, int | np.integer):
        raise ValueError(f"max_lag must be an integer, got {max_lag!r}")
    if not 1 <= max_lag < n:
        raise ValueError(f"max_lag={max_lag} outside the allowed range [1, {n - 1}]")
    return int(max_lag)


def allowed_exceedances(n_lags: int, rate: float = 0.05, quantile: float = 0.99) -> int:
    """Largest count of |φ| > limit that chance explains (binomial quantile)."""
    return int(stats.binom.ppf(quantile, n_lags, rate))


def _result(name: str, lags: np.ndarray, values: np.ndarray, n: int) -> CorrelationResult:
    limit = Z95 / np.sqrt(n)
    outside = int(np.sum(np.abs(values) > limit))
    allowed = allowed_exceedances(values.size)
    # one very large value fails too: the Bonferroni limit over the lags (5 % family-wise)
    max_limit = stats.norm.isf(0.025 / max(1, values.size)) / np.sqrt(n)
    ok = outside <= allowed and (values.size == 0 or float(np.max(np.abs(values))) <= max_limit)
    return CorrelationResult(name, lags, values, float(limit), outside, allowed, bool(ok))


def ccf(a: Any, b: Any, max_lag: int, *, lags: str = "both") -> tuple[np.ndarray, np.ndarray]:
    """Normalised cross-correlation φ_ab(τ) = Σ a'(k) b'(k+τ) / √(Σa'² Σb'²), means removed.

    ``lags``: ``"both"`` (τ in [−m, m]), ``"positive"`` ([0, m]) or ``"nonzero"`` ([1, m]).
    A positive τ pairs ``a`` now with ``b`` later. A constant signal gives zeros.
    """
    x = _as_1d(a, "a")
    y = _as_1d(b, "b")
    if x.size != y.size:
        raise ValueError(f"signals differ in length: {x.size} and {y.size}")
    n = x.size
    m = _check_lags(max_lag, n)
    x = x - x.mean()
    y = y - y.mean()
    den = np.sqrt(np.dot(x, x) * np.dot(y, y))
    if lags not in ("both", "positive", "nonzero"):
        raise ValueError(f"lags must be 'both', 'positive' or 'nonzero', got {lags!r}")
    taus = {"both": np.arange(-m, m + 1), "positive": np.arange(0, m + 1)}.get(
        lags, np.arange(1, m + 1)
    )
    if den == 0.0:
        return taus, np.zeros(taus.size)
    vals = np.array(
        [np.dot(x[: n - t], y[t:]) if t >= 0 else np.dot(x[-t:], y[: n + t]) for t in taus]
    )
    return taus, vals / den


def autocorrelation(e: Any, max_lag: int = 20) -> CorrelationResult:
    """φ_ξξ(τ), τ = 1..m, with ±1.96/√N limits."""
    x = _as_1d(e, "e")
    lags, vals = ccf(x, x, max_lag, lags="nonzero")
    return _result("phi_xi_xi", lags, vals, x.size)


def ljung_box(e: Any, max_lag: int = 20, alpha: float = 0.05) -> ScalarTest:
    """Ljung–Box portmanteau test: Q = N(N+2) Σ_{τ=1..m} ρ²(τ)/(N−τ) ~ χ²(m) for white ``e``."""
    x = _as_1d(e, "e")
    n = x.size
    lags, rho = ccf(x, x, max_lag, lags="nonzero")
    q = float(n * (n + 2) * np.sum(rho**2 / (n - lags)))
    p = float(stats.chi2.sf(q, df=lags.size))
    return ScalarTest("ljung_box", float(rho[0]), q, p, p >= alpha)


def cross_correlation(
    u: Any, e: Any, max_lag: int = 20, name: str = "phi_u_xi"
) -> CorrelationResult:
    """φ_uξ(τ) for τ in [−m, m] with ±1.96/√N limits (u now against ξ τ samples later)."""
    x = _as_1d(e, "e")
    lags, vals = ccf(u, x, max_lag, lags="both")
    return _result(name, lags, vals, x.size)


def billings_voon(u: Any, e: Any, max_lag: int = 20) -> dict[str, CorrelationResult]:
    """Billings–Voon higher-order correlation tests of a residual ``e`` against an input ``u``.

    Returns ``phi_xi_xiu`` (φ_ξ(ξu), τ ≥ 0), ``phi_u2_xi`` (φ_u²'ξ, all τ), ``phi_u2_xi2``
    (φ_u²'ξ²', all τ) and ``phi_xi_xi2`` (φ_ξ'ξ'², τ ≥ 0; depends on ``e`` only). For a model
    with no unmodelled (nonlinear) structure all are zero within ±1.96/√N.
    """
    x = _as_1d(e, "e")
    v = _as_1d(u, "u")
    if v.size != x.size:
        raise ValueError(f"u and e differ in length: {v.size} and {x.size}")
    xc = x - x.mean()
    vc = v - v.mean()
    n = x.size
    out: dict[str, CorrelationResult] = {}
    # φ_ξ(ξu)(τ) = E[ξ(k) ξ(k+1+τ) u(k+1+τ)] (Billings & Voon 1986, eq. for τ ≥ 0)
    xu = np.empty_like(xc)
    xu[:-1] = xc[1:] * vc[1:]
    xu[-1] = 0.0
    lags, vals = ccf(xc, xu, max_lag, lags="positive")
    out["phi_xi_xiu"] = _result("phi_xi_xiu", lags, vals, n)
    u2 = vc**2 - np.mean(vc**2)
    lags, vals = ccf(u2, xc, max_lag, lags="both")
    out["phi_u2_xi"] = _result("phi_u2_xi", lags, vals, n)
    x2 = xc**2 - np.mean(xc**2)
    lags, vals = ccf(u2, x2, max_lag, lags="both")
    out["phi_u2_xi2"] = _result("phi_u2_xi2", lags, vals, n)
    lags, vals = ccf(xc, x2, max_lag, lags="positive")
    out["phi_xi_xi2"] = _result("phi_xi_xi2", lags, vals, n)
    return out


def batch_means_se(x: Any, n_batches: int = 20) -> float:
    """Standard error of the mean of ``x`` by non-overlapping batch means (autocorrelation-robust)."""
    a = np.asarray(x, dtype=np.float64).ravel()
    nb = int(min(n_batches, max(2, a.size // 5)))
    L = a.size // nb
    if L < 1:
        raise ValueError(f"too few samples ({a.size}) for batch means")
    means = a[: nb * L].reshape(nb, L).mean(axis=1)
    return float(np.std(means, ddof=1) / np.sqrt(nb))


def bias_test(e: Any, alpha: float = 0.05, n_batches: int = 20) -> ScalarTest:
    """Mean of ``e`` against zero: t = mean / SE_batch-means, t(n_batches − 1) reference."""
    x = _as_1d(e, "e")
    se = batch_means_se(x, n_batches)
    m = float(x.mean())
    t = m / se if se > 0 else (0.0 if m == 0 else np.inf * np.sign(m))
    df = min(n_batches, max(2, x.size // 5)) - 1
    p = float(2 * stats.t.sf(abs(t), df))
    return ScalarTest("bias", m, float(t), p, p >= alpha)


def drift_test(
    e: Any, sample_time_s: float = 1.0, alpha: float = 0.05, n_batches: int = 20
) -> ScalarTest:
    """Slope of a least-squares line through ``e`` (units per hour), t-test by batch means.

    The slope is Σ w_k e_k with w_k = (t_k − t̄)/Σ(t − t̄)²; its standard error comes from the
    batch means of N·w_k·e'_k (e' = the detrended residual), which allows for autocorrelation.
    """
    x = _as_1d(e, "e")
    n = x.size
    t = np.arange(n) * float(sample_time_s) / 3600.0
    tc = t - t.mean()
    sxx = float(np.dot(tc, tc))
    slope = float(np.dot(tc, x - x.mean()) / sxx)
    detr = x - x.mean() - slope * tc
    infl = n * tc * detr / sxx
    se = batch_means_se(infl, n_batches)
    stat = slope / se if se > 0 else 0.0
    df = min(n_batches, max(2, n // 5)) - 1
    p = float(2 * stats.t.sf(abs(stat), df))
    return ScalarTest("drift_per_h", slope, float(stat), p, p >= alpha)


def robust_noise_std(e: Any) -> float:
    """White-noise std of ``e`` from the median absolute first difference (MAD / 0.6745 / √2).

    Slow structure (bias, drift, slow dynamics) and rare transients barely change it, so it
    estimates the measurement-noise floor of a residual that also carries model error.
    """
    x = np.asarray(e, dtype=np.float64).ravel()
    d = np.diff(x)
    mad = np.median(np.abs(d - np.median(d)))
    return float(mad / 0.6744897501960817 / np.sqrt(2.0))


def diagnose(
    e: Any,
    others: dict[str, Any] | None = None,
    *,
    sample_time_s: float = 1.0,
    max_lag: int = 20,
) -> dict[str, Any]:
    """All tests of one residual channel as a JSON-ready summary.

    ``others``: name → signal (inputs and other measurements) for cross-correlation and the
    Billings–Voon tests.
    """
    x = _as_1d(e, "e")
    out: dict[str, Any] = {
        "n": int(x.size),
        "rmse": float(np.sqrt(np.mean(x**2))),
        "noise_std_robust": robust_noise_std(x),
        "bias": bias_test(x).summary(),
        "drift": drift_test(x, sample_time_s).summary(),
        "autocorrelation": autocorrelation(x, max_lag).summary(),
        "ljung_box": ljung_box(x, max_lag).summary(),
        "cross_correlation": {},
        "billings_voon": {},
    }
    out["billings_voon"]["phi_xi_xi2"] = billings_voon(x, x, max_lag)["phi_xi_xi2"].summary()
    for name, sig in (others or {}).items():
        s = _as_1d(sig, name)
        out["cross_correlation"][name] = cross_correlation(s, x, max_lag).summary()
        bv = billings_voon(s, x, max_lag)
        out["billings_voon"][name] = {k: r.summary() for k, r in bv.items() if k != "phi_xi_xi2"}
    return out
