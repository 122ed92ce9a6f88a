"""File helpers shared by every package: one atomic writer, one JSON scrubber, one table reader
(CSV, or Parquet with the optional ``pyarrow``).

Every file the project writes (datasets, saved diagnosers, result-store cells, reports) goes
through :func:`atomic_write`: the bytes go to a temporary file in the target's folder, are
flushed to disk and renamed over the target, so a process killed at any instant leaves either the
old file or the complete new one, never a torn one. The temporary file gets the permissions a
plain ``open`` would give (``0o666`` less the umask), not the ``0o600`` of
:func:`tempfile.mkstemp`.

>>> import tempfile, pathlib, json
>>> d = pathlib.Path(tempfile.mkdtemp())
>>> atomic_write_json(d / "x.json", {"a": float("nan"), "b": [1.5]})
PosixPath(...x.json')
>>> json.loads((d / "x.json").read_text())
{'a': None, 'b': [1.5]}
"""

from __future__ import annotations

import csv
import json
import math
import os
import tempfile
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import IO, Any

import numpy as np

__all__ = [
    "PARQUET_SUFFIXES",
    "TMP_SUFFIX",
    "atomic_open",
    "atomic_write",
    "atomic_write_json",
    "json_default",
    "json_safe",
    "read_columns",
    "read_csv_columns",
    "read_header",
    "read_parquet_columns",
    "remove_stale_tmp",
    "require_pyarrow",
]

#: Suffix of the temporary files of :func:`atomic_open` (a kill leaves them behind; see
#: :func:`remove_stale_tmp`).
TMP_SUFFIX = ".tmp"


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


@contextmanager
def atomic_open(path: str | os.PathLike, mode: str = "w") -> Iterator[IO[Any]]:
    """Open a temporary file beside ``path``; on a clean exit it replaces ``path`` atomically.

    On an exception the temporary file is removed and ``path`` is left as it was.

    Args:
        path: the file to write (its folder is created if missing).
        mode: ``"w"`` (text) or ``"wb"`` (bytes).
    """
    if mode not in ("w", "wb"):
        raise ValueError(f"mode={mode!r} is outside the allowed set: one of ['w', 'wb']")
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    fh = tempfile.NamedTemporaryFile(
        mode, dir=target.parent, prefix=f".{target.name}.", suffix=TMP_SUFFIX, delete=False
    )
    try:
        with fh:
            yield fh
            fh.flush()
            os.fsync(fh.fileno())
        os.chmod(fh.name, 0o666 & ~_umask())
        os.replace(fh.name, target)
    except BaseException:
        Path(fh.name).unlink(missing_ok=True)
        raise


def atomic_write(path: str | os.PathLike, data: str | bytes) -> Path:
    """Write ``data`` (text or bytes) to ``path`` atomically; returns the path."""
    with atomic_open(path, "wb" if isinstance(data, bytes) else "w") as fh:
        fh.write(data)
    return Path(path)


def json_safe(obj: Any) -> Any:
    """``obj`` with every non-finite float replaced by ``None`` (strict JSON has no NaN).

    Mappings and sequences are walked; numpy scalars become Python numbers.
    """
    if isinstance(obj, np.generic):
        obj = obj.item()
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    if isinstance(obj, Mapping):
        return {k: json_safe(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [json_safe(v) for v in obj]
    return obj


def json_default(o: Any) -> Any:
    """``json.dumps(default=...)`` hook: numpy scalars and arrays as Python values, paths as text."""
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, os.PathLike):
        return os.fspath(o)
    raise TypeError(f"Object of type {type(o).__name__} is not JSON serializable")


def atomic_write_json(
    path: str | os.PathLike,
    obj: Any,
    *,
    indent: int | None = 2,
    sort_keys: bool = False,
    default: Callable[[Any], Any] | None = json_default,
) -> Path:
    """Write ``obj`` as strict JSON (NaN and inf as ``null``) to ``path`` atomically."""
    text = json.dumps(
        json_safe(obj), indent=indent, sort_keys=sort_keys, allow_nan=False, default=default
    )
    return atomic_write(path, text)


def remove_stale_tmp(directory: str | os.PathLike, *, min_age_s: float = 0.0) -> list[Path]:
    """Delete temporary files that a killed writer left in ``directory`` (recursively).

    Only files named like :func:`atomic_open`'s (``.<name>.<random>.tmp``) and last modified
    at least ``min_age_s`` seconds ago are touched (a positive age spares the files of a writer
    still running beside this one). Returns the removed paths.
    """
    import time

    root = Path(directory)
    removed = []
    now = time.time()
    if root.is_dir():
        for p in root.rglob(f".*{TMP_SUFFIX}"):
            if p.is_file() and now - p.stat().st_mtime >= min_age_s:
                p.unlink(missing_ok=True)
                removed.append(p)
    return removed


def read_csv_columns(
    path: str | os.PathLike,
    columns: Sequence[str] | None = None,
    *,
    column_names: Sequence[str] | None = None,
    delimiter: str = ",",
) -> tuple[list[str], np.ndarray]:
    """The one CSV reader: ``(names, data)`` of the numeric ``columns`` of a CSV file.

    Args:
        path: the file (UTF-8 text).
        columns: the columns wanted, by name, in this order (``None``: all of them).
        column_names: names of all columns of a headerless file, in order; ``None`` reads them
            from the first row.
        delimiter: field separator.

    Returns:
        The names read and a float array ``(n_rows, n_columns)``.

    Raises:
        ValueError: a missing or empty file, bytes that are not UTF-8 (the message names the
            line), an unknown column (the message lists the available ones), a wanted column
            named twice, a short row or a field that is not a number (the message names the
            column, the data row and the line); each message names the file.
    """
    p = Path(path)
    if not p.is_file():
        raise ValueError(f"{p} does not exist or is not a file")
    skip = 0
    if column_names is None:
        names = read_header(p, delimiter=delimiter)
        skip = 1
    else:
        names = [str(c) for c in column_names]
    wanted = names if columns is None else [str(c) for c in columns]
    missing = [c for c in wanted if c not in names]
    if missing:
        raise ValueError(f"{p}: unknown column(s) {missing}. Available: {names}")
    _refuse_repeated(p, names, wanted)
    usecols = [names.index(c) for c in wanted]
    try:
        data = np.loadtxt(
            p, delimiter=delimiter, skiprows=skip, usecols=usecols, ndmin=2, encoding="utf-8"
        )
    except UnicodeDecodeError as e:
        raise _not_utf8(p) from e
    except ValueError as e:
        # loadtxt names neither the column nor the line; find the field again to say both
        located = _bad_field(p, names, usecols, skip, delimiter)
        raise located or ValueError(
            f"{p}: could not read numeric data ({e}); check the delimiter, the header and for "
            "text or empty fields"
        ) from e
    return names, data


def _refuse_repeated(p: Path, names: Sequence[str], wanted: Sequence[str]) -> None:
    """A wanted column named twice would be read from its first copy only: refuse it."""
    twice = sorted({c for c in wanted if list(names).count(c) > 1})
    if twice:
        raise ValueError(
            f"{p}: column name(s) {twice} appear more than once among the columns {list(names)}; "
            "allowed: each name once (rename the copies)"
        )


def _not_utf8(p: Path) -> ValueError:
    """The error for a file that is not UTF-8 text, naming the first bad line and byte."""
    with p.open("rb") as fh:
        for line, raw in enumerate(fh, 1):
            try:
                raw.decode("utf-8")
            except UnicodeDecodeError as e:
                return ValueError(
                    f"{p}: line {line} is not UTF-8 text (byte {raw[e.start : e.start + 1]!r} at "
                    f"byte {e.start + 1} of the line); allowed: UTF-8 (or ASCII) text, so save "
                    "the file as UTF-8"
                )
    return ValueError(f"{p} is not UTF-8 text; allowed: UTF-8 (or ASCII) text")


def _is_number(field: str) -> bool:
    if "_" in field:  # float() takes '1_000'; loadtxt does not
        return False
    try:
        float(field)
    except ValueError:
        return False
    return True


def _bad_field(
    p: Path, names: Sequence[str], usecols: Sequence[int], skip: int, delimiter: str
) -> ValueError | None:
    """The first short row or non-numeric wanted field of a CSV, as an error naming the column,
    the data row (counted from 0, as in the array read) and the line; ``None`` if none found."""
    with p.open(newline="", encoding="utf-8") as fh:
        reader = csv.reader(fh, delimiter=delimiter)
        row = -1
        for i, fields in enumerate(reader):
            if i < skip or not fields:  # loadtxt skips blank lines too
                continue
            row += 1
            where = f"data row {row} (line {reader.line_num})"
            for j in usecols:
                if j >= len(fields):
                    return ValueError(
                        f"{p}: {where} has {len(fields)} fields, but column {names[j]!r} is field "
                        f"{j + 1}; allowed: {len(names)} fields per line, as many as the columns"
                    )
                if not _is_number(fields[j]):
                    return ValueError(
                        f"{p}: could not read numeric data: column {names[j]!r}, {where}: "
                        f"{fields[j]!r} is not a number; allowed: a decimal number such as "
                        "12.5, -3e2 or nan"
                    )
    return None


#: File name endings read as Parquet.
PARQUET_SUFFIXES = (".parquet", ".pq")


def require_pyarrow(path: str | os.PathLike, action: str = "reading") -> Any:
    """``pyarrow.parquet``, or an ImportError that names the file and how to install it."""
    try:
        import pyarrow.parquet as pq
    except ImportError as e:
        raise ImportError(
            f"{action} {os.fspath(path)} needs pyarrow, an optional dependency: "
            "pip install 'fcc-fault-diagnosis[parquet]' (or pip install 'pyarrow>=14'); "
            "or use a .csv file"
        ) from e
    return pq


def read_parquet_columns(
    path: str | os.PathLike, columns: Sequence[str] | None = None
) -> tuple[list[str], np.ndarray]:
    """``(names, data)`` of the numeric ``columns`` of a Parquet file (needs ``pyarrow``).

    Same contract as :func:`read_csv_columns`: ``names`` are all the file's columns, ``data``
    the wanted ones as floats ``(n_rows, n_columns)``; errors name the file.
    """
    p = Path(path)
    if not p.is_file():
        raise ValueError(f"{p} does not exist or is not a file")
    pq = require_pyarrow(p)
    try:
        schema = pq.read_schema(p)
    except Exception as e:  # pyarrow raises its own error types for a damaged file
        raise ValueError(f"{p}: not a readable Parquet file ({e})") from e
    names = list(schema.names)
    wanted = names if columns is None else [str(c) for c in columns]
    missing = [c for c in wanted if c not in names]
    if missing:
        raise ValueError(f"{p}: unknown column(s) {missing}. Available: {names}")
    _refuse_repeated(p, names, wanted)
    for c in wanted:
        _refuse_non_numeric(p, c, schema.field(c).type)
    table = pq.read_table(p, columns=wanted)
    try:
        cols = [table.column(c).to_numpy(zero_copy_only=False).astype(np.float64) for c in wanted]
    except (ValueError, TypeError) as e:
        raise ValueError(f"{p}: could not read numeric data ({e})") from e
    data = np.column_stack(cols) if cols else np.empty((table.num_rows, 0))
    return names, data


def _refuse_non_numeric(p: Path, column: str, arrow_type: Any) -> None:
    """Booleans, times and text cast to floats without a word (True -> 1.0, a timestamp -> its
    nanoseconds), so a column of them is refused, not converted."""
    import pyarrow.types as pat

    if pat.is_integer(arrow_type) or pat.is_floating(arrow_type) or pat.is_decimal(arrow_type):
        return
    if pat.is_boolean(arrow_type):
        hint = "; store 0/1 integers if the flags are meant as numbers"
    elif pat.is_temporal(arrow_type):
        hint = "; store times as seconds (a number)"
    else:
        hint = ""
    raise ValueError(
        f"{p}: column {column!r} holds {arrow_type} values; allowed: integer or floating-point "
        f"numbers{hint}"
    )


def read_header(path: str | os.PathLike, *, delimiter: str = ",") -> list[str]:
    """The column names of a CSV (its first row) or Parquet file (its schema), nothing else."""
    p = Path(path)
    if not p.is_file():
        raise ValueError(f"{p} does not exist or is not a file")
    if p.suffix.lower() in PARQUET_SUFFIXES:
        try:
            return list(require_pyarrow(p).read_schema(p).names)
        except ImportError:
            raise
        except Exception as e:
            raise ValueError(f"{p}: not a readable Parquet file ({e})") from e
    try:
        with p.open(newline="", encoding="utf-8") as fh:
            header = next(csv.reader(fh, delimiter=delimiter), None)
    except UnicodeDecodeError as e:
        raise _not_utf8(p) from e
    if header is None:
        raise ValueError(f"{p} is empty; expected a header row and data")
    return [h.strip() for h in header]


def read_columns(
    path: str | os.PathLike,
    columns: Sequence[str] | None = None,
    *,
    column_names: Sequence[str] | None = None,
    delimiter: str = ",",
) -> tuple[list[str], np.ndarray]:
    """:func:`read_parquet_columns` for a ``.parquet``/``.pq`` file, else :func:`read_csv_columns`."""
    if Path(path).suffix.lower() in PARQUET_SUFFIXES:
        return read_parquet_columns(path, columns)
    return read_csv_columns(path, columns, column_names=column_names, delimiter=delimiter)
