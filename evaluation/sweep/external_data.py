"""External (measured or third-party) data as a sweep data source: a directory of CSV/Parquet files.

Each file is one record (an episode). The user says which columns are the channels (split into
``inputs`` and ``outputs``), which files are healthy training runs, and for each test file where
its fault starts (``None`` for a healthy test run, which is scored for false alarms only).
:class:`ExternalData` implements the harness's ``DataSource`` protocol, so
``run_sweep(SweepConfig(diagnosers=..., data=ExternalData(...)), store)`` trains on the healthy
files and scores the fault files exactly like simulated scenarios (one "seed", 0, per file, or
one per episode of a multi-episode file).

CSV files either have a header row (``column_names=None``) or are headerless with
``column_names`` naming every column in order. A file with an ``episode`` column (the project's own
``python -m fcc_env.generate`` files stack several episodes that way) holds several records: each
episode is its own training episode, or its own test cell (scenario = the file's name, seed = the
episode number; the file's onset applies within each episode). ``episode_column`` names that
column (``None``: every file is one record). Parquet files need ``pyarrow`` (not a dependency of
this package); without it loading one raises an ``ImportError`` that says so.

A directory is described by a ``dataset.json`` manifest or, for the third-party FCCU data set of
Santander et al. (2022), by a ready-made description: :mod:`evaluation.sweep.dataset_loaders`.
"""

from __future__ import annotations

import dataclasses
import hashlib
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from diagnosers.episode.record import Episode
from diagnosers.episode.units import units_for
from evaluation.sweep.sources import DataDescription, LoadedEpisode
from evaluation.sweep.store import check_name
from fcc_common.io import read_csv_columns, read_header, read_parquet_columns

__all__ = ["SUFFIXES", "ExternalData", "ExternalFile", "read_table"]

SUFFIXES: tuple[str, ...] = (".csv", ".parquet", ".pq")


@dataclass(frozen=True)
class ExternalFile:
    """One file of an external data set.

    Args:
        path: file name relative to the data directory; it must stay inside the directory
            after resolving ``..`` and symbolic links.
        onset: fault onset sample (0-based row index), ``None`` for a healthy record.
        name: scenario name in results (default: the file stem); letters, digits, ``._+-``.
        onset_assumed: the onset is the user's assumption, not stated by the data (e.g. the
            Santander data set's): tables and figures say so, since ``r_td`` and ``t_dt``
            count from it.
    """

    path: str
    onset: int | None = None
    name: str | None = None
    onset_assumed: bool = False

    @property
    def key(self) -> str:
        return self.name if self.name is not None else Path(self.path).stem


def _is_parquet(path: Path) -> bool:
    return path.suffix.lower() in (".parquet", ".pq")


def read_table(
    path: str | Path,
    columns: Sequence[str],
    *,
    column_names: Sequence[str] | None = None,
    delimiter: str = ",",
) -> np.ndarray:
    """Read ``columns`` of one CSV or Parquet file as a float array ``(n_rows, len(columns))``.

    Args:
        path: the file (``.csv``, ``.parquet`` or ``.pq``).
        columns: the columns wanted, by name, in this order.
        column_names: names of all columns of a headerless CSV, in order; ``None`` reads the
            names from the CSV's first row (ignored for Parquet, which names its columns).
        delimiter: CSV field separator.

    Raises:
        ValueError: unreadable file, unknown column (the message lists the available ones),
            non-numeric or missing values.
        ImportError: a Parquet file without ``pyarrow`` installed.
    """
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"{path} does not exist or is not a file")
    if _is_parquet(path):
        _, data = read_parquet_columns(path, list(columns))
    else:
        if path.suffix.lower() != ".csv":
            raise ValueError(f"{path}: unsupported file type {path.suffix!r}. Allowed: {SUFFIXES}")
        _, data = read_csv_columns(
            path, list(columns), column_names=column_names, delimiter=delimiter
        )
    if data.shape[0] == 0:
        raise ValueError(f"{path} has no data rows")
    bad = ~np.isfinite(data)
    if bad.any():
        row, col = np.argwhere(bad)[0]
        raise ValueError(
            f"{path}: column {columns[col]!r} has a missing or non-finite value at data row "
            f"{row} ({int(bad.sum())} in all); clean or drop those samples first"
        )
    return data


def _file_digest(path: Path) -> str:
    with path.open("rb") as fh:
        return hashlib.file_digest(fh, "sha256").hexdigest()


@dataclass(frozen=True, kw_only=True)
class ExternalData:
    """A directory of CSV/Parquet records as a sweep data source (see the module doc).

    Args:
        directory: the data directory.
        inputs: channel (column) names that are inputs (exogenous or manipulated variables).
        outputs: channel names that are measured outputs. The episode's channels are
            ``inputs + outputs``, in this order; other columns are ignored.
        train_files: healthy records to train on.
        test_files: records to score; each with its fault onset (``None`` = healthy).
        column_names: names of all columns, in order, for headerless CSVs; ``None`` = header row.
        sample_time_s: sample period [s].
        delimiter: CSV field separator.
        episode_column: the column that tells a file's stacked episodes apart (used when a file
            has it and it is not a channel); ``None``: every file is one record.
        units: ``{column: unit}`` as the data state them (e.g. ``{"Tr": "degF"}``); a channel
            without an entry has an unknown unit and is labelled without one. Presentation
            only: the episodes carry them to figures and tables.

    Each test file is one cell per diagnoser, with scenario ``ExternalFile.key`` and seed 0; a
    test file with several episodes is one cell per episode, seed = the episode number. The
    store hash includes every field (``episode_column`` too, so stores written before files were
    split are not resumed with split episodes) but the presentation-only ``units`` and
    ``onset_assumed``, and the SHA-256 of every file, so changed data are never mixed with
    stored results.
    """

    directory: str
    inputs: tuple[str, ...]
    outputs: tuple[str, ...]
    train_files: tuple[str, ...]
    test_files: tuple[ExternalFile, ...]
    column_names: tuple[str, ...] | None = None
    sample_time_s: float = 1.0
    delimiter: str = ","
    episode_column: str | None = "episode"
    units: Mapping[str, str] | None = field(default=None, hash=False)  # a dict is unhashable

    @property
    def channels(self) -> tuple[str, ...]:
        return tuple(self.inputs) + tuple(self.outputs)

    @property
    def channel_units(self) -> tuple[str, ...] | None:
        """The unit of each channel (``""`` where unknown); ``None`` when no unit is known."""
        return units_for(self.channels, self.units, f"{self.directory}: units")

    @property
    def assumed_onsets(self) -> tuple[str, ...]:
        """The scenarios (test file keys) whose fault onset is assumed, not stated by the data."""
        return tuple(tf.key for tf in self.test_files if tf.onset_assumed and tf.onset is not None)

    def _path(self, name: str) -> Path:
        """The data file ``name`` (relative to the directory), resolved through symbolic links.

        Raises ValueError when it lies outside the data directory (an absolute path, ``..``,
        or a link that leads out): a manifest never makes the harness read, train on or echo
        a file elsewhere."""
        root = Path(self.directory).resolve()
        p = (root / name).resolve()
        if not p.is_relative_to(root):
            raise ValueError(
                f"data file {name!r} is outside the allowed range: a file inside the data "
                f"directory {str(root)!r} (it resolves to {str(p)!r}); copy it into the directory"
            )
        return p

    def validate(self) -> None:
        d = Path(self.directory)
        if not d.is_dir():
            raise ValueError(f"data directory {str(d)!r} does not exist or is not a directory")
        for field_name in ("inputs", "outputs", "train_files"):
            v = getattr(self, field_name)
            if isinstance(v, str) or not isinstance(v, Sequence):
                raise ValueError(f"{field_name}={v!r} must be a sequence of names, not {type(v)}")
        if not self.outputs:
            raise ValueError("outputs must name at least one column")
        if len(set(self.channels)) != len(self.channels):
            raise ValueError(
                f"inputs {list(self.inputs)} and outputs {list(self.outputs)} must be distinct "
                "column names"
            )
        if not self.train_files:
            raise ValueError("train_files must name at least one healthy record")
        if not self.test_files:
            raise ValueError("test_files must name at least one record to score")
        for tf in self.test_files:
            if not isinstance(tf, ExternalFile):
                raise ValueError(f"test_files must hold ExternalFile objects, got {tf!r}")
            check_name("test file name", tf.key)
            if tf.onset is not None and (
                isinstance(tf.onset, bool) or not isinstance(tf.onset, int) or tf.onset < 0
            ):
                raise ValueError(f"{tf.path}: onset={tf.onset!r} must be an integer >= 0 or None")
            if not isinstance(tf.onset_assumed, bool) or (tf.onset_assumed and tf.onset is None):
                raise ValueError(
                    f"{tf.path}: onset_assumed={tf.onset_assumed!r} is outside the allowed range: "
                    "true or false, and true only for a record with an onset"
                )
        keys = [tf.key for tf in self.test_files]
        if len(set(keys)) != len(keys):
            raise ValueError(f"test file names {keys} repeat; give ExternalFile(name=...)")
        # resolved paths: "../d/a.csv", "./a.csv" and a link to a.csv are all a.csv
        overlap = sorted(
            {str(self._path(f)) for f in self.train_files}
            & {str(self._path(tf.path)) for tf in self.test_files}
        )
        if overlap:
            raise ValueError(
                f"files {overlap} are both training and test records; a diagnoser must not be "
                "scored on the data it was trained on"
            )
        for f in [*self.train_files, *(tf.path for tf in self.test_files)]:
            p = self._path(f)
            if not p.is_file():
                raise ValueError(f"data file {str(p)!r} does not exist")
            if p.suffix.lower() not in SUFFIXES:
                raise ValueError(f"{p}: unsupported file type {p.suffix!r}. Allowed: {SUFFIXES}")
        if not (
            isinstance(self.sample_time_s, int | float)
            and math.isfinite(self.sample_time_s)
            and self.sample_time_s > 0
        ):
            raise ValueError(f"sample_time_s={self.sample_time_s!r} must be a positive number")
        if not isinstance(self.delimiter, str) or len(self.delimiter) != 1:
            raise ValueError(
                f"delimiter={self.delimiter!r} is outside the allowed range: one character, "
                'e.g. "," or ";"'
            )
        if self.units is not None and not (
            isinstance(self.units, Mapping)
            and all(isinstance(k, str) and isinstance(v, str) for k, v in self.units.items())
        ):
            raise ValueError(
                f"units={self.units!r} is outside the allowed range: a mapping of column names "
                'to unit strings, e.g. {"Tr": "degF"}, or None'
            )

    def store_key(self) -> dict[str, Any]:
        key = dataclasses.asdict(self)
        # units and assumed onsets change no result: left out, stores written before they
        # existed stay readable and a relabelled onset reuses its cells
        del key["units"]
        for tf in key["test_files"]:
            del tf["onset_assumed"]
        key["directory"] = str(Path(self.directory).resolve())
        key["kind"] = "external"
        key["sha256"] = {
            f: _file_digest(self._path(f))
            for f in [*self.train_files, *(tf.path for tf in self.test_files)]
        }
        return key

    def describe(self) -> DataDescription:
        lines = [
            "External records: one test file per scenario (seed 0, or one seed per episode "
            "of a multi-episode file); see results.json."
        ]
        assumed = [tf for tf in self.test_files if tf.key in self.assumed_onsets]
        if assumed:
            at = ", ".join(f"{tf.key} (sample {tf.onset})" for tf in assumed)
            lines.append(
                f"Assumed fault onsets, not stated by the data: {at}; r_td and t_dt count from "
                'them (marked † in the tables, "(assumed)" in the figures).'
            )
        return DataDescription(label=f"external:{Path(self.directory).name}", lines=tuple(lines))

    def _episode_key(self, path: Path) -> str | None:
        """The episode column of ``path`` if it has one (and it is not a channel)."""
        col = self.episode_column
        if col is None or col in self.channels:
            return None
        names = self.column_names or read_header(path, delimiter=self.delimiter)
        return col if col in names else None

    def _episodes_of(self, path: Path) -> list[int]:
        key = self._episode_key(path)
        if key is None:
            return [0]
        ids = read_table(path, (key,), column_names=self.column_names, delimiter=self.delimiter)
        return _episode_ids(path, ids[:, 0])

    def cells(self) -> list[tuple[str, int]]:
        return [
            (tf.key, e) for tf in self.test_files for e in self._episodes_of(self._path(tf.path))
        ]

    def _load(self, file: str, onset: int | None, name: str) -> list[Episode]:
        """The episodes of one file (one, or one per value of its episode column)."""
        path = self._path(file)
        key = self._episode_key(path)
        cols = self.channels if key is None else (*self.channels, key)
        table = read_table(path, cols, column_names=self.column_names, delimiter=self.delimiter)
        if key is None:
            parts = [(0, table)]
        else:
            ids = table[:, -1]
            parts = [(e, table[ids == e, :-1]) for e in _episode_ids(path, ids)]
        out = []
        for e, y in parts:
            where = str(path) if key is None else f"{path} episode {e}"
            if onset is not None and onset >= y.shape[0]:
                raise ValueError(
                    f"{where}: fault onset {onset} is beyond the record's {y.shape[0]} samples"
                )
            out.append(
                Episode(
                    y=y,
                    channels=self.channels,
                    sample_time_s=float(self.sample_time_s),
                    fault_onset=onset,
                    scenario=name,
                    seed=e,
                    units=self.channel_units,
                )
            )
        return out

    def train_episodes(self) -> list[Episode]:
        return [ep for f in self.train_files for ep in self._load(f, None, Path(f).stem)]

    def load_test(self, scenario: str, seed: int) -> LoadedEpisode:
        for tf in self.test_files:
            if tf.key == scenario:
                eps = {ep.seed: ep for ep in self._load(tf.path, tf.onset, tf.key)}
                if seed not in eps:
                    raise ValueError(
                        f"test record {scenario!r} ({tf.path}) has no episode {seed}. "
                        f"Available: {sorted(eps)}"
                    )
                ep = eps[seed]
                return LoadedEpisode(
                    episode=ep, fault_onset=tf.onset, n_samples_planned=ep.n_samples
                )
        raise ValueError(
            f"Unknown test record {scenario!r}. Available: {[tf.key for tf in self.test_files]}"
        )


def _episode_ids(path: Path, ids: np.ndarray) -> list[int]:
    """The distinct episode numbers of a column, in file order; each must be a whole number."""
    bad = ids != np.round(ids)
    if bad.any():
        raise ValueError(
            f"{path}: episode column value {ids[bad][0]!r} (data row {int(np.argmax(bad))}) is not "
            "a whole number"
        )
    return [int(v) for v in dict.fromkeys(ids.tolist())]
