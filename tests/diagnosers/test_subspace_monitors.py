"""The dynamic black-box monitors against oracles: ``dpca``, ``cva`` and ``n4sid-glr``.

Oracles: canonical correlations by an independent QR-based computation and by the exact
covariances of a VAR(1) process (scipy's Lyapunov solver); χ² for the T² of a Gaussian
process; the transfer functions of a known state-space system (scipy.signal); the exact
innovations of a system simulated in innovation form.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import linalg, signal, stats
from synthetic import make_episode, with_fault_twins

import diagnosers
from diagnosers import Episode
from diagnosers.classical.dpca_monitor import pca_maps
from diagnosers.classical.n4sid_glr import predictor_innovations
from diagnosers.classical.subspace import (
    StateSpace,
    aic_order,
    canonical_variates,
    lagged,
    n4sid,
    past_future,
)

PHI = np.array([[0.8, 0.3, 0.0], [-0.2, 0.6, 0.1], [0.0, 0.2, 0.5]])


def var1(n: int, seed: int, noise: tuple[float, ...] = (1.0, 1.0, 1.0)) -> np.ndarray:
    """A Gaussian VAR(1) ``y_t = Φ y_{t-1} + S ε_t``, ε standard normal, ``S = diag(noise)``,
    from its stationary law."""
    rng = np.random.default_rng(seed)
    s = np.diag(noise)
    g0 = linalg.solve_discrete_lyapunov(PHI, s @ s)
    y = np.empty((n, 3))
    y[0] = rng.multivariate_normal(np.zeros(3), g0)
    for t in range(1, n):
        y[t] = PHI @ y[t - 1] + s @ rng.normal(size=3)
    return y


def test_lagged_and_past_future_align() -> None:
    y = np.arange(12.0).reshape(6, 2)
    v = lagged(y, 3)
    assert v.shape == (4, 6)
    np.testing.assert_array_equal(v[0], [4, 5, 2, 3, 0, 1])  # y_2, y_1, y_0
    p, f = past_future(y, 2, 2)
    assert p.shape == f.shape == (3, 4)
    np.testing.assert_array_equal(p[0], [2, 3, 0, 1])  # y_1, y_0 for t = 2
    np.testing.assert_array_equal(f[0], [4, 5, 6, 7])  # y_2, y_3


def test_canonical_correlations_equal_an_independent_computation() -> None:
    p, f = past_future(var1(3000, 0), 3, 2)
    cv = canonical_variates(p, f)
    # Björck & Golub: the singular values of Q_pᵀ Q_f, Q from QR of the centred data
    qp = np.linalg.qr(p - p.mean(0))[0]
    qf = np.linalg.qr(f - f.mean(0))[0]
    np.testing.assert_allclose(
        cv.correlations, np.linalg.svd(qp.T @ qf, compute_uv=False), atol=1e-9
    )
    # the variates have unit variance and are uncorrelated on the sample
    u = (p - cv.mean) @ cv.past_weights.T
    np.testing.assert_allclose(np.cov(u.T), np.eye(p.shape[1]), atol=1e-8)


def test_canonical_correlations_of_a_var_process_match_its_exact_covariances() -> None:
    p, f = past_future(var1(40_000, 1), 1, 1)
    g0 = linalg.solve_discrete_lyapunov(PHI, np.eye(3))
    w = linalg.inv(linalg.sqrtm(g0).real)
    exact = np.linalg.svd(w @ PHI @ g0 @ w, compute_uv=False)  # Σ_ff = Σ_pp = Γ0, Σ_fp = ΦΓ0
    np.testing.assert_allclose(canonical_variates(p, f).correlations, exact, atol=0.02)


def test_aic_order_drops_the_negligible_correlations() -> None:
    rho = np.array([0.9, 0.6, 0.3, 0.001, 0.001])
    assert aic_order(rho, 10_000, 1, 5) == 3


def _episodes(y: np.ndarray, n: int) -> list[Episode]:
    names = ("a", "b", "c")
    return [Episode(part, channels=names, sample_time_s=1.0) for part in np.array_split(y, n)]


def test_cva_state_t2_is_chi2_on_a_gaussian_process() -> None:
    det = diagnosers.make("cva", past=2, n_states=3, residual="past", ewma_lambda=1.0)
    det.fit(_episodes(var1(30_000, 2), 3))
    t2 = det.statistics(var1(30_000, 3))[det.window() - 1 :, 0]
    k = det.n_states_
    assert k == 3
    assert abs(t2.mean() / k - 1.0) < 0.03
    # the share over the χ²_k 99 % point is 1 % (binomial 4-sigma band over 30,000 samples)
    share = float(np.mean(t2 > stats.chi2.ppf(0.99, k)))
    assert abs(share - 0.01) < 4 * np.sqrt(0.01 * 0.99 / 30_000)


def test_cva_prediction_error_is_the_var_innovation() -> None:
    # past = 1 and three states span the whole past: the states' one-step prediction of a VAR(1)
    # is Φ y_{t-1}, so T²_e is the squared norm of its standard normal innovation
    det = diagnosers.make("cva", past=1, n_states=3, ewma_lambda=1.0)
    det.fit(_episodes(var1(30_000, 8), 3))
    y = var1(3000, 9)
    t2e = det.statistics(y)[1:, 1]
    exact = np.sum((y[1:] - y[:-1] @ PHI.T) ** 2, axis=1)
    assert np.mean(np.abs(t2e - exact)) < 0.03 * np.mean(exact)
    assert det.signal_names_ == ("T2s", "T2e")


def test_dpca_maps_equal_the_covariance_eigendecomposition() -> None:
    v = lagged(var1(5000, 4), 2)
    centre, state, resid, eig = pca_maps(v, 2, 0.9)
    w, vec = np.linalg.eigh(np.cov(v.T))
    order = np.argsort(w)[::-1]
    np.testing.assert_allclose(eig, w[order], rtol=1e-9)
    c = v - centre
    top = vec[:, order[:2]]
    np.testing.assert_allclose(
        np.sum((c @ state.T) ** 2, 1), np.sum((c @ top) ** 2 / w[order[:2]], 1), rtol=1e-8
    )
    q = np.sum((c - c @ top @ top.T) ** 2, axis=1)
    np.testing.assert_allclose(np.sum((c @ resid.T) ** 2, 1), q, rtol=1e-8)


def test_dpca_q_sees_a_broken_dynamic_relation_that_static_limits_miss() -> None:
    # channel c is nearly a function of the others' past (small noise of its own)
    noise = (1.0, 1.0, 0.02)
    train = _episodes(var1(20_000, 5, noise), 2)
    det = diagnosers.make("dpca", lags=2, n_components=4, ewma_lambda=1.0).fit(train)
    y = var1(4000, 6, noise)
    # from sample 2000 channel c follows another law with the same marginal variance: each
    # sample alone is as likely as before, the relation to the past is broken
    y[2000:, 2] = np.random.default_rng(7).normal(size=2000) * y[:2000, 2].std()
    static = diagnosers.make("pca", n_components=2).fit(train)
    static_alarm = static.detect(Episode(y, channels=("a", "b", "c"), sample_time_s=1.0)).alarm
    alarm = det.detect(Episode(y, channels=("a", "b", "c"), sample_time_s=1.0)).alarm
    assert alarm[:2000].mean() < 0.03
    assert alarm[2000:].mean() > 0.3
    assert static_alarm[2000:].mean() < 0.5 * alarm[2000:].mean()


# ---- n4sid ---------------------------------------------------------------------------------------
A = np.array([[0.9, 0.2], [-0.2, 0.7]])
B = np.array([[1.0], [0.5]])
C = np.array([[1.0, 0.0]])
D = np.array([[0.3]])
K = np.array([[0.5], [0.2]])


def simulate(n: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    u, e = rng.normal(size=(n, 1)), 0.3 * rng.normal(size=(n, 1))
    x, y = np.zeros(2), np.empty((n, 1))
    for t in range(n):
        y[t] = C @ x + D @ u[t] + e[t]
        x = A @ x + B @ u[t] + K @ e[t]
    return u, y, e


def test_n4sid_recovers_a_known_systems_transfer_functions() -> None:
    u, y, _ = simulate(20_000, 0)
    m = n4sid([u], [y], 2, 10)
    w = np.linspace(0.01, 3.0, 25)

    def response(a, b, c, d):
        return signal.dlti(a, b, c, d, dt=1.0).freqresp(w)[1]

    for (a, b, c, d), (ta, tb, tc, td) in (
        ((m.A, m.B, m.C, m.D), (A, B, C, D)),  # input to output
        ((m.A, m.K, m.C, np.eye(1)), (A, K, C, np.eye(1))),  # innovation to output
    ):
        exact = response(ta, tb, tc, td)
        assert np.max(np.abs(response(a, b, c, d) - exact) / np.abs(exact)) < 0.05
    np.testing.assert_allclose(m.R, [[0.09]], rtol=0.05)
    assert np.max(np.abs(m.predictor_poles())) < 1.0


def test_predictor_innovations_of_the_true_model_are_the_true_innovations() -> None:
    u, y, e = simulate(500, 1)
    model = StateSpace(A, B, C, D, K, np.eye(1) * 0.09)
    np.testing.assert_allclose(predictor_innovations(model, u, y), e, atol=1e-10)


def test_n4sid_glr_learns_fault_directions_and_detects_along_them() -> None:
    healthy = [make_episode(2500, seed=s) for s in (1000, 1001, 1002, 1003)]
    train = with_fault_twins(healthy, "f3", onset=600)
    det = diagnosers.make("n4sid-glr", order=6, horizon=10, warm_up=50).fit(train)
    assert det.direction_faults_ == ("f3",)
    assert det.signal_names_ == ("T2[ewma]", "glr[f3]")
    # a GLR alarms in streaks: the healthy share is judged over four episodes
    healthy_share, faulty_share = [], []
    for seed in (7, 8, 9, 10):
        test = with_fault_twins([make_episode(1500, seed=seed)], "f3", onset=800)
        healthy_share.append(det.detect(test[0]).alarm.mean())
        faulty_share.append(det.detect(test[1]).alarm[800:].mean())
    assert np.mean(healthy_share) < 0.05
    assert min(faulty_share) > 0.8


def test_n4sid_glr_refuses_an_input_that_is_not_monitored() -> None:
    det = diagnosers.make("n4sid-glr", channels=["T_rx", "T_rg1"], inputs=["T_fp"])
    with pytest.raises(ValueError, match="must be among the monitored channels"):
        det.fit([make_episode(600, seed=1)])
