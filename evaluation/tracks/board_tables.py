"""A track's tables and files: the Markdown/CSV/JSON leaderboard of a track, its isolation
table and confusion figures, and the summary over tracks with the goal table.

A track has two tables: the compact one (:func:`track_table`, printed, and first in
``leaderboard.md``): r_fd with its interval, per fault r_td / t_dt / delay with misses counted
(rank) and the ratio to the optimal CUSUM row; and the wide one (:func:`track_wide_table`, below
it in ``leaderboard.md``, and every column in ``leaderboard.csv`` / ``.json``). Ranks range over
the registered detectors whose r_fd meets the goal (:func:`evaluation.tracks.rows.rank_rows`);
every other row is shown unranked, a row over the goal marked with :data:`OVER_GOAL`, and a
line under each table says what each reference row is."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from evaluation.metrics.intervals import Interval, bootstrap_ci
from evaluation.metrics.isolation_metrics import MISSED, confusion_matrix
from evaluation.reports.outputs import write_csv
from evaluation.reports.plots import confusion_figure
from evaluation.reports.tables import R_FD_TEXT, R_TD_TEXT, t_dt_text
from evaluation.sweep.records import CellResult
from evaluation.tracks.filter_bound import FILTER_LABEL
from evaluation.tracks.goal import (
    GOAL_R_FD,
    GOAL_R_TD_MARGIN,
    GOAL_TIME_FACTOR,
    GOAL_TIME_SLACK,
    LimitGoal,
    goal_table,
    limit_goal,
    track_goals,
)
from evaluation.tracks.oracle import CUSUM_LABEL, ORACLE_LABEL, REFERENCE_NOTES
from evaluation.tracks.rows import TrackRow, TrackRun, records_of
from evaluation.tracks.track import Track
from fcc_common.io import atomic_write, atomic_write_json

__all__ = [
    "isolation_labels",
    "isolation_table",
    "summary_table",
    "track_legend",
    "track_table",
    "track_wide_table",
    "write_summary",
    "write_track",
]


def _ci(iv: Interval, digits: int) -> str:
    if not math.isfinite(iv.estimate):
        return "–"
    return f"{iv.estimate:.{digits}f} [{iv.low:.{digits}f}, {iv.high:.{digits}f}]"


#: the mark of a row whose r_fd's upper 95 % end exceeds the goal on the test episodes
OVER_GOAL = "†"


def _label(row: TrackRow) -> str:
    return row.label + (f" {OVER_GOAL}" if not row.meets_r_fd_goal else "")


def _marks_text() -> str:
    return (
        f"Ranks ((rank), '=' where intervals overlap) range over the registered detectors of one "
        "tier (black box: the records alone; grey box: also the published model, never the "
        f"scored plant's parameters) whose r_fd's upper 95 % end is at most {GOAL_R_FD:g}; "
        "reference rows and detectors over "
        f"that goal show '–'. {OVER_GOAL}: r_fd's upper 95 % end above {GOAL_R_FD:g} on the test "
        "episodes (a detector: unranked; a reference row: no detector is scored against it)."
    )


def _references_line(run: TrackRun) -> str:
    """What each reference row of ``run`` is, and which rows the ratios are taken against."""
    refs = [r for r in run.rows if r.reference]
    if not refs:
        return "No reference rows."
    limit, optimal, bound = run.limit_row, run.optimal_row, run.filter_row
    parts = [f"{r.label}: {REFERENCE_NOTES.get(r.label, 'a reference row')}" for r in refs]
    return (
        "Reference rows (read what no detector may; never ranked): "
        + "; ".join(parts)
        + f". t_dt/oracle is against `{limit.label if limit else 'none'}`, t_dt/optimal "
        f"against `{optimal.label if optimal else 'none'}`, t_dt/filter against "
        f"`{bound.label if bound else 'none'}` (the first reference row from "
        f"`{ORACLE_LABEL}`, resp. `{CUSUM_LABEL}`, resp. `{FILTER_LABEL}`, on that meets the "
        "r_fd goal)."
    )


def _delay_text() -> str:
    return (
        "delay: mean over the seeds of min(t_dt, T − onset), a miss counted as T − onset (T: "
        "the episode's end), so a miss costs its whole silent time, unlike t_dt's mean over the "
        "detected seeds"
    )


def track_legend(sample_time_s: float | None = None) -> str:
    """What a track table's columns, units and brackets mean (worded as the classic table's).

    Args:
        sample_time_s: the data's sample time, to say what a sample of ``t_dt`` is in seconds
            (``None``: not said).
    """
    return (
        f"Legend: {R_FD_TEXT}; healthy eps. alarmed: the share of healthy episodes with any "
        "alarm [0-1]; worst r_fd (seed): the largest r_fd of one healthy episode and its seed; "
        f"{R_TD_TEXT}, (rank) on r_td with '=' where intervals overlap; "
        f"{t_dt_text(sample_time_s)}; {_delay_text()}; t_dt/oracle: (t_dt + 1) / (oracle t_dt + "
        "1) [-] over the seeds both detected, 1 = as fast as the physical limit (where that row "
        "misses the r_fd goal, the reference row named under the table); t_dt/optimal: the same "
        "against the optimal CUSUM row (the filter row's own: the price of input noise); "
        "t_dt/filter: the same against the optimal filter row, the reachable bound; missed/ended: faulty episodes "
        "never alarmed after the onset / episodes the plant ended early, with the reasons "
        "(well_empty, afterburn, extinguished; scored on their samples before the end). "
        "a [lo, hi]: estimate and 95 % BCa bootstrap interval over the seeds; –: no value."
    )


def _seed_line(track: Track) -> str:
    test, train = track.test_seeds, track.train_seeds
    return (
        f"Test seeds {test.start}–{test.stop - 1}; trained on healthy episodes of seeds "
        f"{train.start}–{train.stop - 1}."
    )


def _point(iv: Interval, digits: int) -> str:
    return f"{iv.estimate:.{digits}f}" if math.isfinite(iv.estimate) else "–"


def track_table(run: TrackRun) -> str:
    """The compact Markdown table of a track (printed): r_fd with its interval, per fault
    r_td / t_dt / delay (rank) and t_dt/optimal; header sentences, legend, the reference line."""
    faults = run.track.faults
    head = ["diagnoser", "tier", "r_fd [95 % CI]"]
    for f in faults:
        head += [f"{f} r_td / t_dt / delay (rank)", f"{f} t_dt/optimal"]
    dt = run.records[0].sample_time_s if run.records else None
    lines = [
        f"## Track `{run.track.name}`",
        "",
        run.track.description,
        "",
        _seed_line(run.track),
        "",
        f"Legend: {R_FD_TEXT}; {R_TD_TEXT}; {t_dt_text(dt)}; {_delay_text()}; t_dt/optimal: "
        "(t_dt + 1) / (optimal t_dt + 1) [-] over the seeds both detected; a [lo, hi]: estimate "
        f"and 95 % BCa bootstrap interval over the seeds; –: no value. {_marks_text()} "
        "The wide table (intervals everywhere, misses, ended episodes) is in leaderboard.md/.csv.",
        "",
        "| " + " | ".join(head) + " |",
        "|" + "---|" * len(head),
    ]
    for row in run.rows:
        cells = [_label(row), row.tier, _ci(row.r_fd, 4)]
        for f in faults:
            c = row.faults[f]
            cells += [
                f"{_point(c.r_td, 3)} / {_point(c.t_dt, 0)} / {_point(c.delay, 0)} ({c.rank})",
                _point(c.ratio_optimal, 2),
            ]
        lines.append("| " + " | ".join(cells) + " |")
    lines += ["", _references_line(run)]
    return "\n".join(lines) + "\n"


def track_wide_table(run: TrackRun) -> str:
    """The wide Markdown table of a track (every column with its interval; legend, reference
    line)."""
    faults = run.track.faults
    head = ["diagnoser", "tier", "r_fd [95 % CI]", "healthy eps. alarmed", "worst r_fd (seed)"]
    for f in faults:
        head += [f"{f} r_td (rank)", f"{f} t_dt", f"{f} delay", f"{f} t_dt/oracle"]
        head += [f"{f} t_dt/optimal", f"{f} t_dt/filter", f"{f} missed/ended"]
    lines = [
        f"### Track `{run.track.name}`, every column",
        "",
        track_legend(run.records[0].sample_time_s if run.records else None) + " " + _marks_text(),
        "",
        "| " + " | ".join(head) + " |",
        "|" + "---|" * len(head),
    ]
    for row in run.rows:
        cells = [
            _label(row),
            row.tier,
            _ci(row.r_fd, 4),
            f"{row.alarmed_share:.2f}",
            f"{row.worst_r_fd:.4f} ({row.worst_seed})",
        ]
        for f in faults:
            c = row.faults[f]
            cells += [
                f"{_ci(c.r_td, 3)} ({c.rank})",
                _ci(c.t_dt, 0),
                _ci(c.delay, 0),
                _ci(c.ratio, 2),
                _ci(c.ratio_optimal, 2),
                _ci(c.ratio_filter, 2),
                f"{c.misses}/{c.terminated}"
                + "".join(f" {reason}×{n}" for reason, n in c.ended_reasons),
            ]
        lines.append("| " + " | ".join(cells) + " |")
    lines += ["", _references_line(run)]
    return "\n".join(lines) + "\n"


def _flat(row: TrackRow, track: str, run: TrackRun) -> dict[str, Any]:
    limit, optimal, bound = run.limit_row, run.optimal_row, run.filter_row
    d: dict[str, Any] = {
        "track": track,
        "diagnoser": row.label,
        "tier": row.tier,
        "reference": row.reference,
        "r_fd_meets_goal": row.meets_r_fd_goal,
        "limit_reference": limit.label if limit else "",
        "optimal_reference": optimal.label if optimal else "",
        "filter_reference": bound.label if bound else "",
        "r_fd": row.r_fd.estimate,
        "r_fd_low": row.r_fd.low,
        "r_fd_high": row.r_fd.high,
        "healthy_alarmed_share": row.alarmed_share,
        "worst_r_fd": row.worst_r_fd,
        "worst_seed": row.worst_seed,
    }
    for f, c in row.faults.items():
        for name, iv in (
            ("r_td", c.r_td),
            ("t_dt", c.t_dt),
            ("t_dt_over_oracle", c.ratio),
            ("delay_censored", c.delay),
            ("t_dt_over_optimal", c.ratio_optimal),
            ("t_dt_over_filter", c.ratio_filter),
        ):
            d[f"{f}_{name}"], d[f"{f}_{name}_low"], d[f"{f}_{name}_high"] = (
                iv.estimate,
                iv.low,
                iv.high,
            )
        d[f"{f}_misses"], d[f"{f}_terminated"], d[f"{f}_rank"] = c.misses, c.terminated, c.rank
    return d


def isolation_labels(records: Sequence[CellResult]) -> list[str]:
    """The diagnosers of ``records`` that isolate (their faulty records carry a diagnosis)."""
    return list(dict.fromkeys(r.diagnoser for r in records if r.diagnosis))


def isolation_table(run: TrackRun) -> str:
    """Markdown: isolation indexes per isolating diagnoser and fault, and its confusion matrix
    (``""`` when no diagnoser of the run isolates). Definitions: :mod:`evaluation.metrics.isolation_metrics`."""
    labels = isolation_labels(run.records)
    if not labels:
        return ""
    faults = run.track.faults
    head = ["diagnoser"]
    for f in faults:
        head += [f"{f} CDR", f"{f} t_it", f"{f} r_fi"]
    lines = [
        "",
        "### Isolation",
        "",
        "CDR: share of the alarmed post-onset samples with the right diagnosis; t_it: samples "
        "from onset until the right label holds for 100 samples (mean over isolated faults); "
        "r_fi: share of the post-onset samples with a wrong fault label. Brackets: 95 % BCa "
        "bootstrap intervals over seeds.",
        "",
        "| " + " | ".join(head) + " |",
        "|" + "---|" * len(head),
    ]
    tables = []
    for label in labels:
        cells = [label]
        truths, diags = [], []
        for f in faults:
            recs = [r for r in records_of(run.records, label, f) if r.n_fault_samples > 0]
            cells += [
                _ci(bootstrap_ci([r.cdr for r in recs]), 3),
                _ci(bootstrap_ci([r.t_it for r in recs]), 0),
                _ci(bootstrap_ci([r.r_fi for r in recs]), 3),
            ]
            truths += [f] * len(recs)
            diags += [r.diagnosis or MISSED for r in recs]
        lines.append("| " + " | ".join(cells) + " |")
        rows, cols, m = confusion_matrix(truths, diags, faults)
        tables += [
            "",
            f"Confusion of `{label}` (episodes; rows: true fault, columns: diagnosis):",
            "",
            "| true \\ diagnosis | " + " | ".join(cols) + " |",
            "|---|" + "---|" * len(cols),
            *(
                f"| {r} | " + " | ".join(str(c) for c in row) + " |"
                for r, row in zip(rows, m, strict=True)
            ),
        ]
    return "\n".join(lines + tables) + "\n"


def confusion_figures(run: TrackRun, out: Path) -> list[Path]:
    """One confusion-matrix PNG per isolating diagnoser: ``<out>/figures/confusion-<label>.png``."""
    paths = []
    for label in isolation_labels(run.records):
        recs = [
            r
            for f in run.track.faults
            for r in records_of(run.records, label, f)
            if r.n_fault_samples > 0
        ]
        rows, cols, m = confusion_matrix(
            [r.scenario for r in recs], [r.diagnosis or MISSED for r in recs], run.track.faults
        )
        paths.append(
            confusion_figure(
                rows,
                cols,
                m,
                f"{label}, track {run.track.name}",
                out / "figures" / f"confusion-{label}.png",
            )
        )
    return paths


def write_track(run: TrackRun, out: Path) -> list[Path]:
    """The track's table (Markdown, CSV, JSON) and its per-seed records."""
    name = run.track.name
    paths = [
        atomic_write(
            out / "leaderboard.md",
            track_table(run) + "\n" + track_wide_table(run) + isolation_table(run),
        ),
        write_csv(out / "leaderboard.csv", [_flat(r, name, run) for r in run.rows]),
        atomic_write_json(
            out / "leaderboard.json",
            {
                "track": run.track.to_json(),
                "r_fd_goal": GOAL_R_FD,
                "limit_reference": run.limit_row.label if run.limit_row else None,
                "optimal_reference": run.optimal_row.label if run.optimal_row else None,
                "rows": [r.to_json() for r in run.rows],
            },
            indent=1,
        ),
        write_csv(out / "results.csv", [r.to_json() for r in run.records]),
        atomic_write_json(
            out / "results.json", {"records": [r.to_json() for r in run.records]}, indent=1
        ),
        *confusion_figures(run, out),
    ]
    return paths


def summary_table(runs: Sequence[TrackRun]) -> tuple[str, list[dict[str, Any]]]:
    """Diagnosers × tracks: r_fd with interval, mean r_td, mean t_dt / oracle, the faults at the
    physical limit and whether r_fd holds the goal (:func:`limit_goal`; empty for the limit row
    itself and on a track without it); wall times."""
    rows: list[dict[str, Any]] = []
    goals: list[LimitGoal | None] = []
    for run in runs:
        limit = run.limit_row
        for row in run.rows:
            goal = limit_goal(row, limit) if limit is not None and row is not limit else None
            goals.append(goal)
            rows.append(
                {
                    "track": run.track.name,
                    "diagnoser": row.label,
                    "tier": row.tier,
                    "r_fd": row.r_fd.estimate,
                    "r_fd_low": row.r_fd.low,
                    "r_fd_high": row.r_fd.high,
                    "mean_r_td": row.mean_r_td(),
                    "mean_t_dt_over_oracle": row.mean_ratio(),
                    "faults_at_limit": "" if goal is None else " ".join(goal.faults_at_limit),
                    "n_faults_at_limit": "" if goal is None else len(goal.faults_at_limit),
                    "n_faults": len(row.faults),
                    "r_fd_holds_goal": "" if goal is None else goal.r_fd_holds,
                    "track_wall_s": run.wall_s,
                }
            )
    lines = [
        "# Benchmark v2 summary",
        "",
        f"At the limit: faults whose mean t_dt ≤ {GOAL_TIME_FACTOR:g} × the physical limit's + "
        f"{GOAL_TIME_SLACK:g} samples with r_td at most {GOAL_R_TD_MARGIN:g} below it; "
        f"r_fd ≤ {GOAL_R_FD:g}: the upper end of its 95 % interval. Test seeds from "
        + ", ".join(str(s) for s in sorted({run.track.test_seed_start for run in runs}))
        + "."
        + _stand_ins(runs),
        "",
        f"| track | diagnoser | r_fd [95 % CI] | r_fd ≤ {GOAL_R_FD:g} | mean r_td | "
        "mean t_dt/oracle | faults at the limit | track wall time |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r, goal in zip(rows, goals, strict=True):
        at = holds = ""  # the limit row itself, or a track without it
        if goal is not None:
            at = f"{len(goal.faults_at_limit)}/{goal.n_faults} {r['faults_at_limit']}".rstrip()
            holds = "yes" if goal.r_fd_holds else "no"
        lines.append(
            f"| {r['track']} | {r['diagnoser']} | {r['r_fd']:.4f} [{r['r_fd_low']:.4f}, "
            f"{r['r_fd_high']:.4f}] | {holds} | {r['mean_r_td']:.3f} | "
            f"{r['mean_t_dt_over_oracle']:.2f} | {at} | {r['track_wall_s']:.0f} s |"
        )
    return "\n".join(lines) + "\n", rows


def _stand_ins(runs: Sequence[TrackRun]) -> str:
    """A sentence per track whose physical-limit row misses the r_fd goal: what stands in."""
    out = ""
    for run in runs:
        if not any(r.label == ORACLE_LABEL for r in run.rows):
            continue
        limit = run.limit_row
        if limit is None or limit.label != ORACLE_LABEL:
            out += (
                f" Track {run.track.name}: the physical limit's r_fd misses the goal, so the limit "
                f"is {'none' if limit is None else f'`{limit.label}`'}."
            )
    return out


def write_summary(runs: Sequence[TrackRun], out: Path) -> list[Path]:
    text, rows = summary_table(runs)
    goals = track_goals(runs)
    if goals:
        text += "\n" + goal_table(goals)
    return [
        atomic_write(out / "summary.md", text),
        write_csv(out / "summary.csv", rows),
        atomic_write_json(out / "summary.json", {"rows": rows, "goals": goals}, indent=1),
    ]
