"""The goal of the project's detector issue (issue 11), scored once for every table.

A fault is *at the physical limit* for a row when the row's mean t_dt is at most
:data:`GOAL_TIME_FACTOR` × the physical-limit row's + :data:`GOAL_TIME_SLACK` samples and its
mean r_td at most :data:`GOAL_R_TD_MARGIN` below it; r_fd *holds* when the upper end of its 95 %
interval is at most :data:`GOAL_R_FD` (:func:`limit_goal`). Where the physical-limit row itself
misses that r_fd goal on the test episodes, the goal is taken against the next reference row
that meets it (:attr:`~evaluation.tracks.rows.TrackRun.limit_row`), and none when none does.
:func:`track_goals` reads the goal across a track's registered diagnosers and :func:`goal_table`
prints it; the track summary (:mod:`evaluation.tracks.board_tables`) ends with that table.

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

from evaluation.tracks.oracle import GOAL_R_FD, ORACLE_LABEL, STAGE_LABEL
from evaluation.tracks.rows import TrackRow, TrackRun, meets_r_fd_goal

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
# GOAL_R_FD, the bound on the upper end of r_fd's 95 % interval, is declared beside the
# reference rows' calibration target (evaluation.tracks.oracle) and re-exported here.


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
    return LimitGoal(tuple(at), len(row.faults), meets_r_fd_goal(row.r_fd))


def track_goals(runs: Sequence[TrackRun]) -> list[dict[str, Any]]:
    """Per track with a yardstick (:attr:`TrackRun.limit_row`: the physical-limit row, or the
    next reference row meeting the r_fd goal), the goal read across its registered diagnosers
    (reference rows never count): the diagnosers whose r_fd holds; the best of them (most faults
    at the limit, then the lower mean t_dt/oracle), which needs at least one fault at the limit
    (else ``best`` is None); and each fault at the limit for any of them, with the first such
    diagnoser in that order. A track where no diagnoser holds r_fd has no best and no fault at
    the limit. ``limit`` names the yardstick. ``reachable`` lists the faults that the perfect
    model on the measured inputs with `lrgf-glr`'s stage
    (:data:`~evaluation.tracks.oracle.STAGE_LABEL`) brings to the limit, or is None when the run
    has no such row or that row misses the r_fd goal on the test episodes (``reachable_note``
    says which)."""
    out = []
    for run in runs:
        limit = run.limit_row
        if limit is None:
            continue
        scored = [(row, limit_goal(row, limit)) for row in run.rows if not row.reference]
        holding = sorted(
            ((row, g) for row, g in scored if g.r_fd_holds),
            key=lambda rg: (-len(rg[1].faults_at_limit), _nan_last(rg[0].mean_ratio())),
        )
        by_fault: dict[str, str] = {}
        for row, goal in holding:
            for fault in goal.faults_at_limit:
                by_fault.setdefault(fault, row.label)
        best = holding[0] if holding and holding[0][1].faults_at_limit else None
        stage = next((row for row in run.rows if row.label == STAGE_LABEL), None)
        # a stage row over the r_fd goal buys its detections with false alarms: not read
        reachable: list[str] | None = None
        note = ""
        if stage is not None and stage.meets_r_fd_goal:
            reachable = list(limit_goal(stage, limit).faults_at_limit)
        elif stage is not None:
            note = "over the r_fd goal"
        out.append(
            {
                "track": run.track.name,
                "limit": limit.label,
                "n_faults": len(limit.faults),
                "r_fd_holds": [row.label for row, _ in holding],
                "best": None if best is None else best[0].label,
                "best_faults_at_limit": [] if best is None else list(best[1].faults_at_limit),
                "faults_at_limit_any": {f: by_fault[f] for f in limit.faults if f in by_fault},
                "reachable": reachable,
                "reachable_note": note,
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
        "Among the registered diagnosers whose r_fd holds the goal (reference rows never "
        "count): the best one (most faults at the limit, at least one; 'none' when no "
        "diagnoser has a fault at the limit), and each fault at the limit for any of them. "
        "The limit is the physical-limit row, or where its r_fd misses the goal the reference "
        "row named in brackets. The last column: the faults a perfect model on the measured "
        "inputs, with lrgf-glr's stage, brings to the limit (what any detector of that family "
        "could reach; blank without that reference row, '— (over the r_fd goal)' where that "
        "row misses the goal on the test episodes and so says nothing at a matched rate).",
        "",
        "| track | r_fd holds | best diagnoser | its faults at the limit | "
        "faults at the limit, any diagnoser | reachable from the measured inputs |",
        "|---|---|---|---|---|---|",
    ]
    for g in goals:
        anyone = ", ".join(f"{f} ({d})" for f, d in g["faults_at_limit_any"].items())
        reach = g["reachable"]
        reach_cell = "" if reach is None else f"{len(reach)}/{g['n_faults']} {' '.join(reach)}"
        if reach is None and g.get("reachable_note"):
            reach_cell = f"— ({g['reachable_note']})"
        track = g["track"]
        if g.get("limit", ORACLE_LABEL) != ORACLE_LABEL:
            track += f" (limit: {g['limit']})"
        lines.append(
            f"| {track} | {', '.join(g['r_fd_holds']) or 'none'} | {g['best'] or 'none'} | "
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
