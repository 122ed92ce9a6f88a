"""The evaluation harness: diagnosers × scenarios × seeds, in parallel, with a resumable store.

This module gathers the harness's public names for one release; the code lives in rooms:

* :mod:`evaluation.sources` — where episodes come from (:class:`SimulatedData`, the
  :class:`DataSource` protocol, :class:`LoadedEpisode`);
* :mod:`evaluation.records` — what a cell records (:class:`CellResult`, :func:`score_episode`,
  :func:`summarize`);
* :mod:`evaluation.backends` — where tasks run (local processes, Ray, this process);
* :mod:`evaluation.sweep` — the sweep itself (:class:`SweepConfig`, :class:`DiagnoserSpec`,
  :func:`run_sweep`) over the result store of :mod:`evaluation.store`.

Import from those modules in new code.
"""

from evaluation.backends import BACKENDS, ray_runtime_env
from evaluation.records import CellResult, CellSummary, score_episode, summarize
from evaluation.sources import TRAIN_SEED_BASE, DataSource, LoadedEpisode, SimulatedData
from evaluation.sweep import (
    BASELINES,
    HARNESS_VERSION,
    DiagnoserSpec,
    SweepConfig,
    SweepResults,
    default_specs,
    detect_episode,
    load_cell,
    run_sweep,
)

__all__ = [
    "BACKENDS",
    "BASELINES",
    "HARNESS_VERSION",
    "TRAIN_SEED_BASE",
    "CellResult",
    "CellSummary",
    "DataSource",
    "DiagnoserSpec",
    "LoadedEpisode",
    "SimulatedData",
    "SweepConfig",
    "SweepResults",
    "default_specs",
    "detect_episode",
    "load_cell",
    "ray_runtime_env",
    "run_sweep",
    "score_episode",
    "summarize",
]
