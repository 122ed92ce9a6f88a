"""Parquet tables whose schema carries each column's unit, role and description.

The JSON sidecar of a dataset (:mod:`fcc_env.generate`) describes every column; a Parquet file
carries the same record in its schema's field metadata, so a reader that never opens the sidecar
(pyarrow, pandas, Polars, DuckDB) still finds the unit and the role of a column beside its data:

>>> import tempfile, pathlib, numpy as np, pyarrow.parquet as pq
>>> path = pathlib.Path(tempfile.mkdtemp()) / "x.parquet"
>>> table = parquet_table(
...     {"T_rx": np.array([530.0, 531.0])},
...     {"T_rx": {"unit": "°C", "description": "reactor temperature", "role": "measured"}},
... )
>>> pq.write_table(table, path)
>>> pq.read_schema(path).field("T_rx").metadata[b"unit"].decode()
'°C'
>>> field_metadata(path)["T_rx"]["role"]
'measured'
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from typing import Any

import numpy as np

from fcc_common.io import require_pyarrow

__all__ = ["field_metadata", "parquet_table"]


def parquet_table(
    columns: Mapping[str, np.ndarray], metadata: Mapping[str, Mapping[str, str]]
) -> Any:
    """A ``pyarrow.Table`` of ``columns`` (name → 1-D array, in file order) whose field ``name``
    carries ``metadata[name]`` (``{"unit", "description", "role"}``, the sidecar's record) as
    UTF-8 bytes.

    Raises:
        ValueError: a column without metadata, or metadata that is not text (names them).
    """
    import pyarrow as pa

    missing = [n for n in columns if n not in metadata]
    if missing:
        raise ValueError(
            f"column(s) {missing} have no metadata (unit, role); described: {list(metadata)}"
        )
    arrays, fields = [], []
    for name, values in columns.items():
        record = metadata[name]
        bad = {k: v for k, v in record.items() if not (isinstance(k, str) and isinstance(v, str))}
        if bad:
            raise ValueError(f"column {name!r}: metadata {bad} must map text to text")
        array = pa.array(np.ascontiguousarray(values))
        arrays.append(array)
        fields.append(
            pa.field(name, array.type, metadata={k.encode(): v.encode() for k, v in record.items()})
        )
    return pa.Table.from_arrays(arrays, schema=pa.schema(fields))


def field_metadata(path: str | os.PathLike) -> dict[str, dict[str, str]]:
    """``{column: {key: value}}`` read from the schema of the Parquet file ``path`` (columns
    without metadata map to ``{}``); needs ``pyarrow``."""
    schema = require_pyarrow(path).read_schema(path)
    return {f.name: {k.decode(): v.decode() for k, v in (f.metadata or {}).items()} for f in schema}
