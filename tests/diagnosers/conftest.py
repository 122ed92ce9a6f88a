"""Fixtures shared by the per-diagnoser test files of this folder.

Several files check a property of *every* registered diagnoser on a fitted instance (the
scikit-learn habits, hostile save directories). Fitting all of them with their fast parameters
takes tens of seconds, so it is done once per test session (per ``pytest-xdist`` worker) and the
files share the instances; they only read them (clone, score, save).
"""

from __future__ import annotations

import pytest

import diagnosers
from diagnosers import Diagnoser
from diagnosers.bank.relations import required_channels
from diagnosers.conformance import default_episodes
from diagnosers.episode.record import Episode

#: ``default_episodes``'s triple: healthy training, faulty test, labelled faulty training.
Episodes = tuple[list[Episode], Episode, list[Episode]]


@pytest.fixture(scope="session")
def default_data() -> dict[bool, Episodes]:
    """``default_episodes(1000, 900)`` on the open-loop (False) and closed-loop (True) plant."""
    return {cl: default_episodes(1000, 900, closed_loop=cl) for cl in (False, True)}


def reads_closed_loop(name: str) -> bool:
    """Whether registered diagnoser ``name`` needs the closed-loop plant's channels."""
    return "u_F" in required_channels(name)


@pytest.fixture(scope="session")
def fast_fitted(default_data: dict[bool, Episodes]) -> dict[str, Diagnoser]:
    """Every registered diagnoser with its fast parameters, fitted once on ``default_data``
    (its healthy training episodes, plus the labelled faults where it isolates). Read only."""
    out = {}
    for name in diagnosers.available():
        train, _, faulty = default_data[reads_closed_loop(name)]
        cls = diagnosers.diagnoser_class(name)
        out[name] = cls(**cls.fast_params()).fit(train + (faulty if cls.isolates else []))
    return out
