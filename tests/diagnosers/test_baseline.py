"""The regression baseline against a direct weighted ridge solve and a hand-written filter."""

from __future__ import annotations

import numpy as np
import pytest

from diagnosers.stages.baseline import RegressionBaseline
from diagnosers.stages.baseline_kernels import adapt_step, filter_step, signals_step, solver


def _oracle_theta(phi: np.ndarray, e: np.ndarray, f: float, ridge: float) -> np.ndarray:
    """θ_T of the exponentially weighted ridge regression, solved directly (no recursion)."""
    n, k, p = phi.shape
    w = f ** np.arange(n - 1, -1, -1)  # weight of sample i at time T
    out = np.empty((k, p))
    for j in range(k):
        info = f**n * ridge * np.eye(p) + (1 - f) * ridge * w.sum() * np.eye(p)
        info += np.einsum("t,ti,tk->ik", w, phi[:, j], phi[:, j])
        out[j] = np.linalg.solve(info, np.einsum("t,ti,t->i", w, phi[:, j], e[:, j]))
    return out


@pytest.mark.parametrize(("lam", "ridge"), [(0.0, 1.0), (0.01, 0.5), (0.2, 3.0)])
def test_recursion_is_the_weighted_ridge_solution(lam: float, ridge: float) -> None:
    rng = np.random.default_rng(3)
    rb = RegressionBaseline([3, 2], (1.0, 5.0), forgetting_lambda=lam, ridge=ridge)
    x = rb.pad([rng.normal(size=(250, 3)), rng.normal(size=(250, 2))])
    phi = rb.features_batch(x)
    e = rng.normal(size=(250, 2)) + phi[..., 1] * np.array([0.7, -1.2])
    preds = []
    for t in range(250):
        preds.append(rb.predict(phi[t]))
        rb.adapt(phi[t], e[t])
    np.testing.assert_allclose(rb.theta_, _oracle_theta(phi, e, 1.0 - lam, ridge), rtol=1e-8)
    # the prediction of sample t uses the coefficients of samples before it only
    np.testing.assert_allclose(
        preds[100],
        np.einsum("kp,kp->k", _oracle_theta(phi[:100], e[:100], 1.0 - lam, ridge), phi[100]),
        rtol=1e-8,
    )
    # padding: the second relation's third signal is zero, its coefficients never move
    assert phi[:, 1, 3].max() == 0.0 and rb.theta_[1, 3] == 0.0


def test_filters_are_first_order_lags_and_batch_equals_stream() -> None:
    rng = np.random.default_rng(4)
    taus = (1.0, 4.0, 50.0)
    rb = RegressionBaseline([2], taus, forgetting_lambda=0.0, ridge=1.0)
    x = rng.normal(size=(120, 1, 2))
    batch = rb.features_batch(x)
    stream = np.array([rb.features(row) for row in x])
    np.testing.assert_allclose(batch, stream, rtol=1e-12, atol=1e-12)
    for i, tau in enumerate(taus):
        s, hand = x[0, 0].copy(), []
        for row in x[:, 0]:
            s = s + (row - s) / tau
            hand.append(s.copy())
        np.testing.assert_allclose(batch[:, 0, 1 + 2 * i : 3 + 2 * i], hand, rtol=1e-12)
    np.testing.assert_array_equal(batch[:, 0, 0], 1.0)  # the constant regressor


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"time_constants": ()}, r"time_constants=\[\]; allowed: a non-empty list of numbers >= 1"),
        ({"time_constants": (0.5,)}, r"time_constants=\[0.5\]; allowed"),
        ({"forgetting_lambda": 1.0}, r"forgetting_lambda=1.0; allowed: \[0, 1\)"),
        ({"ridge": 0.0}, "ridge=0.0; allowed: a number > 0"),
    ],
)
def test_bad_arguments_are_refused_by_value(kwargs: dict, match: str) -> None:
    args = {"time_constants": (1.0,), "forgetting_lambda": 0.0, "ridge": 1.0, **kwargs}
    with pytest.raises(ValueError, match=match):
        RegressionBaseline([2], **args)


def test_compiled_steps_give_the_numpy_expressions_bits() -> None:
    # the streaming path's kernels against the NumPy code they replaced, bit for bit
    rng = np.random.default_rng(5)
    k, p, f = 3, 13, 1.0 - 1e-4
    prior = (1.0 - f) * 3.0 * np.eye(p)
    info = np.broadcast_to(3.0 * np.eye(p), (k, p, p)).copy()
    moment, theta = np.zeros((k, p)), np.zeros((k, p))
    ref_info, ref_moment = info.copy(), moment.copy()
    for _ in range(300):
        phi, e = rng.normal(size=(k, p)), rng.normal(size=k)
        adapt_step(info, moment, theta, phi, e, f, prior)
        ref_info *= f
        ref_info += phi[:, :, None] * phi[:, None, :] + prior
        ref_moment *= f
        ref_moment += phi * e[:, None]
        ref_theta = np.linalg.solve(ref_info, ref_moment[:, :, None])[:, :, 0]
        np.testing.assert_array_equal(info, ref_info)
        np.testing.assert_array_equal(moment, ref_moment)
        np.testing.assert_array_equal(theta, ref_theta)

    gains = 1.0 / np.array([1.0, 10.0, 50.0])
    state, ref = np.zeros((k, 3, 4)), np.zeros((k, 3, 4))
    for t in range(50):
        x = rng.normal(size=(k, 4))
        filter_step(x, gains, state, t > 0)
        if t == 0:
            ref[...] = x[:, None, :]
        else:
            ref += gains[None, :, None] * (x[:, None, :] - ref)
        np.testing.assert_array_equal(state, ref)

    y, y_m = rng.normal(size=8), rng.normal(size=k)
    gather = np.array([[0, 3, 8, 11], [5, 9, 11, 11], [2, 7, 10, 11]])  # 8..10: y_m, 11: zero
    mean, scale = rng.normal(size=(k, 4)), rng.uniform(0.5, 2.0, size=(k, 4))
    out = np.empty((k, 4))
    signals_step(y, y_m, gather, mean, scale, out)
    ext = np.concatenate([y, y_m, [0.0]])
    np.testing.assert_array_equal(out, (ext[gather] - mean) / scale)


def test_the_solver_is_numpys_lapack_where_numpy_has_one() -> None:
    # None would only cost speed (adapt_step then solves with NumPy), never change a result
    adapt = solver()
    if adapt is None:
        pytest.skip("NumPy's dgesv is not reachable here: adapt_step solves with NumPy")
    rng = np.random.default_rng(6)
    a = rng.normal(size=(2, 5, 9))
    info = a @ a.transpose(0, 2, 1) + np.eye(5)
    moment, theta = rng.normal(size=(2, 5)), np.empty((2, 5))
    phi, e = np.zeros((2, 5)), np.zeros(2)  # with f = 1 and P = 0 the update leaves R, b alone
    adapt(info, moment, theta, phi, e, 1.0, np.zeros((5, 5)))
    np.testing.assert_array_equal(theta, np.linalg.solve(info, moment[:, :, None])[:, :, 0])


def test_a_sample_of_the_wrong_shape_is_refused_before_the_kernels() -> None:
    # the compiled steps do not check their indices: the shapes are checked before them
    rb = RegressionBaseline([3, 2], (1.0, 5.0), forgetting_lambda=0.0, ridge=1.0)
    with pytest.raises(ValueError, match=r"x has shape \(2, 2\); allowed: \(2, 3\)"):
        rb.features(np.zeros((2, 2)))
    with pytest.raises(ValueError, match=r"phi has shape \(2, 6\) and e \(2,\); allowed: \(2, 7\)"):
        rb.adapt(np.zeros((2, 6)), np.zeros(2))
