"""The sweep: diagnosers × test episodes, in parallel, over a resumable result store.

A sweep is described by a frozen :class:`~evaluation.sweep.config.SweepConfig`: the diagnosers (:class:`DiagnoserSpec`,
registry name + hyperparameters + label), a data source (:mod:`evaluation.sweep.sources`) and the
start-up time ``t_on``. :func:`run_sweep` does three things, keeping recording, metrics and
presentation apart:

1. **Train** every diagnoser once per sweep on the healthy training episodes (one parallel task per
   diagnoser, and one per relation of its banks: :mod:`evaluation.sweep.training_stage`). The
   fitted diagnoser is stored with :meth:`Diagnoser.save` under the store's ``models/<label>``
   directory, so workers load it and a resumed sweep reuses it.
2. **Score** every test episode: one parallel task per ``(scenario, seed)`` episode runs every
   diagnoser whose cell is missing on it. One task per episode, not per cell, because simulating
   the episode costs far more than a baseline's ``detect`` (≈ 45 ms versus < 1 ms for 4000
   samples), so the work grows linearly with the number of seeds and spreads over all workers.
   Each finished cell (diagnoser, scenario, seed) is written to the store at once
   (:mod:`evaluation.sweep.store`), so an interrupted sweep loses nothing finished. For the cells named
   in ``SweepConfig.keep_detections`` the worker also returns the whole :class:`Detection` and the
   episode, stored beside the cell, so figures are drawn from the scoring pass itself.
   An isolator wrapping a detector of the same sweep (:func:`inner_detectors`: its saved inner
   model is that detector's, file for file) does not run that detector again: its cell takes
   the detector's detection of the episode, computed first in the same task, or stored by an
   earlier run (``inner/<detector>/``, keyed by the detector's cell hash), and runs only its
   isolation stage; the records are the bits of a full ``detect``.
3. **Collect** the cell records of the sweep into :class:`SweepResults`
   (:mod:`evaluation.sweep.records`).

Where the tasks run is :mod:`evaluation.sweep.backends`' business (local processes by default, Ray on a
cluster, or this process with ``n_workers=0``).
"""

from __future__ import annotations

import logging
import os
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from tqdm.auto import tqdm

from diagnosers.detection import Detection
from diagnosers.diagnoser import Diagnoser
from diagnosers.isolation.isolating_detector import IsolatingDetector
from diagnosers.registry import import_modules
from evaluation.sweep.backends import BACKENDS, Backend, make_backend
from evaluation.sweep.config import DiagnoserSpec, SweepConfig, SweepResults
from evaluation.sweep.records import (
    CellResult,
)
from evaluation.sweep.sources import LoadedEpisode
from evaluation.sweep.store import ResultStore
from evaluation.sweep.task_log import TIMINGS_FILE, ProfiledBackend, TaskLog, submit_task
from evaluation.sweep.tasks import OWN_INNER, EpisodeTask, dir_files, episode_task
from evaluation.sweep.training_stage import train_all
from fcc_common.workers import cpu_count

__all__ = ["detect_episode", "inner_detectors", "load_cell", "run_sweep"]

logger = logging.getLogger(__name__)


# ---- the sweep ---------------------------------------------------------------------------------
def run_sweep(
    config: SweepConfig,
    store_dir: str | os.PathLike,
    backend: str = "local",
    n_workers: int | None = None,
    ray_address: str | None = None,
    progress: bool = True,
    figure_cells: Sequence[tuple[str, int]] = (),
    relation_cache: str | os.PathLike | None = None,
) -> SweepResults:
    """Train and score every diagnoser of ``config``, resuming from ``store_dir``.

    Args:
        config: the sweep.
        store_dir: result store directory (created if missing; see :mod:`evaluation.sweep.store`).
        backend: ``"local"`` (process pool) or ``"ray"``.
        n_workers: worker processes / Ray CPUs for a local Ray instance; default: all cores of
            this machine, capped at the number of tasks. ``0`` (local backend only) runs every
            task in this process, for debugging and fast tests.
        ray_address: address of a running Ray cluster (``backend="ray"`` only). Its workers
            must be able to import this package (install it there, or start the cluster with a
            ``runtime_env``); a local instance started here gets :func:`ray_runtime_env`. If
            Ray is already initialised in this process, that instance is used and left running.
        progress: show a tqdm progress bar over cells (on stderr).
        figure_cells: ``(scenario, seed)`` test cells whose whole detection (and band view) is
            kept in the store (:meth:`ResultStore.read_detection`) for figures: it is computed
            in the scoring pass itself, never by a second simulation and detection.
        relation_cache: a directory of trained relations that the trainings share
            (:mod:`diagnosers.bank.relation_cache`): a relation job that one LRGF diagnoser trains
            is read by the others (``lrgf-mem``'s bank is the isolators' inner bank and partly
            ``lrgf-glr``'s fold bank). ``None`` (default): each trains its own. It changes no
            model: a cached relation has the bits of a fresh training.

    Returns:
        :class:`SweepResults` with every cell of the sweep.

    Raises:
        ValueError: bad configuration (message names the value and the allowed set).
        evaluation.sweep.store.StoreError: the store is corrupted, foreign or of another sweep.
        RuntimeError: a training or scoring task failed (cells finished before stay stored).
    """
    t_start = time.perf_counter()
    if backend not in BACKENDS:
        raise ValueError(f"Unknown backend {backend!r}. Available: {list(BACKENDS)}")
    if ray_address is not None and backend != "ray":
        raise ValueError("ray_address is only used with backend='ray'")
    if n_workers is not None and (
        isinstance(n_workers, bool) or not isinstance(n_workers, int) or n_workers < 0
    ):
        raise ValueError(f"n_workers={n_workers!r} must be an integer >= 0 or None")
    if n_workers == 0 and backend != "local":
        raise ValueError("n_workers=0 (run in this process) needs backend='local'")
    config.validate()
    store = ResultStore.open(store_dir, config.data.store_key())
    specs = list(config.diagnosers)
    mhash = {s.key: config.model_hash(s, store.data_hash) for s in specs}
    chash = {s.key: config.cell_hash(s, store.data_hash) for s in specs}

    log = TaskLog(store.root / TIMINGS_FILE, "sweep", backend, n_workers)
    with log.stage("plan"):
        to_train, missing, stored = _work_left(store, config, specs, mhash, chash, figure_cells)
    cells = config.data.cells()
    n_missing = sum(need_cell for v in missing.values() for _, need_cell, _ in v)
    logger.info(
        "sweep in %s: %d of %d diagnosers to train, %d of %d cells to score (%s backend)",
        store.root,
        len(to_train),
        len(specs),
        n_missing,
        len(specs) * len(cells),
        backend,
    )

    if to_train or missing:
        # a training may add relation tasks, unknown before it runs: then no cap below the
        # workers (a local pool starts its workers on demand)
        n_tasks = max(len(to_train), len(missing), (n_workers or cpu_count()) if to_train else 0)
        runner = ProfiledBackend(make_backend(backend, n_workers, n_tasks, ray_address), log)
        cancel = True
        try:
            cache = None if relation_cache is None else str(relation_cache)
            with log.stage("train"), _progress_bar(len(to_train), "training", progress) as bar:
                train_all(runner, store, config, to_train, mhash, cache, bar)
            with log.stage("score"):
                inner_of = inner_detectors(store, specs)
                plan = _ScorePlan(store, chash, inner_of)
                _score_all(runner, store, config, missing, mhash, plan, n_missing, progress)
            cancel = False
        finally:
            runner.close(cancel=cancel)

    records = []
    with log.stage("collect"):
        for s in specs:
            for sc, seed in cells:
                if (s.key, sc, seed) in stored:
                    records.append(stored[s.key, sc, seed])
                    continue
                rec = store.read_cell(s.key, sc, seed, chash[s.key])
                if rec is None:  # only if a file vanished while we ran
                    raise RuntimeError(f"cell {s.key}/{sc}/seed {seed} is missing after the sweep")
                records.append(_cell_result(store, rec, s.key, sc, seed))
    return SweepResults(
        config=config,
        store_dir=store.root,
        records=tuple(records),
        n_computed=n_missing,
        n_reused=len(records) - n_missing,
        n_trained=len(to_train),
        wall_s=time.perf_counter() - t_start,
    )


def _work_left(
    store: ResultStore,
    config: SweepConfig,
    specs: Sequence[DiagnoserSpec],
    mhash: Mapping[str, str],
    chash: Mapping[str, str],
    figure_cells: Sequence[tuple[str, int]],
) -> tuple[
    list[DiagnoserSpec],
    dict[tuple[str, int], list[tuple[DiagnoserSpec, bool, bool]]],
    dict[tuple[str, str, int], CellResult],
]:
    """Which work is left: ``(models to train, per episode the diagnosers still missing as
    (spec, cell missing?, detection missing?), the stored cells read)``."""
    to_train = [s for s in specs if not store.has_model(s.key, mhash[s.key])]
    cells = config.data.cells()
    unknown = sorted(set(map(tuple, figure_cells)) - set(cells))
    if unknown:
        raise ValueError(f"figure_cells={unknown} are not test cells of this sweep")
    figures = set(map(tuple, figure_cells))
    # Per episode: (spec, cell missing?, detection missing?) for every diagnoser with work left.
    missing: dict[tuple[str, int], list[tuple[DiagnoserSpec, bool, bool]]] = {}
    stored: dict[tuple[str, str, int], CellResult] = {}  # each stored file is read once
    for sc, seed in cells:
        for s in specs:
            rec = store.read_cell(s.key, sc, seed, chash[s.key])
            no_cell = rec is None
            if rec is not None:  # a bad stored record is reported before any work is done
                stored[s.key, sc, seed] = _cell_result(store, rec, s.key, sc, seed)
            no_det = (sc, seed) in figures and (
                store.read_detection(s.key, sc, seed, chash[s.key]) is None
            )
            if no_cell or no_det:
                missing.setdefault((sc, seed), []).append((s, no_cell, no_det))
    return to_train, missing, stored


def _cell_result(
    store: ResultStore, rec: Mapping[str, Any], label: str, scenario: str, seed: int
) -> CellResult:
    """The stored record as a :class:`CellResult`; a bad one names its file and the remedy."""
    try:
        return CellResult.from_json(rec)
    except (ValueError, TypeError) as e:
        path = store.cell_path(label, scenario, seed)
        raise ValueError(f"{path}: {e}; delete it to recompute this cell") from e


def _progress_bar(total: int, desc: str, enabled: bool) -> Any:
    return tqdm(total=total, desc=desc, unit="cell", disable=not enabled or total == 0, leave=False)


def _score_all(
    runner: Backend,
    store: ResultStore,
    config: SweepConfig,
    missing: Mapping[tuple[str, int], list[tuple[DiagnoserSpec, bool, bool]]],
    mhash: Mapping[str, str],
    plan: _ScorePlan,
    n_missing: int,
    progress: bool,
) -> None:
    if not missing:
        return
    chash = plan.chash
    labels_needed = {s.key for ss in missing.values() for s, _, _ in ss}
    refs: dict[str, Any] = {}
    if not runner.passes_paths:
        # Ship each model's files once (Ray's object store), not once per task.
        refs = {lab: runner.put(dir_files(store.model_dir(lab))) for lab in labels_needed}
    handles: dict[Any, tuple[str, int]] = {}
    need_cell = {(sc, seed, s.key): cell for (sc, seed), ss in missing.items() for s, cell, _ in ss}
    for (sc, seed), unordered in missing.items():
        ss = sorted(unordered, key=lambda t: t[0].key in plan.inner_of)  # detectors first
        labels = tuple(s.key for s, _, _ in ss)
        inner, given, share = plan.episode(sc, seed, labels)
        task = EpisodeTask(
            data=config.data,
            scenario=sc,
            seed=seed,
            t_on=config.t_on,
            labels=labels,
            model_hashes=tuple(mhash[lab] for lab in labels),
            model_paths=(
                tuple(str(store.model_dir(lab).resolve()) for lab in labels)
                if runner.passes_paths
                else None
            ),
            keep=tuple(det for _, _, det in ss),
            imports=tuple(config.imports),
            inner=inner,
            inner_arrays=given,
            share=share,
        )
        args = [] if runner.passes_paths else [refs[lab] for lab in labels]
        handle = submit_task(runner, "episode", f"{sc}/{seed}", episode_task, task, *args, after=())
        handles[handle] = (sc, seed)
    with _progress_bar(n_missing, "cells", progress) as bar:
        it = runner.completed(list(handles))
        while True:
            try:
                handle, recs = next(it)
            except StopIteration:
                break
            except Exception as e:
                raise RuntimeError(f"scoring failed: {type(e).__name__}: {e}") from e
            sc, seed = handles[handle]
            for rec, arrays, inner_arrays in recs:
                label = rec["diagnoser"]
                if arrays is not None:
                    store.write_detection(label, sc, seed, chash[label], arrays)
                if inner_arrays is not None:  # a detector's detection, for its isolators
                    det_label = plan.inner_of.get(label, label)
                    store.write_detection(
                        det_label, sc, seed, chash[det_label], inner_arrays, inner=True
                    )
                if need_cell[(sc, seed, label)]:
                    store.write_cell(label, sc, seed, chash[label], rec)
                    bar.update(1)


def inner_detectors(store: ResultStore, specs: Sequence[DiagnoserSpec]) -> dict[str, str]:
    """Which isolator of the sweep wraps which detector of the sweep: ``{isolator label:
    detector label}``, from their stored models.

    An isolator (:class:`~diagnosers.isolation.isolating_detector.IsolatingDetector`) counts
    as wrapping a detector only when its saved inner model (``models/<isolator>/detector``)
    holds the same files, byte for byte, as the detector's model: then the detector's
    detection of an episode *is* the inner detection, and the isolator's cell reuses it.
    Settings that merely look alike (the same name and hyperparameters) are not trusted.
    """
    out: dict[str, str] = {}
    for s in specs:
        iso = s.build()
        if not isinstance(iso, IsolatingDetector):
            continue
        inner_dir = store.model_dir(s.key) / "detector"
        if not inner_dir.is_dir():
            continue
        inner_files = dir_files(inner_dir)
        for d in specs:
            if d.name != iso.detector_name or d.key == s.key:
                continue
            files = dir_files(store.model_dir(d.key))
            files.pop("spec.json", None)  # the store's own record (wall times)
            if files == inner_files:
                out[s.key] = d.key
                break
    return out


@dataclass(frozen=True)
class _ScorePlan:
    """Which inner detections each episode task computes, reads or hands on (for
    :class:`~evaluation.sweep.tasks.EpisodeTask`'s ``inner``, ``inner_arrays``, ``share``)."""

    store: ResultStore
    chash: Mapping[str, str]
    inner_of: Mapping[str, str]  # isolator label -> detector label (inner_detectors)

    def _stored(self, det_label: str, sc: str, seed: int) -> dict[str, Any] | None:
        return self.store.read_detection(det_label, sc, seed, self.chash[det_label], inner=True)

    def episode(
        self, sc: str, seed: int, labels: Sequence[str]
    ) -> tuple[tuple[int, ...], tuple[dict[str, Any] | None, ...], tuple[bool, ...]]:
        """``(inner, inner_arrays, share)`` of the task of episode ``(sc, seed)`` that scores
        ``labels`` (detectors before isolators)."""
        wrapped = set(self.inner_of.values())
        inner, given, share = [], [], []
        for label in labels:
            det_label = self.inner_of.get(label)
            stored = None
            if det_label is None:
                inner.append(-1)
            elif det_label in labels:  # computed earlier in the task
                inner.append(labels.index(det_label))
            else:
                stored = self._stored(det_label, sc, seed)
                inner.append(-1 if stored is not None else OWN_INNER)
            given.append(stored)
            share.append(label in wrapped and not self._has_inner(label, sc, seed))
        return tuple(inner), tuple(given), tuple(share)

    def _has_inner(self, det_label: str, sc: str, seed: int) -> bool:
        return self.store.detection_path(det_label, sc, seed, inner=True).is_file()


def detect_episode(
    config: SweepConfig, store_dir: str | os.PathLike, label: str, scenario: str, seed: int
) -> tuple[LoadedEpisode, Detection]:
    """Re-run one cell in this process and return the episode and the full :class:`Detection`.

    For inspection of any cell after :func:`run_sweep` (which keeps whole detections only of its
    ``figure_cells``): the model is loaded from the store and the episode regenerated, so the
    arrays match the stored cell.
    """
    loaded, diag = load_cell(config, store_dir, label, scenario, seed)
    return loaded, diag.detect(loaded.episode)


def load_cell(
    config: SweepConfig, store_dir: str | os.PathLike, label: str, scenario: str, seed: int
) -> tuple[LoadedEpisode, Diagnoser]:
    """The episode of one cell and the trained diagnoser ``label`` loaded from the store."""
    import_modules(config.imports)
    store = ResultStore.open(store_dir, config.data.store_key())
    specs = {s.key: s for s in config.diagnosers}
    if label not in specs:
        raise ValueError(f"Unknown diagnoser label {label!r}. In this sweep: {sorted(specs)}")
    if not store.has_model(label, config.model_hash(specs[label], store.data_hash)):
        raise ValueError(f"{label!r} has no trained model in {store.root}; run run_sweep first")
    diag = Diagnoser.load(store.model_dir(label))
    return config.data.load_test(scenario, seed), diag
