"""The diagnosers' input: :class:`Episode`, one record of measurements, and its constructors.

``Episode.from_batch`` (a simulated :class:`fcc_env.BatchResult`), ``Episode.from_dataset`` (a
``python -m fcc_env.generate`` file) and ``Episode.from_frame`` (a pandas DataFrame) build
episodes from data in one call; the package exports the class as ``diagnosers.Episode``.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:  # annotations only: building episodes needs no simulator import
    from fcc_env.simulation import BatchResult

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class Episode:
    """One record of measurements, as a plant historian would hold it.

    Attributes:
        y: measurements, shape ``(n_samples, n_channels)``, physical units.
        channels: channel names, one per column of ``y`` (for FCC-v0:
            ``fcc_env.MEASUREMENT_NAMES``).
        sample_time_s: sample period in seconds.
        fault_onset: ground-truth onset sample, or ``None`` for a healthy record. Used to
            score; the harness passes faulty training records (labelled by ``scenario``) only
            to diagnosers that isolate (:attr:`Diagnoser.isolates`).
        scenario: scenario name (``"nominal"``, ``"f1"``... or a file stem for external data);
            for an isolating diagnoser's faulty training records, the fault class.
        seed: seed the episode was simulated with, if any.
        y_clean: optional noise-free measurements (simulation only; for plots and diagnostics).
    """

    y: np.ndarray
    channels: tuple[str, ...]
    sample_time_s: float
    fault_onset: int | None = None
    scenario: str = "unknown"
    seed: int | None = None
    y_clean: np.ndarray | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        ch = self.channels
        if (
            not isinstance(ch, Sequence)
            or isinstance(ch, str | bytes)
            or not all(isinstance(c, str) for c in ch)
        ):
            raise ValueError(
                f"Episode channels={ch!r} is outside the allowed range: a sequence of channel "
                "names, e.g. ('T_rx', 'T_rg1'), not one string"
            )
        object.__setattr__(self, "channels", tuple(ch))
        y = np.asarray(self.y, dtype=np.float64)
        if y.ndim != 2 or y.shape[1] != len(self.channels):
            raise ValueError(
                f"Episode.y must have shape (n_samples, {len(self.channels)}) to match channels "
                f"{self.channels}; got {y.shape}"
            )
        if not np.isfinite(y).all():
            raise ValueError("Episode.y contains NaN or inf; clean or drop those samples first")
        if not (np.isfinite(self.sample_time_s) and self.sample_time_s > 0):
            raise ValueError(f"sample_time_s must be a positive number, got {self.sample_time_s!r}")
        if self.fault_onset is not None and not 0 <= self.fault_onset < y.shape[0]:
            raise ValueError(
                f"fault_onset={self.fault_onset} outside the episode [0, {y.shape[0]})"
            )
        object.__setattr__(self, "y", y)

    @property
    def n_samples(self) -> int:
        return int(self.y.shape[0])

    def channel(self, name: str) -> np.ndarray:
        """Column of ``y`` named ``name``, shape ``(n_samples,)``."""
        try:
            return self.y[:, self.channels.index(name)]
        except ValueError:
            raise ValueError(
                f"Unknown channel {name!r}. Available: {list(self.channels)}"
            ) from None

    # ---- constructors from data ----------------------------------------------------------------
    @classmethod
    def from_batch(cls, batch: BatchResult) -> list[Episode]:
        """The episodes of an :class:`fcc_env.BatchResult`, one per seed.

        Each episode keeps its samples before ``terminated_at`` (the env would have ended there)
        and carries its scenario, seed, fault onset (``None`` when healthy or when the episode
        ended before the onset) and noise-free measurements ``y_clean``.

        >>> import fcc_env, diagnosers
        >>> batch = fcc_env.simulate_episodes([1000, 1001], 300)
        >>> det = diagnosers.make("limits").fit(diagnosers.Episode.from_batch(batch))
        >>> test = fcc_env.simulate_episodes([0], 300, scenario="f1", fault_time=150)
        >>> [ep] = diagnosers.Episode.from_batch(test)
        >>> ep.scenario, ep.seed, ep.fault_onset, det.detect(ep).alarm.shape
        ('f1', 0, 150, (300,))
        """
        from fcc_env.params import MEASUREMENT_NAMES  # local: diagnosers works without the env

        obs = np.asarray(batch.observations)
        if obs.ndim != 3:
            raise ValueError(
                f"batch.observations must have shape (n_episodes, n_samples, n_channels); "
                f"got {obs.shape}"
            )
        out = []
        for b in range(obs.shape[0]):
            term = int(batch.terminated_at[b])
            n_used = term if term >= 0 else obs.shape[1]
            onset = batch.fault_onsets[b]
            out.append(
                cls(
                    y=np.asarray(obs[b, :n_used], dtype=np.float64),
                    channels=tuple(getattr(batch, "channels", MEASUREMENT_NAMES)),
                    sample_time_s=float(batch.sample_time_s),
                    fault_onset=None if onset is None or onset >= n_used else int(onset),
                    scenario=str(batch.scenarios[b]),
                    seed=int(batch.seeds[b]),
                    y_clean=np.asarray(batch.y_clean[b, :n_used], dtype=np.float64),
                )
            )
        return out

    @classmethod
    def from_dataset(cls, path: str | os.PathLike) -> list[Episode]:
        """The episodes of a ``python -m fcc_env.generate`` dataset (CSV + JSON sidecar).

        The CSV stacks its episodes; the ``episode`` column (or, in a file without one, the
        ``seed`` column) tells them apart, so a file of several seeds gives several episodes, in
        file order. Channels are the sidecar's ``measured`` columns; ``clean_<channel>`` columns,
        when all present, become ``y_clean``. Scenario, seed, fault onset and ``terminated_at``
        come from the sidecar's per-episode lists when it has them (each episode is cut at its
        ``terminated_at``, as in :meth:`from_batch`).
        """
        from fcc_env.generate import read_dataset  # local: diagnosers works without the env

        meta, cols = read_dataset(path)
        roles = meta.get("roles") if isinstance(meta.get("roles"), dict) else {}
        channels = tuple(roles.get("measured") or ())
        missing = [c for c in channels if c not in cols]
        if not channels or missing:
            raise ValueError(
                f"dataset {str(path)!r}: the sidecar's roles.measured must name columns of the "
                f"CSV; got {list(channels)}, missing {missing}, columns {sorted(cols)}"
            )
        dt = meta.get("sample_time_s")
        if dt is None:
            raise ValueError(
                f"dataset {str(path)!r}: the sidecar has no sample_time_s; add it (in seconds)"
            )
        key = next((k for k in ("episode", "seed") if k in cols), None)
        n_rows = len(cols[channels[0]])
        ids = np.asarray(cols[key]) if key is not None else np.zeros(n_rows)
        # episodes in file order (np.unique would sort them)
        order = list(dict.fromkeys(ids.tolist()))
        clean = [f"clean_{c}" for c in channels]
        has_clean = all(c in cols for c in clean)

        def per_episode(field_name: str, i: int) -> Any:
            values = meta.get(field_name)
            return values[i] if isinstance(values, list) and i < len(values) else None

        out = []
        for i, ep_id in enumerate(order):
            rows = np.flatnonzero(ids == ep_id)
            term = per_episode("terminated_at", i)
            n_used = len(rows) if term is None else min(int(term), len(rows))
            rows = rows[:n_used]
            onset = per_episode("fault_onsets", i)
            seed = per_episode("seeds", i)
            if seed is None and "seed" in cols:
                seed = cols["seed"][rows[0]]
            out.append(
                cls(
                    y=np.column_stack([cols[c][rows] for c in channels]),
                    channels=channels,
                    sample_time_s=float(dt),
                    fault_onset=None if onset is None or onset >= n_used else int(onset),
                    scenario=str(per_episode("scenarios", i) or meta.get("scenario", "unknown")),
                    seed=None if seed is None else int(seed),
                    y_clean=np.column_stack([cols[c][rows] for c in clean]) if has_clean else None,
                )
            )
        return out

    @classmethod
    def from_frame(
        cls,
        df: Any,
        *,
        channels: Sequence[str] | None = None,
        sample_time_s: float,
        fault_onset: int | None = None,
        scenario: str = "unknown",
        seed: int | None = None,
    ) -> Episode:
        """One episode from a pandas ``DataFrame`` (one row per sample, one column per channel).

        Args:
            df: the record; pandas is optional for this library and imported here only.
            channels: the columns to use, in this order (default: every column).
            sample_time_s: sample period in seconds.
            fault_onset, scenario, seed: as for :class:`Episode`.
        """
        try:
            import pandas as pd
        except ImportError as e:
            raise ImportError(
                "Episode.from_frame needs pandas, which is not installed: pip install pandas "
                "(or build Episode(y=array, channels=..., sample_time_s=...) directly)"
            ) from e
        if not isinstance(df, pd.DataFrame):
            raise TypeError(f"df must be a pandas DataFrame, got {type(df).__name__}")
        names = tuple(str(c) for c in df.columns) if channels is None else tuple(channels)
        missing = [c for c in names if c not in df.columns]
        if missing:
            raise ValueError(
                f"channels {missing} are not columns of the frame. Columns: {list(df.columns)}"
            )
        try:
            y = df.loc[:, list(names)].to_numpy(dtype=np.float64)
        except (TypeError, ValueError) as e:
            raise ValueError(f"channels {list(names)} must hold numbers: {e}") from e
        return cls(
            y=y,
            channels=names,
            sample_time_s=sample_time_s,
            fault_onset=fault_onset,
            scenario=scenario,
            seed=seed,
        )
