"""scikit-learn habits: ``clone`` of every registered diagnoser, the normalised
``Detection.score``, :func:`diagnosers.tuning.grid_search.grid_search`, and hyperparameters documented on
every registered class."""

from __future__ import annotations

import inspect
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from sklearn.base import clone

import diagnosers
import fcc_env
from diagnosers import Decision, Detection, Diagnoser, Episode, NotFittedError
from diagnosers.bank.relations import read_channels
from diagnosers.conformance import default_episodes
from diagnosers.detection import SCORE_THRESHOLD, exceedance, normalised_score
from diagnosers.tuning.grid_search import DetectionScorer, grid_search

ROOT = Path(__file__).resolve().parents[2]
NAMES = diagnosers.available()
#: the diagnosers of one actuator fault, scored on that fault, not on f1: (fault, magnitude,
#: seed), the seed one on which the fault shows within the short test episode (a capped blower
#: binds only where the program asks for more air than the cap)
OWN_FAULT = {
    "oscillation-acf": ("valve-stiction", 0.2, 3),
    "stiction-ccf": ("valve-stiction", 0.2, 3),
    "stiction-ukf": ("valve-stiction", 0.2, 3),
    "loop-offset": ("blower-capacity", 0.12, 5),
    "air-deficit": ("blower-capacity", 0.12, 5),
}

# small episodes: (healthy training, faulty test, labelled faulty training) per plant
Episodes = tuple[list[Episode], Episode, list[Episode]]


def _closed_loop(d: Diagnoser) -> bool:
    return "u_F" in read_channels(d)


def _fit(d: Diagnoser, episodes: dict[bool, Episodes]) -> Diagnoser:
    train, _, faulty = episodes[_closed_loop(d)]
    return d.fit(train + (faulty if d.isolates else []))


@pytest.fixture(scope="module")
def episodes(default_data: dict[bool, Episodes]) -> dict[bool, Episodes]:
    return default_data  # tests/diagnosers/conftest.py: simulated once per session


@pytest.fixture(scope="module")
def fitted(fast_fitted: dict[str, Diagnoser]) -> dict[str, Diagnoser]:
    """One fitted instance per registered diagnoser (fast hyperparameters; shared, read only)."""
    return fast_fitted


# ---- clone -------------------------------------------------------------------------------------
@pytest.mark.parametrize("name", NAMES)
def test_clone_gives_an_unfitted_equal_parameter_copy(
    name: str, fitted: dict[str, Diagnoser]
) -> None:
    for original in (diagnosers.make(name), fitted[name]):
        twin = clone(original)
        assert type(twin) is type(original) and twin is not original
        assert twin.get_params() == original.get_params()
        with pytest.raises(NotFittedError):
            twin.check_is_fitted()
    fitted[name].check_is_fitted()  # cloning leaves the original fitted


# ---- the normalised score ----------------------------------------------------------------------
@pytest.mark.parametrize("name", NAMES)
def test_score_over_one_is_the_alarm(
    name: str, fitted: dict[str, Diagnoser], episodes: dict[bool, Episodes]
) -> None:
    d = fitted[name]
    test = episodes[_closed_loop(d)][1]
    if name in OWN_FAULT:  # they watch for one actuator fault, which f1 does not make
        scenario, magnitude, seed = OWN_FAULT[name]
        [test] = Episode.from_batch(
            fcc_env.simulate_episodes(
                [seed],
                1200,
                fault=fcc_env.FaultSpec(scenario=scenario, magnitude=magnitude, onset=200),
                plant=fcc_env.PlantConfig.build(regulatory=True),
            )
        )
    det = d.detect(test)
    assert det.score.shape == (test.n_samples,) and det.score.dtype == np.float64
    assert det.threshold == SCORE_THRESHOLD == 1.0
    np.testing.assert_array_equal(det.alarm, det.score > det.threshold)
    assert det.alarm.any(), "the faulty test episode should raise some alarm"
    d.reset()
    for t, row in enumerate(test.y[:200]):  # the streaming decisions carry the score too
        dec = d.update(row)
        assert dec.alarm == (dec.score > dec.threshold)
        assert dec.score == pytest.approx(det.score[t], rel=1e-9, abs=1e-9)


def test_on_delay_filters_the_alarm_not_the_score(episodes: dict[bool, Episodes]) -> None:
    cls = diagnosers.diagnoser_class("lrgf-glr")
    d = _fit(cls(**{**cls.fast_params(), "on_delay": 3}), episodes)
    det = d.detect(episodes[False][1])
    over = det.score > 1
    # alarm after three exceedances in a row: a filtered subset of the raw test
    runs = np.zeros(len(over), dtype=int)
    for t, o in enumerate(over):
        runs[t] = runs[t - 1] + 1 if o and t else int(o)
    np.testing.assert_array_equal(det.alarm, runs >= 3)
    assert det.alarm.sum() < over.sum()


def test_exceedance_formulas() -> None:
    inf = np.inf
    s = np.array([0.5, 3.0, -3.0, 2.0, -1.0, 0.5, -2.0, 1.0, 7.0, 2.0, 5.0])
    lo = np.array([-1.0, -1.0, -1.0, -inf, -inf, -inf, -1.0, 2.0, -inf, 2.0, -inf])
    hi = np.array([1.0, 1.0, 1.0, 4.0, -2.0, 0.0, inf, inf, inf, 2.0, 5.0])
    e = exceedance(s, lo, hi)
    expected = [0.5, 3.0, 3.0, 0.5, 1.5, 1.5, 2.0, 1.5, 0.0, 1.0, 1.0]
    np.testing.assert_allclose(e, expected, rtol=0, atol=1e-15)
    np.testing.assert_array_equal(e > 1, (s < lo) | (s > hi))


def test_the_exact_limit_test_decides_at_the_edge() -> None:
    upper = 0.3
    for s in (upper, np.nextafter(upper, np.inf), np.nextafter(upper, -np.inf)):
        for lower in (-np.inf, 0.1, -0.7):
            e = float(exceedance(np.array(s), np.array(lower), np.array(upper)))
            assert (e > 1) == (s > upper), (s, lower, e)
    # a zero-width band: on it is on the limit, off it is infinitely outside
    np.testing.assert_array_equal(
        exceedance(np.array([2.0, 2.5]), np.array([2.0, 2.0]), np.array([2.0, 2.0])), [1.0, np.inf]
    )


def test_score_reduces_over_signals_and_decisions_agree() -> None:
    signal = np.array([[0.0, 9.0], [2.0, 1.0]])
    lower = np.array([[-1.0, -np.inf], [-1.0, -np.inf]])
    upper = np.array([[1.0, 10.0], [1.0, 10.0]])
    det = Detection(np.array([False, True]), signal, lower, upper, np.zeros((2, 2)), ("band", "T2"))
    np.testing.assert_allclose(det.score, [0.9, 2.0])
    np.testing.assert_array_equal(normalised_score(signal, lower, upper), det.score)
    assert det.decision(1).score == det.score[1]
    assert Decision(False, signal[0], lower[0], upper[0], signal[0]).threshold == 1.0


# ---- grid search -------------------------------------------------------------------------------
def _validation(episodes: dict[bool, Episodes]) -> list[Episode]:
    train, test, _ = episodes[False]
    healthy = default_episodes(900, 900)[0]  # seeds 1000/1001 again, shorter: a stand-in
    return [test, *healthy[:1]]


def test_grid_search_finds_and_fits_the_best(episodes: dict[bool, Episodes]) -> None:
    train = episodes[False][0]
    validation = _validation(episodes)
    result = grid_search(diagnosers.make("limits"), {"alpha": [1e-6, 1e-3, 0.2]}, train, validation)
    assert [row["params"] for row in result.results] == [{"alpha": a} for a in (1e-6, 1e-3, 0.2)]
    scores = [row["score"] for row in result.results]
    assert result.best_score == max(scores)
    assert result.results[scores.index(max(scores))]["rank"] == 1
    assert sorted(row["rank"] for row in result.results)[0] == 1
    for row in result.results:
        assert set(row) >= {
            "params",
            "score",
            "true_detection_rate",
            "false_detection_rate",
            "mean_delay_share",
            "fit_time_s",
            "rank",
        }
    best = result.best_diagnoser
    best.check_is_fitted()
    assert best.get_params() == {**diagnosers.make("limits").get_params(), **result.best_params}
    expected = DetectionScorer()(best, validation)
    assert expected["score"] == result.best_score


def test_grid_search_takes_a_custom_scorer_and_checks_names(
    episodes: dict[bool, Episodes],
) -> None:
    train, test, _ = episodes[False]
    n_alarms = lambda d, eps: -float(sum(d.detect(e).alarm.sum() for e in eps))  # noqa: E731
    result = grid_search(
        diagnosers.make("limits"), [{"alpha": [0.01, 0.001]}], train, [test], scorer=n_alarms
    )
    assert result.best_params == {"alpha": 0.001}  # fewer alarms at the lower level
    assert set(result.results[0]) == {"params", "score", "fit_time_s", "rank"}
    with pytest.raises(ValueError, match=r"Unknown hyperparameter\(s\) \['alhpa'\]"):
        grid_search(diagnosers.make("limits"), {"alhpa": [0.01]}, train, [test])
    with pytest.raises(ValueError, match="'score' entry"):
        grid_search(
            diagnosers.make("limits"), {"alpha": [0.01]}, train, [test], scorer=lambda d, e: {}
        )
    with pytest.raises(ValueError, match="validation episodes, got 2 and 0"):
        grid_search(diagnosers.make("limits"), {"alpha": [0.01]}, train, [])
    with pytest.raises(ValueError, match=r"false_detection_target=1\.5 is outside"):
        DetectionScorer(false_detection_target=1.5)


def test_grid_search_without_scikit_learn_names_the_extra(
    monkeypatch: pytest.MonkeyPatch, episodes: dict[bool, Episodes]
) -> None:
    monkeypatch.setitem(sys.modules, "sklearn.model_selection", None)
    with pytest.raises(ImportError, match=r"needs scikit-learn.*pip install scikit-learn"):
        grid_search(diagnosers.make("limits"), {"alpha": [0.01]}, *episodes[False][:2])


def test_the_package_imports_without_scikit_learn() -> None:
    code = (
        "import sys; sys.modules['sklearn'] = None\n"
        "import diagnosers, diagnosers.tuning.grid_search\n"
        "d = diagnosers.make('lrgf-glr'); print(len(diagnosers.available()))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=False
    )
    assert out.returncode == 0, out.stderr


def test_the_documented_tuning_example_runs() -> None:
    text = (ROOT / "docs" / "diagnosers.md").read_text()
    section = text.split("### A held-out validation set: `grid_search`", 1)[1]
    section = section.split("\n## ", 1)[0]
    [code] = re.findall(r"```python\n(.*?)```", section, flags=re.S)
    # the example's own switches: fast training, short episodes
    for line in ("N = 4000", "FAST = False"):
        assert line in code, f"the example lost its switch {line!r}"
    code = code.replace("N = 4000", "N = 900").replace("FAST = False", "FAST = True")
    code = code.replace("range(1000, 1006)", "range(1000, 1002)")
    code = code.replace('"false_alarm_target": [0.002, 0.01]', '"false_alarm_target": [0.002]')
    namespace: dict[str, object] = {"__name__": "docs_example"}
    exec(compile(code, "docs/diagnosers.md tuning example", "exec"), namespace)
    search = namespace["search"]
    assert len(search.results) == 2  # type: ignore[attr-defined]
    search.best_diagnoser.check_is_fitted()  # type: ignore[attr-defined]


# ---- documentation -----------------------------------------------------------------------------
@pytest.mark.parametrize("name", NAMES)
def test_every_hyperparameter_is_documented_on_its_class(name: str) -> None:
    cls = diagnosers.diagnoser_class(name)
    doc = inspect.getdoc(cls) or ""
    # as a literal (``name``, ``name=...``) or as an Args entry (``name: ...``)
    missing = [
        p
        for p in cls.get_params(cls())  # type: ignore[arg-type]
        if not re.search(rf"(``{p}(``|=)|^\s*{p}:)", doc, flags=re.M)
    ]
    assert not missing, f"{cls.__name__} ({name!r}) does not document {missing} in its docstring"
