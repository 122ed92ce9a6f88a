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
safely: a job is trained under an exclusive lock on its key (POSIX ``flock`` on a regular
``.lock`` file, created exclusively), so a second process that wants it waits (at most
:data:`LOCK_TIMEOUT_S`) and reads it instead of training it again.

A cache directory is a place anyone may have edited, so nothing in it is trusted:

* entries are ``.npz`` files read within caps and without unpickling
  (:func:`fcc_common.safe_files.load_npz`: regular files only, no decompression bomb);
* an entry names its own key: another job's entry copied or linked in is refused;
* its learned arrays must be finite (a NaN weight would surface far away, as an SVD that does
  not converge);
* a lock that is not a regular file (a FIFO would block ``open`` for ever) or that stays held
  too long is bypassed, and a shard folder that is a link (it would put entries outside the
  cache) is refused.

Each of these is a warning naming the file, and the job is trained again (its entry replaced
atomically) or trained without the cache: a bad cache costs time, never a wrong model or a hang.
"""

from __future__ import annotations

import contextlib
import dataclasses
import errno
import hashlib
import json
import logging
import math
import os
import re
import stat
import time
from collections.abc import Callable, Iterator, Sequence
from contextvars import ContextVar
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np
import torch

from fcc_common.io import atomic_open
from fcc_common.safe_files import load_npz
from fcc_common.validation import invalid

try:  # POSIX: processes that want the same job wait for the one training it
    import fcntl
except ImportError:  # pragma: no cover - Windows: each process may train a job once more
    fcntl = None  # type: ignore[assignment]

__all__ = [
    "CACHE_FORMAT",
    "LOCK_TIMEOUT_S",
    "RelationCache",
    "active_cache",
    "job_key",
    "shared_relations",
]

logger = logging.getLogger(__name__)

#: bumped when an entry's layout changes (old entries are then simply not found); 2: an entry
#: holds its own key
CACHE_FORMAT = 2
#: Seconds a process waits for another that trains the same job before it trains it itself.
LOCK_TIMEOUT_S = 1800.0

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
    """A directory of trained relations keyed by :func:`job_key` (see the module doc).

    ``lock_timeout_s``: how long a process waits for another that trains the same job before
    it trains the job itself (both write the same bits, atomically).
    """

    def __init__(
        self, directory: str | os.PathLike, *, lock_timeout_s: float = LOCK_TIMEOUT_S
    ) -> None:
        self.root = Path(directory)
        self.lock_timeout_s = lock_timeout_s

    def path(self, key: str) -> Path:
        """Where the entry of ``key`` (64 hex digits, :func:`job_key`) lives."""
        if not isinstance(key, str) or not _KEY.fullmatch(key):
            raise invalid("key", key, "64 lower-case hex digits (a job_key)")
        return self.root / key[:2] / f"{key}.npz"

    def get(self, key: str) -> tuple[Any, ...] | None:
        """The sound entry of ``key``, or ``None`` (missing, or not trusted: a warning names the
        file). No lock: for a scheduler that trains the missing jobs itself
        (:mod:`evaluation.sweep.training_stage`)."""
        target = self.path(key)
        try:
            _confined_shard(self.root, target.parent)
        except OSError as e:
            logger.warning("relation cache: %s; not read", _reason(e))
            return None
        return _fetch(target, key)

    def put(self, key: str, result: tuple[Any, ...]) -> None:
        """Store ``result`` as the entry of ``key`` (atomically; a result that is not finite,
        or a write that fails, is left out with a warning)."""
        target = self.path(key)
        try:
            _confined_shard(self.root, target.parent)
        except OSError as e:
            logger.warning("relation cache: %s; not cached", _reason(e))
            return
        _store(target, key, result)

    def fetch_or_train(self, key: str, train: Callable[[], tuple[Any, ...]]) -> tuple[Any, ...]:
        """The cached result of ``key``, or ``train()``'s, stored under ``key`` (atomically,
        under the key's lock, so that a concurrent process waits for it).

        A cache that cannot be used safely (a shard folder that leads outside the cache, an
        unusable lock, an entry that cannot be written) is bypassed with a warning naming the
        file: the job is trained as without a cache, never hangs and never trusts a file.
        """
        target = self.path(key)
        try:
            _confined_shard(self.root, target.parent)
        except OSError as e:
            logger.warning("relation cache: %s; training without the cache", _reason(e))
            return train()
        with _locked(target.with_suffix(".lock"), self.lock_timeout_s):
            cached = _fetch(target, key)
            if cached is not None:
                return cached
            result = train()
            _store(target, key, result)
            return result


#: A job key: SHA-256 in hex.
_KEY = re.compile(r"[0-9a-f]{64}")


def _reason(e: OSError) -> str:
    return f"{e.filename}: {e.strerror}" if e.filename and e.strerror else str(e)


def _confined_shard(root: Path, shard: Path) -> None:
    """Create the shard folder ``shard`` of the cache ``root`` and check that it is a folder of
    the cache itself: a link put in its place must not lead entries elsewhere. (``root`` may
    itself be a link: the user chose it.) Raises ``OSError`` naming the folder."""
    shard.mkdir(parents=True, exist_ok=True)
    if shard.is_symlink() or shard.resolve().parent != root.resolve():
        raise OSError(
            errno.EXDEV,
            f"resolves to {shard.resolve()}, outside the cache {root.resolve()}: a link in "
            "place of a shard folder is refused",
            str(shard),
        )


def _fetch(target: Path, key: str) -> tuple[Any, ...] | None:
    """The entry ``target`` of ``key`` if it is a sound one; ``None`` (with a warning naming
    the file) when it is missing, unreadable, another job's, or not finite."""
    if not target.exists():
        return None
    try:
        return _read(target, key)
    except Exception as e:  # an entry is a convenience: retrain, never trust it
        logger.warning(
            "relation cache %s is unreadable or not trusted (%s); training again", target, e
        )
        return None


@contextlib.contextmanager
def _locked(lock_path: Path, timeout_s: float) -> Iterator[None]:
    """Hold the exclusive lock of one key, waiting at most ``timeout_s`` seconds for another
    process. The lock file is a regular file, created exclusively; an unusable one (a FIFO, a
    link, a folder, a lock held too long) is bypassed with a warning: the entry's atomic
    writes keep the cache sound without it, at the cost of a job trained twice."""
    if fcntl is None:  # pragma: no cover
        yield
        return
    try:
        fd = _open_lock(lock_path)
    except OSError as e:
        logger.warning("relation cache lock %s; going on without the lock", _reason(e))
        yield
        return
    try:
        held = _flock(fd, timeout_s)
        if not held:
            logger.warning(
                "relation cache lock %s: held by another process for over %g s; training "
                "without waiting",
                lock_path,
                timeout_s,
            )
        try:
            yield
        finally:
            if held:
                fcntl.flock(fd, fcntl.LOCK_UN)
    finally:
        os.close(fd)


_LOCK_FLAGS = os.O_RDWR | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0)


def _open_lock(lock_path: Path) -> int:
    """A descriptor of the regular file ``lock_path``: created exclusively when missing,
    opened without following a link and without blocking (a FIFO's ``open`` returns at once
    with ``O_NONBLOCK``) when present, and refused unless it is a regular file."""
    try:
        return os.open(lock_path, _LOCK_FLAGS | os.O_CREAT | os.O_EXCL, 0o666)
    except FileExistsError:
        pass
    fd = os.open(lock_path, _LOCK_FLAGS | os.O_NONBLOCK)
    if not stat.S_ISREG(os.fstat(fd).st_mode):
        os.close(fd)
        raise OSError(errno.EINVAL, "not a regular file (a lock must be one)", str(lock_path))
    return fd


def _flock(fd: int, timeout_s: float) -> bool:
    """Take the exclusive ``flock`` of ``fd`` within ``timeout_s`` seconds (released by the
    kernel when its holder dies, so a killed run leaves no stale lock); False on timeout."""
    deadline = time.monotonic() + timeout_s
    pause = 0.01
    while True:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            return True
        except BlockingIOError:
            if time.monotonic() >= deadline:
                return False
            time.sleep(min(pause, max(0.0, deadline - time.monotonic())))
            pause = min(2 * pause, 0.5)


def _store(target: Path, key: str, result: tuple[Any, ...]) -> None:
    """Write ``result`` as the entry of ``key``; a result that is not finite is not stored, and
    a failed write leaves the cache as it was (a warning names the file either way)."""
    try:
        arrays = _entry_arrays(key, result)
        _check_finite(arrays, result[2])
    except ValueError as e:
        logger.warning("relation cache: not storing %s (%s)", target, e)
        return
    try:
        with atomic_open(target, "wb") as fh:
            np.savez(fh, **arrays)
    except OSError as e:
        logger.warning("relation cache: cannot write %s (%s); not cached", target, _reason(e))


def _entry_arrays(key: str, result: tuple[Any, ...]) -> dict[str, np.ndarray]:
    (net_cfg, net_state), (mem_cfg, mem_state), v_paper, fit = result
    meta = {
        "key": key,  # an entry names its job: one copied or linked under another key is refused
        "net_config": net_cfg,
        "mem_config": mem_cfg,
        "v_paper": float(v_paper),
        "fit": dataclasses.asdict(fit),
    }
    arrays = {f"net/{k}": np.asarray(v) for k, v in net_state.items()}
    arrays.update({f"mem/{k}": np.asarray(v) for k, v in mem_state.items()})
    arrays["meta"] = np.array(json.dumps(meta))
    return arrays


def _check_finite(arrays: dict[str, np.ndarray], v_paper: Any) -> None:
    """Refuse learned arrays (and the error band ``v_paper``) that are not finite, naming the
    array (the caller names the file): a NaN weight would otherwise surface far away, as an
    SVD that does not converge."""
    for name, a in arrays.items():
        if name != "meta" and a.dtype.kind in "fc" and not np.isfinite(a).all():
            raise ValueError(f"its array {name!r} holds non-finite values (NaN or inf)")
    if not isinstance(v_paper, int | float) or not math.isfinite(v_paper):
        raise ValueError(f"its v_paper={v_paper!r} is not a finite number")


def _read(target: Path, key: str) -> tuple[Any, ...]:
    """The entry ``target`` (read within :mod:`fcc_common.safe_files`' caps, never unpickling),
    checked to be the entry of ``key`` and finite; ``ValueError`` (or the reader's error)
    otherwise."""
    from diagnosers.networks.optimisers import FitResult

    arrays = load_npz(target)
    meta = json.loads(str(arrays["meta"]))
    if not isinstance(meta, dict) or meta.get("key") != key:
        found = meta.get("key") if isinstance(meta, dict) else None
        raise ValueError(
            f"it is the entry of another job (key {str(found)[:12]}..., not {key[:12]}...): "
            "copied or linked in, it is not trusted"
        )
    _check_finite(arrays, meta.get("v_paper"))
    net = {k.removeprefix("net/"): v for k, v in arrays.items() if k.startswith("net/")}
    mem = {k.removeprefix("mem/"): v for k, v in arrays.items() if k.startswith("mem/")}
    fit = FitResult(**meta["fit"])
    return (meta["net_config"], net), (meta["mem_config"], mem), float(meta["v_paper"]), fit
