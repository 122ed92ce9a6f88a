"""The posterior-driven supervisor (issue 42 item 7b): its decision rule against hand-computed
expectations, and the policy running on ``FCC-control-v0`` episodes."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from evaluation.control import make_policy
from evaluation.control.policies import fixed_setpoints
from evaluation.control.policy_registry import policy_spec
from evaluation.control.posterior_policy import (
    PosteriorSupervisor,
    best_candidate,
    expected_returns,
)
from evaluation.control.returns import run_episode

# two hypotheses (rows), three candidates (columns): A is best if h0, B if h1, C hedges
R = np.array([[100.0, 0.0, 80.0], [0.0, 100.0, 80.0]])


def test_expected_returns_are_the_posterior_weighted_rows():
    # by hand: 0.7*100 + 0.3*0 = 70; 0.7*0 + 0.3*100 = 30; 80
    np.testing.assert_allclose(expected_returns(np.array([0.7, 0.3]), R), [70.0, 30.0, 80.0])
    # renormalised: (2, 8) is (0.2, 0.8) -> 20, 80, 80
    np.testing.assert_allclose(expected_returns(np.array([2.0, 8.0]), R), [20.0, 80.0, 80.0])


def test_an_uncertain_posterior_hedges_and_a_sure_one_commits():
    # (0.5, 0.5): 50, 50, 80 -> C, the hedge, though it is neither hypothesis's best
    assert best_candidate(np.array([0.5, 0.5]), R) == 2
    # (0.95, 0.05): 95, 5, 80 -> A; (0.1, 0.9): 10, 90, 80 -> B
    assert best_candidate(np.array([0.95, 0.05]), R) == 0
    assert best_candidate(np.array([0.1, 0.9]), R) == 1


def test_a_switch_needs_more_than_the_margin():
    # (0.9, 0.1): 90, 10, 80. From C, A gains 10: kept at margin 10, switched at margin 9.9
    p = np.array([0.9, 0.1])
    assert best_candidate(p, R, current=2, margin=10.0) == 2
    assert best_candidate(p, R, current=2, margin=9.9) == 0


def test_a_move_home_has_its_own_margin():
    # (0.85, 0.15): 85, 15, 80. From B, A (the best, home) gains 70: at margin 75 a move
    # only by the home margin
    p = np.array([0.85, 0.15])
    assert best_candidate(p, R, current=1, margin=75.0) == 1
    assert best_candidate(p, R, current=1, margin=75.0, home=0, home_margin=69.9) == 0
    assert best_candidate(p, R, current=1, margin=75.0, home=0, home_margin=70.0) == 1
    # the home move when the best is another column: (0.9, 0.1) gives 81, 10, 85.5; from B,
    # C gains 75.5 (a move at margin 75, blocked at 90); home A gains 71: taken at margin 5
    p = np.array([0.9, 0.1])
    R2 = np.array([[90.0, 0.0, 95.0], [0.0, 100.0, 0.0]])
    assert best_candidate(p, R2, current=1, margin=75.0) == 2
    assert best_candidate(p, R2, current=1, margin=90.0, home=0, home_margin=5.0) == 0
    assert best_candidate(p, R, current=0, margin=75.0, home=0, home_margin=0.0) == 0


@pytest.mark.parametrize("p", [np.array([0.5]), np.array([-0.1, 1.1]), np.zeros(2)])
def test_a_bad_posterior_is_refused(p):
    with pytest.raises(ValueError, match="posterior"):
        expected_returns(p, R)


class _Stub:
    """A diagnoser whose posterior turns to f1 after ``flip`` updates (after the reset)."""

    hypotheses_ = ("nominal", "f1")

    def __init__(self, flip: int, after: tuple[float, float] = (0.01, 0.99)):
        self.flip, self.n, self.after = flip, 0, np.array(after)

    def reset(self):
        self.n = 0

    def update(self, y):
        self.n += 1
        p = self.after if self.n > self.flip else np.array([0.999, 0.001])
        return SimpleNamespace(alarm=self.n > self.flip, posterior=p)


def test_the_policy_runs_in_the_study_and_moves_to_the_likely_faults_setpoints():
    healthy = fixed_setpoints().target(0, {})
    f1_sp = healthy + np.array([-4.0, 2.0])
    table = {"nominal": {"healthy": 100.0, "f1": 90.0}, "f1": {"healthy": 0.0, "f1": 100.0}}
    sup = PosteriorSupervisor(
        "posterior (stub)", _Stub(flip=20), table, {"healthy": healthy, "f1": f1_sp}, 5.0, 10
    )
    trace: dict = {}
    score = run_episode(sup, "f1", 5000, 60, trace=trace)
    assert score.n_steps == 60 and np.isfinite(score.return_usd)
    assert [e.target for e in sup.history] == ["healthy", "healthy", "f1"]
    assert sup.history[-1].k == 10 + 21  # armed after 10, the 21st update flips
    # the set points in force follow the target (the action is the difference, in range)
    np.testing.assert_allclose(trace["setpoints"][-1], f1_sp, atol=1e-3)
    np.testing.assert_allclose(trace["setpoints"][15], healthy, atol=1e-3)


def test_a_table_without_the_diagnosers_hypotheses_is_refused():
    with pytest.raises(ValueError, match="table"):
        PosteriorSupervisor("x", _Stub(1), {"nominal": {"healthy": 1.0}}, {"healthy": np.zeros(2)})


def test_it_is_registered_and_needs_no_keywords():
    assert policy_spec("posterior").needs == ""


@pytest.mark.slow
def test_the_registered_policy_runs_an_episode():
    sup = make_policy("posterior")
    score = run_episode(sup, "f1", 5000, 400)
    assert score.n_steps == 400 and sup.history[0].target == "healthy"


def test_the_posterior_is_not_acted_on_before_trust_after():
    healthy = fixed_setpoints().target(0, {})
    table = {"nominal": {"healthy": 100.0, "f1": 90.0}, "f1": {"healthy": 0.0, "f1": 100.0}}
    cands = {"healthy": healthy, "f1": healthy + np.array([-4.0, 2.0])}
    sup = PosteriorSupervisor("posterior (stub)", _Stub(flip=5), table, cands, 5.0, 10, 30)
    run_episode(sup, "nominal", 5000, 60)
    # the stub names f1 from its 6th update (k = 16), acted on from k = 10 + 30 + 1
    assert next((e.k, e.target) for e in sup.history if e.target == "f1") == (41, "f1")


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("margin_usd_per_h", -1.0),
        ("home_margin_usd_per_h", float("nan")),
        ("confirmed_margin_usd_per_h", -1.0),
        ("confidence", 1.0),
        ("confirm_after", 0),
    ],
)
def test_a_bad_setting_is_refused_by_name(field: str, value: float) -> None:
    # the settings are checked before the diagnoser is read, so no fitted bank is needed
    with pytest.raises(ValueError, match=rf"{field}=(-1\.0|nan|1\.0|0) is outside the allowed"):
        PosteriorSupervisor("posterior", None, {}, {}, **{field: value})


def test_a_confirmation_without_a_confidence_is_refused() -> None:
    with pytest.raises(
        ValueError, match=r"confirm_after=300 is outside the allowed range: None unless confidence"
    ):
        PosteriorSupervisor("posterior", None, {}, {}, confirm_after=300)


def _first_move(table: dict, after: tuple[float, float], **kw) -> int | None:
    """The sample of the first move off the healthy set points of a stub supervisor (armed
    after 10 samples, margin 5) whose posterior turns to ``after`` from its 21st update."""
    healthy = fixed_setpoints().target(0, {})
    cands = {"healthy": healthy, "f1": healthy + np.array([-4.0, 2.0])}
    stub = _Stub(flip=20, after=after)
    sup = PosteriorSupervisor("posterior (stub)", stub, table, cands, 5.0, 10, **kw)
    run_episode(sup, "nominal", 5000, 60)
    return next((e.k for e in sup.history if e.target != "healthy"), None)


def test_a_posterior_below_the_confidence_is_not_acted_on():
    table = {"nominal": {"healthy": 100.0, "f1": 90.0}, "f1": {"healthy": 0.0, "f1": 100.0}}
    # (0.3, 0.7): f1's set points gain 70 - 30 = 40 USD/h, a move at once (k = 10 + 21)
    assert _first_move(table, (0.3, 0.7)) == 31
    # held while no hypothesis reaches 0.9; (0.05, 0.95) reaches it
    assert _first_move(table, (0.3, 0.7), confidence=0.9) is None
    assert _first_move(table, (0.05, 0.95), confidence=0.9) == 31


def test_a_confirmed_fault_moves_on_the_smaller_margin():
    # posterior (0.01, 0.99) after the flip: healthy 0.01*100 + 0.99*96 = 96.04, f1's
    # 0.01*90 + 0.99*100 = 99.9, a gain of 3.86 USD/h: below the margin 5, above 1
    table = {"nominal": {"healthy": 100.0, "f1": 90.0}, "f1": {"healthy": 96.0, "f1": 100.0}}
    confirmed = {"confidence": 0.98, "confirmed_margin_usd_per_h": 1.0}
    assert _first_move(table, (0.01, 0.99)) is None
    # 1 - P(nominal) = 0.99 >= 0.98 from k = 31: confirmed on its 5th sample in a row
    assert _first_move(table, (0.01, 0.99), confirm_after=5, **confirmed) == 35
    # a confidence of 0.995 is never reached: neither acted on nor confirmed
    confirmed["confidence"] = 0.995
    assert _first_move(table, (0.01, 0.99), confirm_after=5, **confirmed) is None
