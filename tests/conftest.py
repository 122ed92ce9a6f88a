"""Fixtures shared by the test folders (which mirror the packages: tests/fcc_env, tests/evaluation/...).

The helpers of :mod:`synthetic` are imported as ``from synthetic import ...`` from any folder:
this directory is put on ``sys.path`` here (pytest's default import mode would add only each test
file's own folder).
"""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

TESTS = Path(__file__).resolve().parent
if str(TESTS) not in sys.path:
    sys.path.insert(0, str(TESTS))

from synthetic import make_episode  # noqa: E402  (after the path is set)

from diagnosers.episode.record import Episode  # noqa: E402


@pytest.fixture(scope="module")
def train() -> list[Episode]:
    """Three healthy synthetic training episodes of 1500 samples (seeds 1, 2, 3)."""
    return [make_episode(1500, seed=s) for s in (1, 2, 3)]
