"""Training an LRGF + MEM bank: every (relation, training set) job, in this process or a pool.

A bank (:mod:`diagnosers.lrgf.lrgf_mem`) trains, per relation, an LRGF nominal model and then an
NNARX model-error model on that network's residual; ``lrgf-glr`` does it for ``n_folds + 1``
training sets (its cross-fitted calibration). The jobs are independent: each has its own data and
its own seed (``seed + 101 j`` for relation ``j``, whichever set), and each trains with one
torch thread. So they can run in any order and in any process: :func:`train_banks` runs them in
this process (``n_jobs=1``) or in a pool of ``n_jobs`` worker processes, and both give the same
bits.

Every job goes through the same path, :func:`_train_relation`, which returns the trained modules
in their exported form (config + state dict as numpy arrays, from
:func:`diagnosers.networks.modules.export_module`); the caller rebuilds them with
:func:`diagnosers.networks.modules.build_module`. Torch modules never cross a process boundary as
pickles, and the in-process path is the pooled one without the pool.

The pool uses the ``spawn`` start method with :func:`fcc_common.workers.init_worker` (one thread per
worker, exit when the parent dies), as the sweep's local backend does. As with any ``spawn``
pool, a script that trains with ``n_jobs > 1`` needs the ``if __name__ == "__main__":`` guard:
each worker imports the script's main module.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, replace
from typing import Any, NamedTuple, TypeVar

import numpy as np
import torch

from diagnosers.bank.relation_cache import RelationCache, active_cache, job_key
from diagnosers.bank.relation_plan import RelationsNeeded, active_plan
from diagnosers.networks.lrgf_net import LRGF
from diagnosers.networks.mem_net import NNARXErrorModel
from diagnosers.networks.modules import build_module, export_module
from diagnosers.networks.optimisers import FitResult, torch_threads
from diagnosers.networks.training import fit_lrgf, fit_mem
from fcc_common.workers import init_worker, spawn_context

__all__ = [
    "BankSettings",
    "RelationJob",
    "TrainedBank",
    "TrainedRelation",
    "run_jobs",
    "train_banks",
    "train_relation",
]

J = TypeVar("J")
R = TypeVar("R")


@dataclass(frozen=True, kw_only=True)
class BankSettings:
    """The hyperparameters of an LRGF + MEM diagnoser that training one relation uses.

    Named as in :class:`diagnosers.lrgf.lrgf_mem.LRGFMEM`, where they are documented and validated.
    """

    n_hidden: int
    order: int
    n_linear: int
    steady_window: int
    mem_hidden: int
    mem_input_delays: int
    mem_output_delays: int
    mem_output_activation: str
    method: str
    lr: float
    max_epochs: int
    val_fraction: float
    mem_max_epochs: int
    progress: bool | None

    @classmethod
    def from_params(cls, params: dict[str, Any]) -> BankSettings:
        """The settings out of a diagnoser's ``get_params()`` (other entries are ignored)."""
        return cls(**{k: params[k] for k in cls.__dataclass_fields__})


class TrainedBank(NamedTuple):
    """One training set's bank: per relation the network, the error model, the paper's ``v``
    (std of y_e on the training records) and the network's :class:`FitResult`."""

    lrgf: list[LRGF]
    mem: list[NNARXErrorModel]
    v_paper: list[float]
    fits: list[FitResult]


@dataclass(frozen=True)
class RelationJob:
    """Train one relation on one training set: inputs ``u`` (T_i, n) and output ``y`` (T_i, 1)
    per record, with the relation's seed."""

    settings: BankSettings
    u: list[np.ndarray]
    y: list[np.ndarray]
    seed: int
    #: the exported LRGF to start from (a warm start), or None for the seed's initialisation
    init: _Exported | None = None
    #: a :class:`~diagnosers.bank.relation_cache.RelationCache` directory to read and fill, or None
    cache_dir: str | None = None

    @property
    def key(self) -> str:
        """The job's :func:`~diagnosers.bank.relation_cache.job_key`: its result's address."""
        return job_key(self.settings, self.u, self.y, self.seed, self.init)

    @property
    def cost(self) -> int:
        # training time grows with the samples, the epochs and, less than proportionally, with
        # the neurons (measured: 10 neurons take 1.7x the time of 5 on T_rg1)
        samples = sum(len(u) for u in self.u)
        return samples * (self.settings.n_hidden + 2) * self.settings.max_epochs


#: a trained module in transit: (config, state dict as numpy arrays)
_Exported = tuple[dict[str, Any], dict[str, np.ndarray]]


def _export(module: LRGF | NNARXErrorModel) -> _Exported:
    config, state = export_module(module)
    return config, {k: v.numpy() for k, v in state.items()}


def _build(exported: _Exported) -> Any:
    config, state = exported
    module = build_module(config, {k: torch.from_numpy(v) for k, v in state.items()})
    module.eval()
    return module


#: one trained relation: (LRGF export, error-model export, v_paper, the network's fit)
TrainedRelation = tuple[_Exported, _Exported, float, FitResult]


def train_relation(job: RelationJob) -> TrainedRelation:
    """Train one relation job, as a task of a pool or cluster (no cache): the same bits in any
    process (:mod:`diagnosers.bank.relation_plan`)."""
    return _train_relation(job)


def _train_relation(job: RelationJob) -> TrainedRelation:
    """The LRGF, then the error model on its residual; the same bits in any process."""
    s = job.settings
    # One thread for the whole job, predictions included: a thread count that differed between
    # this process and a worker could change the rounding of a reduction.
    with torch_threads(1):
        net = LRGF(
            job.u[0].shape[1],
            s.n_hidden,
            s.order,
            1,
            n_linear=s.n_linear,
            initial_state="steady",
            steady_window=s.steady_window,
            seed=job.seed,
        ).double()
        if job.init is not None:
            # a warm start: the architecture is the settings'; the state dict must match it
            net.load_state_dict({k: torch.from_numpy(v) for k, v in job.init[1].items()})
        fit = fit_lrgf(
            net,
            job.u,
            job.y,
            method=s.method,
            lr=s.lr,
            max_epochs=s.max_epochs,
            patience=max(50, s.max_epochs // 5),
            val_fraction=s.val_fraction,
            seed=job.seed,
            progress=s.progress,
        )
        net.eval()
        r_tr = [yt - net.predict(ut) for ut, yt in zip(job.u, job.y, strict=True)]
        mem = NNARXErrorModel(
            job.u[0].shape[1],
            1,
            n_hidden=s.mem_hidden,
            input_delays=s.mem_input_delays,
            output_delays=s.mem_output_delays,
            output_activation=s.mem_output_activation,
            seed=job.seed,
        ).double()
        fit_mem(
            mem,
            job.u,
            r_tr,
            max_epochs=s.mem_max_epochs,
            pretrain_epochs=min(300, 3 * s.mem_max_epochs),
            seed=job.seed,
            progress=s.progress,
        )
        mem.eval()
        ye_tr = np.concatenate([mem.predict(ut) for ut in job.u])
    return _export(net), _export(mem), float(ye_tr.std(ddof=1)), fit


def _run_relation(job: RelationJob) -> TrainedRelation:
    """:func:`_train_relation`, through the relation cache when the job names one."""
    if job.cache_dir is None:
        return _train_relation(job)
    key = job.key
    out = RelationCache(job.cache_dir).fetch_or_train(key, lambda: _train_relation(job))
    return out  # type: ignore[return-value]


def run_jobs(
    fn: Callable[[J], R], jobs: Sequence[J], n_jobs: int, cost: Callable[[J], float] | None = None
) -> list[R]:
    """``[fn(job) for job in jobs]``, in this process (``n_jobs=1``) or in ``n_jobs`` workers.

    ``fn`` must be a module-level function and jobs and results picklable. With ``cost`` the
    costliest jobs start first, so the last job to finish is a short one (results keep the order
    of ``jobs``). An exception of a job cancels the jobs not started and is raised here.
    """
    if n_jobs <= 1 or len(jobs) <= 1:
        return [fn(job) for job in jobs]
    order = sorted(range(len(jobs)), key=lambda i: -cost(jobs[i])) if cost else range(len(jobs))
    pool = ProcessPoolExecutor(
        max_workers=min(n_jobs, len(jobs)),
        mp_context=spawn_context(),
        initializer=init_worker,
        initargs=(os.getpid(),),
    )
    failed = True
    try:
        futures = {pool.submit(fn, jobs[i]): i for i in order}
        out: list[Any] = [None] * len(jobs)
        for fut in as_completed(futures):
            out[futures[fut]] = fut.result()  # the first job to fail raises here
        failed = False
        return out
    finally:
        # on failure (or Ctrl-C) do not wait for the jobs still running: they end on their own
        pool.shutdown(wait=not failed, cancel_futures=True)


def train_banks(
    settings: BankSettings | Sequence[BankSettings],
    sets: Sequence[Sequence[np.ndarray]],
    in_idx: Sequence[np.ndarray],
    out_idx: np.ndarray,
    seed: int,
    n_jobs: int,
    init: Sequence[TrainedBank | None] | None = None,
) -> list[TrainedBank]:
    """Train the bank on each training set of ``sets`` (records ``(T_i, channels)`` each).

    Relation ``j`` reads the channels ``in_idx[j]`` and models channel ``out_idx[j]``, with the
    seed ``seed + 101 j``, and its own settings when ``settings`` is a sequence (one per
    relation). All ``len(sets) × len(in_idx)`` jobs share the ``n_jobs`` processes.

    ``init`` (one entry per set) warm-starts a set's LRGF networks from a trained bank of the
    same relations and sizes (``None`` entries start from the seed's initialisation); the error
    models always train from their own initialisation, on the warm-started networks' residuals.

    Inside a :func:`diagnosers.bank.relation_cache.shared_relations` block, a job trained before
    (by any diagnoser, in any process sharing the directory) is read instead of trained again.
    Inside a :func:`diagnosers.bank.relation_plan.planned_relations` block nothing is trained:
    the results come from the block's known relations, and missing ones raise
    :class:`~diagnosers.bank.relation_plan.RelationsNeeded`.
    """
    cache = active_cache()
    per_relation = [settings] * len(in_idx) if isinstance(settings, BankSettings) else settings
    if len(per_relation) != len(in_idx):
        raise ValueError(f"{len(per_relation)} settings for {len(in_idx)} relations")
    inits = [None] * len(sets) if init is None else list(init)
    if len(inits) != len(sets):
        raise ValueError(f"{len(inits)} initial banks for {len(sets)} training sets")
    for bank in inits:
        if bank is not None and len(bank.lrgf) != len(in_idx):
            raise ValueError(
                f"an initial bank has {len(bank.lrgf)} networks for {len(in_idx)} relations"
            )
    jobs = [
        RelationJob(
            per_relation[j],
            [y[:, in_idx[j]] for y in records],
            [y[:, [out_idx[j]]] for y in records],
            seed + 101 * j,
            None if start is None else _export(start.lrgf[j]),
            None if cache is None else str(cache),
        )
        for records, start in zip(sets, inits, strict=True)
        for j in range(len(in_idx))
    ]
    plan = active_plan()
    if plan is None:
        results = run_jobs(_run_relation, jobs, n_jobs, cost=lambda job: job.cost)
    else:
        keys = [job.key for job in jobs]
        missing = {
            k: replace(job, cache_dir=None)
            for k, job in zip(keys, jobs, strict=True)
            if k not in plan
        }
        if missing:
            raise RelationsNeeded(missing)
        results = [plan[k] for k in keys]
    k = len(in_idx)
    banks = []
    for b in range(len(sets)):
        part = results[b * k : (b + 1) * k]
        banks.append(
            TrainedBank(
                [_build(r[0]) for r in part],
                [_build(r[1]) for r in part],
                [r[2] for r in part],
                [r[3] for r in part],
            )
        )
    return banks
