"""Running a sweep: diagnosers × test episodes, in parallel, over a resumable result store.

The rooms:

=====================  ===========================================================================
``runner``             the sweep itself: :class:`SweepConfig`, :class:`DiagnoserSpec`,
                       :func:`run_sweep`, :class:`SweepResults`
``training``           training every diagnoser once per sweep and reloading its saved model
``sources``            where episodes come from: :class:`SimulatedData`, the :class:`DataSource`
                       protocol, :class:`LoadedEpisode`
``external_data``      recorded CSV/Parquet datasets as a data source (:class:`ExternalData`)
``records``            what a cell records: :class:`CellResult`, :func:`score_episode`,
                       :func:`summarize`
``store``              the resumable result store on disk (:class:`ResultStore`)
``backends``           where tasks run: local processes, Ray, or this process
``speed``              ``python -m bench.sweep_speed``: wall time of the sweep
=====================  ===========================================================================

The names below are the sweep's public API; import them from here.
"""

from evaluation.sweep.backends import BACKENDS, ray_runtime_env
from evaluation.sweep.config import (
    BASELINES,
    HARNESS_VERSION,
    DiagnoserSpec,
    SweepConfig,
    SweepResults,
    default_specs,
)
from evaluation.sweep.records import CellResult, CellSummary, score_episode, summarize
from evaluation.sweep.runner import detect_episode, load_cell, run_sweep
from evaluation.sweep.sources import TRAIN_SEED_BASE, DataSource, LoadedEpisode, SimulatedData

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
