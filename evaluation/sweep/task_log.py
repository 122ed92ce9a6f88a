"""Per-task accounting: what each task of a sweep or a track cost, and the driver's own time.

Every driver call that runs tasks (:func:`~evaluation.sweep.runner.run_sweep`,
:func:`~evaluation.tracks.reference_runs.run_references`) wraps its backend in a
:class:`ProfiledBackend`: each task runs inside :func:`timed_call`, which measures its CPU
seconds (:func:`time.process_time` in the process that runs it: the worker's, not the
driver's) and wall seconds, and the driver appends one JSON line per finished task to the
store's ``timings.jsonl`` (:data:`TIMINGS_FILE`, :class:`TaskLog`). The driver's own CPU
seconds are recorded per stage (``kind: "driver"``): reading the store, scheduling, writing
what comes back. Tasks that ran in the driver (``n_workers=0``) are subtracted from it.

A line (format :data:`TIMINGS_FORMAT`, one ``os.write`` on a file opened for appending, so
lines of concurrent writers do not interleave and a killed run loses at most its last line)::

    {"format": "fcc-task-timing", "version": 1, "run": "<id of the driver call>",
     "scope": "sweep" | "references" | "track", "stage": "train" | "score" | ...,
     "id": 7, "kind": "relation", "key": "...", "after": [3],
     "cpu_s": 41.2, "wall_s": 55.0, "start_s": 12.1, "end_s": 67.1,
     "pid": 4242, "startup_cpu_s": 3.1 | null, "parts": {"simulate": 0.04}}

``after`` lists the ids (same run) of the tasks it waited for: its dependencies as the driver
schedules them. ``startup_cpu_s`` is set on a worker's first task: the CPU the process spent
before it (interpreter start, imports). ``parts`` holds the CPU of named blocks inside the
task (:func:`task_part`: the simulation of an episode, each diagnoser's detection).
:mod:`bench.task_profile` reads the files and projects the makespan on ``n`` workers.

Accounting changes no result: the task functions run unchanged inside :func:`timed_call`.
"""

from __future__ import annotations

import contextlib
import json
import os
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextvars import ContextVar
from dataclasses import dataclass
from pathlib import Path
from typing import Any

__all__ = [
    "TIMINGS_FILE",
    "TIMINGS_FORMAT",
    "TIMINGS_VERSION",
    "ProfiledBackend",
    "TaskLog",
    "read_timings",
    "submit_task",
    "task_part",
    "timed_call",
]

TIMINGS_FILE = "timings.jsonl"
TIMINGS_FORMAT = "fcc-task-timing"
TIMINGS_VERSION = 1

#: The parts of the task running in this process (None outside :func:`timed_call`).
_PARTS: ContextVar[dict[str, float] | None] = ContextVar("fcc_task_parts", default=None)
#: Whether this process has run a timed task (its first reports the process's start-up CPU).
_RAN: dict[str, bool] = {"any": False}


@contextlib.contextmanager
def task_part(name: str) -> Iterator[None]:
    """Add the CPU seconds of the block to part ``name`` of the task running here (outside a
    timed task: nothing is recorded)."""
    parts = _PARTS.get()
    if parts is None:
        yield
        return
    c0 = time.process_time()
    try:
        yield
    finally:
        parts[name] = parts.get(name, 0.0) + time.process_time() - c0


def timed_call(
    fn: Callable[..., Any], *args: Any, _serial: bool = False
) -> tuple[Any, dict[str, Any]]:
    """``(fn(*args), its timing)``: CPU and wall seconds, start and end (epoch seconds), the
    process id, its start-up CPU when this is the process's first timed task, and the parts
    (:func:`task_part`). ``_serial``: passed on (the task runs in the driver)."""
    startup = None if (_serial or _RAN["any"]) else time.process_time()
    _RAN["any"] = True
    parts: dict[str, float] = {}
    token = _PARTS.set(parts)
    c0, w0, e0 = time.process_time(), time.perf_counter(), time.time()
    try:
        result = fn(*args, _serial=_serial)
    finally:
        _PARTS.reset(token)
    stats = {
        "cpu_s": time.process_time() - c0,
        "wall_s": time.perf_counter() - w0,
        "start": e0,
        "end": time.time(),
        "pid": os.getpid(),
        "startup_cpu_s": startup,
        "parts": parts,
    }
    return result, stats


class TaskLog:
    """Appends timing lines to ``path`` (see the module doc) for one driver call, ``scope``
    naming it (``"sweep"``, ``"references"``, ``"track"``)."""

    def __init__(self, path: str | os.PathLike, scope: str, backend: str, workers: int | None):
        self.path = Path(path)
        self.scope = scope
        self.run = f"{time.time_ns():x}-{os.getpid()}"
        self.t0 = time.time()
        self.backend, self.workers = backend, workers
        self.stage_name = "plan"
        self._next_id = 0
        self._in_driver_cpu = 0.0  # CPU of tasks that ran in this process (subtracted)

    def new_id(self) -> int:
        self._next_id += 1
        return self._next_id

    def write(self, record: Mapping[str, Any]) -> None:
        """Append one line (one ``os.write``; a symbolic link in its place is refused)."""
        line = {
            "format": TIMINGS_FORMAT,
            "version": TIMINGS_VERSION,
            "run": self.run,
            "run_t0": self.t0,
            "scope": self.scope,
            "stage": self.stage_name,
            "backend": self.backend,
            "workers": self.workers,
            **record,
        }
        data = (json.dumps(line, sort_keys=True) + "\n").encode()
        flags = os.O_WRONLY | os.O_APPEND | os.O_CREAT | getattr(os, "O_NOFOLLOW", 0)
        fd = os.open(self.path, flags, 0o644)
        try:
            os.write(fd, data)
        finally:
            os.close(fd)

    def task(
        self,
        task_id: int,
        kind: str,
        key: str,
        after: Sequence[int],
        stats: Mapping[str, Any],
        info: Mapping[str, Any] | None = None,
    ) -> None:
        """Record a finished task (``stats`` from :func:`timed_call`; ``info``: facts the
        driver knows of it, e.g. a relation job's cost model)."""
        if stats["pid"] == os.getpid():
            self._in_driver_cpu += stats["cpu_s"]
        self.write(
            {
                "id": task_id,
                "kind": kind,
                "key": key,
                "after": sorted(after),
                "cpu_s": stats["cpu_s"],
                "wall_s": stats["wall_s"],
                "start_s": stats["start"] - self.t0,
                "end_s": stats["end"] - self.t0,
                "pid": stats["pid"],
                "startup_cpu_s": stats["startup_cpu_s"],
                "parts": stats["parts"],
                **({"info": dict(info)} if info else {}),
            }
        )

    @contextlib.contextmanager
    def stage(self, name: str) -> Iterator[None]:
        """The block is stage ``name`` of the driver: its tasks are filed under it, and the
        driver's CPU in it (less the tasks it ran itself) is recorded as ``kind: "driver"``."""
        previous, self.stage_name = self.stage_name, name
        c0, w0, e0 = time.process_time(), time.perf_counter(), time.time()
        inside0 = self._in_driver_cpu
        try:
            yield
        finally:
            cpu = time.process_time() - c0 - (self._in_driver_cpu - inside0)
            self.write(
                {
                    "id": 0,
                    "kind": "driver",
                    "key": name,
                    "after": [],
                    "cpu_s": max(cpu, 0.0),
                    "wall_s": time.perf_counter() - w0,
                    "start_s": e0 - self.t0,
                    "end_s": time.time() - self.t0,
                    "pid": os.getpid(),
                    "startup_cpu_s": None,
                    "parts": {},
                }
            )
            self.stage_name = previous


@dataclass
class _Submitted:
    id: int
    kind: str
    key: str
    after: tuple[int, ...]
    info: Mapping[str, Any] | None


class ProfiledBackend:
    """A backend (:class:`~evaluation.sweep.backends.Backend`) whose tasks are timed and logged.

    :meth:`submit_as` names the task (kind, key) and what it waits for (``after``: handles of
    earlier tasks; by default the task whose result the driver took last, which is what
    prompted the submission). :meth:`completed` yields the tasks' own results, as the inner
    backend would, and writes each one's line first.
    """

    def __init__(self, inner: Any, log: TaskLog) -> None:
        self.inner = inner
        self.log = log
        self.passes_paths = inner.passes_paths
        self._tasks: dict[Any, _Submitted] = {}
        self._last: int | None = None

    def put(self, obj: Any) -> Any:
        return self.inner.put(obj)

    def submit(self, fn: Callable[..., Any], *args: Any) -> Any:
        return self.submit_as(fn.__name__, "", fn, *args)

    def submit_as(
        self,
        kind: str,
        key: str,
        fn: Callable[..., Any],
        *args: Any,
        after: Any = None,
        info: Mapping[str, Any] | None = None,
    ) -> Any:
        if after is None:
            deps: tuple[int, ...] = () if self._last is None else (self._last,)
        else:
            deps = tuple(sorted({self._tasks[h].id for h in after if h in self._tasks}))
        handle = self.inner.submit(timed_call, fn, *args)
        self._tasks[handle] = _Submitted(self.log.new_id(), kind, key, deps, info)
        return handle

    def completed(self, handles: list[Any]) -> Iterator[tuple[Any, Any]]:
        for handle, (result, stats) in self.inner.completed(handles):
            t = self._tasks[handle]
            self.log.task(t.id, t.kind, t.key, t.after, stats, t.info)
            self._last = t.id
            yield handle, result

    def close(self, cancel: bool) -> None:
        self.inner.close(cancel=cancel)


def submit_task(
    runner: Any,
    kind: str,
    key: str,
    fn: Callable[..., Any],
    *args: Any,
    after: Any = None,
    info: Mapping[str, Any] | None = None,
) -> Any:
    """Submit ``fn(*args)`` to ``runner``, named and with its dependencies when the runner is a
    :class:`ProfiledBackend` (a plain backend just runs it)."""
    if isinstance(runner, ProfiledBackend):
        return runner.submit_as(kind, key, fn, *args, after=after, info=info)
    return runner.submit(fn, *args)


def read_timings(path: str | os.PathLike) -> list[dict[str, Any]]:
    """The lines of a timings file; a line of another format, or cut short (a killed run's
    last), is skipped; a file that is not one raises ValueError naming it."""
    p = Path(path)
    if p.is_symlink() or not p.is_file():
        raise ValueError(f"{p} is not a regular timings file ({TIMINGS_FILE})")
    out = []
    with p.open(encoding="utf-8") as fh:
        for line in fh:
            try:
                rec = json.loads(line)
            except json.JSONDecodeError:
                continue
            if isinstance(rec, dict) and rec.get("format") == TIMINGS_FORMAT:
                if rec.get("version") != TIMINGS_VERSION:
                    raise ValueError(
                        f"{p}: timings version {rec.get('version')!r}; allowed: {TIMINGS_VERSION}"
                    )
                out.append(rec)
    return out
