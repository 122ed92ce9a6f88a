"""The goal "at the physical limit" (``evaluation.tracks.goal``) and the track summary."""

from __future__ import annotations

import math

from evaluation.metrics.intervals import Interval
from evaluation.tracks import TRACKS
from evaluation.tracks.board_tables import summary_table
from evaluation.tracks.goal import goal_table, limit_goal, track_goals
from evaluation.tracks.oracle import ORACLE_LABEL, REFERENCE_LABELS, STAGE_LABEL
from evaluation.tracks.rows import FaultCell, TrackRow, TrackRun

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


def _run(track: str, *rows: TrackRow) -> TrackRun:
    return TrackRun(TRACKS[track], (), (*rows, LIMIT), wall_s=1.0, n_computed=0, n_reused=0)


def test_goal_per_track_takes_only_diagnosers_whose_r_fd_holds() -> None:
    fast_but_noisy = _row("noisy", 0.02, {"f1": (1.0, 0.0), "f2": (0.9, 5.0), "f3": (1.0, 5.0)})
    quiet = _row("quiet", 0.009, {"f1": (1.0, 1.0), "f2": (0.9, 30.0), "f3": (0.99, 15.0)})
    quieter = _row("quieter", 0.005, {"f1": (1.0, 9.0), "f2": (0.9, 12.0), "f3": (0.5, 99.0)})
    # a reference row meets everything but is not a diagnoser
    perfect = _row(
        next(v for v in REFERENCE_LABELS.values() if v != ORACLE_LABEL),
        0.003,
        {"f1": (1.0, 0.0), "f2": (0.9, 5.0), "f3": (1.0, 5.0)},
    )
    none_holds = _run("small", fast_but_noisy)
    goals = track_goals([_run("paper", fast_but_noisy, quiet, quieter, perfect), none_holds])
    paper, small = goals
    assert paper["r_fd_holds"] == ["quiet", "quieter"]  # "quiet": two faults, "quieter": one
    assert paper["best"] == "quiet" and paper["best_faults_at_limit"] == ["f1", "f3"]
    assert paper["faults_at_limit_any"] == {"f1": "quiet", "f2": "quieter", "f3": "quiet"}
    assert small["r_fd_holds"] == [] and small["best"] is None
    assert small["faults_at_limit_any"] == {}
    text = goal_table(goals)
    assert "| paper | quiet, quieter | quiet | 2/3 f1 f3 | 3/3 f1 (quiet), f2 (quieter), " in text
    assert "| small | none | none | 0/3 | 0/3 |" in text
    assert "Tracks where some diagnoser's r_fd holds: 1 of 2." in text
    assert "Faults at the limit: 2 of 6 with the best diagnoser per track, 3 of 6 with any." in text
    # the perfect-model row on the T² stage is not the one that says what is reachable
    assert paper["reachable"] is None and "Reachable" not in text


def test_goal_says_which_faults_a_perfect_model_on_the_measured_inputs_reaches() -> None:
    # the best diagnoser meets f2 as well, which the perfect model on measured inputs does not
    best = _row("best", 0.009, {"f1": (1.0, 0.0), "f2": (0.9, 12.0), "f3": (0.99, 15.0)})
    # the stage row misses f2 (r_td 0.8 < 0.87); its r_fd holds, so it is scored
    stage = _row(STAGE_LABEL, 0.009, {"f1": (1.0, 1.0), "f2": (0.8, 9.0), "f3": (0.99, 19.0)})
    other = _row("other", 0.009, {"f1": (1.0, 9.0), "f2": (0.9, 12.0), "f3": (0.5, 99.0)})
    goals = track_goals([_run("paper", best, stage), _run("small", other)])
    assert goals[0]["reachable"] == ["f1", "f3"] and goals[1]["reachable"] is None
    assert goals[0]["best"] == "best"  # a reference row is never the best
    text = goal_table(goals)
    assert (
        "| paper | best | best | 3/3 f1 f2 f3 | 3/3 f1 (best), f2 (best), f3 (best) | 2/3 f1 f3 |"
        in text
    )
    assert "| small | other | other | 1/3 f2 | 1/3 f2 (other) | |" in text
    # only tracks with the row count: 2 reachable of paper's 3, both met by its best (its f2,
    # outside the reachable set, is not counted)
    assert "Reachable from the measured inputs: 2 of 3, of which the best diagnoser" in text
    assert text.rstrip().endswith("meets 2.")


def test_equal_counts_rank_by_the_mean_time_ratio() -> None:
    def with_ratio(label: str, ratio: float) -> TrackRow:
        cell = FaultCell(_iv(1.0), _iv(0.0), _iv(ratio), misses=0, terminated=0, n=20)
        return TrackRow(label, _iv(0.005, 0.004, 0.008), 1.0, 0.05, 3, {"f1": cell})

    goals = track_goals([_run("paper", with_ratio("slow", 2.0), with_ratio("fast", 1.2))])
    assert goals[0]["r_fd_holds"] == ["fast", "slow"] and goals[0]["best"] == "fast"


def test_a_run_without_the_limit_row_has_no_goal() -> None:
    run = TrackRun(TRACKS["paper"], (), (LIMIT,)[:0], wall_s=1.0, n_computed=0, n_reused=0)
    assert track_goals([run]) == []
