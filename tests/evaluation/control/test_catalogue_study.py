"""The control study on the whole catalogue: scores name the drawn fault, tables per class."""

from __future__ import annotations

import pytest

import fcc_env  # noqa: F401 (registers the ids)
from evaluation.control.policies import ProgramPolicy
from evaluation.control.returns import EpisodeScore, class_summaries, run_episode


def test_a_drawn_episode_is_scored_under_its_drawn_scenario():
    score = run_episode(ProgramPolicy(), "random", 5003, 5, catalogue="all")
    assert score.scenario == "f2"  # seed 5003's draw (tests/fcc_env/test_control_draws.py)
    assert score.n_steps == 5


def test_class_summaries_split_by_fault_class_against_the_reference():
    scores = [
        EpisodeScore(p, sc, seed, r, False, 0.0, 10)
        for p, bonus in (("blind", 0.0), ("oracle", 7.0))
        for sc, seed, r in (
            ("nominal", 1, 100.0),
            ("f1", 2, 90.0),
            ("sensor-stuck", 3, -50.0),
            ("sensor-bias", 4, 80.0),
        )
        for r in [r + (bonus if sc != "nominal" else 0.0)]
    ]
    tables = class_summaries(scores, reference="oracle")
    assert list(tables) == ["healthy", "process", "sensor"]
    blind = {c: rows[0] for c, rows in tables.items()}
    assert blind["healthy"].loss_vs_oracle_usd.estimate == 0.0
    assert blind["process"].loss_vs_oracle_usd.estimate == pytest.approx(7.0)
    assert blind["sensor"].n_episodes == 2
    assert blind["sensor"].return_usd.estimate == pytest.approx(15.0)
