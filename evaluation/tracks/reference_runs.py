"""The reference rows of a track as tasks of the sweep's backend, stored like cells.

:func:`run_references` gives the records of the reference rows
(:data:`~evaluation.tracks.oracle.DEFAULT_REFERENCES`) on every test cell of a track, as
:func:`~evaluation.tracks.oracle.reference_records` computes them, bit for bit, but:

* **stored like cells.** Each record is a cell file of the track's result store
  (:class:`~evaluation.sweep.store.ResultStore`, written atomically, never overwritten), filed
  under a label that is the row's content address (:func:`reference_label`): the row, its
  configuration (:class:`~evaluation.tracks.oracle.OracleConfig`), the track's data hash (its
  definition with its plant and model version; the store's manifest), ``t_on``, the package
  version and the source of every module the rows' numbers depend on (:data:`REFERENCE_CODE`,
  :func:`code_version`). A re-run of a finished track reads them and computes nothing; a
  change of any of those computes the row again into a new address, and the old files stay
  (delete the store's ``cells/reference+*`` folders to reclaim them).
* **tasks of the backend.** Each row's fit (its calibration on the track's validation seeds,
  the directional row's fault directions, the filter row's signatures) is one task
  (:func:`fit_task`), and the scoring of every test seed is one task per group of rows
  (:func:`seed_task`, :func:`sharing_groups`), submitted as soon as the group's rows are
  fitted: a seed's healthy and faulty cells share the simulations the rows read (the healthy
  episode, its references and, for the optimal rows, the faults' signatures on that seed,
  computed in that task). The driver only schedules the tasks and writes what comes back, on
  the same backends as the detector cells (:func:`evaluation.sweep.backends.make_backend`:
  local processes, Ray, or this process).

Why the label carries the hash rather than only the cell file: a detector's cell of other
settings is an error (a label names one configuration), while a reference row changes with the
code every time a reference module is edited, and a re-run should then recompute it, not ask
for the store to be deleted.
"""

from __future__ import annotations

import dataclasses
import hashlib
import importlib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np
from tqdm.auto import tqdm

from diagnosers.registry import diagnoser_class
from evaluation.sweep.backends import BACKENDS, Backend, make_backend
from evaluation.sweep.records import CellResult, score_episode
from evaluation.sweep.store import ResultStore, canonical_hash
from evaluation.sweep.task_log import TIMINGS_FILE, ProfiledBackend, TaskLog, submit_task, task_part
from evaluation.tracks.filter_bound import SIGNATURE_SEEDS, FilterBound
from evaluation.tracks.oracle import (
    OracleConfig,
    OracleStage,
    PhysicalLimit,
    Simulations,
)
from evaluation.tracks.track_data import TrackData
from fcc_common.import_graph import import_closure
from fcc_common.workers import limit_threads
from fcc_env import MODEL_VERSION, __version__

__all__ = [
    "DIRECTIONAL_CHUNK",
    "FILTER_CHUNK",
    "PROJECT_PACKAGES",
    "REFERENCE_CODE",
    "REFERENCE_REGISTRY",
    "REFERENCE_ROOTS",
    "REFERENCE_STORE_VERSION",
    "ReferenceSeedTask",
    "code_version",
    "directional_fit_task",
    "directional_residuals_task",
    "filter_limits_task",
    "filter_signature_task",
    "filter_statistics_task",
    "fit_task",
    "reference_code",
    "reference_hash",
    "reference_label",
    "run_references",
    "seed_task",
    "sharing_groups",
]

#: Bumped when the meaning of a stored reference record changes (part of every address).
REFERENCE_STORE_VERSION = 1

#: The project's own top-level packages (what the reference rows' closure is kept to).
PROJECT_PACKAGES: tuple[str, ...] = ("diagnosers", "evaluation", "fcc_common", "fcc_env")
#: The modules the reference rows compute with: the rows (:mod:`~evaluation.tracks.oracle`, which
#: imports the optimal and filter rows), their track data and the scoring. Not this module: it
#: schedules and stores, and computes no number (its tasks call the rows and the scoring).
REFERENCE_ROOTS: tuple[str, ...] = (
    "evaluation.tracks.oracle",
    "evaluation.tracks.track_data",
    "evaluation.sweep.records",
)
#: Diagnosers the rows read by registry name (:func:`diagnosers.registry.diagnoser_class`, which
#: the import graph does not show): the directional rows take ``lrgf-glr``'s defaults.
REFERENCE_REGISTRY: tuple[str, ...] = ("lrgf-glr",)


def reference_code() -> tuple[str, ...]:
    """The modules whose source the reference rows' numbers depend on beyond the simulator:
    the import closure (:func:`fcc_common.import_graph.import_closure`) of
    :data:`REFERENCE_ROOTS` and of the modules of :data:`REFERENCE_REGISTRY`, within this
    project's packages. The simulator (``fcc_env``) is left out: it is named by the package and
    model versions, as for every detector cell. Derived, so a new dependency of a row is never
    forgotten; conservative, so an edit of any module the rows import recomputes them."""
    roots = (*REFERENCE_ROOTS, *(diagnoser_class(n).__module__ for n in REFERENCE_REGISTRY))
    return import_closure(roots, PROJECT_PACKAGES, exclude=("fcc_env",))


#: :func:`reference_code` when this module was imported (what :func:`code_version` hashes).
REFERENCE_CODE: tuple[str, ...] = reference_code()


@cache
def code_version(modules: tuple[str, ...] = REFERENCE_CODE) -> str:
    """SHA-256 of the source files of ``modules`` (name and bytes of each, in order).

    Any edit (a comment too) gives another version: a conservative address, which recomputes a
    row rather than ever reading a stale one.
    """
    h = hashlib.sha256()
    for name in modules:
        module = importlib.import_module(name)
        path = getattr(module, "__file__", None)
        if path is None:
            raise ValueError(f"module {name!r} has no source file; allowed: a module from a .py")
        h.update(name.encode() + b"\0" + Path(path).read_bytes() + b"\0")
    return h.hexdigest()


def reference_hash(config: OracleConfig, data_hash: str, t_on: int = 0) -> str:
    """The content address of a reference row's cells on a track (see the module docstring)."""
    if not isinstance(config, OracleConfig):
        raise ValueError(f"config={config!r}; allowed: an evaluation.tracks.oracle.OracleConfig")
    return canonical_hash(
        {
            "v": REFERENCE_STORE_VERSION,
            "package": f"{__version__} ({MODEL_VERSION})",
            "code": code_version(),
            "data": data_hash,
            "row": dataclasses.asdict(config),
            "t_on": t_on,
        }
    )


def reference_label(config: OracleConfig, cell_hash: str) -> str:
    """The store label of a reference row: ``reference+<inputs>+<stage>+<address>`` (a path
    component of the store; the table label, :attr:`OracleConfig.label`, holds spaces)."""
    return f"reference+{config.inputs}+{config.stage}+{cell_hash[:16]}"


# ---- the tasks ---------------------------------------------------------------------------------
def fit_task(data: TrackData, config: OracleConfig, _serial: bool = False) -> PhysicalLimit:
    """Fit one reference row (:meth:`PhysicalLimit.fit`); it travels back without the
    simulations it read (:meth:`PhysicalLimit.__getstate__`)."""
    if not _serial:
        limit_threads()
    try:
        return PhysicalLimit(data, config).fit()
    except Exception as e:  # a worker's traceback does not reach the user: name the row
        raise RuntimeError(f"fitting {config.label!r}: {type(e).__name__}: {e}") from e


#: Calibration episodes per statistics task of the filter row's split fit.
FILTER_CHUNK = 10


def _filter_bound(data: TrackData, config: OracleConfig, terms: Sequence[Any]) -> FilterBound:
    """The filter row's stage as :meth:`PhysicalLimit.fit` builds it, its directions from the
    signature seeds' ``terms`` (:meth:`FilterBound.signature_terms`, in seed order)."""
    bound = FilterBound(data, false_alarm_target=config.false_alarm_target)
    if terms:
        bound.directions_ = bound.combine_signatures(terms)
    return bound


def _filter_bound_seeds(data: TrackData, config: OracleConfig) -> list[int]:
    """The training fault seeds the filter row's signatures are averaged over, in order."""
    return list(data.track.train_fault_seeds[:SIGNATURE_SEEDS])


def filter_signature_task(
    data: TrackData, config: OracleConfig, seed: int, _serial: bool = False
) -> dict[str, list[tuple[int, np.ndarray]]]:
    """One training fault seed's share of the filter row's signatures (the first part of its
    fit, split by seed: :meth:`FilterBound.signature_terms`)."""
    if not _serial:
        limit_threads()
    try:
        return _filter_bound(data, config, ()).signature_terms(seed)
    except Exception as e:  # name the row and seed: a worker's traceback does not reach the user
        raise RuntimeError(f"fitting {config.label!r}, seed {seed}: {type(e).__name__}: {e}") from e


def filter_statistics_task(
    data: TrackData,
    config: OracleConfig,
    terms: Sequence[Any],
    seeds: Sequence[int],
    _serial: bool = False,
) -> np.ndarray:
    """The filter row's statistics on the calibration seeds ``seeds`` (a chunk of them),
    given every signature seed's terms: :meth:`FilterBound.calibration_statistics`."""
    if not _serial:
        limit_threads()
    try:
        healthy = [data.load_test("nominal", s).episode for s in seeds]
        return _filter_bound(data, config, terms).calibration_statistics(healthy)
    except Exception as e:
        raise RuntimeError(f"fitting {config.label!r}: {type(e).__name__}: {e}") from e


def filter_limits_task(
    data: TrackData,
    config: OracleConfig,
    terms: Sequence[Any],
    statistics: Sequence[np.ndarray],
    _serial: bool = False,
) -> PhysicalLimit:
    """The fitted filter row from its parts: the directions from the signature terms, the
    limits on the calibration statistics (chunks in seed order). The same bits as
    :func:`fit_task` of the row (``tests/evaluation/tracks/test_filter_split.py``)."""
    if not _serial:
        limit_threads()
    row = PhysicalLimit(data, config)
    row.stage_ = _filter_bound(data, config, terms).set_limits(statistics)
    return row


#: Calibration episodes per residuals task of the directional row's split fit.
DIRECTIONAL_CHUNK = 10


def directional_residuals_task(
    data: TrackData, config: OracleConfig, seeds: Sequence[int], _serial: bool = False
) -> tuple[tuple[str, ...], list[np.ndarray]]:
    """The directional row's calibration residuals on the seeds ``seeds`` (a chunk of them)
    and the episodes' channels: :meth:`PhysicalLimit.directional_residuals`."""
    if not _serial:
        limit_threads()
    try:
        return PhysicalLimit(data, config).directional_residuals(seeds)
    except Exception as e:
        raise RuntimeError(f"fitting {config.label!r}: {type(e).__name__}: {e}") from e


def directional_fit_task(
    data: TrackData,
    config: OracleConfig,
    chunks: Sequence[tuple[tuple[str, ...], list[np.ndarray]]],
    _serial: bool = False,
) -> PhysicalLimit:
    """The fitted directional row from its calibration residuals (chunks in seed order): the
    fault directions from the training faults, then the stage. The same bits as
    :func:`fit_task` of the row (``tests/evaluation/tracks/test_filter_split.py``)."""
    if not _serial:
        limit_threads()
    try:
        residuals = [r for _, rem in chunks for r in rem]
        return PhysicalLimit(data, config).fit_directional(residuals, chunks[0][0])
    except Exception as e:
        raise RuntimeError(f"fitting {config.label!r}: {type(e).__name__}: {e}") from e


#: The parts of the split fits: part → (the task log's kind, the part it waits for).
_SPLIT_PARTS: dict[str, tuple[str, str | None]] = {
    "signature": ("filter-signature", None),
    "statistics": ("filter-statistics", "signature"),
    "limits": ("filter-limits", "statistics"),
    "residuals": ("directional-residuals", None),
    "directional": ("directional-fit", "residuals"),
}


@dataclass(frozen=True)
class ReferenceSeedTask:
    """Score fitted reference rows on the test cells ``cells`` (one seed's) of ``data``."""

    data: TrackData
    cells: tuple[tuple[str, int], ...]
    t_on: int = 0


def seed_task(
    task: ReferenceSeedTask, observers: Sequence[PhysicalLimit], _serial: bool = False
) -> list[list[dict[str, Any]]]:
    """Per cell of the task, per observer, the record (:meth:`CellResult.to_json`).

    The observers share one :class:`~evaluation.tracks.oracle.Simulations` for the task: the
    healthy episode, the references and the faults' signatures of its seed are simulated once.
    """
    if not _serial:
        limit_threads()
    sims = Simulations(task.data)
    for obs in observers:
        obs.share_simulations(sims)
    out = []
    for sc, seed in task.cells:
        with task_part("simulate"):
            loaded = task.data.load_test(sc, seed)
        row = []
        for obs in observers:
            try:
                # score_episode only calls .detect and reads .name, which the observer has
                rec = score_episode(obs, loaded, label=obs.name, t_on=task.t_on)  # type: ignore[arg-type]
            except Exception as e:
                raise RuntimeError(
                    f"{obs.name!r} on {sc}, seed {seed}: {type(e).__name__}: {e}"
                ) from e
            row.append(rec.to_json())
        out.append(row)
    return out


# ---- the driver --------------------------------------------------------------------------------
def run_references(
    data: TrackData,
    configs: Sequence[OracleConfig],
    store_dir: str | Path,
    *,
    backend: str = "local",
    n_workers: int | None = None,
    ray_address: str | None = None,
    progress: bool = True,
    t_on: int = 0,
) -> tuple[list[CellResult], int]:
    """The records of the reference rows ``configs`` on every test cell of ``data`` (cells in
    :meth:`TrackData.cells` order, the rows in ``configs`` order within a cell, as
    :func:`~evaluation.tracks.oracle.reference_records` returns them) and how many were
    computed now; the others are read from the store at ``store_dir`` (the track's sweep
    store).

    ``backend``, ``n_workers``, ``ray_address``: as :func:`evaluation.sweep.run_sweep` (0
    workers: this process). No backend is started when every record is stored.

    Raises:
        ValueError: an unknown backend, or a config that is not an :class:`OracleConfig`.
        evaluation.sweep.store.StoreError: a stored file is corrupted or foreign.
        RuntimeError: a fit or scoring task failed (records finished before stay stored).
    """
    if backend not in BACKENDS:
        raise ValueError(f"backend={backend!r}; allowed: one of {list(BACKENDS)}")
    configs = list(configs)
    for c in configs:
        if not isinstance(c, OracleConfig):
            raise ValueError(f"configs holds {c!r}; allowed: evaluation.tracks.oracle.OracleConfig")
        c.calibration_seeds(data.track)  # seed clashes are refused before any work
    store = ResultStore.open(store_dir, data.store_key())
    log = TaskLog(store.root / TIMINGS_FILE, "references", backend, n_workers)
    hashes = [reference_hash(c, store.data_hash, t_on) for c in configs]
    labels = [reference_label(c, h) for c, h in zip(configs, hashes, strict=True)]
    cells = data.cells()
    # what is stored is read once (a fully stored track reads every file once, no more)
    with log.stage("plan"):
        stored = {
            (i, cell): store.read_cell(labels[i], *cell, hashes[i])
            for i in range(len(configs))
            for cell in cells
        }
    missing = {i: [cell for cell in cells if stored[i, cell] is None] for i in range(len(configs))}
    todo = [i for i in range(len(configs)) if missing[i]]
    n_missing = sum(len(missing[i]) for i in todo)
    if todo:
        groups = sharing_groups([configs[i] for i in todo])
        plan = [
            (
                [todo[j] for j in group],
                _seed_cells(cells, [missing[todo[j]] for j in group]),
            )
            for group in groups
        ]
        n_tasks = len(todo) + sum(len(seeds) for _, seeds in plan)
        runner = ProfiledBackend(make_backend(backend, n_workers, n_tasks, ray_address), log)
        cancel = True
        try:
            with log.stage("references"):
                work = _Work(runner, store, data, configs, labels, hashes, missing, t_on)
                work.run(plan, n_tasks, progress)
            cancel = False
        finally:
            runner.close(cancel=cancel)
    with log.stage("collect"):
        records = _collect(store, cells, configs, labels, hashes, stored)
    return records, n_missing


def _collect(
    store: ResultStore,
    cells: Sequence[tuple[str, int]],
    configs: Sequence[OracleConfig],
    labels: Sequence[str],
    hashes: Sequence[str],
    stored: Mapping[tuple[int, tuple[str, int]], Mapping[str, Any] | None],
) -> list[CellResult]:
    """The records of every cell (read now unless ``stored`` holds them), rows in order."""
    records = []
    for sc, seed in cells:
        for i, (c, label, h) in enumerate(zip(configs, labels, hashes, strict=True)):
            rec = stored[i, (sc, seed)] or store.read_cell(label, sc, seed, h)
            if rec is None:  # only if a file vanished while we ran
                raise RuntimeError(f"reference cell {label}/{sc}/seed {seed} is missing")
            try:
                result = CellResult.from_json(rec)
            except (ValueError, TypeError) as e:
                path = store.cell_path(label, sc, seed)
                raise ValueError(f"{path}: {e}; delete it to recompute this cell") from e
            records.append(dataclasses.replace(result, diagnoser=c.label))
    return records


def sharing_groups(configs: Sequence[OracleConfig]) -> list[list[int]]:
    """The rows (indexes into ``configs``) that are scored by the same seed tasks.

    Rows scored together share their simulations (the test episode, its healthy references,
    the faults' signatures), so every row is in one group, but the filter row: it reads only
    the episode's observations (its own task costs one more simulation of the episode, a tenth
    of its filter) and its fit, about a hundred filter runs, is the longest; alone, it does not
    hold back the scoring of the others.
    """
    rest = [i for i, c in enumerate(configs) if c.stage != OracleStage.FILTER]
    alone = [[i] for i, c in enumerate(configs) if c.stage == OracleStage.FILTER]
    return ([rest] if rest else []) + alone


def _seed_cells(
    cells: Sequence[tuple[str, int]], missing: Sequence[Sequence[tuple[str, int]]]
) -> list[tuple[tuple[str, int], ...]]:
    """The cells that any of ``missing`` lacks, one tuple per seed (in ``cells`` order)."""
    lacking = {cell for m in missing for cell in m}
    by_seed: dict[int, list[tuple[str, int]]] = {}
    for cell in cells:
        if cell in lacking:
            by_seed.setdefault(cell[1], []).append(cell)
    return [tuple(v) for v in by_seed.values()]


class _Work:
    """One run's tasks: every row's fit, then, as soon as a group's rows are all fitted, one
    scoring task per seed of that group; the records that come back are written at once."""

    def __init__(
        self,
        runner: Backend,
        store: ResultStore,
        data: TrackData,
        configs: Sequence[OracleConfig],
        labels: Sequence[str],
        hashes: Sequence[str],
        missing: Mapping[int, Sequence[tuple[str, int]]],
        t_on: int,
    ) -> None:
        self.runner, self.store, self.data = runner, store, data
        self.configs, self.labels, self.hashes, self.t_on = (
            configs,
            labels,
            hashes,
            t_on,
        )
        self.missing = {i: set(m) for i, m in missing.items()}

    def run(
        self,
        plan: Sequence[tuple[list[int], list[tuple[tuple[str, int], ...]]]],
        n_tasks: int,
        progress: bool,
    ) -> None:
        fits: dict[Any, int] = {}
        self._parts: dict[Any, tuple[int, str, int]] = {}  # the filter rows' split fits
        self._terms: dict[int, list[Any]] = {}
        self._stats: dict[int, list[Any]] = {}
        self._resid: dict[int, list[Any]] = {}
        self._pending: list[Any] = []
        fitted: dict[int, PhysicalLimit] = {}
        fitted_by: dict[int, Any] = {}  # row -> the task that finished its fit (task log)
        self._part_handles: dict[tuple[int, str], list[Any]] = {}
        scoring: dict[Any, tuple[list[int], tuple[tuple[str, int], ...]]] = {}
        pending = self._pending
        with tqdm(
            total=n_tasks,  # one per fit: a split fit adds its parts less one
            desc="reference rows",
            unit="task",
            disable=not progress,
            leave=False,
        ) as bar:
            self._bar = bar
            for i in (i for g, _ in plan for i in g):
                if self.configs[i].stage == OracleStage.FILTER:
                    bar.total -= 1
                    self._start_filter(i)
                elif self.configs[i].stage == OracleStage.DIRECTIONAL:
                    bar.total -= 1
                    self._start_directional(i)
                else:
                    handle = submit_task(
                        self.runner,
                        "reference-fit",
                        f"{self.configs[i].inputs}+{self.configs[i].stage}",
                        fit_task,
                        self.data,
                        self.configs[i],
                        after=(),
                    )
                    fits[handle] = i
            pending.extend(fits)
            while pending:
                try:
                    handle, result = next(self.runner.completed(pending))
                except Exception as e:  # a worker's exception (it names the row and cell)
                    raise RuntimeError(f"reference rows: {type(e).__name__}: {e}") from e
                pending.remove(handle)
                bar.update(1)
                if handle in scoring:
                    self._write(*scoring.pop(handle), result)
                    continue
                if handle in self._parts:
                    i, row = self._split_part(handle, result)
                    if row is None:
                        continue
                    result = row
                else:
                    i = fits[handle]
                fitted[i] = result
                fitted_by[i] = handle  # its fit task, or the last part of a split fit
                for rows, seeds in plan:
                    if i in rows and all(j in fitted for j in rows):
                        shared = self.runner.put(tuple(fitted[j] for j in rows))
                        group = "+".join(str(self.configs[j].stage) for j in rows)
                        for cells in seeds:
                            task = ReferenceSeedTask(data=self.data, cells=cells, t_on=self.t_on)
                            h = submit_task(
                                self.runner,
                                "reference-seed",
                                f"{group}/seed-{cells[0][1]}",
                                seed_task,
                                task,
                                shared,
                                after=[fitted_by[j] for j in rows],
                            )
                            scoring[h] = (rows, cells)
                            pending.append(h)

    # ---- split fits: the filter row's signatures per seed, statistics per chunk, limits; the
    # ---- directional row's calibration residuals per chunk, then its directions and stage
    def _submit_part(self, i: int, kind: str, index: int, fn: Any, *args: Any) -> None:
        log_kind, before = _SPLIT_PARTS[kind]
        after = self._part_handles.get((i, before), []) if before else ()
        handle = submit_task(
            self.runner,
            log_kind,
            f"{self.configs[i].stage}/{index}",
            fn,
            self.data,
            self.configs[i],
            *args,
            after=after,
        )
        self._part_handles.setdefault((i, kind), []).append(handle)
        self._parts[handle] = (i, kind, index)
        self._pending.append(handle)
        self._bar.total += 1

    def _start_filter(self, i: int) -> None:
        seeds = _filter_bound_seeds(self.data, self.configs[i])
        self._terms[i] = [None] * len(seeds)
        for k, seed in enumerate(seeds):
            self._submit_part(i, "signature", k, filter_signature_task, seed)

    def _start_directional(self, i: int) -> None:
        seeds = list(self.configs[i].calibration_seeds(self.data.track))
        chunks = [seeds[k : k + DIRECTIONAL_CHUNK] for k in range(0, len(seeds), DIRECTIONAL_CHUNK)]
        self._resid[i] = [None] * len(chunks)
        for k, chunk in enumerate(chunks):
            self._submit_part(i, "residuals", k, directional_residuals_task, chunk)

    def _split_part(self, handle: Any, result: Any) -> tuple[int, PhysicalLimit | None]:
        """Take one finished part of a split fit; submit what it unblocks. Returns the row
        and, once its last part is in, the fitted row."""
        i, kind, index = self._parts.pop(handle)
        if kind in ("limits", "directional"):
            return i, result
        if kind == "residuals":
            self._resid[i][index] = result
            if all(r is not None for r in self._resid[i]):
                self._submit_part(i, "directional", 0, directional_fit_task, self._resid[i])
            return i, None
        if kind == "signature":
            self._terms[i][index] = result
            if any(t is None for t in self._terms[i]):
                return i, None
            seeds = list(self.configs[i].calibration_seeds(self.data.track))
            chunks = [seeds[k : k + FILTER_CHUNK] for k in range(0, len(seeds), FILTER_CHUNK)]
            self._stats[i] = [None] * len(chunks)
            for k, chunk in enumerate(chunks):
                self._submit_part(i, "statistics", k, filter_statistics_task, self._terms[i], chunk)
            return i, None
        self._stats[i][index] = result
        if all(st is not None for st in self._stats[i]):
            self._submit_part(i, "limits", 0, filter_limits_task, self._terms[i], self._stats[i])
        return i, None

    def _write(
        self,
        rows: Sequence[int],
        cells: Sequence[tuple[str, int]],
        records: Sequence[Sequence[dict[str, Any]]],
    ) -> None:
        for cell, recs in zip(cells, records, strict=True):
            for i, rec in zip(rows, recs, strict=True):
                if cell in self.missing[i]:
                    rec = {
                        **rec,
                        "diagnoser": self.labels[i],
                    }  # the record names its folder
                    self.store.write_cell(self.labels[i], *cell, self.hashes[i], rec)
