"""The goal "at the physical limit" (``evaluation.trackboard.limit_goal``) and the summary."""

from __future__ import annotations

import math

from evaluation.intervals import Interval
from evaluation.oracle import ORACLE_LABEL
from evaluation.trackboard import FaultCell, TrackRow, TrackRun, limit_goal, summary_table
from evaluation.tracks import TRACKS

NAN = math.nan


def _iv(x: float, low: float | None = None, high: float | None = None) -> Interval:
    return Interval(x, x if low is None else low, x if high is None else high, 20)


def _cell(r_td: float, t_dt: float) -> FaultCell:
    return FaultCell(_iv(r_td), _iv(t_dt), _iv(1.0), misses=0, terminated=0, n=20)


def _row(label: str, r_fd_high: float, cells: dict[str, tuple[float, float]]) -> TrackRow:
    faults = {f: _cell(*v) for f, v in cells.items()}
    return TrackRow(label, _iv(0.005, 0.004, r_fd_high), 1.0, 0.05, 3, faults)


LIMIT = _row(ORACLE_LABEL, 0.002, {"f1": (1.0, 0.0), "f2": (0.9, 10.0), "f3": (0.99, 12.0)})


def test_time_bound_is_one_and_a_half_times_the_limit_plus_two_samples() -> None:
    # f1: limit 0 samples, bound 2; f2: bound 17; f3: bound 20
    at = _row("d", 0.009, {"f1": (1.0, 2.0), "f2": (0.9, 17.0), "f3": (0.99, 20.0)})
    assert limit_goal(at, LIMIT).faults_at_limit == ("f1", "f2", "f3")
    late = _row("d", 0.009, {"f1": (1.0, 2.01), "f2": (0.9, 17.5), "f3": (0.99, 20.1)})
    assert limit_goal(late, LIMIT).faults_at_limit == ()


def test_r_td_may_be_at_most_003_below_the_limit() -> None:
    row = _row("d", 0.009, {"f1": (0.97, 0.0), "f2": (0.869, 5.0), "f3": (1.0, 5.0)})
    goal = limit_goal(row, LIMIT)
    assert goal.faults_at_limit == ("f1", "f3")  # f2: 0.869 < 0.9 - 0.03
    assert goal.n_faults == 3


def test_undefined_values_are_not_at_the_limit() -> None:
    row = _row("d", 0.009, {"f1": (NAN, NAN), "f2": (0.95, 3.0), "f4": (1.0, 1.0)})
    goal = limit_goal(row, LIMIT)
    assert goal.faults_at_limit == ("f2",)  # f1 never detected; the limit row has no f4


def test_r_fd_goal_is_on_the_intervals_upper_end() -> None:
    assert limit_goal(_row("d", 0.01, {}), LIMIT).r_fd_holds
    assert not limit_goal(_row("d", 0.0101, {}), LIMIT).r_fd_holds
    assert not limit_goal(_row("d", NAN, {}), LIMIT).r_fd_holds


def test_summary_scores_every_row_but_the_limit() -> None:
    good = _row("good", 0.008, {"f1": (1.0, 0.0), "f2": (0.9, 12.0), "f3": (0.95, 40.0)})
    run = TrackRun(TRACKS["paper"], (), (good, LIMIT), wall_s=1.0, n_computed=0, n_reused=0)
    text, rows = summary_table([run])
    assert rows[0]["faults_at_limit"] == "f1 f2" and rows[0]["r_fd_holds_goal"] is True
    assert rows[1]["faults_at_limit"] == "" and rows[1]["r_fd_holds_goal"] == ""
    assert "| paper | good | 0.0050 [0.0040, 0.0080] | yes | " in text
    assert "| 2/3 f1 f2 | 1 s |" in text
    assert "Test seeds from 0." in text
