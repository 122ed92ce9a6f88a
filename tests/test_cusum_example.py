"""The worked example ``examples/cusum_diagnoser.py``: a diagnoser of one's own, end to end.

``examples`` is a package at the repository root (not installed): it is importable when the root
is on ``sys.path``, as it is for ``python -m pytest`` and ``python -m evaluation.leaderboard``
run from the root; the fixture below makes sure of it for a bare ``pytest`` too.
"""

from __future__ import annotations

import csv
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import diagnosers
import fcc_env
from diagnosers import Diagnoser, Episode
from evaluation.leaderboard import main

ROOT = Path(__file__).resolve().parents[1]
TINY = ["--scenarios", "nominal,f1", "--seeds", "1", "--train-episodes", "2",
        "--n-samples", "300", "--fault-time", "150", "--no-figures", "--no-progress"]  # fmt: skip


@pytest.fixture(scope="module")
def cusum():
    if str(ROOT) not in sys.path:
        sys.path.insert(0, str(ROOT))
    import examples.cusum_diagnoser as mod

    return mod


@pytest.fixture(scope="module")
def fitted(cusum) -> Diagnoser:
    train = Episode.from_batch(fcc_env.simulate_episodes([1000, 1001], 400))
    return diagnosers.make("cusum-example", channel="T_rx").fit(train)


@pytest.fixture(scope="module")
def faulty() -> Episode:
    [ep] = Episode.from_batch(
        fcc_env.simulate_episodes([0], 400, fault=fcc_env.FaultSpec(scenario="f1", onset=200))
    )
    return ep


def test_registered_and_fitted(cusum, fitted) -> None:
    assert "cusum-example" in diagnosers.available()
    assert isinstance(fitted, cusum.CUSUMDiagnoser)
    assert fitted.signal_names_ == ("T_rx cusum+", "T_rx cusum-")
    assert np.isfinite(fitted.mean_) and fitted.std_ > 0


def test_detect_equals_streaming_update(fitted, faulty) -> None:
    det = fitted.detect(faulty)
    fitted.reset()
    stream = [fitted.update(y) for y in faulty.y]
    np.testing.assert_array_equal(det.alarm, [d.alarm for d in stream])
    np.testing.assert_allclose(det.signal, np.stack([d.signal for d in stream]), rtol=0, atol=0)
    np.testing.assert_array_equal(det.upper, np.stack([d.upper for d in stream]))
    np.testing.assert_array_equal(det.residual, np.stack([d.residual for d in stream]))
    assert det.alarm[200:].all()  # f1 moves T_rx by several degrees: caught at once


def test_save_load_round_trip(fitted, faulty, tmp_path) -> None:
    fitted.save(tmp_path / "m")
    back = Diagnoser.load(tmp_path / "m")
    assert type(back) is type(fitted) and back.get_params() == fitted.get_params()
    assert (back.mean_, back.std_) == (fitted.mean_, fitted.std_)
    a, b = fitted.detect(faulty), back.detect(faulty)
    np.testing.assert_array_equal(a.alarm, b.alarm)
    np.testing.assert_array_equal(a.signal, b.signal)


def test_bad_hyperparameters_name_the_value(cusum) -> None:
    train = [Episode.from_batch(fcc_env.simulate_episodes([1000], 50))[0]]
    with pytest.raises(ValueError, match=r"h=0 is outside the allowed range: a number in \(0,"):
        diagnosers.make("cusum-example", h=0).fit(train)
    with pytest.raises(ValueError, match=r"Unknown channel 'T_nope'"):
        diagnosers.make("cusum-example", channel="T_nope").fit(train)


def test_leaderboard_cli_imports_the_module(tmp_path, capsys, cusum) -> None:
    out = tmp_path / "lb"
    args = ["--import", "examples.cusum_diagnoser", "--diagnosers", "cusum-example,limits"]
    assert main([*args, *TINY, "--workers", "0", "--out", str(out)]) == 0
    table = capsys.readouterr().out
    assert "| cusum-example |" in table and "| limits |" in table
    with open(out / "results.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert {r["diagnoser"] for r in rows} == {"cusum-example", "limits"}


def test_leaderboard_cli_bad_import_names_the_module(tmp_path, capsys) -> None:
    with pytest.raises(SystemExit):
        main(["--import", "examples.no_such_thing", *TINY, "--out", str(tmp_path / "o")])
    assert "cannot import module 'examples.no_such_thing'" in capsys.readouterr().err


def test_leaderboard_cli_in_spawn_workers(tmp_path) -> None:
    """A fresh process with a spawn worker: the worker imports the module itself."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.run(
        [sys.executable, "-m", "evaluation.leaderboard", "--import", "examples.cusum_diagnoser",
         "--diagnosers", "cusum-example", *TINY, "--workers", "1", "--out", str(tmp_path / "w")],
        cwd=ROOT, env=env, capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    assert "| cusum-example |" in proc.stdout


def test_grid_search_cv_runs_on_the_example(cusum) -> None:
    # issue 45 item 6: a diagnoser of one's own is a scikit-learn estimator as it is
    from sklearn.model_selection import GridSearchCV, StratifiedKFold

    f1 = fcc_env.FaultSpec(scenario="f1", onset=200)
    X = Episode.from_batch(fcc_env.simulate_episodes(range(5000, 5004), 400)) + Episode.from_batch(
        fcc_env.simulate_episodes([5004, 5005], 400, fault=f1)
    )
    y = diagnosers.episode_labels(X)
    search = GridSearchCV(
        diagnosers.make("cusum-example", channel="T_rg1"),
        {"h": [4.0, 8.0, 16.0]},
        scoring=diagnosers.make_scorer(),
        cv=StratifiedKFold(n_splits=2),
        error_score="raise",
    )
    search.fit(X, y)
    assert [p["h"] for p in search.cv_results_["params"]] == [4.0, 8.0, 16.0]
    assert np.isfinite(search.cv_results_["mean_test_score"]).all()
    best = search.best_estimator_
    assert isinstance(best, cusum.CUSUMDiagnoser) and best.h == search.best_params_["h"]
    # refitted on the healthy episodes only
    healthy = cusum.CUSUMDiagnoser(channel="T_rg1", h=best.h).fit(X[:4])
    assert (best.mean_, best.std_) == (healthy.mean_, healthy.std_)
