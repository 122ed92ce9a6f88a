"""Benchmark v2: the leaderboard per track, with the physical-limit row and 95 % intervals.

``python -m evaluation.leaderboard --track paper,small`` (or ``--track all``) runs, for each
track of :mod:`evaluation.tracks`, a sweep of the chosen diagnosers over the track's test cells
(:class:`evaluation.sources.TrackData`), scores the physical-limit observer
(:mod:`evaluation.oracle`) on the same cells, and writes into ``<out>/<track>/``:

* ``leaderboard.md`` / ``.csv`` / ``.json`` — one row per diagnoser plus three reference rows
  (:data:`evaluation.oracle.DEFAULT_REFERENCES`), the ``oracle`` (physical limit), the
  ``perfect model (measured inputs)`` and the ``perfect model + lrgf-glr stage (measured
  inputs)``:
  r_fd with its 95 % bootstrap interval over healthy episodes, the share of healthy episodes
  with any alarm and the worst one; per fault r_td and t_dt with intervals, the ratio
  ``(t_dt + 1) / (oracle t_dt + 1)`` with its paired interval, misses and early terminations;
  ranks per fault on r_td that mark ties when intervals overlap;
* ``results.csv`` / ``results.json`` — every per-seed record (the oracle's too);
* ``figures/`` — as the classic leaderboard.

and ``<out>/summary.md`` / ``.csv`` / ``.json``: diagnosers × tracks (r_fd with interval, mean
r_td over faults, mean t_dt / oracle ratio, the faults at the physical limit and whether r_fd's
upper end holds the goal, :func:`limit_goal`) and the wall time per track.
"""

from __future__ import annotations

import math
import os
import shutil
import tempfile
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from diagnosers.registry import import_modules
from evaluation.goal import (
    GOAL_R_FD,
    GOAL_R_TD_MARGIN,
    GOAL_TIME_FACTOR,
    GOAL_TIME_SLACK,
    LimitGoal,
    goal_table,
    limit_goal,
    track_goals,
)
from evaluation.intervals import (
    Interval,
    bootstrap_ci,
    limit_ratio_ci,
    rank_with_ties,
    share_with_alarm,
    worst,
)
from evaluation.oracle import (
    DEFAULT_REFERENCES,
    ORACLE_LABEL,
    REFERENCE_LABELS,
    reference_records,
)
from evaluation.outputs import write_csv
from evaluation.records import CellResult
from evaluation.sources import TrackData
from evaluation.store import ResultStore, canonical_hash
from evaluation.sweep import DiagnoserSpec, SweepConfig, default_specs, dir_files, run_sweep
from evaluation.tables import R_FD_TEXT, R_TD_TEXT, t_dt_text
from evaluation.tracks import Track
from fcc_env.io import atomic_write, atomic_write_json

# the goal's names (evaluation.goal) stay importable from here, as before they moved
__all__ = [
    "TrackRow",
    "TrackRun",
    "isolation_table",
    "run_track",
    "track_legend",
    "track_rows",
    "track_table",
    "write_track",
]


@dataclass(frozen=True)
class FaultCell:
    """One diagnoser on one fault of a track, over the track's faulty seeds."""

    r_td: Interval
    t_dt: Interval
    ratio: Interval
    misses: int
    terminated: int
    n: int
    rank: str = ""
    ended_reasons: tuple[tuple[str, int], ...] = ()  # (termination reason, episodes)


@dataclass(frozen=True)
class TrackRow:
    """One row of a track table (a diagnoser, or the physical limit)."""

    label: str
    r_fd: Interval
    alarmed_share: float
    worst_r_fd: float
    worst_seed: int
    faults: dict[str, FaultCell]

    def mean_r_td(self) -> float:
        v = [c.r_td.estimate for c in self.faults.values()]
        return float(np.nanmean(v)) if v else math.nan

    def mean_ratio(self) -> float:
        v = [c.ratio.estimate for c in self.faults.values() if math.isfinite(c.ratio.estimate)]
        return float(np.mean(v)) if v else math.nan

    def to_json(self) -> dict[str, Any]:
        return {
            "label": self.label,
            "r_fd": self.r_fd.to_json(),
            "alarmed_share": self.alarmed_share,
            "worst_r_fd": self.worst_r_fd,
            "worst_seed": self.worst_seed,
            "faults": {
                f: {
                    "r_td": c.r_td.to_json(),
                    "t_dt": c.t_dt.to_json(),
                    "t_dt_over_oracle": c.ratio.to_json(),
                    "misses": c.misses,
                    "terminated": c.terminated,
                    "ended_reasons": dict(c.ended_reasons),
                    "n": c.n,
                    "rank_r_td": c.rank,
                }
                for f, c in self.faults.items()
            },
        }


@dataclass(frozen=True)
class TrackRun:
    track: Track
    records: tuple[CellResult, ...]
    rows: tuple[TrackRow, ...]
    wall_s: float
    n_computed: int
    n_reused: int
    n_trained: int = 0
    n_reused_models: int = 0

    @property
    def limit_row(self) -> TrackRow | None:
        """The physical-limit row, None when the run has none."""
        return next((r for r in self.rows if r.label == ORACLE_LABEL), None)


def _by(records: Sequence[CellResult], label: str, scenario: str) -> list[CellResult]:
    return [r for r in records if r.diagnoser == label and r.scenario == scenario]


def _reasons(records: Sequence[CellResult]) -> tuple[tuple[str, int], ...]:
    counts: dict[str, int] = {}
    for r in records:
        if r.terminated_at is not None:
            reason = r.termination_reason or "unknown"
            counts[reason] = counts.get(reason, 0) + 1
    return tuple(sorted(counts.items()))


def track_rows(
    records: Sequence[CellResult], labels: Sequence[str], faults: Sequence[str]
) -> list[TrackRow]:
    """The rows of a track table from per-seed records (pure; intervals seeded, reproducible)."""
    rows = []
    # the reference rows present in the records, in REFERENCE_LABELS order
    present = {x.diagnoser for x in records}
    refs = [r for r in REFERENCE_LABELS.values() if r in present]
    for label in [*labels, *refs]:
        healthy = _by(records, label, "nominal")
        w = worst(healthy)
        cells = {}
        for f in faults:
            recs = [r for r in _by(records, label, f) if r.n_fault_samples > 0]
            orc = {r.seed: r for r in _by(records, ORACLE_LABEL, f) if r.n_fault_samples > 0}
            pairs = [(r.t_dt, orc[r.seed].t_dt) for r in recs if r.seed in orc]
            cells[f] = FaultCell(
                r_td=bootstrap_ci([r.r_td for r in recs]),
                t_dt=bootstrap_ci([r.t_dt for r in recs]),
                ratio=limit_ratio_ci([p[0] for p in pairs], [p[1] for p in pairs]),
                misses=sum(r.missed for r in recs),
                terminated=sum(r.terminated_at is not None for r in _by(records, label, f)),
                n=len(recs),
                ended_reasons=_reasons(_by(records, label, f)),
            )
        rows.append(
            TrackRow(
                label=label,
                r_fd=bootstrap_ci([r.r_fd for r in healthy]),
                alarmed_share=share_with_alarm(healthy),
                worst_r_fd=w.r_fd,
                worst_seed=w.seed,
                faults=cells,
            )
        )
    for f in faults:
        ranks = rank_with_ties([row.faults[f].r_td for row in rows], lower_is_better=False)
        for row, rank in zip(rows, ranks, strict=True):
            row.faults[f] = FaultCell(**{**row.faults[f].__dict__, "rank": rank})
    return rows


def _ci(iv: Interval, digits: int) -> str:
    if not math.isfinite(iv.estimate):
        return "–"
    return f"{iv.estimate:.{digits}f} [{iv.low:.{digits}f}, {iv.high:.{digits}f}]"


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
        f"{t_dt_text(sample_time_s)}; t_dt/oracle: (t_dt + 1) / (oracle t_dt + 1) [-] over the "
        "seeds both detected, 1 = as fast as the physical limit; missed/ended: faulty episodes "
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


def track_table(run: TrackRun) -> str:
    """Markdown table of a track (header sentences, legend, rows)."""
    faults = run.track.faults
    head = ["diagnoser", "r_fd [95 % CI]", "healthy eps. alarmed", "worst r_fd (seed)"]
    for f in faults:
        head += [f"{f} r_td (rank)", f"{f} t_dt", f"{f} t_dt/oracle", f"{f} missed/ended"]
    lines = [
        f"## Track `{run.track.name}`",
        "",
        run.track.description,
        "",
        _seed_line(run.track),
        "",
        track_legend(run.records[0].sample_time_s if run.records else None),
        "",
        "| " + " | ".join(head) + " |",
        "|" + "---|" * len(head),
    ]
    for row in run.rows:
        cells = [
            row.label,
            _ci(row.r_fd, 4),
            f"{row.alarmed_share:.2f}",
            f"{row.worst_r_fd:.4f} ({row.worst_seed})",
        ]
        for f in faults:
            c = row.faults[f]
            cells += [
                f"{_ci(c.r_td, 3)} ({c.rank})",
                _ci(c.t_dt, 0),
                _ci(c.ratio, 2),
                f"{c.misses}/{c.terminated}"
                + "".join(f" {reason}×{n}" for reason, n in c.ended_reasons),
            ]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def run_track(
    track: Track,
    diagnosers: Sequence[str],
    out: Path,
    *,
    backend: str = "local",
    workers: int | None = None,
    ray_address: str | None = None,
    progress: bool = True,
    figures: bool = True,
    model_cache: Path | None = None,
    imports: Sequence[str] = (),
) -> TrackRun:
    """Sweep ``diagnosers`` over ``track`` and add the physical-limit row (resumable).

    ``model_cache``: a directory of trained models shared by tracks; a track whose training
    episodes equal another's (:meth:`TrackData.training_key`: same seeds, noise and plant
    variation) reuses that track's models instead of training again. ``imports``: modules
    that register diagnosers of your own (:attr:`SweepConfig.imports`).
    """
    from evaluation.outputs import figure_cells, write_figures

    t0 = time.perf_counter()
    data = TrackData(track=track)
    import_modules(imports)
    config = SweepConfig(diagnosers=default_specs(diagnosers), data=data, imports=tuple(imports))
    config.validate()
    for reference in DEFAULT_REFERENCES:  # refuse seed clashes before any work, not after it
        reference.calibration_seeds(track)
    store = out / "store" / canonical_hash(data.store_key())[:12]
    n_reused_models = 0
    if model_cache is not None:
        n_reused_models = _models_from_cache(config, store, model_cache)
    results = run_sweep(
        config,
        store,
        backend=backend,
        n_workers=workers,
        ray_address=ray_address,
        progress=progress,
        figure_cells=figure_cells(config) if figures else (),
    )
    if model_cache is not None:
        _models_to_cache(config, store, model_cache)
    records = (*results.records, *reference_records(data, DEFAULT_REFERENCES))
    rows = track_rows(records, [s.key for s in config.diagnosers], track.faults)
    if figures:
        write_figures(results, out / "figures")
    return TrackRun(
        track=track,
        records=records,
        rows=tuple(rows),
        wall_s=time.perf_counter() - t0,
        n_computed=results.n_computed,
        n_reused=results.n_reused,
        n_trained=results.n_trained,
        n_reused_models=n_reused_models,
    )


def _cache_dir(config: SweepConfig, spec: DiagnoserSpec, cache: Path) -> Path:
    data = config.data
    assert isinstance(data, TrackData)
    # model_hash with a constant data part: the package version and the resolved settings
    key = {"training": data.training_key(), "model": config.model_hash(spec, "training-key")}
    if spec.build().isolates:  # it also learns the track's labelled faults
        key["faults"] = data.fault_training_key()
    return cache / spec.key / canonical_hash(key)[:16]


def _models_from_cache(config: SweepConfig, store_dir: Path, cache: Path) -> int:
    """Copy cached models of an equal training set into the track's store; how many."""
    store = ResultStore.open(store_dir, config.data.store_key())
    n = 0
    for spec in config.diagnosers:
        mhash = config.model_hash(spec, store.data_hash)
        src = _cache_dir(config, spec, cache)
        if not store.has_model(spec.key, mhash) and (src / "model").is_dir():
            files = dir_files(src / "model")
            store.write_model(spec.key, mhash, files, {**spec.to_json(), "from_cache": str(src)})
            n += 1
    return n


def _models_to_cache(config: SweepConfig, store_dir: Path, cache: Path) -> None:
    """Offer the track's trained models to the cache (atomic: a renamed temporary copy)."""
    store = ResultStore.open(store_dir, config.data.store_key())
    for spec in config.diagnosers:
        dst = _cache_dir(config, spec, cache)
        if (dst / "model").is_dir():
            continue
        dst.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(dir=dst, prefix=".model.", suffix=".tmp"))
        shutil.copytree(store.model_dir(spec.key), tmp, dirs_exist_ok=True, ignore=_spec_json)
        try:
            os.rename(tmp, dst / "model")
        except OSError:  # another run cached it first
            shutil.rmtree(tmp, ignore_errors=True)


def _spec_json(directory: str, names: list[str]) -> list[str]:
    return ["spec.json"] if "spec.json" in names else []


def _flat(row: TrackRow, track: str) -> dict[str, Any]:
    d: dict[str, Any] = {
        "track": track,
        "diagnoser": row.label,
        "r_fd": row.r_fd.estimate,
        "r_fd_low": row.r_fd.low,
        "r_fd_high": row.r_fd.high,
        "healthy_alarmed_share": row.alarmed_share,
        "worst_r_fd": row.worst_r_fd,
        "worst_seed": row.worst_seed,
    }
    for f, c in row.faults.items():
        for name, iv in (("r_td", c.r_td), ("t_dt", c.t_dt), ("t_dt_over_oracle", c.ratio)):
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
    (``""`` when no diagnoser of the run isolates). Definitions: :mod:`evaluation.isolation`."""
    from evaluation.isolation import MISSED, confusion_matrix

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
            recs = [r for r in _by(run.records, label, f) if r.n_fault_samples > 0]
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
    from evaluation.isolation import MISSED, confusion_matrix
    from evaluation.isolation_study import confusion_figure

    paths = []
    for label in isolation_labels(run.records):
        recs = [
            r for f in run.track.faults for r in _by(run.records, label, f) if r.n_fault_samples > 0
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
        atomic_write(out / "leaderboard.md", track_table(run) + isolation_table(run)),
        write_csv(out / "leaderboard.csv", [_flat(r, name) for r in run.rows]),
        atomic_write_json(
            out / "leaderboard.json",
            {"track": run.track.to_json(), "rows": [r.to_json() for r in run.rows]},
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
        + ".",
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
