"""Trained relations shared by every diagnoser built on a bank: a content-addressed cache.

The LRGF diagnosers train the same relation jobs again and again: ``lrgf-mem`` and the inner
``lrgf-mem`` of ``lrgf-iso`` and ``lrgf-lda`` train the same bank, and two of its three
relations equal jobs of ``lrgf-glr``'s third cross-fit fold (the same records, settings and
seed). A job's result depends only on what goes into :func:`diagnosers.bank.parallel.train_banks`'s
job (the relation's settings, its input and output arrays, its seed and its warm start) and on
the training code, so the cache keys a result by all of them: :func:`job_key`, a SHA-256 over
the settings, the seed, the bytes of every array and a fingerprint of the source of the modules
that train (a changed trainer never reuses a stale result). A hit returns the bits a fresh
training would give.

Use it around any fit with :func:`shared_relations`::

    with shared_relations("results/banks"):
        diagnosers.make("lrgf-mem").fit(episodes)
        diagnosers.make("lrgf-iso").fit(episodes + faults)  # its inner lrgf-mem: from the cache

The benchmark's sweeps do (one cache for all tracks, ``--out/banks``). Processes share a cache
safely: a job is trained under an exclusive lock on its key (POSIX ``flock``), so a second
process that wants it waits and reads it instead of training it again. Entries are ``.npz``
files read without unpickling (:func:`fcc_common.safe_files.load_npz`); an unreadable entry is
trained again and replaced (with a warning), never trusted.
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import json
import logging
import os
from collections.abc import Callable, Iterator, Sequence
from contextvars import ContextVar
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np
import torch

from fcc_common.io import atomic_open
from fcc_common.safe_files import load_npz

try:  # POSIX: processes that want the same job wait for the one training it
    import fcntl
except ImportError:  # pragma: no cover - Windows: each process may train a job once more
    fcntl = None  # type: ignore[assignment]

__all__ = ["CACHE_FORMAT", "RelationCache", "active_cache", "job_key", "shared_relations"]

logger = logging.getLogger(__name__)

#: bumped when an entry's layout changes (old entries are then simply not found)
CACHE_FORMAT = 1

#: the modules whose code decides a trained relation's bits (their source is in the key)
_TRAINING_MODULES = (
    "diagnosers.networks.iir",
    "diagnosers.networks.lrgf_net",
    "diagnosers.networks.mem_net",
    "diagnosers.networks.optimisers",
    "diagnosers.networks.training",
    "diagnosers.bank.parallel",
)

_ACTIVE: ContextVar[Path | None] = ContextVar("fcc_relation_cache", default=None)

#: one trained relation: (LRGF export, error-model export, v_paper, fit result as a dict);
#: an export is (config, state dict of numpy arrays)
Exported = tuple[dict[str, Any], dict[str, np.ndarray]]


@contextlib.contextmanager
def shared_relations(directory: str | os.PathLike | None) -> Iterator[None]:
    """Within the block, bank training reads and fills the cache in ``directory`` (created if
    missing); ``None`` turns the cache off for the block."""
    token = _ACTIVE.set(None if directory is None else Path(directory))
    try:
        yield
    finally:
        _ACTIVE.reset(token)


def active_cache() -> Path | None:
    """The cache directory of the enclosing :func:`shared_relations` block, if any."""
    return _ACTIVE.get()


@lru_cache(maxsize=1)
def _code_fingerprint() -> str:
    import importlib

    digest = hashlib.sha256(f"torch {torch.__version__}; numpy {np.__version__}".encode())
    for name in _TRAINING_MODULES:
        path = importlib.import_module(name).__file__
        assert path is not None
        digest.update(Path(path).read_bytes())
    return digest.hexdigest()


def _update_array(digest: Any, a: np.ndarray) -> None:
    a = np.ascontiguousarray(a)
    digest.update(f"{a.dtype.str}{a.shape}".encode())
    digest.update(a.tobytes())


def job_key(
    settings: Any,
    u: Sequence[np.ndarray],
    y: Sequence[np.ndarray],
    seed: int,
    init: Exported | None,
) -> str:
    """SHA-256 (hex) of everything a relation job's result depends on.

    ``settings`` is a :class:`diagnosers.bank.parallel.BankSettings` (its ``progress`` only draws a
    bar, so it is left out); ``u`` and ``y`` the job's records; ``init`` its warm start.
    """
    fields = {k: v for k, v in dataclasses.asdict(settings).items() if k != "progress"}
    head = {"format": CACHE_FORMAT, "code": _code_fingerprint(), "settings": fields, "seed": seed}
    digest = hashlib.sha256(json.dumps(head, sort_keys=True).encode())
    for group in (u, y):
        digest.update(f"records {len(group)}".encode())
        for a in group:
            _update_array(digest, a)
    if init is not None:
        digest.update(json.dumps(init[0], sort_keys=True).encode())
        for name in sorted(init[1]):
            digest.update(name.encode())
            _update_array(digest, init[1][name])
    return digest.hexdigest()


class RelationCache:
    """A directory of trained relations keyed by :func:`job_key` (see the module doc)."""

    def __init__(self, directory: str | os.PathLike) -> None:
        self.root = Path(directory)

    def path(self, key: str) -> Path:
        return self.root / key[:2] / f"{key}.npz"

    def fetch_or_train(self, key: str, train: Callable[[], tuple[Any, ...]]) -> tuple[Any, ...]:
        """The cached result of ``key``, or ``train()``'s, stored under ``key`` (atomically,
        under the key's lock, so that a concurrent process waits for it)."""
        target = self.path(key)
        target.parent.mkdir(parents=True, exist_ok=True)
        with _locked(target.with_suffix(".lock")):
            if target.is_file():
                try:
                    return _read(target)
                except Exception as e:  # an entry is a convenience: retrain, never trust it
                    logger.warning(
                        "relation cache %s is unreadable (%s); training again", target, e
                    )
            result = train()
            _write(target, result)
            return result


@contextlib.contextmanager
def _locked(lock_path: Path) -> Iterator[None]:
    if fcntl is None:  # pragma: no cover
        yield
        return
    with open(lock_path, "a") as fh:
        fcntl.flock(fh.fileno(), fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(fh.fileno(), fcntl.LOCK_UN)


def _write(target: Path, result: tuple[Any, ...]) -> None:
    (net_cfg, net_state), (mem_cfg, mem_state), v_paper, fit = result
    meta = {
        "net_config": net_cfg,
        "mem_config": mem_cfg,
        "v_paper": float(v_paper),
        "fit": dataclasses.asdict(fit),
    }
    arrays = {f"net/{k}": v for k, v in net_state.items()}
    arrays.update({f"mem/{k}": v for k, v in mem_state.items()})
    arrays["meta"] = np.array(json.dumps(meta))
    with atomic_open(target, "wb") as fh:
        np.savez(fh, **arrays)


def _read(target: Path) -> tuple[Any, ...]:
    from diagnosers.networks.optimisers import FitResult

    arrays = load_npz(target)
    meta = json.loads(str(arrays.pop("meta")))
    net = {k.removeprefix("net/"): v for k, v in arrays.items() if k.startswith("net/")}
    mem = {k.removeprefix("mem/"): v for k, v in arrays.items() if k.startswith("mem/")}
    fit = FitResult(**meta["fit"])
    return (meta["net_config"], net), (meta["mem_config"], mem), float(meta["v_paper"]), fit
