"""Execution backends of a sweep: local processes (default), Ray, or this process.

``"local"`` runs tasks in a :class:`~concurrent.futures.ProcessPoolExecutor` with the ``spawn``
start method (numba and torch thread pools do not survive ``fork`` reliably), one worker per
core by default; each worker limits numba, torch and BLAS to one thread, since parallelism comes
from the processes (:mod:`fcc_common.workers`). ``"ray"`` runs the
same task functions as Ray tasks (``ray.init(address=...)`` when an address is given, else a
local instance with one CPU per worker). ``n_workers=0`` runs every task in the calling process
(:class:`SerialBackend`), for debugging and fast tests. Results always travel back to the driver,
which alone writes the store, so remote Ray nodes need no shared file system.
"""

from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import Callable, Iterator
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from pathlib import Path
from typing import Any, Protocol

# the worker set-up is shared with diagnosers.bank.parallel (fcc_common.workers)
from fcc_common.workers import (
    THREAD_ENV_VARS,
    cpu_count,
    init_worker,
    spawn_context,
    stop_workers,
)

#: Execution backends accepted by :func:`evaluation.sweep.run_sweep`.
BACKENDS: tuple[str, ...] = ("local", "ray")


class Backend(Protocol):
    passes_paths: bool

    def put(self, obj: Any) -> Any: ...

    def submit(self, fn: Callable[..., Any], *args: Any) -> Any: ...

    def completed(self, handles: list[Any]) -> Iterator[tuple[Any, Any]]: ...

    def close(self, cancel: bool) -> None: ...


class LocalBackend:
    passes_paths = True

    def __init__(self, n_workers: int) -> None:
        self._pool = ProcessPoolExecutor(
            max_workers=n_workers,
            mp_context=spawn_context(),
            initializer=init_worker,
            initargs=(os.getpid(),),
        )

    def put(self, obj: Any) -> Any:
        return obj

    def submit(self, fn: Callable[..., Any], *args: Any) -> Future:
        return self._pool.submit(fn, *args)

    def completed(self, handles: list[Future]) -> Iterator[tuple[Future, Any]]:
        pending = set(handles)
        while pending:
            done, pending = wait(pending, return_when=FIRST_COMPLETED)
            for fut in done:
                yield fut, fut.result()

    def close(self, cancel: bool) -> None:
        if cancel:  # a Ctrl-C: no worker, even one still starting, outlives the driver
            stop_workers()
        self._pool.shutdown(wait=not cancel, cancel_futures=cancel)


def ray_runtime_env() -> dict[str, Any]:
    """Runtime environment that lets local Ray workers import this repository's packages."""
    root = str(Path(__file__).resolve().parents[1])
    path = os.pathsep.join([root, *filter(None, [os.environ.get("PYTHONPATH", "")])])
    # one thread per task for the native libraries a worker loads (see fcc_common.workers)
    return {"env_vars": {"PYTHONPATH": path, **dict.fromkeys(THREAD_ENV_VARS, "1")}}


def start_watchdog() -> subprocess.Popen[bytes] | None:
    """Start :mod:`evaluation.sweep.backends_watchdog` on this process (Linux only): it reaps the
    local Ray processes if this driver is killed, which Ray does not do for its agents."""
    if not os.path.isdir("/proc"):
        return None
    script = Path(__file__).with_name("backends_watchdog.py")
    proc = subprocess.Popen(
        [sys.executable, str(script), str(os.getpid())],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        start_new_session=True,  # a Ctrl-C of the driver's terminal leaves it to its job
    )
    assert proc.stdout is not None
    proc.stdout.readline()  # it has noted the processes that are not Ray's
    proc.stdout.close()
    return proc


def stop_watchdog(proc: subprocess.Popen[bytes]) -> None:
    """A normal shutdown: the watchdog exits without touching a process."""
    try:
        assert proc.stdin is not None
        proc.stdin.write(b"stop")
        proc.stdin.close()
    except OSError:
        pass
    proc.wait(timeout=10)


class RayBackend:
    """Ray tasks of one CPU each, at most ``max_in_flight`` at once (``None``: as many as the
    cluster takes). The cap is how ``n_workers`` applies to a cluster that has more CPUs than
    the sweep should use (the scaling benchmark's 1, 2, 4... workers on one cluster): tasks
    beyond it wait here and start, in submission order, as others finish."""

    passes_paths = False

    class _Task:
        """A submitted task (hashable by identity); ``ref`` once it runs on Ray."""

        def __init__(self, fn: Any, args: tuple) -> None:
            self.fn, self.args, self.ref = fn, args, None

    def __init__(
        self, n_workers: int, address: str | None, max_in_flight: int | None = None
    ) -> None:
        try:
            import ray
        except ImportError as e:
            raise ImportError(
                "backend='ray' needs Ray: pip install 'fcc-fault-diagnosis[ray]'"
            ) from e
        self._ray = ray
        self._owned = False
        self._watchdog: subprocess.Popen[bytes] | None = None
        if not ray.is_initialized():
            if address is not None:
                ray.init(address=address)
            else:
                self._watchdog = start_watchdog()  # before Ray's processes: it records them
                ray.init(
                    num_cpus=n_workers,
                    include_dashboard=False,
                    runtime_env=ray_runtime_env(),
                    log_to_driver=False,
                )
            self._owned = True
        self._remote: dict[Callable[..., Any], Any] = {}
        self._limit = max_in_flight
        self._queue: list[RayBackend._Task] = []  # submitted, waiting for a free slot
        self._running: dict[Any, RayBackend._Task] = {}  # ref -> task
        self._done: dict[RayBackend._Task, Any] = {}  # finished, not yet collected

    def put(self, obj: Any) -> Any:
        return self._ray.put(obj)

    def submit(self, fn: Callable[..., Any], *args: Any) -> RayBackend._Task:
        task = self._Task(fn, args)
        self._queue.append(task)
        self._start_queued()
        return task

    def _start_queued(self) -> None:
        while self._queue and (self._limit is None or len(self._running) < self._limit):
            task = self._queue.pop(0)
            if task.fn not in self._remote:
                self._remote[task.fn] = self._ray.remote(num_cpus=1)(task.fn)
            task.ref = self._remote[task.fn].remote(*task.args)
            self._running[task.ref] = task

    def completed(self, handles: list[Any]) -> Iterator[tuple[Any, Any]]:
        pending = set(handles)
        while pending:
            ready = [h for h in pending if h in self._done]
            if not ready:
                if not self._running:
                    raise RuntimeError("waiting for Ray tasks that were never submitted")
                done, _ = self._ray.wait(list(self._running), num_returns=1)
                for ref in done:
                    task = self._running.pop(ref)
                    try:
                        self._done[task] = (True, self._ray.get(ref))
                    except Exception as e:  # raised when its turn to be collected comes
                        self._done[task] = (False, e)
                self._start_queued()
                continue
            for h in ready:
                pending.discard(h)
                ok, value = self._done.pop(h)
                if not ok:
                    raise value
                yield h, value

    def close(self, cancel: bool) -> None:
        for ref in list(self._running) if cancel else ():
            self._ray.cancel(ref)
        self._queue.clear()
        if self._owned:
            self._ray.shutdown()
        if self._watchdog is not None:  # Ray cleaned up: tell the watchdog so, and let it go
            stop_watchdog(self._watchdog)
            self._watchdog = None


class SerialBackend:
    """Runs each task in the calling process when its result is collected (``n_workers=0``).

    For debugging and fast tests: no process start-up, exceptions with their full traceback. The
    caller's thread settings are left alone (``limit_threads`` is a worker-only measure).
    """

    passes_paths = True

    def put(self, obj: Any) -> Any:
        return obj

    class _Deferred:
        """A task not run yet (hashable by identity, like a Future)."""

        def __init__(self, fn: Callable[..., Any], args: tuple) -> None:
            self.fn, self.args = fn, args

    def submit(self, fn: Callable[..., Any], *args: Any) -> SerialBackend._Deferred:
        return self._Deferred(fn, args)

    def completed(self, handles: list[Any]) -> Iterator[tuple[Any, Any]]:
        for h in handles:
            yield h, h.fn(*h.args, _serial=True)

    def close(self, cancel: bool) -> None:
        pass


def make_backend(
    backend: str, n_workers: int | None, n_tasks: int, ray_address: str | None = None
) -> Backend:
    """The backend that runs ``n_tasks`` tasks: ``n_workers=0`` runs them in this process;
    otherwise ``n_workers`` (default: all cores) capped at the number of tasks. On a Ray cluster
    (``ray_address``, or Ray already initialised) ``n_workers`` caps the tasks running at once,
    and its default is the whole cluster."""
    if n_workers == 0:
        return SerialBackend()
    workers = min(n_workers or cpu_count(), max(n_tasks, 1))
    if backend == "local":
        return LocalBackend(workers)
    return RayBackend(workers, ray_address, max_in_flight=None if n_workers is None else workers)
