"""Issue 45 item 8: the own-diagnoser docs and the worked example name every attribute and hook
that ``check_diagnoser`` requires (a new user's ``_fit`` that did not set ``signal_names_`` was
caught only by the check). The list is read from ``diagnosers/conformance.py`` itself, so a
requirement added there fails here until the docs name it."""

from __future__ import annotations

import re
from pathlib import Path

import diagnosers
from diagnosers import Diagnoser

ROOT = Path(__file__).resolve().parents[2]


def _required() -> set[str]:
    """The attributes the checks read from a diagnoser (not its methods), and its hooks."""
    source = (ROOT / "diagnosers" / "conformance.py").read_text()
    read = set(re.findall(r"\b(?:d|back|diagnoser)\.([A-Za-z_][A-Za-z0-9_]*)\b", source))
    read |= set(re.findall(r'getattr\((?:d|diagnoser), "([A-Za-z_][A-Za-z0-9_]*)"', source))
    attributes = {
        a for a in read if not a.startswith("_") and not callable(getattr(Diagnoser, a, None))
    }
    return attributes | set(Diagnoser.__abstractmethods__)


def _section() -> str:
    text = (ROOT / "docs" / "diagnosers.md").read_text()
    return text.split("## Your own diagnoser", 1)[1].split("\n## ", 1)[0]


def test_the_list_is_what_the_checks_read() -> None:
    required = _required()
    assert {
        "signal_names_",
        "channels_",
        "sample_time_s_",
        "classes_",
        "name",
        "isolates",
    } <= required
    assert {"_fit", "_reset", "_update", "_get_state", "_set_state"} <= required


def test_the_docs_section_names_every_requirement() -> None:
    section = _section()
    missing = sorted(a for a in _required() if f"`{a}" not in section)
    assert not missing, f"docs/diagnosers.md, 'Your own diagnoser', does not name {missing}"
    assert "`_fit` **and** `_set_state`" in section  # signal_names_ on a loaded model too


def test_the_example_names_every_requirement() -> None:
    example = (ROOT / "examples" / "cusum_diagnoser.py").read_text()
    missing = sorted(a for a in _required() if a not in example)
    assert not missing, f"examples/cusum_diagnoser.py does not name {missing}"


def test_a_fit_without_signal_names_is_caught_by_name() -> None:
    import numpy as np
    import pytest

    from diagnosers import Decision
    from diagnosers.registry import unregister

    @diagnosers.register("no-signal-names-test")
    class Forgetful(Diagnoser):
        def __init__(self) -> None:
            pass

        def _fit(self, episodes):  # forgets signal_names_
            self.mean_ = float(np.mean([ep.y.mean() for ep in episodes]))

        def _reset(self) -> None:
            pass

        def _update(self, y):
            z = np.zeros(1)
            return Decision(False, z, z - 1, z + 1, z)

        def _get_state(self):
            return {"mean": np.array(self.mean_)}

        def _set_state(self, state):
            self.mean_ = float(state["mean"])

    try:
        with pytest.raises(diagnosers.ConformanceError, match=r"'fit' check.*signal_names_"):
            diagnosers.check_diagnoser(Forgetful())
    finally:
        unregister("no-signal-names-test")
