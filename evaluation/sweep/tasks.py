"""The sweep's tasks, as a worker process runs them: train one diagnoser, score one episode.

Tasks travel to worker processes (or Ray nodes), so they take and return plain data: a trained
model goes back as its saved files (:func:`dir_files`), and a worker loads each model once
(:func:`load_model`, cached per process by model hash).
"""

from __future__ import annotations

import dataclasses
import tempfile
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple

from diagnosers.bank.relation_plan import RelationsNeeded, planned_relations
from diagnosers.detection import Detection
from diagnosers.diagnoser import Diagnoser
from diagnosers.episode.record import Episode
from diagnosers.isolation.isolating_detector import IsolatingDetector
from diagnosers.registry import import_modules
from evaluation.sweep.config import DiagnoserSpec
from evaluation.sweep.records import (
    detect_and_score,
    detection_arrays,
    detection_from_arrays,
    pack_detection,
)
from evaluation.sweep.sources import DataSource
from evaluation.sweep.task_log import task_part
from fcc_common.workers import limit_threads

__all__ = [
    "OWN_INNER",
    "EpisodeTask",
    "TrainOutcome",
    "dir_files",
    "episode_task",
    "load_model",
    "train_task",
    "training_episodes",
]

_MODEL_CACHE: dict[str, Diagnoser] = {}
_MODEL_CACHE_SIZE = 8


def dir_files(path: Path) -> dict[str, bytes]:
    """Every file under ``path`` as ``{relative POSIX path: bytes}`` (a model shipped whole)."""
    return {
        p.relative_to(path).as_posix(): p.read_bytes()
        for p in sorted(path.rglob("*"))
        if p.is_file()
    }


def load_model(model_hash: str, source: str | Mapping[str, bytes]) -> Diagnoser:
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


class TrainOutcome(NamedTuple):
    """What a training task returns: the model (``files``, ``info``), or the relation jobs its
    banks need first (``needed``: job key → :class:`~diagnosers.bank.parallel.RelationJob`,
    then ``files`` and ``info`` are empty)."""

    files: dict[str, bytes]
    info: dict[str, Any]
    needed: dict[str, Any]


def train_task(
    spec: DiagnoserSpec,
    data: DataSource,
    imports: tuple[str, ...] = (),
    relations: Mapping[str, Any] | None = None,
    _serial: bool = False,
) -> TrainOutcome:
    """Fit one diagnoser on the healthy training episodes; return its saved files and facts, or
    the relations its banks still need.

    A diagnoser that isolates or learns from faults also gets the labelled training faults
    (:func:`training_episodes`). Its banks train nothing here
    (:func:`diagnosers.bank.relation_plan.planned_relations`): their relation jobs come from
    ``relations`` (job key → trained relation), and when some are missing the task returns
    them in :attr:`TrainOutcome.needed` for the scheduler
    (:mod:`evaluation.sweep.training_stage`) to train as tasks of their own, and is run again
    with them.
    """
    if not _serial:
        limit_threads()
    import_modules(imports)  # a fresh worker has not seen the user's registrations
    t0 = time.perf_counter()
    diag = spec.build()
    with task_part("data"):
        episodes = training_episodes(diag, data, spec.key)
    try:
        with planned_relations(relations or {}), task_part("fit"):
            diag.fit(episodes)
    except RelationsNeeded as need:
        return TrainOutcome({}, {}, need.jobs)
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
    return TrainOutcome(files, info, {})


def training_episodes(diag: Diagnoser, data: DataSource, key: str) -> list[Episode]:
    """What ``diag`` (labelled ``key`` in errors) is fitted on: the healthy training episodes,
    and the labelled training faults (training seeds only) when it isolates or learns from
    faults (:attr:`~diagnosers.Diagnoser.learns_from_faults`).

    An isolator needs them: a data source without ``train_fault_episodes`` is an error. A
    detector that learns from faults works without (recorded data have none: it then learns
    no fault directions, and says so).
    """
    episodes = data.train_episodes()
    if not (diag.isolates or diag.learns_from_faults):
        return episodes
    faulty = getattr(data, "train_fault_episodes", None)
    if faulty is None:
        if diag.isolates:
            raise RuntimeError(
                f"training {key}: it isolates faults, but the data source "
                f"{type(data).__name__} has no labelled training faults (train_fault_episodes)"
            )
        return episodes
    return episodes + faulty()


#: :attr:`EpisodeTask.inner` of a label whose isolator computes its inner detection itself
#: (and returns it for the store); ``-1``: no inner detection is involved.
OWN_INNER = -2


@dataclass(frozen=True)
class EpisodeTask:
    """Score the diagnosers ``labels`` on episode ``(scenario, seed)`` of ``data``.

    The isolators' inner detections (:mod:`evaluation.sweep.runner` finds which detector of the
    sweep an isolator wraps): per label, ``inner`` is the index of the label in this task whose
    detection is its inner detection (computed first), :data:`OWN_INNER` (its own inner
    detector detects; the detection goes back for the store) or ``-1`` (not an isolator of a
    detector of the sweep); ``inner_arrays`` the stored inner detection
    (:func:`~evaluation.sweep.records.detection_arrays`) when the detector's cell is not in
    this task; ``share`` whether the label's detection goes back for the store as a detector's
    inner detection.
    """

    data: DataSource
    scenario: str
    seed: int
    t_on: int
    labels: tuple[str, ...]
    model_hashes: tuple[str, ...]
    model_paths: tuple[str, ...] | None  # local backend; None when models come as bytes
    keep: tuple[bool, ...] = ()  # per label: return the whole detection (a figure cell)
    imports: tuple[str, ...] = ()  # SweepConfig.imports, imported in the worker
    inner: tuple[int, ...] = ()  # per label (see the class docstring); () all -1
    inner_arrays: tuple[Mapping[str, Any] | None, ...] = ()  # per label; () all None
    share: tuple[bool, ...] = ()  # per label; () all False


def episode_task(
    task: EpisodeTask, *model_files: Mapping[str, bytes], _serial: bool = False
) -> list[tuple[dict[str, Any], dict[str, Any] | None, dict[str, Any] | None]]:
    """``(record, detection arrays or None, inner detection arrays or None)`` per label.

    An isolator whose inner detection is given (by an earlier label of the task or as stored
    arrays) runs only its isolation stage on it
    (:meth:`~diagnosers.isolation.isolating_detector.IsolatingDetector.diagnose_detection`):
    the detection is the one :meth:`detect` computes, bit for bit, since its inner model is the
    detector's (the driver compares the saved files).
    """
    if not _serial:
        limit_threads()
    import_modules(task.imports)
    with task_part("simulate"):
        loaded = task.data.load_test(task.scenario, task.seed)
    n = len(task.labels)
    out = []
    keep = task.keep or (False,) * n
    inner = task.inner or (-1,) * n
    given = task.inner_arrays or (None,) * n
    share = task.share or (False,) * n
    dets: list[Detection | None] = [None] * n
    for i, (label, mhash) in enumerate(zip(task.labels, task.model_hashes, strict=True)):
        source = task.model_paths[i] if task.model_paths is not None else model_files[i]
        try:
            with task_part(f"load:{label}"):
                diag = load_model(mhash, source)
            with task_part(f"detect:{label}"):
                detect, box = _inner_detect(diag, inner[i], given[i], dets)
                rec, det = detect_and_score(
                    diag, loaded, label=label, t_on=task.t_on, detect=detect
                )
            dets[i] = det
            arrays = (
                pack_detection(loaded, det, diag.band_view(loaded.episode)) if keep[i] else None
            )
            shared = box.get("own", det if share[i] else None)
            inner_out = None if shared is None else detection_arrays(shared)
        except Exception as e:
            # Name the cell: the traceback of a worker process does not reach the user.
            raise RuntimeError(
                f"{label} on {task.scenario}, seed {task.seed}: {type(e).__name__}: {e}"
            ) from e
        # External data name the episode by file; keep the sweep's cell key as given.
        rec = dataclasses.replace(rec, scenario=task.scenario, seed=task.seed)
        out.append((rec.to_json(), arrays, inner_out))
    return out


def _inner_detect(
    diag: Diagnoser,
    inner: int,
    given: Mapping[str, Any] | None,
    dets: list[Detection | None],
) -> tuple[Callable[[Episode], Detection] | None, dict[str, Detection]]:
    """How an isolator's cell detects: ``(detect, box)``, ``box["own"]`` the inner detection
    ``detect`` computed itself, if it did; ``(None, box)`` for any other cell (its own
    ``detect``)."""
    box: dict[str, Detection] = {}
    if inner == -1 and given is None:
        return None, box
    if not isinstance(diag, IsolatingDetector):
        raise TypeError(f"an inner detection was given to {diag.name!r}, which is no isolator")

    def detect(episode: Episode) -> Detection:
        if given is not None:
            det = detection_from_arrays(given)
        elif inner >= 0:
            found = dets[inner]
            if found is None:
                raise RuntimeError(f"the inner detection (label {inner}) is not computed yet")
            det = found
        else:  # OWN_INNER: timed with the cell, as its detect would be
            det = box["own"] = diag.detector_.detect(episode)
        return diag.diagnose_detection(det)

    return detect, box
