"""What a leaderboard run writes: its tables as Markdown and CSV, the raw per-seed cells, and the
figures. Presentation only: every figure and table here is read from a finished sweep
(:class:`evaluation.sweep.SweepResults`) and its store; nothing is computed that the sweep did
not already score.

Every file is written atomically (:mod:`fcc_common.io`): a killed run never leaves half a table.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from evaluation.reports.plots import detection_figure, save_png
from evaluation.reports.tables import (
    SUMMARY_COLUMNS,
    data_label,
    header_text,
    markdown_table,
    reference_row,
    summary_rows,
)
from evaluation.sweep.config import SweepConfig, SweepResults
from evaluation.sweep.records import CellResult, unpack_detection
from evaluation.sweep.store import ResultStore
from fcc_common.io import atomic_open, atomic_write, atomic_write_json
from fcc_env import MODEL_VERSION, __version__

__all__ = ["figure_cells", "package_version", "write_csv", "write_figures", "write_outputs"]


def package_version() -> str:
    """The package's and the plant model's versions, as every results file records them."""
    return f"{__version__} ({MODEL_VERSION})"


def write_outputs(results: SweepResults, out: Path, *, figures: bool = True) -> list[Path]:
    """Write the table, CSVs, raw results and figures of ``results`` into ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    summaries = results.summary()
    reference = reference_row(results.config)
    md = header_text(results) + markdown_table(summaries, reference=reference)
    written = [atomic_write(out / "leaderboard.md", md)]
    version = package_version()
    rows = summary_rows(summaries, data=data_label(results.config), version=version)
    written.append(
        write_csv(out / "leaderboard.csv", rows, [*SUMMARY_COLUMNS, "data", "package_version"])
    )
    records = [r.to_json() for r in results.records]
    written.append(write_csv(out / "results.csv", records, list(CellResult.__dataclass_fields__)))
    cfg = results.config
    payload = {
        "data": cfg.data.store_key(),
        "diagnosers": [s.to_json() for s in cfg.diagnosers],
        "cells": [list(c) for c in cfg.data.cells()],
        "t_on": cfg.t_on,
        "package_version": version,
        "records": records,
    }
    written.append(atomic_write_json(out / "results.json", payload, indent=1))
    if figures:
        written += write_figures(results, out / "figures")
    return written


def _cell(v: Any) -> Any:
    """A CSV cell: a missing value (None or NaN) is an empty cell."""
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return ""
    return v


def write_csv(
    path: Path, rows: Sequence[Mapping[str, Any]], fields: Sequence[str] | None = None
) -> Path:
    """A CSV table of ``rows``, written atomically.

    ``fields``: the columns in order; by default every key of the rows, in the order they first
    appear. Missing values (None, NaN) are written as empty cells.
    """
    if fields is None:
        fields = list(dict.fromkeys(k for r in rows for k in r))
    with atomic_open(path, "w") as fh:
        w = csv.DictWriter(fh, fieldnames=list(fields), lineterminator="\r\n")
        w.writeheader()
        w.writerows({k: _cell(v) for k, v in r.items()} for r in rows)
    return path


def figure_cells(config: SweepConfig) -> list[tuple[str, int]]:
    """The cells drawn as figures: each scenario's first test seed."""
    first: dict[str, int] = {}
    for sc, seed in config.data.cells():
        first.setdefault(sc, seed)
    return list(first.items())


def write_figures(results: SweepResults, directory: Path) -> list[Path]:
    """One PNG per scenario × diagnoser on the scenario's first test seed.

    Diagnosers with a :meth:`~diagnosers.contract.DiagnoserContract.band_view` (``lrgf-mem``:
    one band per relation around its measured output) get a second one,
    ``<label>-bands.png``, whose strip shows the detector's alarms with the band exits as a
    separate row. The arrays come from the scoring pass (``run_sweep(figure_cells=...)`` keeps
    them in the store); a cell whose arrays are missing (a sweep run without figures) is
    skipped.
    """
    cfg = results.config
    store = ResultStore.open(results.store_dir, cfg.data.store_key())
    paths = []
    for sc, seed in figure_cells(cfg):
        for spec in cfg.diagnosers:
            arrays = store.read_detection(spec.key, sc, seed, cfg.cell_hash(spec, store.data_hash))
            if arrays is None:
                continue
            episode, onset, detection, bands = unpack_detection(arrays)
            onset = onset if episode.fault_onset is not None else None
            fig = detection_figure(
                episode, detection, title=f"{spec.key} on {sc}, seed {seed}", fault_onset=onset
            )
            paths.append(save_png(fig, directory / sc / f"{spec.key}.png"))
            if bands is not None:
                # the panels show the models' bands; shading and strip the detector's alarms,
                # the band exits a row of their own (they are not the detector's decision)
                fig = detection_figure(
                    episode,
                    bands,
                    title=f"{spec.key} on {sc}, seed {seed}: model bands",
                    fault_onset=onset,
                    decisions=detection,
                )
                paths.append(save_png(fig, directory / sc / f"{spec.key}-bands.png"))
    return paths
