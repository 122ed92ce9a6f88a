"""Leaderboard tables (pure formatting, no I/O): the classic Markdown table, CSV rows, legends.

:func:`markdown_table` ranks diagnosers by mean r_td over faults minus r_fd; the paper's Table 2
(:data:`PAPER_TABLE2`) is a reference row beside the paper's own set-up only.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

from evaluation.sweep.config import SweepConfig, SweepResults
from evaluation.sweep.records import CellSummary

__all__ = [
    "ASSUMED_MARK",
    "PAPER_TABLE2",
    "SUMMARY_COLUMNS",
    "data_label",
    "header_text",
    "markdown_table",
    "reference_row",
    "sample_time",
    "summary_rows",
    "table_legend",
]

#: The seed paper's Table 2 (Patan et al., IFAC 2005; LRGF + model-error model): r_fd on healthy data, then per fault
#: (r_td, t_dt [samples]). No dispersion is published, so the reference row has none.
PAPER_TABLE2: dict[str, Any] = {
    "label": "paper Table 2 (LRGF+MEM)",
    "r_fd": 0.0881,
    "faults": {
        "f1": (0.6978, 250.0),
        "f2": (0.7184, 370.0),
        "f3": (0.6634, 80.0),
        "f4": (0.5294, 55.0),
    },
}


#: Marks the columns of a fault whose onset is assumed, not stated by the data (no Markdown
#: meaning, unlike ``*``).
ASSUMED_MARK = "†"


# ---- formatting -------------------------------------------------------------------------
def _fmt(mean: float, std: float, digits: int) -> str:
    if math.isnan(mean):
        return "–"
    s = f"{mean:.{digits}f}"
    return s + (f" ± {std:.{digits}f}" if not math.isnan(std) else "")


def _fmt_tdt(c: CellSummary) -> str:
    core = _fmt(c.t_dt, c.t_dt_std, 0)
    if c.misses:
        core += f" ({c.misses}/{c.n_seeds} missed)"
    return core


def _score(rows: Sequence[CellSummary]) -> float:
    """Primary ranking metric: mean r_td over faults minus mean r_fd over healthy scenarios."""
    td = [c.r_td for c in rows if c.faulty and not math.isnan(c.r_td)]
    fd = [c.r_fd for c in rows if not c.faulty and not math.isnan(c.r_fd)]
    if not td and not fd:
        return -math.inf
    return (sum(td) / len(td) if td else 0.0) - (sum(fd) / len(fd) if fd else 0.0)


def markdown_table(
    summaries: Sequence[CellSummary],
    *,
    reference: dict[str, Any] | None = None,
) -> str:
    """The leaderboard as a Markdown table (pure function of the summaries).

    Columns: for every healthy scenario ``r_fd``; for every fault scenario ``r_td`` and ``t_dt``
    [samples]. Rows are sorted by mean ``r_td`` over faults minus mean ``r_fd`` over healthy
    scenarios (higher is better). ``reference`` (e.g. :data:`PAPER_TABLE2`) adds a last row.
    A fault whose onset is assumed (:attr:`CellSummary.onset_assumed`) has its columns marked
    :data:`ASSUMED_MARK` (``table_legend(onset_assumed=True)`` says what it means).
    """
    scenarios: list[tuple[str, bool]] = []
    by_diag: dict[str, dict[str, CellSummary]] = {}
    assumed = {c.scenario for c in summaries if c.onset_assumed}
    for c in summaries:
        if (c.scenario, c.faulty) not in scenarios:
            scenarios.append((c.scenario, c.faulty))
        by_diag.setdefault(c.diagnoser, {})[c.scenario] = c
    header = ["diagnoser"]
    for sc, faulty in scenarios:
        name = sc + (ASSUMED_MARK if sc in assumed else "")
        header += [f"{name} r_td", f"{name} t_dt"] if faulty else [f"r_fd ({sc})"]
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join(["---"] * len(header)) + "|"]
    order = sorted(by_diag, key=lambda d: -_score(list(by_diag[d].values())))
    for diag in order:
        row = [diag]
        for sc, faulty in scenarios:
            c = by_diag[diag].get(sc)
            if c is None:
                row += ["", ""] if faulty else [""]
            elif faulty:
                row += [_fmt(c.r_td, c.r_td_std, 4), _fmt_tdt(c)]
            else:
                row.append(_fmt(c.r_fd, c.r_fd_std, 4))
        lines.append("| " + " | ".join(row) + " |")
    if reference is not None:
        row = [reference["label"]]
        for sc, faulty in scenarios:
            ref = reference["faults"].get(sc)
            if faulty:
                row += [f"{ref[0]:.4f}", f"{ref[1]:.0f}"] if ref else ["", ""]
            else:
                row.append(f"{reference['r_fd']:.4f}" if sc == "nominal" else "")
        lines.append("| " + " | ".join(row) + " |")
    return "\n".join(lines) + "\n"


SUMMARY_COLUMNS = (
    "diagnoser",
    "scenario",
    "n_seeds",
    "r_fd",
    "r_fd_std",
    "r_td",
    "r_td_std",
    "t_dt",
    "t_dt_std",
    "t_dt_s",
    "t_dt_s_std",
    "misses",
    "n_detected",
    "n_terminated",
    "onset_assumed",
)


def summary_rows(summaries: Sequence[CellSummary], *, data: str, version: str) -> list[dict]:
    """Rows of ``leaderboard.csv`` (NaN written as empty fields)."""
    rows = []
    for c in summaries:
        d = c.to_json()
        row = {
            k: ("" if isinstance(d[k], float) and math.isnan(d[k]) else d[k])
            for k in SUMMARY_COLUMNS
        }
        row.update(data=data, package_version=version)
        rows.append(row)
    return rows


def data_label(config: SweepConfig) -> str:
    return config.data.describe().label


def reference_row(config: SweepConfig) -> dict[str, Any] | None:
    """The paper's row, shown only beside the paper's own set-up."""
    return PAPER_TABLE2 if config.data.describe().paper_setup else None


#: The metrics' definitions, worded once for every table's legend.
R_FD_TEXT = (
    "r_fd: false detection rate, the share of a healthy episode's samples in alarm "
    "[0-1, lower is better]"
)
R_TD_TEXT = (
    "r_td: true detection rate, the share of the samples from the fault onset on in alarm "
    "[0-1, higher is better]"
)


def t_dt_text(sample_time_s: float | None) -> str:
    """The definition of t_dt, with what a sample is in seconds when known."""
    ts = f" (1 sample = {sample_time_s:g} s)" if sample_time_s else ""
    return (
        f"t_dt: detection time, from the onset to the first alarm [samples]{ts}, mean over the "
        "detected faults"
    )


#: What :data:`ASSUMED_MARK` means, worded once for every legend.
ASSUMED_TEXT = (
    f"{ASSUMED_MARK}: the fault onset is assumed, not stated by the data; r_td and t_dt count "
    "from the assumed onset."
)


def table_legend(sample_time_s: float | None = None, *, onset_assumed: bool = False) -> str:
    """What the table's columns, units and signs mean (one paragraph, Markdown).

    Args:
        sample_time_s: the data's sample time, to say what a sample of ``t_dt`` is in seconds
            (``None``: not said).
        onset_assumed: some fault's onset is assumed (its columns are marked
            :data:`ASSUMED_MARK`): the legend says what the mark means.
    """
    return (
        f"Legend: {R_FD_TEXT}; {R_TD_TEXT}; {t_dt_text(sample_time_s)}, '(k/n missed)': k of "
        "n faulty episodes never alarmed after the onset. a ± b: mean ± standard deviation over "
        "the test seeds (the spread of single episodes, not an interval for the mean); no ±: "
        "one seed, or the paper's published values; –: no value (e.g. no seed detected the "
        "fault)." + (f" {ASSUMED_TEXT}" if onset_assumed else "")
    )


def sample_time(results: SweepResults) -> float | None:
    return results.records[0].sample_time_s if results.records else None


def header_text(results: SweepResults) -> str:
    """What the table is about: data, seeds, the legend (metrics, units, ±), ranking."""
    description = results.config.data.describe()
    lines = [f"# Fault-detection leaderboard: {description.label}", "", *description.lines]
    assumed = any(r.onset_assumed for r in results.records)
    lines += [
        table_legend(sample_time(results), onset_assumed=assumed),
        "Rows are sorted by mean r_td over faults minus r_fd on healthy episodes.",
        "",
    ]
    return "\n".join(lines) + "\n"  # a blank line before the table, as Markdown needs
