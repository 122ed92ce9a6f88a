"""CPU seconds per test (this process and its waited-for workers), for a test run on a shared
machine, where ``pytest --durations`` reports wall times that measure the contention.

    python lab/suite_cpu_times.py tests/evaluation/tracks/test_oracle.py -k share_their

Runs pytest in this process with the arguments given (``-p no:randomly -p no:cacheprovider``
added) and a small plugin that times each test's whole protocol (setup, call, teardown) with
``resource.getrusage`` of this process and its children, then prints the total and the 60
largest. A module- or session-scoped fixture is charged to the first test that asks for it.
Written for the default suite's time budget (lab/test-time.md).
"""

from __future__ import annotations

import resource
import sys
from collections.abc import Generator

import pytest


def cpu_seconds() -> float:
    """User and system CPU of this process and of its children that were waited for."""
    me = resource.getrusage(resource.RUSAGE_SELF)
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return me.ru_utime + me.ru_stime + kids.ru_utime + kids.ru_stime


class CpuTimes:
    """The pytest plugin: one (CPU s, node id) row per test."""

    def __init__(self) -> None:
        self.rows: list[tuple[float, str]] = []

    @pytest.hookimpl(hookwrapper=True)
    def pytest_runtest_protocol(self, item: pytest.Item) -> Generator[None, None, None]:
        t0 = cpu_seconds()
        yield
        self.rows.append((cpu_seconds() - t0, item.nodeid))

    def pytest_terminal_summary(self, terminalreporter: pytest.TerminalReporter) -> None:
        total = sum(t for t, _ in self.rows)
        terminalreporter.write_line(f"CPU total over tests: {total:.1f} s ({len(self.rows)})")
        for t, node in sorted(self.rows, reverse=True)[:60]:
            terminalreporter.write_line(f"CPU {t:8.2f} s {node}")


def main(argv: list[str]) -> int:
    return int(pytest.main(["-p", "no:randomly", "-p", "no:cacheprovider", *argv], [CpuTimes()]))


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
