"""The sweep's training stage: every diagnoser, and every relation of every bank, a task.

A diagnoser built on banks of LRGF relations (:mod:`diagnosers.bank`) spends nearly all of its
training in the relation jobs (one LRGF network and its error model per relation and training
set: measured, about 2 s of CPU per relation at 100 epochs against 1 s for the rest of an
``lrgf-mem`` fit). :func:`train_all` therefore runs each relation job as a task of the sweep's
own pool or Ray cluster, beside the other diagnosers' trainings, instead of a few at a time
inside one diagnoser's task:

1. each diagnoser's training task (:func:`~evaluation.sweep.tasks.train_task`) fits with the
   relations known so far; a baseline finishes there, a bank detector names the relation jobs
   it still needs (:mod:`diagnosers.bank.relation_plan`);
2. each needed job is read from the relation cache (when the sweep has one), or trained once
   as a task (:func:`relation_task`), however many diagnosers need it (``lrgf-mem``'s bank is
   also the inner bank of ``lrgf-iso`` and ``lrgf-lda``), costliest first;
3. a diagnoser whose jobs are all known is trained again with them, and stored.

The driver only schedules and writes: it alone reads and fills the relation cache, so Ray nodes
need no shared file system. The relations have the bits of an in-process training (one torch
thread per job, its own seed), so a model is the same for any backend and worker count.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from typing import Any

from diagnosers.bank.parallel import RelationJob, TrainedRelation, train_relation
from diagnosers.bank.relation_cache import RelationCache
from evaluation.sweep.backends import Backend
from evaluation.sweep.config import DiagnoserSpec, SweepConfig
from evaluation.sweep.store import ResultStore
from evaluation.sweep.task_log import submit_task
from evaluation.sweep.tasks import TrainOutcome, train_task
from fcc_common.workers import limit_threads

__all__ = ["relation_task", "train_all"]


def relation_task(job: RelationJob, _serial: bool = False) -> tuple[TrainedRelation, float]:
    """Train one relation job in a worker: ``(trained relation, wall seconds)``."""
    if not _serial:
        limit_threads()
    t0 = time.perf_counter()
    try:
        relation = train_relation(job)
    except Exception as e:  # name the job: a worker's traceback does not reach the user
        raise RuntimeError(f"relation job with seed {job.seed}: {type(e).__name__}: {e}") from e
    return relation, time.perf_counter() - t0


def train_all(
    runner: Backend,
    store: ResultStore,
    config: SweepConfig,
    to_train: list[DiagnoserSpec],
    mhash: Mapping[str, str],
    relation_cache: str | None = None,
    bar: Any = None,
) -> None:
    """Train ``to_train`` and their relation jobs on ``runner``; store each model as it is done.

    ``relation_cache``: a :class:`~diagnosers.bank.relation_cache.RelationCache` directory read
    before a job is trained and filled after, or ``None``. ``bar``: a progress bar updated per
    stored model. Raises RuntimeError naming the diagnoser (or relation) whose task failed.
    """
    cache = None if relation_cache is None else RelationCache(relation_cache)
    specs = {s.key: s for s in to_train}
    known: dict[str, TrainedRelation] = {}
    trained_s: dict[str, float] = {}  # relation key -> wall of its task in this sweep
    needs: dict[str, set[str]] = {key: set() for key in specs}  # diagnoser -> relation keys
    waiting: dict[str, set[str]] = {}  # relation key in flight -> diagnosers waiting for it
    pending: dict[Any, tuple[str, str]] = {}  # handle -> ("train", diagnoser) | ("relation", key)
    # for the task log (evaluation.sweep.task_log): what each task waited for
    relation_handle: dict[str, Any] = {}  # relation key -> its task in this sweep
    last_training: dict[str, Any] = {}  # diagnoser -> its latest training task

    def submit_training(key: str) -> None:
        relations = {k: known[k] for k in sorted(needs[key])}
        after = [relation_handle[k] for k in sorted(needs[key]) if k in relation_handle]
        after += [last_training[key]] if key in last_training else []
        handle = submit_task(
            runner,
            "train",
            key,
            train_task,
            specs[key],
            config.data,
            config.imports,
            relations,
            after=after,
        )
        pending[handle] = ("train", key)
        last_training[key] = handle

    def ask(key: str, jobs: Mapping[str, RelationJob]) -> None:
        needs[key].update(jobs)
        new = []
        for rkey, job in jobs.items():
            if rkey in known:
                continue
            if rkey not in waiting and cache is not None:
                hit = cache.get(rkey)
                if hit is not None:
                    known[rkey] = hit  # type: ignore[assignment]
                    continue
            if rkey not in waiting:
                waiting[rkey] = set()
                new.append((rkey, job))
            waiting[rkey].add(key)
        for rkey, job in sorted(new, key=lambda kj: -kj[1].cost):  # costliest first
            handle = submit_task(
                runner,
                "relation",
                rkey[:16],
                relation_task,
                job,
                after=[last_training[key]],
                info={"cost": job.cost, "max_epochs": job.settings.max_epochs},
            )
            pending[handle] = ("relation", rkey)
            relation_handle[rkey] = handle
        if needs[key] <= known.keys():
            submit_training(key)

    for key in specs:
        submit_training(key)
    while pending:
        try:  # the first task to finish (the backend's iterator is rebuilt as tasks are added)
            handle, result = next(runner.completed(list(pending)))
        except Exception as e:  # a worker's exception (a training names its diagnoser)
            raise RuntimeError(f"training failed: {type(e).__name__}: {e}") from e
        kind, key = pending.pop(handle)
        if kind == "relation":
            relation, wall = result
            known[key], trained_s[key] = relation, wall
            if cache is not None:
                cache.put(key, relation)
            for diag in sorted(waiting.pop(key)):
                if needs[diag] <= known.keys():
                    submit_training(diag)
            continue
        outcome = TrainOutcome(*result)
        if outcome.needed:
            if set(outcome.needed) <= needs[key]:  # it was given them: never ask in circles
                raise RuntimeError(f"training {key}: it asks again for relations it was given")
            ask(key, outcome.needed)
            continue
        relation_s = sum(trained_s.get(r, 0.0) for r in needs[key])
        info = {**outcome.info, "n_relation_jobs": len(needs[key]), "relation_wall_s": relation_s}
        store.write_model(key, mhash[key], outcome.files, {**specs[key].to_json(), **info})
        if bar is not None:
            bar.update(1)
