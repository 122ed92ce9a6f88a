"""What the control study shows: its table, its files and its figures.

* :func:`summary_table`: the Markdown table the command prints (one row per policy);
* :func:`write_study`: ``control.csv`` (one row per episode), ``control.json`` (the summaries
  and the episodes) and one figure per fault (:func:`evaluation.control.figures.episode_figure`)
  into a directory.

It computes nothing: the numbers are :func:`evaluation.control.returns.study`'s.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import asdict
from pathlib import Path
from typing import Any

from evaluation.control.figures import episode_figure
from evaluation.control.returns import EpisodeScore, PolicySummary, StudyResults
from evaluation.metrics.intervals import Interval
from fcc_common.io import atomic_write, atomic_write_json
from fcc_env.plant import PlantConfig

__all__ = ["episodes_csv", "summary_table", "write_study"]


def summary_table(summaries: Sequence[PolicySummary]) -> str:
    """One Markdown row per policy: return, trips, time in constraint regions, loss."""

    def ci(i: Interval) -> str:
        return f"{i.estimate:,.0f} [{i.low:,.0f}, {i.high:,.0f}]"

    lines = [
        "| policy | return per episode [USD] | trips per 100 episodes | time in constraint "
        "regions | loss against the oracle [USD] |",
        "|---|---|---|---|---|",
    ]
    for s in summaries:
        lines.append(
            f"| {s.policy} | {ci(s.return_usd)} | {s.trips_per_100:.1f} | "
            f"{100 * s.constraint_share:.2f} % | {ci(s.loss_vs_oracle_usd)} |"
        )
    return "\n".join(lines) + "\n"


def episodes_csv(scores: Sequence[EpisodeScore]) -> str:
    """The episodes as CSV: a header of :class:`EpisodeScore`'s fields, one row each."""
    rows = [asdict(s) for s in scores]
    header = ",".join(rows[0])
    body = "\n".join(",".join(str(v) for v in r.values()) for r in rows)
    return header + "\n" + body + "\n"


def write_study(
    results: StudyResults,
    traces: Mapping[str, Mapping[str, Mapping[str, Sequence[Any]]]],
    out: Path,
    *,
    trace_seed: int = 0,
) -> list[Path]:
    """Write ``control.csv``, ``control.json`` and ``episode_<fault>.png`` (one per entry of
    ``traces``, :func:`evaluation.control.returns.fault_traces` on test seed ``trace_seed``)
    into ``out``; returns the figures' paths."""
    out.mkdir(parents=True, exist_ok=True)
    atomic_write(out / "control.csv", episodes_csv(results.scores))
    atomic_write_json(
        out / "control.json",
        {
            "summaries": [asdict(s) for s in results.summaries],
            "episodes": [asdict(s) for s in results.scores],
        },
    )
    return [
        episode_figure(
            by_policy,
            PlantConfig().sample_time_s,  # the registered env's
            out / f"episode_{scenario}.png",
            title=f"FCC-control-v0, {scenario} at the paper's size and onset, test seed "
            f"{trace_seed}",
        )
        for scenario, by_policy in traces.items()
    ]
