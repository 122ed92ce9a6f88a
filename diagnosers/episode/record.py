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

from diagnosers.episode.checks import (
    check_channels,
    check_labels,
    frame_values,
    read_dataset_episodes,
    real_values,
)
from diagnosers.episode.units import check_units

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
        units: the unit of each channel (``""`` where the data do not state it), or ``None``
            when no units were recorded. Presentation only: figures and tables label values
            with them; no diagnoser reads them.

    Construction refuses what would be read wrongly rather than convert it: no samples, repeated
    channel names, boolean, time or complex values, text that is not a number, NaN or inf, an
    onset or seed that is not an integer; the message names the channel, row and value.
    """

    y: np.ndarray
    channels: tuple[str, ...]
    sample_time_s: float
    fault_onset: int | None = None
    scenario: str = "unknown"
    seed: int | None = None
    y_clean: np.ndarray | None = field(default=None, repr=False)
    units: tuple[str, ...] | None = None

    def __post_init__(self) -> None:
        # every constructor of data ends here, so these checks are the one gate (issue 32)
        channels = check_channels(self.channels)
        object.__setattr__(self, "channels", channels)
        object.__setattr__(self, "units", check_units(self.units, channels))
        y = real_values(self.y, channels)
        check_labels(
            y.shape[0],
            sample_time_s=self.sample_time_s,
            fault_onset=self.fault_onset,
            seed=self.seed,
            scenario=self.scenario,
        )
        if self.y_clean is not None:
            clean = real_values(self.y_clean, channels, name="y_clean")
            if clean.shape != y.shape:
                raise ValueError(
                    f"Episode y_clean has shape {clean.shape}; allowed: the shape of y, {y.shape}"
                )
        object.__setattr__(self, "y", y)

    @property
    def n_samples(self) -> int:
        return int(self.y.shape[0])

    @property
    def channel_units(self) -> dict[str, str]:
        """``{channel: unit}`` for every channel, ``""`` where the unit is unknown (empty when
        no units were recorded)."""
        if self.units is None:
            return {}
        return dict(zip(self.channels, self.units, strict=True))

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
        >>> f1 = fcc_env.FaultSpec(scenario="f1", onset=150)
        >>> test = fcc_env.simulate_episodes([0], 300, fault=f1)
        >>> [ep] = diagnosers.Episode.from_batch(test)
        >>> ep.scenario, ep.seed, ep.fault_onset, det.detect(ep).alarm.shape
        ('f1', 0, 150, (300,))
        """
        # local: diagnosers works without the env
        from fcc_env.closed_loop import CHANNEL_UNITS
        from fcc_env.params import MEASUREMENT_NAMES

        obs = np.asarray(batch.observations)
        if obs.ndim != 3:
            raise ValueError(
                f"batch.observations must have shape (n_episodes, n_samples, n_channels); "
                f"got {obs.shape}"
            )
        channels = tuple(getattr(batch, "channels", MEASUREMENT_NAMES))
        units = tuple(CHANNEL_UNITS.get(c, "") for c in channels)
        out = []
        for b in range(obs.shape[0]):
            term = int(batch.terminated_at[b])
            n_used = term if term >= 0 else obs.shape[1]
            onset = batch.fault_onsets[b]
            out.append(
                cls(
                    y=np.asarray(obs[b, :n_used], dtype=np.float64),
                    channels=channels,
                    sample_time_s=float(batch.sample_time_s),
                    fault_onset=None if onset is None or onset >= n_used else int(onset),
                    scenario=str(batch.scenarios[b]),
                    seed=int(batch.seeds[b]),
                    y_clean=np.asarray(batch.y_clean[b, :n_used], dtype=np.float64),
                    units=units,
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
        ``terminated_at``, as in :meth:`from_batch`); units from its ``columns[name]["unit"]``.

        The file is checked as it is read (:func:`diagnosers.episode.checks.read_dataset_episodes`):
        rows that disagree with the sidecar or with each other (a ``time_s`` step other than
        ``sample_time_s``, missing or reversed rows, two seeds under one ``episode``), sidecar
        entries of the wrong form and values that are not finite numbers raise ``ValueError``
        naming the file, the column, the data row and what is allowed.
        """
        return [cls(**fields) for fields in read_dataset_episodes(path)]

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
        names, y = frame_values(df, channels)
        return cls(
            y=y,
            channels=names,
            sample_time_s=sample_time_s,
            fault_onset=fault_onset,
            scenario=scenario,
            seed=seed,
        )
