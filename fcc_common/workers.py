"""Worker-process set-up shared by every process pool of the project.

Two pools use it: the sweep's local backend (:mod:`evaluation.backends`) and the parallel training
of a diagnoser's models (:mod:`diagnosers.bank.parallel`). Both start workers with the ``spawn`` method
(numba and torch thread pools do not survive ``fork`` reliably) and call :func:`init_worker` in
each: one compute thread per worker, since the parallelism comes from the processes, and a
watchdog that ends the worker when the process that started it dies.

**Threads.** One worker per core (:func:`cpu_count`, the pools' default), and one compute
thread per worker: numba's thread pool, torch's intra-op pool and the BLAS/OpenMP pools of
NumPy and SciPy (OpenBLAS, MKL, BLIS, libgomp, through ``threadpoolctl``, which scikit-learn
installs) are set to one thread, and the ``*_NUM_THREADS`` variables (:data:`THREAD_ENV_VARS`)
to ``1`` for libraries loaded later. A task that wants more threads (a large matrix product, say) asks for them with
:func:`task_threads`; on the local pool it then shares its core with others, so size the pool
to match (``n_workers`` times threads at most the cores). Ray workers get the same limits from
:func:`limit_threads`, which every task of the sweep calls first. The native vector env's
OpenMP barrier settings are documented in the user guide (``docs/cluster.md``).

A Ctrl-C reaches every process of the terminal's process group, the workers included. The
driver reports it in one line (:func:`fcc_common.invocation.run_command`); a worker must not
print a traceback of its own, wherever it is (starting the interpreter, importing, running a
task). So :func:`spawn_context` starts each worker with SIGINT blocked (a blocked signal stays
pending across ``fork`` and ``exec``), and :func:`init_worker` then makes SIGINT end the worker
silently before unblocking it: the driver, interrupted too, does the reporting.
"""

from __future__ import annotations

import contextlib
import multiprocessing
import os
import signal
import sys
import threading
from collections.abc import Iterator
from multiprocessing.context import SpawnContext, SpawnProcess
from typing import Any

__all__ = [
    "PARENT_POLL_S",
    "THREAD_ENV_VARS",
    "cpu_count",
    "exit_with_parent",
    "init_worker",
    "limit_threads",
    "spawn_context",
    "task_threads",
    "thread_counts",
]

#: Seconds between a worker's checks that the driver process is still alive.
PARENT_POLL_S = 0.5


#: Environment variables that size the thread pools of native libraries when they load.
THREAD_ENV_VARS: tuple[str, ...] = (
    "OMP_NUM_THREADS",
    "OPENBLAS_NUM_THREADS",
    "MKL_NUM_THREADS",
    "BLIS_NUM_THREADS",
    "VECLIB_MAXIMUM_THREADS",
    "NUMEXPR_NUM_THREADS",
)


def _set_native_threads(n: int) -> None:
    """BLAS/OpenMP pools already loaded in this process, through ``threadpoolctl`` if installed."""
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # the environment variables (set before the libraries load) suffice
        return
    threadpool_limits(limits=n)


def limit_threads(n: int = 1) -> None:
    """``n`` compute threads per worker (one by default: the parallelism comes from the worker
    processes) for torch, numba and the BLAS/OpenMP pools already loaded."""
    if "torch" in sys.modules:
        sys.modules["torch"].set_num_threads(n)
    if "numba" in sys.modules:
        numba = sys.modules["numba"]  # at most its pool's size (NUMBA_NUM_THREADS, the cores)
        numba.set_num_threads(min(n, numba.config.NUMBA_NUM_THREADS))
    _set_native_threads(n)


def thread_counts() -> dict[str, int]:
    """The compute threads this process would use: ``torch``, ``numba`` (of the modules
    loaded) and ``blas`` (the largest pool ``threadpoolctl`` sees; absent without it)."""
    out: dict[str, int] = {}
    if "torch" in sys.modules:
        out["torch"] = int(sys.modules["torch"].get_num_threads())
    if "numba" in sys.modules:
        out["numba"] = int(sys.modules["numba"].get_num_threads())
    try:
        from threadpoolctl import threadpool_info
    except ImportError:
        return out
    pools = [int(p["num_threads"]) for p in threadpool_info()]
    if pools:
        out["blas"] = max(pools)
    return out


@contextlib.contextmanager
def task_threads(n: int) -> Iterator[None]:
    """Within the block, ``n`` compute threads for torch, numba and BLAS; one again after it.

    For a task that asks for more than the worker's one thread (see the module doc). Worker
    processes only: it leaves the limits at one thread, not at what they were before.
    """
    if isinstance(n, bool) or not isinstance(n, int) or n < 1:
        raise ValueError(f"task_threads(n={n!r}): n must be an integer >= 1")
    limit_threads(n)
    try:
        yield
    finally:
        limit_threads(1)


def exit_with_parent(parent_pid: int, poll_s: float = PARENT_POLL_S) -> None:
    """Make this worker exit when ``parent_pid`` dies, even when the parent is SIGKILLed.

    On Linux the kernel signals it (``prctl(PR_SET_PDEATHSIG, SIGKILL)``); everywhere a daemon
    thread also polls ``os.getppid()`` (re-parenting means the parent is gone) and calls
    ``os._exit``. Without this a killed leaderboard leaves its spawn workers running forever.
    """
    import time

    if sys.platform.startswith("linux"):
        try:
            import ctypes
            import signal

            libc = ctypes.CDLL(None, use_errno=True)
            pr_set_pdeathsig = 1
            libc.prctl(pr_set_pdeathsig, int(signal.SIGKILL), 0, 0, 0)
        except (OSError, AttributeError):  # no libc prctl: the thread below suffices
            pass

    def watch() -> None:
        while os.getppid() == parent_pid:
            time.sleep(poll_s)
        os._exit(1)

    if os.getppid() != parent_pid:  # already orphaned between spawn and here
        os._exit(1)
    threading.Thread(target=watch, name="fcc-parent-watch", daemon=True).start()


@contextlib.contextmanager
def _sigint_blocked() -> Iterator[None]:
    """SIGINT held pending in this thread (and in the processes it starts) within the block."""
    if not hasattr(signal, "pthread_sigmask"):  # pragma: no cover - not POSIX
        yield
        return
    old = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)  # a pending Ctrl-C is delivered here


@contextlib.contextmanager
def _sigint_deferred() -> Iterator[None]:
    """:func:`_sigint_blocked`, and a Ctrl-C that arrives within the block raised after it.

    Blocking SIGINT in this thread is not enough in a process with other threads (a progress
    bar's, the pool's manager): the kernel hands the signal to one of them, and Python then
    raises KeyboardInterrupt in the main thread whatever its mask, in the middle of writing a
    starting worker's preparation data (the worker then prints an ``EOFError`` traceback). So
    the main thread's handler only records the signal until the worker has started."""
    if threading.current_thread() is not threading.main_thread():
        with _sigint_blocked():
            yield
        return
    caught: list[int] = []
    previous = signal.signal(signal.SIGINT, lambda signum, _frame: caught.append(signum))
    try:
        with _sigint_blocked():
            yield
    finally:
        signal.signal(signal.SIGINT, previous)
        if caught:
            signal.raise_signal(signal.SIGINT)  # delivered now, to the handler restored above


class _QuietSpawnProcess(SpawnProcess):
    """A ``spawn`` process that starts with SIGINT blocked (see the module doc)."""

    def start(self) -> None:
        with _sigint_deferred():
            super().start()


class _QuietSpawnContext(SpawnContext):
    Process = _QuietSpawnProcess


def stop_workers(timeout_s: float = 5.0) -> None:
    """Stop every pool worker this process started (:func:`spawn_context`'s processes), at
    once, and wait for them: what an interrupted driver does before it exits.

    A worker still starting when Ctrl-C arrives would otherwise unpickle the pool's semaphores
    after the driver has released them and print a traceback of its own; one that the pool had
    not yet registered is among these too (``multiprocessing.active_children``)."""
    workers = [p for p in multiprocessing.active_children() if isinstance(p, _QuietSpawnProcess)]
    for proc in workers:
        proc.terminate()
    for proc in workers:
        proc.join(timeout=timeout_s)


def spawn_context() -> Any:
    """The ``spawn`` multiprocessing context of the project's pools: the same start method as
    ``multiprocessing.get_context("spawn")``, with workers that a Ctrl-C ends silently (module
    doc; the pool's ``initializer`` must be :func:`init_worker`)."""
    if not hasattr(signal, "pthread_sigmask"):  # pragma: no cover - not POSIX
        return multiprocessing.get_context("spawn")
    return _QuietSpawnContext()


def _exit_quietly(signum: int, _frame: Any) -> None:
    os._exit(128 + signum)  # no traceback, no clean-up: the driver reports the interruption


def init_worker(parent_pid: int | None = None) -> None:
    """Initializer of a pool worker: a Ctrl-C ends it silently, the parent watchdog, then one
    compute thread."""
    if hasattr(signal, "pthread_sigmask"):
        signal.signal(signal.SIGINT, _exit_quietly)
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
    if parent_pid is not None:
        exit_with_parent(parent_pid)
    for name in THREAD_ENV_VARS:  # for the native libraries this worker has not loaded yet
        os.environ[name] = "1"
    import numba
    import torch

    limit_threads()
    # the first parallel numba call starts its pool with this count; torch's inter-op pool
    # too can only be sized before its first use
    numba.set_num_threads(1)
    try:
        torch.set_num_interop_threads(1)
    except RuntimeError:  # already used in this process (a fork): its pool stays as it is
        pass


def cpu_count() -> int:
    """Cores this process may run on (its affinity mask where the platform has one)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1
