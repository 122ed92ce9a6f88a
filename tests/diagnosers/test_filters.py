"""The FCC state estimator (issue 42 item 1): the algebra against the exact Kalman filter, the
innovations on simulated episodes (training seeds 1000+, validation seeds 5000+), stream =
batch, and the configuration's errors."""

from __future__ import annotations

import numpy as np
import pytest

import fcc_env
from diagnosers.filters import FCCStateEstimator, UKFConfig
from diagnosers.filters.ukf_linear import linear_filter
from fcc_env import FaultSpec, PlantConfig

TRAIN_SEEDS = [1000, 1001, 1002, 1003]
N = 1500
SKIP = 100  # the program's warm-up at nominal


def lag1(x: np.ndarray) -> np.ndarray:
    """Lag-1 autocorrelation per channel of (B, T, C), pooled over episodes."""
    x = x - x.mean(axis=1, keepdims=True)
    return (x[:, 1:] * x[:, :-1]).sum(axis=(0, 1)) / (x**2).sum(axis=(0, 1))


@pytest.fixture(scope="module")
def healthy() -> tuple[fcc_env.BatchResult, object]:
    b = fcc_env.simulate_episodes(TRAIN_SEEDS, N)
    return b, FCCStateEstimator(fcc_env.FCCParams()).filter(b.observations)


# ---- the algebra: exact on a linear-Gaussian model ---------------------------------------------
def kalman(A, C, q, r_abs, r_rel, m, P, Y):
    """The textbook Kalman filter, written out: innovations, S, posterior means and stds."""
    out = {"innovations": [], "innovation_cov": [], "states": [], "state_std": []}
    for y in Y:
        R = np.diag((r_abs + r_rel * np.abs(y)) ** 2)
        S = C @ P @ C.T + R
        K = P @ C.T @ np.linalg.inv(S)
        nu = y - C @ m
        m = m + K @ nu
        P = (np.eye(len(m)) - K @ C) @ P
        out["innovations"].append(nu)
        out["innovation_cov"].append(S)
        out["states"].append(m)
        out["state_std"].append(np.sqrt(np.diag(P)))
        m, P = A @ m, A @ P @ A.T + np.diag(q)
    return {k: np.array(v) for k, v in out.items()}


@pytest.mark.parametrize("alpha,beta,kappa", [(1.0, 2.0, 0.0), (0.3, 2.0, 1.0), (1.0, 0.0, 3.0)])
def test_ukf_equals_the_kalman_filter_on_a_linear_model(alpha, beta, kappa) -> None:
    rng = np.random.default_rng(1000)
    n, ny, T = 5, 3, 60
    A = np.eye(n) + 0.1 * rng.standard_normal((n, n))
    C = rng.standard_normal((ny, n))
    q = rng.uniform(0.01, 0.1, n)
    r_abs, r_rel = np.array([0.3, 0.5, 0.2]), np.array([0.0, 0.0, 0.01])
    m0 = rng.standard_normal(n)
    G = rng.standard_normal((n, n))
    P0 = G @ G.T + np.eye(n)
    z, Y = m0.copy(), []
    for _ in range(T):
        y = C @ z
        Y.append(y + (r_abs + r_rel * np.abs(y)) * rng.standard_normal(ny))
        z = A @ z + np.sqrt(q) * rng.standard_normal(n)
    Y = np.array(Y)
    ukf = linear_filter(A, C, q, r_abs, r_rel, m0, P0, Y, alpha, beta, kappa)
    ref = kalman(A, C, q, r_abs, r_rel, m0, P0, Y)
    for key, want in ref.items():
        np.testing.assert_allclose(ukf[key], want, rtol=1e-9, atol=1e-9, err_msg=key)
    L = np.linalg.cholesky(ref["innovation_cov"])
    white = np.linalg.solve(L, ref["innovations"][..., None])[..., 0]
    np.testing.assert_allclose(ukf["whitened"], white, rtol=1e-9, atol=1e-9)
    stdz = ref["innovations"] / np.sqrt(np.diagonal(ref["innovation_cov"], axis1=1, axis2=2))
    np.testing.assert_allclose(ukf["standardized"], stdz, rtol=1e-9, atol=1e-9)
    assert not ukf["status"].any()


# ---- the FCC model ------------------------------------------------------------------------------
def test_healthy_innovations_are_white(healthy) -> None:
    _, out = healthy
    assert not out.status.any()
    for name in ("standardized", "whitened"):
        s = getattr(out, name)[:, SKIP:]
        mean, var, rho = s.mean(axis=(0, 1)), s.var(axis=(0, 1)), lag1(s)
        # 4 x 1400 samples: standard errors about 0.013 (mean, lag 1) and 0.02 (variance)
        assert np.all(np.abs(mean) < 0.08), (name, mean)
        assert np.all(np.abs(var - 1.0) < 0.12), (name, var)
        assert np.all(np.abs(rho) < 0.08), (name, rho)
    assert abs(out.nis[:, SKIP:].mean() - 8.0) < 0.5


def test_estimated_inputs_are_closer_to_the_truth_than_the_readings(healthy) -> None:
    b, out = healthy
    for channel, name in enumerate(("R_ar", "T_ar", "T_fp")):
        column = fcc_env.INPUT_NAMES.index(name)
        true = b.inputs[:, SKIP:, column]
        rmse_est = np.sqrt(np.mean((out.state(name)[:, SKIP:] - true) ** 2))
        rmse_read = np.sqrt(np.mean((b.observations[:, SKIP:, channel] - true) ** 2))
        assert rmse_est < 0.7 * rmse_read, (name, rmse_est, rmse_read)
    # the model states too: the unmeasured coke on regenerated catalyst within 0.002 wt%
    c2 = out.state("C2")[:, SKIP:] - b.states[:, SKIP:, fcc_env.STATE_NAMES.index("C2")]
    assert np.sqrt(np.mean(c2**2)) < 2e-5


def test_an_f3_fault_moves_the_innovations() -> None:
    seeds, onset, window = [5000, 5001], 300, 300
    spec = FaultSpec(scenario="f3", onset=onset)
    est = FCCStateEstimator(fcc_env.FCCParams())
    faulty = est.filter(fcc_env.simulate_episodes(seeds, onset + window, fault=spec).observations)
    ok = est.filter(fcc_env.simulate_episodes(seeds, onset + window).observations)
    shift = faulty.standardized[:, onset:].mean(axis=(0, 1))
    base = ok.standardized[:, onset:].mean(axis=(0, 1))
    ch = list(faulty.channels)
    # f3: less heat per mole of O2 (the beds cool), more CO to the afterburn (the dilute
    # phases heat up); measured at the paper's size: T_rg1 −2.2, T_d1 +3.1 standard deviations
    assert shift[ch.index("T_rg1")] < -1.0 and abs(base[ch.index("T_rg1")]) < 0.3
    assert shift[ch.index("T_d1")] > 1.5 and abs(base[ch.index("T_d1")]) < 0.3
    assert faulty.nis[:, onset:].mean() > 3 * ok.nis[:, onset:].mean()


def _assert_same(step, out, b: int, k: int) -> None:
    pairs = {
        "innovation": out.innovations, "standardized": out.standardized,
        "whitened": out.whitened, "innovation_cov": out.innovation_cov, "state": out.states,
        "state_std": out.state_std, "steps": out.steps, "status": out.status,
    }  # fmt: skip
    for name, arr in pairs.items():
        got = getattr(step, name)
        got = got if got.ndim == arr.ndim - 2 else got[b]
        np.testing.assert_array_equal(got, arr[b, k], err_msg=f"{name} at sample {k}")


def test_streaming_update_equals_the_batch_bit_for_bit(healthy) -> None:
    b, _ = healthy
    Y = b.observations[:2, 80:260]  # across the end of the warm-up: the first steps
    est = FCCStateEstimator(fcc_env.FCCParams())
    out = est.filter(Y)
    assert out.steps.any()
    est.reset()
    for k in range(Y.shape[1]):
        _assert_same(est.update(Y[0, k]), out, 0, k)
    est.reset(2)
    for k in range(Y.shape[1]):
        step = est.update(Y[:, k])
        for e in range(2):
            _assert_same(step, out, e, k)
    lean = est.filter(Y, innovation_cov=False)
    assert lean.innovation_cov is None
    np.testing.assert_array_equal(lean.whitened, out.whitened)
    np.testing.assert_array_equal(lean.states, out.states)


def test_closed_loop_with_coking_and_parameters() -> None:
    plant = PlantConfig.build(regulatory=True)
    b = fcc_env.simulate_episodes([1004], 900, plant=plant)
    config = UKFConfig.matching(plant, parameters=("k_sigma", "UA_1"))
    est = FCCStateEstimator(fcc_env.FCCParams(), config)
    assert est.state_names[-3:] == ("f_coke", "k_sigma", "UA_1")
    out = est.filter(b.observations)
    s = out.standardized[:, SKIP:]
    assert np.all(np.abs(s.mean(axis=(0, 1))) < 0.15) and np.all(s.var(axis=(0, 1)) < 1.3)
    # the coking drift is tracked: closer to the truth than the constant 1 a model assumes
    true = b.inputs[0, 300:, fcc_env.INPUT_NAMES.index("f_coke")]
    err = np.sqrt(np.mean((out.state("f_coke")[0, 300:] - true) ** 2))
    assert err < 0.5 * np.sqrt(np.mean((true - 1.0) ** 2))
    est.reset()
    for k in range(40):
        _assert_same(est.update(b.observations[0, k]), out, 0, k)


def test_a_skipped_sample_leaves_nan_innovations_and_goes_on(healthy) -> None:
    b, _ = healthy
    Y = b.observations[:1, :150].astype(np.float64)
    Y[0, 120, 4] = np.nan
    out = FCCStateEstimator(fcc_env.FCCParams()).filter(Y)
    assert np.isnan(out.innovations[0, 120]).all() and out.status[0, 120] == 1
    assert np.isfinite(out.innovations[0, 121:]).all()


@pytest.mark.parametrize(
    "changes,match",
    [
        ({"alpha": 0.0}, r"alpha=0\.0 is outside the allowed range: a number in \(0, 1\]"),
        ({"noise_scale": 0.0}, r"noise_scale=0\.0 is outside the allowed range"),
        ({"rk4_substeps": 0}, r"rk4_substeps=0 is outside the allowed range"),
        ({"step_gate": 0.5}, r"step_gate=0\.5 is outside the allowed range: .* or None"),
        ({"parameters": ("k_sigma", "nope")}, r"parameters=.* one of|values from"),
        ({"parameters": ("k_sigma", "k_sigma")}, r"\['k_sigma'\] repeat"),
        ({"coking_walk_std": -1e-4}, r"coking_walk_std=-0\.0001 is outside"),
        ({"closed_loop": 1}, r"closed_loop=1 is outside the allowed range: True or False"),
    ],
)
def test_bad_settings_are_refused_by_name(changes, match) -> None:
    with pytest.raises(ValueError, match=match):
        UKFConfig(**changes)


def test_bad_use_is_refused() -> None:
    with pytest.raises(ValueError, match="beta_sv is 0"):
        FCCStateEstimator(fcc_env.FCCParams(beta_sv=0.0), UKFConfig(parameters=("beta_sv",)))
    with pytest.raises(ValueError, match=r"params=.* an FCCParams"):
        FCCStateEstimator(PlantConfig())  # a plant is not its parameters
    est = FCCStateEstimator(fcc_env.FCCParams())
    with pytest.raises(RuntimeError, match="reset"):
        est.update(np.zeros(8))
    with pytest.raises(ValueError, match="8 open-loop channels"):
        est.filter(np.zeros((1, 10, 11)))
    est.reset(2)
    with pytest.raises(ValueError, match="expected 2 axes"):
        est.update(np.zeros(8))
