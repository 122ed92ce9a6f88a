"""Rankings at a matched false-alarm rate (issue 33): who is ranked, who is marked, what the
ratios and the goal are taken against, and the delay that counts misses. Synthetic rows and
records only, no simulation."""

from __future__ import annotations

import math

import numpy as np
import pytest
from synthetic import cell_record

from evaluation.metrics.detection_metrics import censored_delay
from evaluation.metrics.intervals import UNRANKED, Interval
from evaluation.sweep.records import CellResult
from evaluation.tracks import TRACKS
from evaluation.tracks.board_tables import OVER_GOAL, summary_table, track_table, track_wide_table
from evaluation.tracks.goal import goal_table, track_goals
from evaluation.tracks.optimal import CUSUM_LABEL, GLR_LABEL
from evaluation.tracks.oracle import GOAL_R_FD, ORACLE_LABEL, STAGE_LABEL
from evaluation.tracks.rows import FaultCell, TrackRow, TrackRun, rank_rows, track_rows, yardstick

PAPER = TRACKS["paper"]
QUIET, NOISY = 0.008, 0.02  # upper ends of r_fd's interval: within and over the goal


def _iv(x: float, high: float | None = None) -> Interval:
    return Interval(x, x, x if high is None else high, 20)


def _row(label: str, r_fd_high: float, r_td: float, t_dt: float = 5.0) -> TrackRow:
    cell = FaultCell(_iv(r_td), _iv(t_dt), _iv(1.0), misses=0, terminated=0, n=20)
    return TrackRow(label, _iv(0.002, r_fd_high), 1.0, 0.01, 0, dict.fromkeys(PAPER.faults, cell))


def _run(*rows: TrackRow, records: tuple[CellResult, ...] = ()) -> TrackRun:
    return TrackRun(PAPER, records, rows, wall_s=1.0, n_computed=0, n_reused=0)


def _rec(label: str, scenario: str, seed: int, t_dt: float, *, r_fd: float = 0.001) -> CellResult:
    faulty = scenario != "nominal"
    return cell_record(
        label,
        scenario,
        seed,
        r_td=math.nan if not faulty else (0.0 if math.isnan(t_dt) else 0.9),
        t_dt=math.nan if not faulty else t_dt,
        r_fd=r_fd,
        n_alarms=1,
    )


def _records(label: str, t_dt: list[float], r_fd: float) -> list[CellResult]:
    """Six healthy seeds at ``r_fd`` and one faulty seed per entry of ``t_dt`` on f1."""
    healthy = [_rec(label, "nominal", s, math.nan, r_fd=r_fd) for s in range(6)]
    return healthy + [_rec(label, "f1", s, t) for s, t in enumerate(t_dt)]


def test_a_reference_row_is_never_ranked() -> None:
    # the oracle beats the detector on every fault, and still only the detector is ranked
    rows = rank_rows([_row("det", QUIET, 0.9), _row(ORACLE_LABEL, 0.002, 1.0)], PAPER.faults)
    det, orc = rows
    assert all(c.rank == "1" for c in det.faults.values())
    assert all(c.rank == UNRANKED for c in orc.faults.values())


def test_a_detector_over_the_r_fd_goal_is_unranked_and_marked() -> None:
    noisy, quiet = _row("noisy", NOISY, 1.0), _row("quiet", QUIET, 0.5)
    rows = rank_rows([noisy, quiet, _row(ORACLE_LABEL, 0.002, 1.0)], PAPER.faults)
    assert rows[0].faults["f1"].rank == UNRANKED and rows[1].faults["f1"].rank == "1"
    assert not rows[0].meets_r_fd_goal and rows[1].meets_r_fd_goal
    text = track_table(_run(*rows))
    assert f"| noisy {OVER_GOAL} | " in text and "| quiet | " in text
    assert f"{OVER_GOAL}: r_fd's upper 95 % end above {GOAL_R_FD:g}" in text
    # the rank shows in the compact cell: r_td / t_dt / delay (rank)
    assert f"| 1.000 / 5 / – ({UNRANKED}) |" in text and "| 0.500 / 5 / – (1) |" in text


def test_best_detector_is_none_without_a_fault_at_the_limit() -> None:
    limit = _row(ORACLE_LABEL, 0.002, 1.0, t_dt=2.0)
    slow = _row("slow", QUIET, 1.0, t_dt=50.0)  # meets r_fd, no fault at the limit
    fast_but_noisy = _row("noisy", NOISY, 1.0, t_dt=2.0)  # at the limit, r_fd over the goal
    (goal,) = track_goals([_run(slow, fast_but_noisy, limit)])
    assert goal["r_fd_holds"] == ["slow"] and goal["best"] is None
    assert goal["best_faults_at_limit"] == []
    assert "| paper | slow | none | 0/4 | 0/4 |" in goal_table([goal])


def test_the_censored_delay_counts_a_miss() -> None:
    assert censored_delay(10.0, 300) == 10.0
    assert censored_delay(math.nan, 300) == 300.0
    with pytest.raises(ValueError, match="horizon=0"):
        censored_delay(1.0, 0)
    with pytest.raises(ValueError, match="t_dt=-1"):
        censored_delay(-1.0, 300)
    # four seeds detected after 10 samples, one missed of 300 post-onset samples
    recs = _records("det", [10.0, 10.0, 10.0, 10.0, math.nan], r_fd=0.001)
    (row,) = track_rows(recs, ["det"], ("f1",))
    cell = row.faults["f1"]
    assert cell.t_dt.estimate == pytest.approx(10.0) and cell.misses == 1
    assert cell.delay.estimate == pytest.approx((4 * 10 + 300) / 5)
    assert cell.delay.n == 5  # every faulty seed, the miss included
    assert row.to_json()["faults"]["f1"]["delay_censored"]["estimate"] == pytest.approx(68.0)


def test_a_reference_row_over_the_goal_is_marked_and_not_the_yardstick() -> None:
    t = [9.0, 11.0, 13.0]
    recs = [
        *_records("det", t, r_fd=0.001),
        *_records(ORACLE_LABEL, [0.0, 0.0, 0.0], r_fd=0.05),  # fast because it alarms a lot
        *_records(CUSUM_LABEL, [4.0, 4.0, 4.0], r_fd=0.002),
    ]
    rows = track_rows(recs, ["det"], ("f1",))
    det, orc, cusum = rows
    assert not orc.meets_r_fd_goal and cusum.meets_r_fd_goal
    # both ratios fall back on the next reference that meets the goal: the CUSUM row
    expected = (np.mean(t) + 1) / 5.0
    assert det.faults["f1"].ratio.estimate == pytest.approx(expected)
    assert det.faults["f1"].ratio_optimal.estimate == pytest.approx(expected)
    run = TrackRun(
        PAPER.replace(faults=("f1",), magnitudes=None), tuple(recs), tuple(rows), 1.0, 0, 0
    )
    assert run.limit_row is cusum and run.optimal_row is cusum
    wide = track_wide_table(run)
    assert f"| {ORACLE_LABEL} {OVER_GOAL} | " in wide
    assert f"t_dt/oracle is against `{CUSUM_LABEL}`" in wide
    # the goal is scored against the CUSUM row too, and says so
    (goal,) = track_goals([run])
    assert goal["limit"] == CUSUM_LABEL
    assert f"| paper (limit: {CUSUM_LABEL}) |" in goal_table([goal])


def test_no_reference_within_the_goal_leaves_no_yardstick() -> None:
    recs = [*_records("det", [5.0], r_fd=0.001), *_records(ORACLE_LABEL, [1.0], r_fd=0.05)]
    det, _ = track_rows(recs, ["det"], ("f1",))
    assert math.isnan(det.faults["f1"].ratio.estimate)
    assert math.isnan(det.faults["f1"].ratio_optimal.estimate)
    assert yardstick({ORACLE_LABEL: _iv(0.05)}, ORACLE_LABEL) is None
    # the next one from the CUSUM row on is the GLR row, then round to the physical limit
    ok = _iv(0.002)
    assert yardstick({GLR_LABEL: ok, ORACLE_LABEL: ok}, CUSUM_LABEL) == GLR_LABEL
    with pytest.raises(ValueError, match="first='det'"):
        yardstick({}, "det")


def test_reachable_is_not_read_from_a_stage_row_over_the_goal() -> None:
    limit = _row(ORACLE_LABEL, 0.002, 1.0, t_dt=2.0)
    stage = _row(STAGE_LABEL, NOISY, 1.0, t_dt=2.0)
    (goal,) = track_goals([_run(_row("det", QUIET, 1.0, t_dt=2.0), stage, limit)])
    assert goal["reachable"] is None and goal["reachable_note"] == "over the r_fd goal"
    assert goal["best"] == "det"
    assert "— (over the r_fd goal)" in goal_table([goal])


def test_the_summary_names_the_stand_in_for_a_physical_limit_over_the_goal() -> None:
    run = _run(
        _row("det", QUIET, 1.0), _row(ORACLE_LABEL, NOISY, 1.0), _row(CUSUM_LABEL, QUIET, 1.0)
    )
    text, _ = summary_table([run])
    assert (
        f"Track paper: the physical limit's r_fd misses the goal, so the limit is `{CUSUM_LABEL}`"
        in text
    )


def test_ranks_range_within_a_tier() -> None:
    grey = TrackRow(**{**_row("grey", QUIET, 0.99).__dict__, "tier": "grey box"})
    rows = rank_rows([_row("black", QUIET, 0.5), grey, _row("black2", QUIET, 0.9)], PAPER.faults)
    by = {r.label: r.faults["f1"].rank for r in rows}
    assert by["grey"] == "1" and by["black2"] == "1" and by["black"] == "2"
    table = track_table(_run(*rows))
    assert "| grey | grey box |" in table and "| black | black box |" in table
