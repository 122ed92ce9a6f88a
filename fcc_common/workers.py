"""Worker-process set-up shared by every process pool of the project.

Two pools use it: the sweep's local backend (:mod:`evaluation.backends`) and the parallel training
of a diagnoser's models (:mod:`diagnosers.bank.parallel`). Both start workers with the ``spawn`` method
(numba and torch thread pools do not survive ``fork`` reliably) and call :func:`init_worker` in
each: one compute thread per worker, since the parallelism comes from the processes, and a
watchdog that ends the worker when the process that started it dies.

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
from collections.abc import Iterator
from multiprocessing.context import SpawnContext, SpawnProcess
from typing import Any

__all__ = [
    "PARENT_POLL_S",
    "cpu_count",
    "exit_with_parent",
    "init_worker",
    "limit_threads",
    "spawn_context",
]

#: Seconds between a worker's checks that the driver process is still alive.
PARENT_POLL_S = 0.5


def limit_threads() -> None:
    """One compute thread per worker: the parallelism comes from the worker processes."""
    if "torch" in sys.modules:
        sys.modules["torch"].set_num_threads(1)
    if "numba" in sys.modules:
        sys.modules["numba"].set_num_threads(1)


def exit_with_parent(parent_pid: int, poll_s: float = PARENT_POLL_S) -> None:
    """Make this worker exit when ``parent_pid`` dies, even when the parent is SIGKILLed.

    On Linux the kernel signals it (``prctl(PR_SET_PDEATHSIG, SIGKILL)``); everywhere a daemon
    thread also polls ``os.getppid()`` (re-parenting means the parent is gone) and calls
    ``os._exit``. Without this a killed leaderboard leaves its spawn workers running forever.
    """
    import threading
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


class _QuietSpawnProcess(SpawnProcess):
    """A ``spawn`` process that starts with SIGINT blocked (see the module doc)."""

    def start(self) -> None:
        with _sigint_blocked():
            super().start()


class _QuietSpawnContext(SpawnContext):
    Process = _QuietSpawnProcess


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
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    import numba

    numba.set_num_threads(1)
    limit_threads()


def cpu_count() -> int:
    """Cores this process may run on (its affinity mask where the platform has one)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1
