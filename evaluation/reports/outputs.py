"""What a leaderboard run writes: its tables as Markdown and CSV, the raw per-seed cells, and the
figures. Presentation only: every figure and table here is read from a finished sweep
(:class:`evaluation.sweep.SweepResults`) and its store; nothing is computed that the sweep did
not already score.

Every file is written atomically (:mod:`fcc_common.io`): a killed run never leaves half a table.

What the data say of themselves is taken from the data source when the files are written, not
from the store: the units of the channels (figure axes) and which fault onsets are assumed
rather than stated (:func:`marked_results`), so results stored before either existed are
labelled as the data are described now.
"""

from __future__ import annotations

import csv
import dataclasses
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from diagnosers.episode.record import Episode
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
from evaluation.sweep.records import CellResult, mark_assumed_onsets, unpack_detection
from evaluation.sweep.store import ResultStore
from fcc_common.io import atomic_open, atomic_write, atomic_write_json
from fcc_env import MODEL_VERSION, __version__

__all__ = [
    "assumed_onsets",
    "figure_cells",
    "marked_results",
    "package_version",
    "write_csv",
    "write_figures",
    "write_outputs",
]


def package_version() -> str:
    """The package's and the plant model's versions, as every results file records them."""
    return f"{__version__} ({MODEL_VERSION})"


def assumed_onsets(data: object) -> tuple[str, ...]:
    """The scenarios of a data source whose fault onset is assumed, not stated by the data
    (:attr:`ExternalData.assumed_onsets`); none for a source that does not say (simulated
    data know their onsets)."""
    return tuple(getattr(data, "assumed_onsets", ()))


def marked_results(results: SweepResults) -> SweepResults:
    """``results`` with each record's ``onset_assumed`` as its data source says now
    (:func:`~evaluation.sweep.records.mark_assumed_onsets`), so tables and files mark them."""
    records = mark_assumed_onsets(results.records, assumed_onsets(results.config.data))
    return dataclasses.replace(results, records=tuple(records))


def _with_source_units(episode: Episode, data: object) -> Episode:
    """``episode`` with the data source's channel units when it was stored without them."""
    units = getattr(data, "channel_units", None)
    channels = getattr(data, "channels", None)
    if episode.units is not None or units is None or tuple(channels or ()) != episode.channels:
        return episode
    return dataclasses.replace(episode, units=tuple(units))


def write_outputs(results: SweepResults, out: Path, *, figures: bool = True) -> list[Path]:
    """Write the table, CSVs, raw results and figures of ``results`` into ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    results = marked_results(results)
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
    assumed = assumed_onsets(cfg.data)
    paths = []
    for sc, seed in figure_cells(cfg):
        for spec in cfg.diagnosers:
            arrays = store.read_detection(spec.key, sc, seed, cfg.cell_hash(spec, store.data_hash))
            if arrays is None:
                continue
            episode, onset, detection, bands = unpack_detection(arrays)
            episode = _with_source_units(episode, cfg.data)
            onset = onset if episode.fault_onset is not None else None
            fig = detection_figure(
                episode,
                detection,
                title=f"{spec.key} on {sc}, seed {seed}",
                fault_onset=onset,
                onset_assumed=sc in assumed,
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
                    onset_assumed=sc in assumed,
                )
                paths.append(save_png(fig, directory / sc / f"{spec.key}-bands.png"))
    return paths
