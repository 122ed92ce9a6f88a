"""``mmae`` (issue 42 item 5): the bank against its filters and scipy's Gaussian density, the
posterior recursion and the window NIS against direct formulas, isolation of simulated faults
(validation seeds 5000+), the posterior on :class:`Detection`, and the parameters' errors."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy import stats

import diagnosers
import fcc_env
from diagnosers import Decision, Detection, Episode
from diagnosers.filters import UKFConfig
from diagnosers.isolation.filter_bank import FilterBank, mmae_run

WALK, INITIAL = 1e-3, 0.01


@pytest.fixture(scope="module")
def fault_episode() -> Episode:
    """f2 at the paper's size on a validation seed, 300 samples after onset."""
    spec = fcc_env.FaultSpec(scenario="f2", onset=1900)
    return Episode.from_batch(fcc_env.simulate_episodes([5001], 2200, fault=spec))[0]


def _tiny_training() -> list[Episode]:
    """mmae learns nothing but its classes from data: tiny labelled episodes do."""
    healthy = Episode.from_batch(fcc_env.simulate_episodes([1000], 600))
    faulty = [
        Episode.from_batch(
            fcc_env.simulate_episodes([1000], 40, fault=fcc_env.FaultSpec(scenario=f, onset=20))
        )[0]
        for f in fcc_env.PAPER_FAULTS
    ]
    return healthy + faulty


@pytest.fixture(scope="module")
def fitted() -> diagnosers.Diagnoser:
    return diagnosers.make("mmae").fit(_tiny_training())


def test_bank_equals_its_filters_and_scipy_density() -> None:
    y = fcc_env.simulate_episodes([5000], 300).observations
    bank = FilterBank.build(
        fcc_env.FCCParams(),
        UKFConfig(),
        ("f1", "f2"),
        fault_walk_std_rel=(WALK, WALK),
        fault_initial_std_rel=INITIAL,
    )
    assert bank.hypotheses == ("nominal", "f1", "f2")
    assert bank.estimators[2].config.parameters == ("K_w1", "K_w2")  # from the registry
    Ms, Ps = bank.start()
    white, loglik = bank.run(Ms, Ps, y[0])
    for h, est in enumerate(bank.estimators):
        own = est.filter(y)
        np.testing.assert_array_equal(white[:, h], own.whitened[0])  # same kernel, same bits
        S = own.innovation_cov[0]
        oracle = [
            stats.multivariate_normal.logpdf(own.innovations[0, k], cov=S[k]) for k in range(300)
        ]
        np.testing.assert_allclose(loglik[:, h], oracle, rtol=1e-9, atol=1e-9)


def test_posterior_and_window_nis_against_direct_formulas() -> None:
    rng = np.random.default_rng(0)
    T, H, W, eps = 60, 4, 7, 0.02
    loglik = rng.normal(-10.0, 3.0, (T, H))
    nis = rng.chisquare(8, (T, H))
    p = np.array([0.7, 0.1, 0.1, 0.1])
    post, win = np.empty((T, H)), np.empty(T)
    pos = mmae_run(
        loglik, nis, p.copy(), np.zeros((W, H)), np.zeros(W), 0, eps, eps / H, 0, post, win
    )
    assert pos == T
    q = p.copy()
    for k in range(T):  # leave = eps / H: the plain switching term
        logq = np.log((1 - eps) * q + eps / H) + loglik[k]
        q = np.exp(logq - logq.max())
        q /= q.sum()
        np.testing.assert_allclose(post[k], q, rtol=1e-12)
        if k + 2 < 2 * W:
            assert np.isnan(win[k])
        else:  # the least over the last W samples of the smallest window sum
            sums = [nis[j + 1 - W : j + 1].sum(axis=0).min() for j in range(k + 1 - W, k + 1)]
            assert win[k] == pytest.approx(min(sums), rel=1e-12)
    # two calls carry the state: the same as one
    post2, win2 = np.empty((T, H)), np.empty(T)
    p2, ring, best = p.copy(), np.zeros((W, H)), np.zeros(W)
    pos = mmae_run(loglik[:25], nis[:25], p2, ring, best, 0, eps, eps / H, 0, post2[:25], win2[:25])
    mmae_run(loglik[25:], nis[25:], p2, ring, best, pos, eps, eps / H, 0, post2[25:], win2[25:])
    np.testing.assert_array_equal(post2, post)
    np.testing.assert_array_equal(win2, win)


@pytest.mark.parametrize("hold", [0, 6])
def test_posterior_with_a_slower_fault_leave_against_the_transition_matrix(hold: int) -> None:
    """A fault's switch to another hypothesis (``leave``) apart from nominal's: the
    recursion equals the prior through the Markov chain's transition matrix, then Bayes;
    for the first ``hold`` samples the posterior is the prior, unchanged."""
    rng = np.random.default_rng(1)
    T, H, W, eps, leave = 40, 4, 5, 0.03, 1e-4
    loglik = rng.normal(-10.0, 3.0, (T, H))
    A = np.full((H, H), leave)  # A[i, j]: from i to j
    A[0, :] = eps / H
    np.fill_diagonal(A, 0.0)
    np.fill_diagonal(A, 1.0 - A.sum(axis=1))
    p = np.array([0.6, 0.2, 0.1, 0.1])
    post, win = np.empty((T, H)), np.empty(T)
    ring, best = np.zeros((W, H)), np.zeros(W)
    mmae_run(loglik, np.ones((T, H)), p.copy(), ring, best, 0, eps, leave, hold, post, win)
    q = p.copy()
    for k in range(T):
        if k >= hold:
            q = (q @ A) * np.exp(loglik[k] - loglik[k].max())
            q /= q.sum()
        np.testing.assert_allclose(post[k], q, rtol=1e-12)


def test_mmae_isolates_a_fault_and_stays_quiet_before_it(
    fitted: diagnosers.Diagnoser, fault_episode: Episode
) -> None:
    det = fitted.detect(fault_episode)
    assert det.hypothesis_names == ("nominal", "f1", "f2", "f3", "f4")
    assert det.posterior is not None and det.diagnosis is not None
    np.testing.assert_allclose(det.posterior.sum(axis=1), 1.0, atol=1e-12)
    onset = fault_episode.fault_onset
    assert onset is not None
    assert not det.alarm[200:onset].any()  # healthy: no alarm (the start's transient aside)
    assert det.posterior[200:onset, 0].mean() > 0.8
    after = det.diagnosis[onset + 100 :]
    assert np.mean(after == "f2") > 0.95, np.unique(after, return_counts=True)
    assert det.posterior[-1, 2] > 0.9
    np.testing.assert_array_equal(det.class_scores, det.posterior[:, 1:])


def test_detection_posterior_checks_and_stacking() -> None:
    z = np.zeros((2, 1))
    base = {"signal": z, "lower": z - 1, "upper": z + 1, "residual": z, "signal_names": ("s",)}
    alarm = np.array([False, True])
    with pytest.raises(ValueError, match=r"posterior must have shape \(2, 2\)"):
        Detection(alarm, posterior=np.ones((2, 3)) / 3, hypothesis_names=("a", "b"), **base)
    with pytest.raises(ValueError, match="summing to 1; row 1"):
        Detection(alarm, posterior=[[0.5, 0.5], [0.9, 0.2]], hypothesis_names=("a", "b"), **base)
    with pytest.raises(ValueError, match="without a posterior"):
        Detection(alarm, hypothesis_names=("a", "b"), **base)
    det = Detection(alarm, posterior=[[1.0, 0.0], [0.3, 0.7]], hypothesis_names=("a", "b"), **base)
    assert det.probabilistic and not Detection(alarm, **base).probabilistic
    d1 = det.decision(1)
    assert isinstance(d1, Decision) and d1.posterior is not None and d1.posterior[1] == 0.7
    again = Detection.from_decisions([det.decision(0), d1], ("s",), hypothesis_names=("a", "b"))
    np.testing.assert_array_equal(again.posterior, det.posterior)
    assert again.hypothesis_names == ("a", "b")


def test_params_and_their_errors(fitted: diagnosers.Diagnoser, tmp_path) -> None:
    m = diagnosers.make("mmae", params={"k_sigma": 2.5})
    assert m.model_params().k_sigma == 2.5
    with pytest.raises(ValueError, match="params="):
        diagnosers.make("mmae", params={"not_a_field": 1.0}).validate_params()
    with pytest.raises(ValueError, match=r"switch_prob=0\.7"):
        diagnosers.make("mmae", switch_prob=0.7).validate_params()
    with pytest.raises(ValueError, match=r"fault_leave_prob=0\.6"):
        diagnosers.make("mmae", fault_leave_prob=0.6).validate_params()
    with pytest.raises(ValueError, match=r"settle=-1"):
        diagnosers.make("mmae", settle=-1).validate_params()
    p = dataclasses.replace(fcc_env.FCCParams(), k_sigma=2.6)
    obj = diagnosers.make("mmae", params=p)
    assert obj.model_params() is p
    healthy = Episode.from_batch(fcc_env.simulate_episodes([1000], 400))
    faulty = Episode.from_batch(
        fcc_env.simulate_episodes([1000], 30, fault=fcc_env.FaultSpec(scenario="f3", onset=10))
    )
    obj.fit(healthy + faulty)
    assert obj.classes_ == ("f3",)
    with pytest.raises(ValueError, match=r"params=dataclasses.asdict\(p\)"):
        obj.save(tmp_path / "m")
    for est in obj.bank_.estimators:  # every filter runs on the given parameters
        np.testing.assert_array_equal(est.filter_model.model[2], p.as_array())


def test_settle_restarts_the_fault_filters_alike_streamed_or_batch() -> None:
    """``settle``: the posterior holds its prior, then every fault filter restarts from the
    healthy filter's estimate; a stream reaches that point sample by sample as one call does."""
    m = diagnosers.make("mmae", settle=40).fit(_tiny_training())
    ep = Episode.from_batch(fcc_env.simulate_episodes([5002], 120))[0]
    y = ep.y
    batch = m.detect(ep)
    assert batch.posterior is not None
    np.testing.assert_array_equal(batch.posterior[:40], np.tile(batch.posterior[0], (40, 1)))
    m.reset()
    streamed = np.array([m.update(y[k]).posterior for k in range(len(y))])
    np.testing.assert_array_equal(streamed, batch.posterior)
    # at the restart each fault filter takes the healthy filter's states, its parameter at prior
    bank = m.bank_
    Ms, Ps = bank.start()
    bank.run(Ms, Ps, y[:40])
    bank.restart_faults(Ms, Ps)
    n0 = Ms[0].shape[0]
    for h in range(1, len(Ms)):
        np.testing.assert_array_equal(Ms[h][:n0], Ms[0])
        np.testing.assert_array_equal(Ps[h][:n0, :n0], Ps[0])
        m0, P0 = bank.estimators[h].initial_prior(1)
        np.testing.assert_array_equal(Ps[h][n0:, n0:], P0[0, n0:, n0:])
        assert not Ps[h][:n0, n0:].any()
