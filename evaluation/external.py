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

The third-party FCCU data set of ``shared/data/fccu-santander-mlpse`` (Santander et al. 2022
simulator, MLforPSE CSVs) has a ready-made description, :func:`load_santander`; its onset
convention is documented there.
"""

from __future__ import annotations

import csv
import dataclasses
import hashlib
import json
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from diagnosers.base import Episode
from evaluation.sources import DataDescription, LoadedEpisode
from evaluation.store import check_name
from fcc_env.io import read_csv_columns, read_header, read_parquet_columns

__all__ = [
    "SANTANDER_ARX_PARAMS",
    "SANTANDER_ONSET",
    "SANTANDER_PARAMS",
    "ExternalData",
    "ExternalFile",
    "load_santander",
    "read_table",
]

SUFFIXES: tuple[str, ...] = (".csv", ".parquet", ".pq")

#: Fault onset (sample index, 1-minute samples) used for every fault file of the Santander data.
#: The data's README says the onsets are not stated. Evidence from the data themselves, not from
#: any diagnoser: in ``deltaP_increase_outputs.csv`` the noise-free channels ``P4`` and ``deltaP``
#: are constant and change for the first time at row index 120 (time column 121 min, i.e. 2 h),
#: and the 10-sample means of ``V6`` in ``CAB_valveLeak_outputs.csv`` start to rise right after
#: sample 120. Generated monitoring data sets introduce all faults at one time, so 120 is taken for
#: every fault file. For slow faults (fouling, drift) this makes detection times long but honest.
SANTANDER_ONSET = 120

#: ``arx-band`` hyperparameters for the Santander data (its defaults name FCC-v0 channels): the
#: riser temperature from feed temperature, regenerator temperature and regenerated-catalyst flow,
#: the analogue of the paper's relation (14) that the data's README suggests.
SANTANDER_ARX_PARAMS: dict[str, Any] = {"output": "Tr", "inputs": ["T2", "Treg", "Frgc"]}

#: Hyperparameters per diagnoser for the Santander data, wherever a default names FCC-v0
#: channels: the same riser relation for the LRGF detectors.
SANTANDER_PARAMS: dict[str, dict[str, Any]] = {
    "arx-band": SANTANDER_ARX_PARAMS,
    "lrgf-mem-paper": {"relations": [["Tr", ["T2", "Treg", "Frgc"]]]},
    "lrgf-mem": {"relations": [["Tr", ["T2", "Treg", "Frgc"]]]},
}

_SANTANDER_TRAIN = "NOC_varyingFeedFlow_outputs.csv"
_SANTANDER_HEALTHY_TEST = "NOC_stableFeedFlow_outputs.csv"
_SANTANDER_FAULTS = (
    "CAB_valveLeak_outputs.csv",
    "deltaP_increase_outputs.csv",
    "UAf_decrease_outputs.csv",
    "condEff_decrease_outputs.csv",
    "Fhn_sensorDrift_outputs.csv",
)


@dataclass(frozen=True)
class ExternalFile:
    """One file of an external data set.

    Args:
        path: file name relative to the data directory (or absolute).
        onset: fault onset sample (0-based row index), ``None`` for a healthy record.
        name: scenario name in results (default: the file stem); letters, digits, ``._+-``.
    """

    path: str
    onset: int | None = None
    name: str | None = None

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

    Each test file is one cell per diagnoser, with scenario ``ExternalFile.key`` and seed 0; a
    test file with several episodes is one cell per episode, seed = the episode number. The
    store hash includes every field (``episode_column`` too, so stores written before files were
    split are not resumed with split episodes) and the SHA-256 of every file, so changed data
    are never mixed with stored results.
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

    @property
    def channels(self) -> tuple[str, ...]:
        return tuple(self.inputs) + tuple(self.outputs)

    def _path(self, name: str) -> Path:
        p = Path(name)
        return p if p.is_absolute() else Path(self.directory) / p

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
        keys = [tf.key for tf in self.test_files]
        if len(set(keys)) != len(keys):
            raise ValueError(f"test file names {keys} repeat; give ExternalFile(name=...)")
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

    def store_key(self) -> dict[str, Any]:
        key = dataclasses.asdict(self)
        key["directory"] = str(Path(self.directory).resolve())
        key["kind"] = "external"
        key["sha256"] = {
            f: _file_digest(self._path(f))
            for f in [*self.train_files, *(tf.path for tf in self.test_files)]
        }
        return key

    def describe(self) -> DataDescription:
        return DataDescription(
            label=f"external:{Path(self.directory).name}",
            lines=(
                "External records: one test file per scenario (seed 0, or one seed per episode "
                "of a multi-episode file); see results.json.",
            ),
        )

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


def _santander_columns(directory: Path) -> list[tuple[str, str]]:
    """``(symbol, unit)`` of every CSV column, from the data set's ``columns.csv``."""
    spec = directory / "columns.csv"
    if not spec.is_file():
        raise ValueError(
            f"{directory} has no columns.csv, so it is not the Santander FCCU data set layout"
        )
    with spec.open(newline="") as fh:
        rows = list(csv.DictReader(fh))
    try:
        rows.sort(key=lambda r: int(r["col"]))
        return [(r["symbol"].strip(), r["unit"].strip()) for r in rows]
    except (KeyError, ValueError) as e:
        raise ValueError(f"{spec}: expected columns col,symbol,unit,description ({e})") from e


def load_santander(
    directory: str | Path,
    *,
    onset: int = SANTANDER_ONSET,
    outputs: Sequence[str] | None = None,
) -> ExternalData:
    """Describe the Santander et al. (2022) FCCU data set (MLforPSE CSVs) as :class:`ExternalData`.

    Choices (all fixed here, none tuned on a diagnoser's result):

    * **Training:** ``NOC_varyingFeedFlow`` (10080 healthy samples; the source notebooks' training
      set). **Healthy test:** ``NOC_stableFeedFlow`` (scored for false alarms, ``r_fd``).
      **Fault tests:** the five fault files, named by their stem without ``_outputs``.
    * **Onset:** :data:`SANTANDER_ONSET` (sample 120) for every fault file; see its comment for
      the evidence. Pass ``onset=`` to study another convention.
    * **Channels:** all 46 variables of ``columns.csv`` except the time column. Inputs are the
      fresh feed flow and temperatures set outside the unit (``F3``, ``Tatm``, ``T1``) and every
      controller valve position (unit ``%``); all other variables are outputs (or only
      ``outputs``, if given).
    * **Sample time:** 60 s (1-minute sampling, per the data's README).

    Args:
        directory: the data directory (holding ``columns.csv`` and the CSVs).
        onset: fault onset sample for every fault file.
        outputs: restrict the outputs to these columns (default: all non-input variables).
    """
    d = Path(directory)
    if not d.is_dir():
        raise ValueError(f"data directory {str(d)!r} does not exist or is not a directory")
    cols = _santander_columns(d)
    names = tuple(sym for sym, _ in cols)
    variables = [(sym, unit) for sym, unit in cols if sym != "time"]
    inputs = tuple(sym for sym, unit in variables if unit == "%" or sym in ("F3", "Tatm", "T1"))
    all_outputs = tuple(sym for sym, _ in variables if sym not in inputs)
    if outputs is not None:
        unknown = [o for o in outputs if o not in all_outputs]
        if unknown:
            raise ValueError(f"unknown output(s) {unknown}. Available: {list(all_outputs)}")
        all_outputs = tuple(outputs)
    tests = [ExternalFile(_SANTANDER_HEALTHY_TEST, None, "NOC_stableFeedFlow")]
    tests += [ExternalFile(f, onset, f.removesuffix("_outputs.csv")) for f in _SANTANDER_FAULTS]
    return ExternalData(
        directory=str(d),
        inputs=inputs,
        outputs=all_outputs,
        train_files=(_SANTANDER_TRAIN,),
        test_files=tuple(tests),
        column_names=names,
        sample_time_s=60.0,
    )


MANIFEST_NAME = "dataset.json"
_MANIFEST_KEYS = {
    "inputs",
    "outputs",
    "train_files",
    "test_files",
    "column_names",
    "sample_time_s",
    "delimiter",
    "diagnoser_params",
    "episode_column",
}


def load_manifest(directory: str | Path) -> tuple[ExternalData, dict[str, dict[str, Any]]]:
    """Describe a user's directory by its ``dataset.json``: the data and per-diagnoser params.

    ``directory`` is the data directory (holding ``dataset.json``) or the manifest file itself
    (any name; file paths in it are relative to its folder).

    The manifest is JSON (never executed) with the fields of :class:`ExternalData`::

        {"inputs": ["T2", "Frgc"], "outputs": ["Tr"], "train_files": ["healthy.csv"],
         "test_files": [{"path": "leak.csv", "onset": 120, "name": "leak"},
                        {"path": "normal.csv", "onset": null}],
         "sample_time_s": 60, "column_names": null, "delimiter": ",", "episode_column": "episode",
         "diagnoser_params": {"arx-band": {"output": "Tr", "inputs": ["T2", "Frgc"]}}}

    ``diagnoser_params`` (optional) gives hyperparameters for diagnosers whose defaults name
    FCC-v0 channels. Returns ``(data, diagnoser_params)``.
    """
    path = Path(directory)
    if path.is_file():  # the manifest itself (any name); the data are beside it
        directory = path.parent
    else:
        path = path / MANIFEST_NAME
    try:
        spec = json.loads(path.read_text())
    except OSError as e:
        raise ValueError(f"cannot read {path}: {e}") from e
    except json.JSONDecodeError as e:
        raise ValueError(f"{path} is not valid JSON: {e}") from e
    if not isinstance(spec, dict):
        raise ValueError(f"{path} must hold a JSON object, got {type(spec).__name__}")
    unknown = sorted(set(spec) - _MANIFEST_KEYS)
    if unknown:
        raise ValueError(f"{path}: unknown field(s) {unknown}. Allowed: {sorted(_MANIFEST_KEYS)}")
    missing = sorted({"inputs", "outputs", "train_files", "test_files"} - set(spec))
    if missing:
        raise ValueError(f"{path}: missing field(s) {missing}")
    try:
        tests = tuple(
            ExternalFile(str(t["path"]), t.get("onset"), t.get("name")) for t in spec["test_files"]
        )
    except (TypeError, KeyError) as e:
        raise ValueError(
            f"{path}: test_files must be a list of {{'path', 'onset', 'name'}} objects ({e})"
        ) from e
    for key in ("inputs", "outputs", "train_files", "column_names"):
        v = spec.get(key)
        if key == "column_names" and v is None:
            continue
        if not isinstance(v, list) or not all(isinstance(x, str) for x in v):
            raise ValueError(
                f"{path}: {key}={v!r} is outside the allowed range: a JSON list of names "
                f'(strings), e.g. ["{v if isinstance(v, str) else "name"}"]'
            )
    sample_time = spec.get("sample_time_s", 1.0)
    if isinstance(sample_time, bool) or not isinstance(sample_time, int | float):
        raise ValueError(
            f"{path}: sample_time_s={sample_time!r} is outside the allowed range: a positive "
            "number of seconds (a JSON number, not text)"
        )
    data = ExternalData(
        directory=str(Path(directory)),
        inputs=tuple(spec["inputs"]),
        outputs=tuple(spec["outputs"]),
        train_files=tuple(spec["train_files"]),
        test_files=tests,
        column_names=tuple(spec["column_names"]) if spec.get("column_names") else None,
        sample_time_s=float(sample_time),
        delimiter=str(spec.get("delimiter", ",")),
        episode_column=_episode_column(path, spec),
    )
    data.validate()
    params = spec.get("diagnoser_params") or {}
    if not isinstance(params, dict) or not all(isinstance(v, dict) for v in params.values()):
        raise ValueError(f"{path}: diagnoser_params must map diagnoser names to objects")
    from diagnosers import available, make

    for name, kw in params.items():  # bad settings fail here, before any training starts
        if name in available():
            try:
                make(name, **kw)._validate_params()
            except (ValueError, TypeError) as e:
                raise ValueError(f"{path}: diagnoser_params[{name!r}]: {e}") from e
    return data, params


def _episode_column(path: Path, spec: dict[str, Any]) -> str | None:
    v = spec.get("episode_column", "episode")
    if v is not None and not isinstance(v, str):
        raise ValueError(
            f"{path}: episode_column={v!r} is outside the allowed range: a column name (string) "
            "or null"
        )
    return v


def load_external(directory: str | Path) -> tuple[ExternalData, dict[str, dict[str, Any]]]:
    """A directory with a ``dataset.json`` manifest, or the Santander data set's layout."""
    d = Path(directory)
    if not d.is_dir():
        raise ValueError(f"data directory {str(d)!r} does not exist or is not a directory")
    if (d / MANIFEST_NAME).is_file():
        return load_manifest(d)
    if (d / "columns.csv").is_file() and (d / _SANTANDER_TRAIN).is_file():
        return load_santander(d), SANTANDER_PARAMS
    raise ValueError(
        f"{str(d)!r} has neither a {MANIFEST_NAME} manifest (see evaluation.external."
        "load_manifest) nor the Santander data set's columns.csv and CSV files"
    )
