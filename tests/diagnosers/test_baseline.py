"""The regression baseline against a direct weighted ridge solve and a hand-written filter."""

from __future__ import annotations

import numpy as np
import pytest

from diagnosers.baseline import RegressionBaseline


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
