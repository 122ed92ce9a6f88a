"""Relation jobs run from outside a fit: the fit names the relations it needs, a scheduler
trains them, and the fit runs again with them known.

A sweep trains every relation of every bank as a task of its own pool or Ray cluster
(:mod:`evaluation.sweep.training_stage`), not a few at a time inside one diagnoser's training.
Inside a :func:`planned_relations` block, :func:`diagnosers.bank.parallel.train_banks` trains
nothing: it takes each job's result from the block's ``known`` results, by
:func:`~diagnosers.bank.relation_cache.job_key`, and when some are missing it raises
:class:`RelationsNeeded` with those jobs (key → job). The caller trains them anywhere
(:func:`diagnosers.bank.parallel.train_relation`) and fits again with them known. A fit that
warm-starts one bank from another (``lrgf-glr`` with ``refit_epochs``) asks twice: the second
bank's jobs depend on the first bank's results.

A known result has the bits of a training in the fit's own process (one torch thread per job,
the job's own seed), so the fitted diagnoser is the same, bit for bit, however its relations
were scheduled.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator, Mapping
from contextvars import ContextVar
from typing import Any

__all__ = ["RelationsNeeded", "active_plan", "planned_relations"]

_PLAN: ContextVar[Mapping[str, Any] | None] = ContextVar("fcc_relation_plan", default=None)


class RelationsNeeded(Exception):
    """A fit inside :func:`planned_relations` needs relations that are not known yet.

    Attributes:
        jobs: ``{job key: job}`` (:class:`diagnosers.bank.parallel.RelationJob`) of the
            missing relations, each key once.
    """

    def __init__(self, jobs: Mapping[str, Any]) -> None:
        super().__init__(f"{len(jobs)} relation jobs to train first")
        self.jobs = dict(jobs)


@contextlib.contextmanager
def planned_relations(known: Mapping[str, Any]) -> Iterator[None]:
    """Within the block, bank training reads ``known`` (job key → trained relation, as
    :func:`diagnosers.bank.parallel.train_relation` returns it) and raises
    :class:`RelationsNeeded` for the rest instead of training them."""
    token = _PLAN.set(known)
    try:
        yield
    finally:
        _PLAN.reset(token)


def active_plan() -> Mapping[str, Any] | None:
    """The known relations of the enclosing :func:`planned_relations` block, if any."""
    return _PLAN.get()
