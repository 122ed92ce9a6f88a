"""Benchmark v2: the leaderboard per track, with the physical-limit row and 95 % intervals.

``python -m evaluation.leaderboard --track paper,small`` (or ``--track all``) runs, for each
track of :mod:`evaluation.tracks`, a sweep of the chosen diagnosers over the track's test cells
(:class:`evaluation.tracks.track_data.TrackData`), scores the physical-limit observer
(:mod:`evaluation.tracks.oracle`) on the same cells, and writes into ``<out>/<track>/``:

* ``leaderboard.md`` / ``.csv`` / ``.json`` — one row per diagnoser plus six reference rows
  (:data:`evaluation.tracks.oracle.DEFAULT_REFERENCES`), the ``oracle`` (physical limit), the
  ``perfect model (measured inputs)``, the ``perfect model + lrgf-glr stage (measured
  inputs)``, the reachable bound ``optimal filter (exact model, measured channels)``
  (:mod:`evaluation.tracks.filter_bound`) and the optimal-detector rows ``optimal CUSUM (known fault)`` (the bound at the
  same false-alarm rate) and ``GLR (known type, unknown size)``
  (:mod:`evaluation.tracks.optimal`):
  r_fd with its 95 % bootstrap interval over healthy episodes, the share of healthy episodes
  with any alarm and the worst one; per fault r_td and t_dt with intervals, the ratio
  ``(t_dt + 1) / (oracle t_dt + 1)`` with its paired interval, misses and early terminations;
  ranks per fault on r_td within each tier (black box, grey box: what a detector may know of
  the plant, :class:`diagnosers.Tier`) that mark ties when intervals overlap;
* ``results.csv`` / ``results.json`` — every per-seed record (the oracle's too);
* ``figures/`` — as the classic leaderboard.

and ``<out>/summary.md`` / ``.csv`` / ``.json``: diagnosers × tracks (r_fd with interval, mean
r_td over faults, mean t_dt / oracle ratio, the faults at the physical limit and whether r_fd's
upper end holds the goal, :func:`~evaluation.tracks.goal.limit_goal`) and the wall time per track.
:func:`run_track` runs a track; :mod:`evaluation.tracks.board_tables` writes those files.
"""

from __future__ import annotations

import os
import shutil
import sys
import tempfile
import time
from collections.abc import Collection, Mapping, Sequence
from pathlib import Path
from typing import Any

from diagnosers.bank.relations import read_channels, required_channels
from diagnosers.range_guard import RangeGuard
from diagnosers.registry import diagnoser_class, import_modules, make
from diagnosers.stages.operating_range import SETPOINT_CHANNELS
from evaluation.reports.outputs import figure_cells, write_figures
from evaluation.sweep.config import DiagnoserSpec, SweepConfig, default_specs
from evaluation.sweep.runner import run_sweep
from evaluation.sweep.store import ResultStore, canonical_hash
from evaluation.sweep.task_log import TIMINGS_FILE, TaskLog
from evaluation.sweep.tasks import dir_files
from evaluation.tracks.oracle import DEFAULT_REFERENCES
from evaluation.tracks.reference_runs import run_references
from evaluation.tracks.rows import TrackRun, track_rows
from evaluation.tracks.track import Track
from evaluation.tracks.track_data import TrackData
from fcc_env.closed_loop import CLOSED_LOOP_CHANNELS
from fcc_env.params import MEASUREMENT_NAMES

__all__ = ["applicable", "model_cache_dir", "run_track", "track_channels"]


def applicable(
    names: Sequence[str],
    channels: Collection[str],
    where: str,
    params: Mapping[str, Mapping[str, Any]] | None = None,
) -> tuple[list[str], list[str]]:
    """(the diagnosers of ``names`` that can read ``channels``, one-line reasons for the
    others, saying they are skipped ``where``). A novelty variant
    (:class:`~diagnosers.range_guard.RangeGuard`) needs a set point among ``channels`` too. ``params``: hyperparameters per diagnoser
    (e.g. a data set's relations) that replace its defaults before its channels are read."""
    keep, skipped = [], []
    for name in names:
        given = (params or {}).get(name)
        need = required_channels(name) if not given else read_channels(make(name, **given))
        missing = sorted(need - set(channels))
        if missing:
            skipped.append(f"{name}: skipped {where} (no channel {', '.join(missing)})")
        elif issubclass(diagnoser_class(name), RangeGuard) and not set(SETPOINT_CHANNELS) & set(
            channels
        ):
            # without set points its novelty flag never fires: it would repeat its base's row
            skipped.append(f"{name}: skipped {where} (no set point for its novelty flag)")
        else:
            keep.append(name)
    return keep, skipped


def track_channels(track: Track) -> tuple[str, ...]:
    """The channels a track's episodes have."""
    return CLOSED_LOOP_CHANNELS if track.closed_loop else MEASUREMENT_NAMES


def run_track(
    track: Track,
    diagnosers: Sequence[str],
    out: Path,
    *,
    backend: str = "local",
    workers: int | None = None,
    ray_address: str | None = None,
    progress: bool = True,
    figures: bool = True,
    model_cache: Path | None = None,
    imports: Sequence[str] = (),
    relation_cache: Path | None = None,
) -> TrackRun:
    """Sweep ``diagnosers`` over ``track`` and add the reference rows (resumable: the rows'
    records are stored in the track's store too, :mod:`evaluation.tracks.reference_runs`, and
    computed as tasks of the same ``backend``).

    ``model_cache``: a directory of trained models shared by tracks; a track whose training
    episodes equal another's (:meth:`TrackData.training_key`: same seeds, noise and plant
    variation) reuses that track's models instead of training again. ``imports``: modules
    that register diagnosers of your own (:attr:`SweepConfig.imports`). ``relation_cache``: a
    directory of trained relations shared by the trainings of every track
    (:mod:`diagnosers.bank.relation_cache`).
    """
    t0 = time.perf_counter()
    data = TrackData(track=track)
    import_modules(imports)
    diagnosers, skipped = applicable(diagnosers, track_channels(track), f"on track {track.name}")
    for line in skipped:
        print(line, file=sys.stderr)
    config = SweepConfig(diagnosers=default_specs(diagnosers), data=data, imports=tuple(imports))
    config.validate()
    for reference in DEFAULT_REFERENCES:  # refuse seed clashes before any work, not after it
        reference.calibration_seeds(track)
    store = out / "store" / canonical_hash(data.store_key())[:12]
    n_reused_models = 0
    if model_cache is not None:
        n_reused_models = _models_from_cache(config, store, model_cache)
    results = run_sweep(
        config,
        store,
        backend=backend,
        n_workers=workers,
        ray_address=ray_address,
        progress=progress,
        figure_cells=figure_cells(config) if figures else (),
        relation_cache=relation_cache,
    )
    log = TaskLog(store / TIMINGS_FILE, "track", backend, workers)
    if model_cache is not None:
        with log.stage("model-cache"):
            _models_to_cache(config, store, model_cache)
    references, n_references = run_references(
        data,
        DEFAULT_REFERENCES,
        store,
        backend=backend,
        n_workers=workers,
        ray_address=ray_address,
        progress=progress,
    )
    records = (*results.records, *references)
    tiers = {s.key: str(diagnoser_class(s.name).tier) for s in config.diagnosers}
    with log.stage("rows"):
        rows = track_rows(records, [s.key for s in config.diagnosers], track.faults, tiers)
    if figures:
        with log.stage("figures"):
            write_figures(results, out / "figures")
    return TrackRun(
        track=track,
        records=records,
        rows=tuple(rows),
        wall_s=time.perf_counter() - t0,
        n_computed=results.n_computed,
        n_reused=results.n_reused,
        n_trained=results.n_trained,
        n_reused_models=n_reused_models,
        n_reference_computed=n_references,
    )


def model_cache_dir(config: SweepConfig, spec: DiagnoserSpec, cache: Path) -> Path:
    """Where the model cache ``cache`` files ``spec``'s model trained on ``config``'s track:
    tracks with the same training set (and, for a diagnoser that learns faults, the same
    labelled faults) share the directory, so a later track reuses the model."""
    data = config.data
    assert isinstance(data, TrackData)
    # model_hash with a constant data part: the package version and the resolved settings
    key = {"training": data.training_key(), "model": config.model_hash(spec, "training-key")}
    diag = spec.build()
    if diag.isolates or diag.learns_from_faults:  # it also learns the track's labelled faults
        key["faults"] = data.fault_training_key()
    return cache / spec.key / canonical_hash(key)[:16]


def _models_from_cache(config: SweepConfig, store_dir: Path, cache: Path) -> int:
    """Copy cached models of an equal training set into the track's store; how many."""
    store = ResultStore.open(store_dir, config.data.store_key())
    n = 0
    for spec in config.diagnosers:
        mhash = config.model_hash(spec, store.data_hash)
        src = model_cache_dir(config, spec, cache)
        if not store.has_model(spec.key, mhash) and (src / "model").is_dir():
            files = dir_files(src / "model")
            store.write_model(spec.key, mhash, files, {**spec.to_json(), "from_cache": str(src)})
            n += 1
    return n


def _models_to_cache(config: SweepConfig, store_dir: Path, cache: Path) -> None:
    """Offer the track's trained models to the cache (atomic: a renamed temporary copy)."""
    store = ResultStore.open(store_dir, config.data.store_key())
    for spec in config.diagnosers:
        dst = model_cache_dir(config, spec, cache)
        if (dst / "model").is_dir():
            continue
        dst.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(dir=dst, prefix=".model.", suffix=".tmp"))
        shutil.copytree(store.model_dir(spec.key), tmp, dirs_exist_ok=True, ignore=_spec_json)
        try:
            os.rename(tmp, dst / "model")
        except OSError:  # another run cached it first
            shutil.rmtree(tmp, ignore_errors=True)


def _spec_json(directory: str, names: list[str]) -> list[str]:
    return ["spec.json"] if "spec.json" in names else []
