"""Reading measured data: only what a plant really knows.

:func:`load_measured` parses the ``measured`` (Table 1) and ``commanded`` columns of a dataset
written by ``python -m fcc_env.generate`` (or a user's file in that format), plus the episode
index and the sample time. It never parses the ``truth`` columns (``in_*``, ``clean_*``, ``x_*``,
``fault_active``) nor the sidecar's ``truth_plant_effects``.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from fcc_common.io import read_columns, read_header
from fcc_common.validation import Real, check
from fcc_env.generate import DATASET_FORMAT, DATASET_SUFFIXES, read_sidecar
from fcc_env.plant import DEFAULT_SAMPLE_TIME_S

__all__ = [
    "DATASET_FORMAT",
    "INDEX_COLUMNS",
    "TABLE1",
    "MeasuredData",
    "from_arrays",
    "from_batch",
    "from_external",
    "load_measured",
]

TABLE1 = ("R_ar", "T_ar", "T_fp", "T_rx", "T_rg1", "T_rg2", "T_d1", "T_dg")
INDEX_COLUMNS = ("episode", "k", "time_s")

#: The sample time must be a finite positive number of seconds.
POSITIVE_SECONDS = Real(0.0, math.inf, closed="neither", unit="s")


@dataclass(frozen=True)
class MeasuredData:
    """What the loop may see: named channels, each (n_episodes, n_samples), and the sample time."""

    channels: Mapping[str, np.ndarray]
    sample_time_s: float
    source: str = "<arrays>"
    #: recorded under a regulatory layer (closed loop): True, False, or None when unknown; the
    #: loop estimates the unmeasured feed-coking drift of closed-loop data by default
    closed_loop: bool | None = None

    def __post_init__(self) -> None:
        if not self.channels:
            raise ValueError("measured data has no channels")
        shapes = {np.shape(v) for v in self.channels.values()}
        if len(shapes) != 1 or len(next(iter(shapes))) != 2:
            raise ValueError(f"channels must share one (n_episodes, n_samples) shape, got {shapes}")
        check("sample_time_s", self.sample_time_s, POSITIVE_SECONDS)
        for name, v in self.channels.items():
            if not np.isfinite(v).all():
                raise ValueError(f"channel {name!r} contains NaN or inf")

    @property
    def n_episodes(self) -> int:
        return int(next(iter(self.channels.values())).shape[0])

    @property
    def n_samples(self) -> int:
        return int(next(iter(self.channels.values())).shape[1])

    @property
    def t_s(self) -> np.ndarray:
        """Time since the episode start, seconds (equidistant samples)."""
        return np.arange(self.n_samples) * self.sample_time_s

    def require(self, names: Sequence[str], who: str) -> None:
        missing = [n for n in names if n not in self.channels]
        if missing:
            raise ValueError(
                f"{who} needs channel(s) {missing}, data {self.source!r} has {sorted(self.channels)}"
            )

    def stack(self, names: Sequence[str]) -> np.ndarray:
        self.require(names, "stack")
        return np.stack([np.asarray(self.channels[n], np.float64) for n in names], axis=-1)


def from_arrays(
    channels: Mapping[str, Any],
    sample_time_s: float = DEFAULT_SAMPLE_TIME_S,
    source: str = "<arrays>",
    closed_loop: bool | None = None,
) -> MeasuredData:
    """Measured data from arrays (T,) or (n_episodes, T) per channel name; ``closed_loop``:
    whether they were recorded under a regulatory layer (None: unknown)."""
    out = {}
    for name, v in channels.items():
        a = np.asarray(v, dtype=np.float64)
        out[str(name)] = a[None] if a.ndim == 1 else a
    return MeasuredData(out, float(sample_time_s), source, closed_loop)


def from_batch(batch: Any) -> MeasuredData:
    """The measured part of a :class:`fcc_env.BatchResult`: noisy Table 1 + commanded u_F, R_ar."""
    obs = np.asarray(batch.observations, dtype=np.float64)
    ch = {name: obs[:, :, i] for i, name in enumerate(TABLE1)}
    ch["cmd_u_F"] = np.asarray(batch.inputs[:, :, 0], np.float64)
    ch["cmd_R_ar"] = np.asarray(batch.inputs[:, :, 1], np.float64)
    closed = "u_F" in tuple(getattr(batch, "channels", ()))
    return MeasuredData(ch, float(batch.sample_time_s), "<BatchResult>", closed)


def load_measured(path: str | os.PathLike) -> MeasuredData:
    """Read the ``measured`` and ``commanded`` columns (and the episode index) of a dataset.

    Only those columns are parsed: truth columns and ``truth_plant_effects`` are never read.
    Raises ValueError naming the problem for a missing file, a bad sidecar or ragged episodes.
    """
    csv = Path(path)
    if csv.suffix.lower() not in DATASET_SUFFIXES:
        raise ValueError(
            f"--data must be a {'/'.join(DATASET_SUFFIXES)} dataset (with a .json sidecar), "
            f"got {str(csv)!r}"
        )
    meta = read_sidecar(csv)
    roles = meta.get("roles")
    if not isinstance(roles, dict) or not isinstance(roles.get("measured"), list):
        raise ValueError(f"sidecar {str(csv.with_suffix('.json'))!r} has no roles.measured list")
    wanted = [str(c) for c in roles["measured"]] + [str(c) for c in roles.get("commanded", [])]
    dt = meta.get("sample_time_s")
    dt = check("sample_time_s", dt, POSITIVE_SECONDS)
    header = read_header(csv)
    missing = [c for c in wanted if c not in header]
    if missing:
        raise ValueError(f"dataset {str(csv)!r} lacks column(s) {missing} named in its sidecar")
    index = [c for c in ("episode",) if c in header]
    try:
        _, table = read_columns(csv, index + wanted)
    except ValueError as e:
        raise ValueError(f"dataset {str(csv)!r} could not be parsed as numbers: {e}") from e
    if table.shape[0] < 50:
        raise ValueError(f"dataset {str(csv)!r} has {table.shape[0]} rows; the loop needs >= 50")
    episode = table[:, 0].astype(int) if index else np.zeros(table.shape[0], int)
    eps, counts = np.unique(episode, return_counts=True)
    if len(set(counts.tolist())) != 1:
        lengths = dict(zip(eps.tolist(), counts.tolist(), strict=True))
        raise ValueError(f"episodes of {str(csv)!r} differ in length: {lengths}")
    order = np.argsort(episode, kind="stable")
    E, T = eps.size, int(counts[0])
    channels = {c: table[order, len(index) + j].reshape(E, T) for j, c in enumerate(wanted)}
    plant = meta.get("plant")
    closed = isinstance(plant, dict) and "regulatory" in plant  # written for closed loop only
    return MeasuredData(channels, float(dt), str(csv), closed or "setpoint" in roles)


def from_external(data: Any) -> MeasuredData:
    """The healthy training records of an :class:`evaluation.sweep.external_data.ExternalData` (e.g. from
    :func:`evaluation.sweep.external_data.load_manifest`): its ``inputs`` and ``outputs`` channels, one
    episode per record (a file's ``episode`` column splits it), at its ``sample_time_s``.

    The loop needs equal-length episodes: longer records are cut to the shortest one's length.
    Test records are not read (a fault record is not data to model).
    """
    episodes = data.train_episodes()
    n = min(ep.n_samples for ep in episodes)
    channels = {
        c: np.stack([np.asarray(ep.y[:n, j], np.float64) for ep in episodes])
        for j, c in enumerate(data.channels)
    }
    return MeasuredData(channels, float(data.sample_time_s), f"external:{data.directory}")
