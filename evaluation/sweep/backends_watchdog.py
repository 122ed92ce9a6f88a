"""Reap the local Ray cluster of a driver that was killed: ``python backends_watchdog.py PID``.

Ray ties its GCS server and raylet to the driver that started them (``PR_SET_PDEATHSIG``), but the
raylet's agents (``ray::DashboardAgent``, ``ray::RuntimeEnvAgent``) notice the raylet's death and
then wait on the dead GCS server for ever. :class:`~evaluation.sweep.backends.RayBackend` starts
this watchdog before ``ray.init`` with a pipe on its standard input. While the pipe is open it
records every process that appears below the driver (with its start time, so that a reused pid is
never taken for one of them). ``stop`` followed by the end of the pipe is a normal shutdown (Ray
cleaned up): it exits. The end of the pipe alone (the driver was killed: the kernel closed it),
or the driver gone, means nothing else will clean up: it terminates, then kills, the recorded
processes still alive.

Run as a file (not ``-m``), so that it imports the standard library only; Linux (``/proc``) only.
"""

from __future__ import annotations

import os
import select
import signal
import sys
import time

#: Seconds between two looks at the process tree, and a terminated process's grace period.
POLL_S = 0.5
GRACE_S = 3.0


def _stat(pid: int) -> tuple[int, int] | None:
    """``(parent pid, start time)`` of a live process, else ``None``."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as f:
            fields = f.read().rsplit(b")", 1)[1].split()  # the name may hold spaces or ')'
    except (OSError, IndexError):
        return None
    return int(fields[1]), int(fields[19])


def descendants(root: int) -> dict[int, int]:
    """Every process below ``root``: pid -> start time."""
    children: dict[int, list[tuple[int, int]]] = {}
    for name in os.listdir("/proc"):
        if name.isdigit():
            st = _stat(int(name))
            if st is not None:
                children.setdefault(st[0], []).append((int(name), st[1]))
    out: dict[int, int] = {}
    todo = [root]
    while todo:
        for pid, start in children.get(todo.pop(), []):
            if pid not in out:
                out[pid] = start
                todo.append(pid)
    return out


def reap(procs: dict[int, int]) -> None:
    """SIGTERM, then after :data:`GRACE_S` SIGKILL, each process that is still the one recorded."""

    def alive() -> list[int]:
        return [p for p, start in procs.items() if (_stat(p) or (0, -1))[1] == start]

    for sig in (signal.SIGTERM, signal.SIGKILL):
        for pid in alive():
            try:
                os.kill(pid, sig)
            except OSError:
                pass
        deadline = time.monotonic() + GRACE_S
        while alive() and time.monotonic() < deadline:
            time.sleep(0.1)


def watch(driver: int) -> None:
    me = os.getpid()
    before = set(descendants(driver))  # the driver's processes of its own: never touched
    print("ready", flush=True)  # the driver starts Ray after this line
    sys.stdout.close()
    seen: dict[int, int] = {}
    text = b""
    stdin = sys.stdin.fileno()
    while True:
        seen.update((p, s) for p, s in descendants(driver).items() if p != me and p not in before)
        ready, _, _ = select.select([stdin], [], [], POLL_S)
        if ready:
            chunk = os.read(stdin, 64)
            if not chunk:
                break
            text += chunk
        if os.getppid() != driver:  # reparented: the driver is gone
            break
    if b"stop" not in text:
        reap(seen)


if __name__ == "__main__":
    watch(int(sys.argv[1]))
