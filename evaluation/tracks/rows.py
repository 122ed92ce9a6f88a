"""The rows of a track table: per diagnoser, intervals over the track's seeds (pure).

:func:`track_rows` turns per-seed records into :class:`TrackRow` objects (r_fd with its 95 %
interval, per fault r_td, t_dt, the delay with misses counted and the ratios to three
reference rows); a :class:`TrackRun` holds a finished track run. Presentation is in
:mod:`evaluation.tracks.board_tables`.

Matched false-alarm rates. A row *meets the r_fd goal* when the upper end of its r_fd interval on
the test episodes is at most :data:`~evaluation.tracks.oracle.GOAL_R_FD`
(:func:`meets_r_fd_goal`). Only registered detectors that meet it are ranked
(:func:`rank_rows`), each within its tier (:class:`diagnosers.Tier`: a grey-box detector knows
the published model, a black-box one only the records; :attr:`TrackRow.tier`); reference rows
are never ranked. A ratio is taken against a *yardstick*
(:func:`yardstick`): the physical-limit row for ``t_dt/oracle`` and the goal, the optimal CUSUM
row for ``t_dt/optimal``, the optimal filter row (the reachable bound) for ``t_dt/filter``,
or, where that row misses the goal on the test episodes, the next
reference row in :data:`~evaluation.tracks.oracle.REFERENCE_LABELS` order that meets it (none
when no reference row does: the ratio is then undefined).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from diagnosers.contract import Tier
from evaluation.metrics.detection_metrics import censored_delay
from evaluation.metrics.intervals import (
    UNRANKED,
    Interval,
    bootstrap_ci,
    limit_ratio_ci,
    rank_with_ties,
    share_with_alarm,
    worst,
)
from evaluation.sweep.records import CellResult
from evaluation.tracks.filter_bound import FILTER_LABEL
from evaluation.tracks.optimal import CUSUM_LABEL
from evaluation.tracks.oracle import GOAL_R_FD, ORACLE_LABEL, REFERENCE_LABELS
from evaluation.tracks.track import Track

__all__ = [
    "REFERENCE_TIER",
    "FaultCell",
    "TrackRow",
    "TrackRun",
    "is_reference",
    "meets_r_fd_goal",
    "rank_rows",
    "records_of",
    "track_rows",
    "yardstick",
]

_NO_VALUE = Interval(math.nan, math.nan, math.nan, 0)
#: The tier column's value on a reference row (it reads the true plant: no detector's tier).
REFERENCE_TIER = "reference"


def is_reference(label: str) -> bool:
    """Whether ``label`` is a reference row's (it reads what no detector may; never ranked)."""
    return label in REFERENCE_LABELS.values()


def meets_r_fd_goal(r_fd: Interval) -> bool:
    """Whether an r_fd interval over test episodes meets the track's false-alarm goal: its upper
    95 % end is finite and at most :data:`~evaluation.tracks.oracle.GOAL_R_FD`."""
    return math.isfinite(r_fd.high) and r_fd.high <= GOAL_R_FD


def yardstick(r_fd: dict[str, Interval], first: str) -> str | None:
    """The reference row a ratio or the goal is taken against: ``first`` when present in
    ``r_fd`` (label → its r_fd interval on the test episodes) and meeting the r_fd goal, else
    the next reference row (in :data:`REFERENCE_LABELS` order, from ``first`` on, wrapping
    round) that does; None when none does. A reference that alarms more than the goal allows
    detects faster for it, and would make every detector look slow.

    >>> ok, over = Interval(0.002, 0.001, 0.003, 20), Interval(0.009, 0.006, 0.014, 20)
    >>> yardstick({ORACLE_LABEL: over, CUSUM_LABEL: ok}, ORACLE_LABEL) == CUSUM_LABEL
    True
    """
    order = list(REFERENCE_LABELS.values())
    if first not in order:
        raise ValueError(f"first={first!r}; allowed: a reference row's label, one of {order}")
    i = order.index(first)
    for label in order[i:] + order[:i]:
        if label in r_fd and meets_r_fd_goal(r_fd[label]):
            return label
    return None


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
    #: mean over the seeds of min(t_dt, T − onset), a miss at T − onset (:func:`censored_delay`)
    delay: Interval = _NO_VALUE
    #: (t_dt + 1) / (yardstick t_dt + 1) against the optimal CUSUM row (or its stand-in)
    ratio_optimal: Interval = _NO_VALUE
    #: the same against the reachable bound, the optimal filter row (or its stand-in): a
    #: detector's gap to the best test of the exact model on the same readings
    ratio_filter: Interval = _NO_VALUE


@dataclass(frozen=True)
class TrackRow:
    """One row of a track table (a diagnoser, or a reference row)."""

    label: str
    r_fd: Interval
    alarmed_share: float
    worst_r_fd: float
    worst_seed: int
    faults: dict[str, FaultCell]
    #: what the row may know of the plant: a :class:`diagnosers.Tier` value, or
    #: :data:`REFERENCE_TIER`; ranks range within one tier
    tier: str = Tier.BLACK_BOX.value

    @property
    def reference(self) -> bool:
        """A reference row (:func:`is_reference`): shown, never ranked."""
        return is_reference(self.label)

    @property
    def meets_r_fd_goal(self) -> bool:
        """Its r_fd's upper 95 % end meets the track's goal (:func:`meets_r_fd_goal`)."""
        return meets_r_fd_goal(self.r_fd)

    def mean_r_td(self) -> float:
        v = [c.r_td.estimate for c in self.faults.values()]
        return float(np.nanmean(v)) if v else math.nan

    def mean_ratio(self) -> float:
        v = [c.ratio.estimate for c in self.faults.values() if math.isfinite(c.ratio.estimate)]
        return float(np.mean(v)) if v else math.nan

    def to_json(self) -> dict[str, Any]:
        return {
            "label": self.label,
            "tier": self.tier,
            "r_fd": self.r_fd.to_json(),
            "alarmed_share": self.alarmed_share,
            "worst_r_fd": self.worst_r_fd,
            "worst_seed": self.worst_seed,
            "reference": self.reference,
            "r_fd_meets_goal": self.meets_r_fd_goal,
            "faults": {
                f: {
                    "r_td": c.r_td.to_json(),
                    "t_dt": c.t_dt.to_json(),
                    "t_dt_over_oracle": c.ratio.to_json(),
                    "t_dt_over_optimal": c.ratio_optimal.to_json(),
                    "delay_censored": c.delay.to_json(),
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
        """The goal's yardstick: the physical-limit row, or where it misses the r_fd goal on the
        test episodes the next reference row that meets it (:func:`yardstick`); None when no
        reference row of the run meets it."""
        return self._row(yardstick({r.label: r.r_fd for r in self.rows}, ORACLE_LABEL))

    @property
    def optimal_row(self) -> TrackRow | None:
        """The yardstick of ``t_dt/optimal``: the optimal CUSUM row or its stand-in
        (:func:`yardstick`); None when no reference row of the run meets the r_fd goal."""
        return self._row(yardstick({r.label: r.r_fd for r in self.rows}, CUSUM_LABEL))

    @property
    def filter_row(self) -> TrackRow | None:
        """The yardstick of ``t_dt/filter``: the reachable-bound row or its stand-in
        (:func:`yardstick`); None when no reference row of the run meets the r_fd goal."""
        return self._row(yardstick({r.label: r.r_fd for r in self.rows}, FILTER_LABEL))

    def _row(self, label: str | None) -> TrackRow | None:
        return next((r for r in self.rows if r.label == label), None)


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
    records: Sequence[CellResult],
    labels: Sequence[str],
    faults: Sequence[str],
    tiers: Mapping[str, str] | None = None,
) -> list[TrackRow]:
    """The rows of a track table from per-seed records (pure; intervals seeded, reproducible):
    ``labels``' rows, then the reference rows present, ratios against the yardsticks
    (:func:`yardstick`), ranks by :func:`rank_rows`. ``tiers``: each label's tier (a
    :class:`diagnosers.Tier` value; a label not in it is a black box)."""
    rows = []
    # the reference rows present in the records, in REFERENCE_LABELS order
    present = {x.diagnoser for x in records}
    refs = [r for r in REFERENCE_LABELS.values() if r in present]
    r_fd = {
        label: bootstrap_ci([r.r_fd for r in records_of(records, label, "nominal")])
        for label in [*labels, *refs]
    }
    limit, optimal = yardstick(r_fd, ORACLE_LABEL), yardstick(r_fd, CUSUM_LABEL)
    bound = yardstick(r_fd, FILTER_LABEL)
    for label in [*labels, *refs]:
        healthy = records_of(records, label, "nominal")
        w = worst(healthy)
        cells = {}
        for f in faults:
            recs = [r for r in records_of(records, label, f) if r.n_fault_samples > 0]
            cells[f] = FaultCell(
                r_td=bootstrap_ci([r.r_td for r in recs]),
                t_dt=bootstrap_ci([r.t_dt for r in recs]),
                ratio=_ratio(recs, records, limit, f),
                misses=sum(r.missed for r in recs),
                terminated=sum(r.terminated_at is not None for r in records_of(records, label, f)),
                n=len(recs),
                ended_reasons=_reasons(records_of(records, label, f)),
                delay=bootstrap_ci([censored_delay(r.t_dt, r.n_fault_samples) for r in recs]),
                ratio_optimal=_ratio(recs, records, optimal, f),
                ratio_filter=_ratio(recs, records, bound, f),
            )
        rows.append(
            TrackRow(
                label=label,
                r_fd=r_fd[label],
                alarmed_share=share_with_alarm(healthy),
                worst_r_fd=w.r_fd,
                worst_seed=w.seed,
                faults=cells,
                tier=REFERENCE_TIER
                if is_reference(label)
                else str((tiers or {}).get(label, Tier.BLACK_BOX.value)),
            )
        )
    return rank_rows(rows, faults)


def _ratio(
    recs: Sequence[CellResult], records: Sequence[CellResult], reference: str | None, fault: str
) -> Interval:
    """The paired ratio of ``recs``' t_dt to ``reference``'s on the same seeds (none: NaN)."""
    if reference is None:
        return _NO_VALUE
    ref = {r.seed: r for r in records_of(records, reference, fault) if r.n_fault_samples > 0}
    pairs = [(r.t_dt, ref[r.seed].t_dt) for r in recs if r.seed in ref]
    return limit_ratio_ci([p[0] for p in pairs], [p[1] for p in pairs])


def rank_rows(rows: Sequence[TrackRow], faults: Sequence[str]) -> list[TrackRow]:
    """``rows`` with per-fault ranks on r_td (ties where intervals overlap,
    :func:`~evaluation.metrics.intervals.rank_with_ties`) among the registered detectors of one
    tier whose r_fd meets the goal (:func:`meets_r_fd_goal`); reference rows and detectors over the goal
    get :data:`~evaluation.metrics.intervals.UNRANKED`: a detector that alarms more than the
    goal allows buys its detection rate with false alarms, and a reference reads what no
    detector may."""
    out = [TrackRow(**{**row.__dict__, "faults": dict(row.faults)}) for row in rows]
    ranked = [row for row in out if not row.reference and row.meets_r_fd_goal]
    for f in faults:
        ranks: dict[int, str] = {}
        for tier in dict.fromkeys(row.tier for row in ranked):
            group = [row for row in ranked if row.tier == tier]
            tier_ranks = rank_with_ties(
                [row.faults[f].r_td for row in group], lower_is_better=False
            )
            ranks.update(zip((id(row) for row in group), tier_ranks, strict=True))
        for row in out:
            cell = row.faults[f]
            row.faults[f] = FaultCell(**{**cell.__dict__, "rank": ranks.get(id(row), UNRANKED)})
    return out
