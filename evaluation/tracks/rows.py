"""The rows of a track table: per diagnoser, intervals over the track's seeds (pure).

:func:`track_rows` turns per-seed records into :class:`TrackRow` objects (r_fd with its 95 %
interval, per fault r_td, t_dt and the ratio to the physical limit); a :class:`TrackRun` holds a
finished track run. Presentation is in :mod:`evaluation.tracks.board_tables`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from evaluation.metrics.intervals import (
    Interval,
    bootstrap_ci,
    limit_ratio_ci,
    rank_with_ties,
    share_with_alarm,
    worst,
)
from evaluation.sweep.records import CellResult
from evaluation.tracks.oracle import ORACLE_LABEL, REFERENCE_LABELS
from evaluation.tracks.track import Track

__all__ = ["FaultCell", "TrackRow", "TrackRun", "records_of", "track_rows"]


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


def records_of(records: Sequence[CellResult], label: str, scenario: str) -> list[CellResult]:
    """The records of diagnoser ``label`` on ``scenario``, in their order."""
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
        healthy = records_of(records, label, "nominal")
        w = worst(healthy)
        cells = {}
        for f in faults:
            recs = [r for r in records_of(records, label, f) if r.n_fault_samples > 0]
            orc = {r.seed: r for r in records_of(records, ORACLE_LABEL, f) if r.n_fault_samples > 0}
            pairs = [(r.t_dt, orc[r.seed].t_dt) for r in recs if r.seed in orc]
            cells[f] = FaultCell(
                r_td=bootstrap_ci([r.r_td for r in recs]),
                t_dt=bootstrap_ci([r.t_dt for r in recs]),
                ratio=limit_ratio_ci([p[0] for p in pairs], [p[1] for p in pairs]),
                misses=sum(r.missed for r in recs),
                terminated=sum(r.terminated_at is not None for r in records_of(records, label, f)),
                n=len(recs),
                ended_reasons=_reasons(records_of(records, label, f)),
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
