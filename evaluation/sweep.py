"""The sweep: diagnosers × test episodes, in parallel, over a resumable result store.

A sweep is described by a frozen :class:`SweepConfig`: the diagnosers (:class:`DiagnoserSpec`,
registry name + hyperparameters + label), a data source (:mod:`evaluation.sources`) and the
start-up time ``t_on``. :func:`run_sweep` does three things, keeping recording, metrics and
presentation apart:

1. **Train** every diagnoser once per sweep on the healthy training episodes (one parallel task per
   diagnoser). The fitted diagnoser is stored with :meth:`Diagnoser.save` under the store's
   ``models/<label>`` directory, so workers load it and a resumed sweep reuses it.
2. **Score** every test episode: one parallel task per ``(scenario, seed)`` episode runs every
   diagnoser whose cell is missing on it. One task per episode, not per cell, because simulating
   the episode costs far more than a baseline's ``detect`` (≈ 45 ms versus < 1 ms for 4000
   samples), so the work grows linearly with the number of seeds and spreads over all workers.
   Each finished cell (diagnoser, scenario, seed) is written to the store at once
   (:mod:`evaluation.store`), so an interrupted sweep loses nothing finished. For the cells named
   in ``SweepConfig.keep_detections`` the worker also returns the whole :class:`Detection` and the
   episode, stored beside the cell, so figures are drawn from the scoring pass itself.
3. **Collect** the cell records of the sweep into :class:`SweepResults`
   (:mod:`evaluation.records`).

Where the tasks run is :mod:`evaluation.backends`' business (local processes by default, Ray on a
cluster, or this process with ``n_workers=0``).
"""

from __future__ import annotations

import dataclasses
import logging
import os
import tempfile
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from diagnosers.base import Detection, Diagnoser
from diagnosers.registry import available, diagnoser_class, import_modules, make
from evaluation.backends import BACKENDS, Backend, cpu_count, limit_threads, make_backend
from evaluation.records import (
    CellResult,
    CellSummary,
    detect_and_score,
    pack_detection,
    summarize,
)
from evaluation.sources import DataSource, LoadedEpisode, SimulatedData
from evaluation.store import ResultStore, canonical_hash, check_name

logger = logging.getLogger(__name__)

BASELINES: tuple[str, ...] = ("limits", "pca", "arx-band")
#: Bumped when the meaning of a stored cell record changes (part of every cell hash).
HARNESS_VERSION = 1
#: Default first training seed: far from the test seeds 0..N-1 of any realistic sweep.
TRAIN_SEED_BASE = 1000


# ---- configuration -----------------------------------------------------------------------------
@dataclass(frozen=True)
class DiagnoserSpec:
    """One diagnoser of a sweep: registry ``name``, hyperparameters and a unique ``label``.

    ``params`` must be JSON-serialisable (they are hashed into the store). ``label`` defaults to
    ``name``; give two specs of the same diagnoser different labels to compare hyperparameters.
    """

    name: str
    params: Mapping[str, Any] = field(default_factory=dict)
    label: str | None = None

    @property
    def key(self) -> str:
        """The label used in the store, tables and figures."""
        return self.label if self.label is not None else self.name

    def build(self) -> Diagnoser:
        return make(self.name, **dict(self.params))

    def to_json(self) -> dict[str, Any]:
        return {"name": self.name, "params": dict(self.params), "label": self.key}


def default_specs(
    names: Sequence[str] | None = None, *, test: bool = False
) -> tuple[DiagnoserSpec, ...]:
    """Specs for registered diagnosers with default hyperparameters.

    Args:
        names: registry names (all of :func:`diagnosers.available` when ``None``).
        test: use each class's :meth:`~diagnosers.base.Diagnoser.fast_params` (small, fast
            hyperparameters for smoke runs and tests) instead of the defaults.
    """
    names = available() if names is None else list(names)
    classes = [diagnoser_class(n) for n in names]  # unknown names: the registry's message
    return tuple(
        DiagnoserSpec(n, dict(cls.fast_params()) if test else {})
        for n, cls in zip(names, classes, strict=True)
    )


@dataclass(frozen=True, kw_only=True)
class SweepConfig:
    """A whole sweep: which diagnosers, on which data, scored from sample ``t_on`` on.

    Args:
        diagnosers: the diagnosers to train and score (labels must be unique).
        data: a :class:`DataSource` (:class:`SimulatedData` or
            :class:`evaluation.external.ExternalData`).
        t_on: start-up samples not scored for false alarms (the paper's ``t_on``; 0 scores all).
        imports: modules that register diagnosers of your own (``@diagnosers.register``),
            imported before the names are resolved, in this process and in every worker (a
            ``spawn`` worker or a Ray worker starts from a fresh interpreter). They must be
            importable there: from the installed packages, or from a directory on ``sys.path``
            (local workers inherit the driver's). Not part of any hash: they say where the code
            is, not what it computes.
    """

    diagnosers: tuple[DiagnoserSpec, ...]
    data: DataSource = field(default_factory=SimulatedData)
    t_on: int = 0
    imports: tuple[str, ...] = ()

    def validate(self) -> None:
        if isinstance(self.imports, str) or not all(isinstance(m, str) for m in self.imports):
            raise ValueError(
                f"imports={self.imports!r} is outside the allowed range: a tuple of module names"
            )
        import_modules(self.imports)
        if not self.diagnosers:
            raise ValueError(f"a sweep needs at least one diagnoser. Available: {available()}")
        labels = [d.key for d in self.diagnosers]
        dup = sorted({lab for lab in labels if labels.count(lab) > 1})
        if dup:
            raise ValueError(
                f"diagnoser labels must be unique, {dup} repeat; give DiagnoserSpec(label=...)"
            )
        for spec in self.diagnosers:
            if not isinstance(spec, DiagnoserSpec):
                raise ValueError(f"diagnosers must be DiagnoserSpec objects, got {spec!r}")
            check_name("diagnoser label", spec.key)
            try:
                # unknown name or hyperparameter, or a bad value: fail before any training
                spec.build()._validate_params()
            except (ValueError, TypeError) as e:
                raise ValueError(f"diagnoser {spec.key!r}: {e}") from e
            canonical_hash(spec.to_json())  # params must be JSON-serialisable
        if not isinstance(self.data, DataSource):
            raise ValueError(f"data={self.data!r} does not implement the DataSource protocol")
        self.data.validate()
        for sc, _ in self.data.cells():
            check_name("scenario", sc)
        if isinstance(self.t_on, bool) or not isinstance(self.t_on, int) or self.t_on < 0:
            raise ValueError(f"t_on={self.t_on!r} must be an integer >= 0")

    def model_hash(self, spec: DiagnoserSpec, data_hash: str) -> str:
        """Hash of what a trained model depends on: the diagnoser and the data.

        The hyperparameters are the *resolved* ones (defaults included) and the package version
        is part of the hash, so a changed default or a new release never reuses stale models or
        cells: the store then says so instead of mixing old and new results. Hyperparameters
        that do not change the fit (:attr:`Diagnoser.execution_params`: ``progress``,
        ``n_jobs``) are left out, so changing them reuses the stored model.
        """
        from fcc_env import MODEL_VERSION, __version__

        return canonical_hash(
            {
                "v": HARNESS_VERSION,
                "package": f"{__version__} ({MODEL_VERSION})",
                "data": data_hash,
                "name": spec.name,
                "params": spec.build().result_params(),
            }
        )

    def cell_hash(self, spec: DiagnoserSpec, data_hash: str) -> str:
        """Hash of what a cell's result depends on: the model and ``t_on``."""
        return canonical_hash({"model": self.model_hash(spec, data_hash), "t_on": self.t_on})


@dataclass(frozen=True)
class SweepResults:
    """What :func:`run_sweep` returns: every cell of the sweep plus bookkeeping.

    Attributes:
        records: one :class:`CellResult` per (diagnoser, scenario, seed), diagnosers in config
            order, then cells in the data source's order.
        n_computed / n_reused: cells computed in this call / found in the store.
        n_trained: diagnosers trained in this call (the others were loaded from the store).
        wall_s: wall time of the call.
    """

    config: SweepConfig
    store_dir: Path
    records: tuple[CellResult, ...]
    n_computed: int
    n_reused: int
    n_trained: int
    wall_s: float

    def summary(self) -> list[CellSummary]:
        return summarize(self.records)


# ---- worker side -------------------------------------------------------------------------------
_MODEL_CACHE: dict[str, Diagnoser] = {}
_MODEL_CACHE_SIZE = 8


def dir_files(path: Path) -> dict[str, bytes]:
    return {
        p.relative_to(path).as_posix(): p.read_bytes()
        for p in sorted(path.rglob("*"))
        if p.is_file()
    }


def _load_model(model_hash: str, source: str | Mapping[str, bytes]) -> Diagnoser:
    """Load a stored model (a directory path, or its files as bytes), cached per process.

    The cache is keyed by the model hash, so a worker that scores many episodes loads each model
    once. ``Diagnoser.detect`` resets the diagnoser before and after, so reuse is safe.
    """
    diag = _MODEL_CACHE.get(model_hash)
    if diag is not None:
        return diag
    if isinstance(source, str):
        diag = Diagnoser.load(source)
    else:
        with tempfile.TemporaryDirectory(prefix="fcc-model-") as d:
            for rel, data in source.items():
                target = Path(d) / rel
                target.parent.mkdir(parents=True, exist_ok=True)
                target.write_bytes(data)
            diag = Diagnoser.load(d)
    if len(_MODEL_CACHE) >= _MODEL_CACHE_SIZE:
        _MODEL_CACHE.pop(next(iter(_MODEL_CACHE)))
    _MODEL_CACHE[model_hash] = diag
    return diag


def training_jobs(to_train: Sequence[DiagnoserSpec], cores: int) -> dict[str, int]:
    """``n_jobs`` for each diagnoser of ``to_train`` that has the parameter and leaves it unset.

    The cores are shared among those trainings (the ones with worker processes of their own, the
    long ones): a bank that trains alone gets them all, and several never get more than the
    cores between them. Baselines train in seconds beside them. ``n_jobs`` is an execution
    parameter: it changes no model hash.
    """
    own = [
        s.key
        for s in to_train
        if "n_jobs" in diagnoser_class(s.name)._param_names() and s.params.get("n_jobs") is None
    ]
    return {key: max(1, cores // len(own)) for key in own}


def _train_task(
    spec: DiagnoserSpec,
    data: DataSource,
    imports: tuple[str, ...] = (),
    n_jobs: int | None = None,
    _serial: bool = False,
) -> tuple[dict[str, bytes], dict[str, Any]]:
    """Fit one diagnoser on the healthy training episodes; return its saved files and facts.

    ``n_jobs``: set on the diagnoser (see :func:`training_jobs`) unless ``None``.
    """
    if not _serial:
        limit_threads()
    import_modules(imports)  # a fresh worker has not seen the user's registrations
    t0 = time.perf_counter()
    episodes = data.train_episodes()
    if spec.build().isolates:
        # an isolating diagnoser also learns labelled faults (training seeds only)
        faulty = getattr(data, "train_fault_episodes", None)
        if faulty is None:
            raise RuntimeError(
                f"training {spec.key}: it isolates faults, but the data source "
                f"{type(data).__name__} has no labelled training faults (train_fault_episodes)"
            )
        episodes = episodes + faulty()
    diag = spec.build()
    if n_jobs is not None:
        diag.set_params(n_jobs=n_jobs)
    try:
        diag.fit(episodes)
    except Exception as e:
        raise RuntimeError(f"training {spec.key}: {type(e).__name__}: {e}") from e
    wall = time.perf_counter() - t0
    with tempfile.TemporaryDirectory(prefix="fcc-train-") as d:
        diag.save(d)
        files = dir_files(Path(d))
    info = {
        "train_wall_s": wall,
        "n_train_episodes": len(episodes),
        "n_train_samples": int(sum(ep.n_samples for ep in episodes)),
    }
    return files, info


@dataclass(frozen=True)
class _EpisodeTask:
    """Score the diagnosers ``labels`` on episode ``(scenario, seed)`` of ``data``."""

    data: DataSource
    scenario: str
    seed: int
    t_on: int
    labels: tuple[str, ...]
    model_hashes: tuple[str, ...]
    model_paths: tuple[str, ...] | None  # local backend; None when models come as bytes
    keep: tuple[bool, ...] = ()  # per label: return the whole detection (a figure cell)
    imports: tuple[str, ...] = ()  # SweepConfig.imports, imported in the worker


def _episode_task(
    task: _EpisodeTask, *model_files: Mapping[str, bytes], _serial: bool = False
) -> list[tuple[dict[str, Any], dict[str, Any] | None]]:
    """``(record, detection arrays or None)`` per label of the task."""
    if not _serial:
        limit_threads()
    import_modules(task.imports)
    loaded = task.data.load_test(task.scenario, task.seed)
    out = []
    keep = task.keep or (False,) * len(task.labels)
    for i, (label, mhash) in enumerate(zip(task.labels, task.model_hashes, strict=True)):
        source = task.model_paths[i] if task.model_paths is not None else model_files[i]
        try:
            diag = _load_model(mhash, source)
            rec, det = detect_and_score(diag, loaded, label=label, t_on=task.t_on)
            arrays = (
                pack_detection(loaded, det, diag.band_view(loaded.episode)) if keep[i] else None
            )
        except Exception as e:
            # Name the cell: the traceback of a worker process does not reach the user.
            raise RuntimeError(
                f"{label} on {task.scenario}, seed {task.seed}: {type(e).__name__}: {e}"
            ) from e
        # External data name the episode by file; keep the sweep's cell key as given.
        rec = dataclasses.replace(rec, scenario=task.scenario, seed=task.seed)
        out.append((rec.to_json(), arrays))
    return out


# ---- the sweep ---------------------------------------------------------------------------------
def run_sweep(
    config: SweepConfig,
    store_dir: str | os.PathLike,
    backend: str = "local",
    n_workers: int | None = None,
    ray_address: str | None = None,
    progress: bool = True,
    figure_cells: Sequence[tuple[str, int]] = (),
) -> SweepResults:
    """Train and score every diagnoser of ``config``, resuming from ``store_dir``.

    Args:
        config: the sweep.
        store_dir: result store directory (created if missing; see :mod:`evaluation.store`).
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

    Returns:
        :class:`SweepResults` with every cell of the sweep.

    Raises:
        ValueError: bad configuration (message names the value and the allowed set).
        evaluation.store.StoreError: the store is corrupted, foreign or of another sweep.
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

    # Which work is left: models to train, and per episode the diagnosers still missing.
    to_train = [s for s in specs if not store.has_model(s.key, mhash[s.key])]
    cells = config.data.cells()
    unknown = sorted(set(map(tuple, figure_cells)) - set(cells))
    if unknown:
        raise ValueError(f"figure_cells={unknown} are not test cells of this sweep")
    figures = set(map(tuple, figure_cells))
    # Per episode: (spec, cell missing?, detection missing?) for every diagnoser with work left.
    missing: dict[tuple[str, int], list[tuple[DiagnoserSpec, bool, bool]]] = {}
    for sc, seed in cells:
        for s in specs:
            rec = store.read_cell(s.key, sc, seed, chash[s.key])
            no_cell = rec is None
            if rec is not None:  # a bad stored record is reported before any work is done
                _cell_result(store, rec, s.key, sc, seed)
            no_det = (sc, seed) in figures and (
                store.read_detection(s.key, sc, seed, chash[s.key]) is None
            )
            if no_cell or no_det:
                missing.setdefault((sc, seed), []).append((s, no_cell, no_det))
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
        runner = make_backend(backend, n_workers, max(len(to_train), len(missing)), ray_address)
        # worker processes of the trainings' own on this machine's cores (local backend only:
        # a Ray task holds one CPU of a node)
        cores = (n_workers or cpu_count()) if backend == "local" and n_workers != 0 else 1
        cancel = True
        try:
            _train_all(runner, store, config, to_train, mhash, progress, cores)
            _score_all(runner, store, config, missing, mhash, chash, n_missing, progress)
            cancel = False
        finally:
            runner.close(cancel=cancel)

    records = []
    for s in specs:
        for sc, seed in cells:
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
    from tqdm.auto import tqdm

    return tqdm(total=total, desc=desc, unit="cell", disable=not enabled or total == 0, leave=False)


def _train_all(
    runner: Backend,
    store: ResultStore,
    config: SweepConfig,
    to_train: list[DiagnoserSpec],
    mhash: Mapping[str, str],
    progress: bool,
    cores: int = 1,
) -> None:
    if not to_train:
        return
    jobs = training_jobs(to_train, cores) if cores > 1 else {}
    handles = {
        runner.submit(_train_task, s, config.data, config.imports, jobs.get(s.key)): s
        for s in to_train
    }
    with _progress_bar(len(to_train), "training", progress) as bar:
        it = runner.completed(list(handles))
        while True:
            try:
                handle, (files, info) = next(it)
            except StopIteration:
                break
            except Exception as e:  # a worker's exception, re-raised with the cell's name
                raise RuntimeError(f"training failed: {type(e).__name__}: {e}") from e
            spec = handles[handle]
            store.write_model(spec.key, mhash[spec.key], files, {**spec.to_json(), **info})
            bar.update(1)


def _score_all(
    runner: Backend,
    store: ResultStore,
    config: SweepConfig,
    missing: Mapping[tuple[str, int], list[tuple[DiagnoserSpec, bool, bool]]],
    mhash: Mapping[str, str],
    chash: Mapping[str, str],
    n_missing: int,
    progress: bool,
) -> None:
    if not missing:
        return
    labels_needed = {s.key for ss in missing.values() for s, _, _ in ss}
    refs: dict[str, Any] = {}
    if not runner.passes_paths:
        # Ship each model's files once (Ray's object store), not once per task.
        refs = {lab: runner.put(dir_files(store.model_dir(lab))) for lab in labels_needed}
    handles: dict[Any, tuple[str, int]] = {}
    need_cell = {(sc, seed, s.key): cell for (sc, seed), ss in missing.items() for s, cell, _ in ss}
    for (sc, seed), ss in missing.items():
        labels = tuple(s.key for s, _, _ in ss)
        task = _EpisodeTask(
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
        )
        args = [] if runner.passes_paths else [refs[lab] for lab in labels]
        handles[runner.submit(_episode_task, task, *args)] = (sc, seed)
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
            for rec, arrays in recs:
                label = rec["diagnoser"]
                if arrays is not None:
                    store.write_detection(label, sc, seed, chash[label], arrays)
                if need_cell[(sc, seed, label)]:
                    store.write_cell(label, sc, seed, chash[label], rec)
                    bar.update(1)


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
