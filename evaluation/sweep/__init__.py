"""Running a sweep: diagnosers × test episodes, in parallel, over a resumable result store.

The rooms:

=====================  ===========================================================================
``config``             what a sweep is: :class:`SweepConfig`, :class:`DiagnoserSpec`,
                       :class:`SweepResults`
``runner``             the sweep itself: :func:`run_sweep`, training every diagnoser once and
                       scoring every cell
``tasks``              the tasks a worker runs: train one diagnoser, score one episode
``training_stage``     the training stage: every diagnoser and every relation of its banks a task
``sources``            where episodes come from: :class:`SimulatedData`, the :class:`DataSource`
                       protocol, :class:`LoadedEpisode`
``external_data``      recorded CSV/Parquet datasets as a data source (:class:`ExternalData`)
``dataset_loaders``    how a data directory (a ``dataset.json`` manifest) becomes one
``records``            what a cell records: :class:`CellResult`, :func:`score_episode`,
                       :func:`summarize`
``store``              the resumable result store on disk (:class:`ResultStore`)
``backends``           where tasks run: local processes, Ray, or this process
``backends_watchdog``  reaps the local Ray cluster of a driver that was killed
``task_log``           per-task accounting: each task's CPU and wall seconds, kind, key and
                       dependencies, and the driver's own time, in the store's ``timings.jsonl``
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
