"""The goal of the project's detector issue (issue 11), scored once for every table.

A fault is *at the physical limit* for a row when the row's mean t_dt is at most
:data:`GOAL_TIME_FACTOR` × the physical-limit row's + :data:`GOAL_TIME_SLACK` samples and its
mean r_td at most :data:`GOAL_R_TD_MARGIN` below it; r_fd *holds* when the upper end of its 95 %
interval is at most :data:`GOAL_R_FD` (:func:`limit_goal`). :func:`track_goals` reads the goal
across a track's diagnosers and :func:`goal_table` prints it; the track summary
(:mod:`evaluation.tracks.board_tables`) ends with that table.

The physical-limit row reads the true inputs, which no diagnoser may. So the table also says
which faults a *perfect model driven by the measured inputs*, with `lrgf-glr`'s alarm stage
(:data:`evaluation.tracks.oracle.STAGE_LABEL`), brings to the limit: a fault it misses is out of reach
of every detector of that family however good its model, and a diagnoser's miss there says
little about the diagnoser. On a track with plant variation (`uncertain`) the perfect model
knows each episode's drawn plant, so there "reachable" means with a model of that very plant.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from evaluation.tracks.oracle import REFERENCE_LABELS, STAGE_LABEL
from evaluation.tracks.rows import TrackRow, TrackRun

__all__ = [
    "GOAL_R_FD",
    "GOAL_R_TD_MARGIN",
    "GOAL_TIME_FACTOR",
    "GOAL_TIME_SLACK",
    "LimitGoal",
    "goal_table",
    "limit_goal",
    "track_goals",
]


#: A fault's mean t_dt is at the limit when it is at most this factor times the physical-limit
#: row's ...
GOAL_TIME_FACTOR = 1.5
#: ... plus this many samples (where the limit detects at once, the next samples are all a
#: detector can do better than nothing).
GOAL_TIME_SLACK = 2.0
#: ... and its mean r_td is at most this far below the limit's.
GOAL_R_TD_MARGIN = 0.03
#: The upper end of r_fd's 95 % interval may not exceed this.
GOAL_R_FD = 0.01


@dataclass(frozen=True)
class LimitGoal:
    """Which faults of a row are at the physical limit, and whether its r_fd holds the goal."""

    faults_at_limit: tuple[str, ...]
    n_faults: int
    r_fd_holds: bool


def limit_goal(row: TrackRow, limit: TrackRow) -> LimitGoal:
    """Score ``row`` against the physical-limit row ``limit`` of the same track.

    A fault is at the limit when the row's mean t_dt ≤ :data:`GOAL_TIME_FACTOR` × the limit's
    + :data:`GOAL_TIME_SLACK` samples and its mean r_td ≥ the limit's − :data:`GOAL_R_TD_MARGIN`
    (point estimates over the track's seeds; an undefined value, e.g. a fault never detected,
    is not at the limit). r_fd holds when the upper end of its interval is at most
    :data:`GOAL_R_FD`. This is the goal of the project's detector issue (issue 11), written
    once here so that every table scores it the same way.
    """
    at = []
    for fault, cell in row.faults.items():
        ref = limit.faults.get(fault)
        if ref is None:
            continue
        t, t_ref = cell.t_dt.estimate, ref.t_dt.estimate
        r, r_ref = cell.r_td.estimate, ref.r_td.estimate
        if not all(math.isfinite(v) for v in (t, t_ref, r, r_ref)):
            continue
        if t <= GOAL_TIME_FACTOR * t_ref + GOAL_TIME_SLACK and r >= r_ref - GOAL_R_TD_MARGIN:
            at.append(fault)
    holds = math.isfinite(row.r_fd.high) and row.r_fd.high <= GOAL_R_FD
    return LimitGoal(tuple(at), len(row.faults), holds)


def track_goals(runs: Sequence[TrackRun]) -> list[dict[str, Any]]:
    """Per track with a physical-limit row, the goal read across its diagnosers (reference rows
    excluded): the diagnosers whose r_fd holds; the best of them (most faults at the limit, then
    the lower mean t_dt/oracle) with its faults; and each fault at the limit for any of them,
    with the first such diagnoser in that order. A track where no diagnoser holds r_fd has no
    best and no fault at the limit. ``reachable`` lists the faults that the perfect model on the
    measured inputs with `lrgf-glr`'s stage (:data:`~evaluation.tracks.oracle.STAGE_LABEL`) brings to
    the limit, whatever its own r_fd, or is None when the run has no such row."""
    out = []
    references = set(REFERENCE_LABELS.values())
    for run in runs:
        limit = run.limit_row
        if limit is None:
            continue
        scored = [(row, limit_goal(row, limit)) for row in run.rows if row.label not in references]
        holding = sorted(
            ((row, g) for row, g in scored if g.r_fd_holds),
            key=lambda rg: (-len(rg[1].faults_at_limit), _nan_last(rg[0].mean_ratio())),
        )
        by_fault: dict[str, str] = {}
        for row, goal in holding:
            for fault in goal.faults_at_limit:
                by_fault.setdefault(fault, row.label)
        best = holding[0] if holding else None
        stage = next((row for row in run.rows if row.label == STAGE_LABEL), None)
        reachable = None if stage is None else list(limit_goal(stage, limit).faults_at_limit)
        out.append(
            {
                "track": run.track.name,
                "n_faults": len(limit.faults),
                "r_fd_holds": [row.label for row, _ in holding],
                "best": None if best is None else best[0].label,
                "best_faults_at_limit": [] if best is None else list(best[1].faults_at_limit),
                "faults_at_limit_any": {f: by_fault[f] for f in limit.faults if f in by_fault},
                "reachable": reachable,
            }
        )
    return out


def _nan_last(x: float) -> float:
    return x if math.isfinite(x) else math.inf


def goal_table(goals: Sequence[dict[str, Any]]) -> str:
    """The per-track goal of :func:`track_goals` as markdown, with the totals."""
    lines = [
        "## The goal per track",
        "",
        "Among the diagnosers whose r_fd holds the goal: the best one (most faults at the "
        "limit), and each fault at the limit for any of them. The last column: the faults a "
        "perfect model on the measured inputs, with lrgf-glr's stage, brings to the limit "
        "(what any detector of that family could reach; blank without that reference row).",
        "",
        "| track | r_fd holds | best diagnoser | its faults at the limit | "
        "faults at the limit, any diagnoser | reachable from the measured inputs |",
        "|---|---|---|---|---|---|",
    ]
    for g in goals:
        anyone = ", ".join(f"{f} ({d})" for f, d in g["faults_at_limit_any"].items())
        reach = g["reachable"]
        reach_cell = "" if reach is None else f"{len(reach)}/{g['n_faults']} {' '.join(reach)}"
        lines.append(
            f"| {g['track']} | {', '.join(g['r_fd_holds']) or 'none'} | {g['best'] or ''} | "
            f"{len(g['best_faults_at_limit'])}/{g['n_faults']} "
            f"{' '.join(g['best_faults_at_limit'])}".rstrip()
            + f" | {len(g['faults_at_limit_any'])}/{g['n_faults']} {anyone}".rstrip()
            + f" | {reach_cell}".rstrip()
            + " |"
        )
    n = sum(g["n_faults"] for g in goals)
    lines += [
        "",
        f"Tracks where some diagnoser's r_fd holds: {sum(bool(g['r_fd_holds']) for g in goals)}"
        f" of {len(goals)}. Faults at the limit: {sum(len(g['best_faults_at_limit']) for g in goals)}"
        f" of {n} with the best diagnoser per track, "
        f"{sum(len(g['faults_at_limit_any']) for g in goals)} of {n} with any.",
    ]
    scored = [g for g in goals if g["reachable"] is not None]
    if scored:
        reach_n = sum(len(g["reachable"]) for g in scored)
        met = sum(len(set(g["best_faults_at_limit"]) & set(g["reachable"])) for g in scored)
        lines[-1] += (
            f" Reachable from the measured inputs: {reach_n} of "
            f"{sum(g['n_faults'] for g in scored)}, of which the best diagnoser per track "
            f"meets {met}."
        )
    return "\n".join(lines) + "\n"
