"""Where a benchmark run's time went, by part: ``python -m bench.task_profile STORE [STORE...]``.

Reads the task timings a sweep or a track writes into its store (``timings.jsonl``,
:mod:`evaluation.sweep.task_log`; a directory is searched for them, so ``results/tracks``
covers every track of a ``--track all`` run) and prints:

* the CPU seconds per kind of task (diagnoser trainings, relation jobs, episode scoring, the
  reference rows' fits and seed tasks, ...), the driver's serial seconds per stage and the
  workers' start-up, with the named parts inside the tasks (simulating the episodes, each
  diagnoser's detection);
* the critical path: the longest chain of tasks that wait for one another (the ``after`` of
  each line), stage by stage, plus the driver's serial time: the run's wall time on unlimited
  workers;
* the makespan projected on ``n`` workers (default 1, 2, 4, 8, 16) by list scheduling with the
  driver's real barriers (:func:`makespan`): the stages run one after the other (a sweep trains
  every model before it scores; each track after the one before), inside a stage a task starts
  when its dependencies are done, the longest ready task first (LPT) or, as the local pool
  does, in submission order (FIFO); the driver's serial time is added, and each pool's start-up;
* the serial fraction: Amdahl's law fitted to the projected speed-ups (:mod:`bench.amdahl`).

CPU seconds of each task are measured in the process that ran it, so they hold on a busy
machine, where wall times measure the contention; the projection is therefore of a quiet
machine with ``n`` free cores (memory bandwidth and turbo aside).
"""

from __future__ import annotations

import argparse
import heapq
import json
import sys
from collections import defaultdict
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from bench.amdahl import amdahl_fit, amdahl_speedup
from evaluation.sweep.task_log import TIMINGS_FILE, read_timings
from fcc_common.invocation import command_parser, run_command
from fcc_common.io import atomic_write
from fcc_common.validation import invalid

__all__ = [
    "Block",
    "blocks_from_records",
    "critical_path",
    "list_schedule",
    "makespan",
    "parse_workers",
    "profile",
    "timing_files",
]

DEFAULT_WORKERS = (1, 2, 4, 8, 16)


@dataclass
class Block:
    """One stage of a driver: tasks that may run at once (``cpu_s`` by id, ``after`` their
    dependencies within the block), then the driver's serial seconds; ``startup_s``: the start-up
    CPU of a worker of the pool that this block starts (0 when it starts none)."""

    name: str
    cpu_s: dict[int, float] = field(default_factory=dict)
    after: dict[int, tuple[int, ...]] = field(default_factory=dict)
    driver_s: float = 0.0
    startup_s: float = 0.0


def list_schedule(
    cpu_s: Mapping[int, float],
    after: Mapping[int, Sequence[int]],
    n: int,
    order: str = "lpt",
) -> float:
    """The makespan of the tasks on ``n`` identical workers: a task is ready when every task of
    ``after`` it names (within ``cpu_s``) is done; a free worker takes the ready task with the
    most CPU (``"lpt"``) or the first submitted (``"fifo"``: lowest id)."""
    if n < 1 or order not in ("lpt", "fifo"):
        raise ValueError(f"n={n!r} must be >= 1 and order={order!r} one of ['lpt', 'fifo']")
    waiting = {i: {d for d in after.get(i, ()) if d in cpu_s} for i in cpu_s}
    children: dict[int, list[int]] = defaultdict(list)
    for i, deps in waiting.items():
        for d in deps:
            children[d].append(i)

    def prio(i: int) -> tuple[float, int]:
        return (-cpu_s[i], i) if order == "lpt" else (float(i), i)

    ready = [prio(i) for i in cpu_s if not waiting[i]]
    heapq.heapify(ready)
    running: list[tuple[float, int]] = []
    t, free, done = 0.0, n, 0
    while ready or running:
        while free and ready:
            _, i = heapq.heappop(ready)
            heapq.heappush(running, (t + cpu_s[i], i))
            free -= 1
        t, i = heapq.heappop(running)
        free, done = free + 1, done + 1
        for c in children[i]:
            waiting[c].discard(i)
            if not waiting[c]:
                heapq.heappush(ready, prio(c))
    if done != len(cpu_s):
        raise ValueError(f"{len(cpu_s) - done} tasks wait for one another in a cycle")
    return t


def critical_path(cpu_s: Mapping[int, float], after: Mapping[int, Sequence[int]]) -> float:
    """The longest chain of dependent tasks (CPU seconds); a dependency is submitted, hence
    numbered, before the tasks that wait for it."""
    finish: dict[int, float] = {}
    for i in sorted(cpu_s):
        finish[i] = cpu_s[i] + max((finish[d] for d in after.get(i, ()) if d in finish), default=0)
    return max(finish.values(), default=0.0)


def makespan(blocks: Sequence[Block], n: int | None, order: str = "lpt") -> float:
    """Projected wall seconds of the blocks one after the other on ``n`` workers (``None``:
    unlimited, the critical path), each block's driver time and pool start-up added."""
    total = 0.0
    for b in blocks:
        if b.cpu_s:
            span = (
                critical_path(b.cpu_s, b.after)
                if n is None
                else list_schedule(b.cpu_s, b.after, n, order)
            )
            total += b.startup_s + span
        total += b.driver_s
    return total


def timing_files(paths: Sequence[str | Path]) -> list[Path]:
    """The timings files of ``paths``: files as given, directories searched recursively."""
    out: list[Path] = []
    for p in map(Path, paths):
        if p.is_dir():
            out += sorted(p.rglob(TIMINGS_FILE))
        elif p.is_file():
            out.append(p)
        else:
            raise invalid("path", str(p), f"a {TIMINGS_FILE} file or a directory holding some")
    if not out:
        raise invalid("paths", [str(p) for p in paths], f"paths holding a {TIMINGS_FILE}")
    return out


def blocks_from_records(records: Sequence[Mapping[str, Any]]) -> list[Block]:
    """The blocks of the records, in the order their stages started: one per (driver call,
    stage); the first block with tasks of each call starts its pool (the mean start-up CPU of
    the workers' first tasks)."""
    by_block: dict[tuple[str, str], list[Mapping[str, Any]]] = defaultdict(list)
    for r in records:
        by_block[r["run"], r["stage"]].append(r)

    def start(key: tuple[str, str]) -> float:
        return min(r["run_t0"] + r["start_s"] for r in by_block[key])

    blocks, pool_started = [], set()
    for key in sorted(by_block, key=start):
        recs = by_block[key]
        tasks = [r for r in recs if r["kind"] != "driver"]
        b = Block(
            name=f"{recs[0]['scope']}:{key[1]}",
            cpu_s={r["id"]: r["cpu_s"] for r in tasks},
            after={r["id"]: tuple(r["after"]) for r in tasks},
            driver_s=sum(r["cpu_s"] for r in recs if r["kind"] == "driver"),
        )
        ups = [r["startup_cpu_s"] for r in records if r["run"] == key[0] and r["startup_cpu_s"]]
        if tasks and key[0] not in pool_started:
            pool_started.add(key[0])
            b.startup_s = sum(ups) / len(ups) if ups else 0.0
        blocks.append(b)
    return blocks


def profile(
    records: Sequence[Mapping[str, Any]], workers: Sequence[int] = DEFAULT_WORKERS
) -> dict[str, Any]:
    """The breakdown, critical path and projections of the records (see the module doc)."""
    tasks = [r for r in records if r["kind"] != "driver"]
    kinds: dict[str, list[float]] = defaultdict(list)
    for r in tasks:
        kinds[r["kind"]].append(r["cpu_s"])
    driver: dict[str, float] = defaultdict(float)
    for r in records:
        if r["kind"] == "driver":
            driver[f"{r['scope']}:{r['stage']}"] += r["cpu_s"]
    parts: dict[str, float] = defaultdict(float)
    for r in tasks:
        for name, cpu in r["parts"].items():
            parts[f"{r['kind']}:{name}"] += cpu
    startup = [r["startup_cpu_s"] for r in tasks if r["startup_cpu_s"]]
    blocks = blocks_from_records(records)
    longest = max(tasks, key=lambda r: r["cpu_s"], default=None)
    projection = {
        order: {n: makespan(blocks, n, order) for n in workers} for order in ("lpt", "fifo")
    }
    lpt = projection["lpt"]
    base = lpt[min(workers)] if 1 in workers else makespan(blocks, 1)
    ns = sorted(workers)
    f = amdahl_fit(ns, [base / lpt[n] for n in ns])
    task_cpu = sum(r["cpu_s"] for r in tasks)
    return {
        "n_tasks": len(tasks),
        "task_cpu_s": task_cpu,
        "driver_cpu_s": sum(driver.values()),
        "startup_cpu_s": sum(startup),
        "n_workers_started": len(startup),
        "measured_wall_s": sum(r["wall_s"] for r in records if r["kind"] == "driver"),
        "kinds": {
            k: {"n": len(v), "cpu_s": sum(v), "mean_s": sum(v) / len(v), "max_s": max(v)}
            for k, v in sorted(kinds.items(), key=lambda kv: -sum(kv[1]))
        },
        "driver": dict(sorted(driver.items(), key=lambda kv: -kv[1])),
        "parts": dict(sorted(parts.items(), key=lambda kv: -kv[1])),
        "longest_task": None
        if longest is None
        else {"kind": longest["kind"], "key": longest["key"], "cpu_s": longest["cpu_s"]},
        "critical_path_s": makespan(blocks, None),
        "projection_s": projection,
        "serial_fraction": f,
        "projected_speedup_16": amdahl_speedup(f, 16) if f == f else float("nan"),
    }


def print_profile(p: Mapping[str, Any], out: Any = None) -> None:
    """The profile as Markdown tables."""
    total = p["task_cpu_s"] + p["driver_cpu_s"] + p["startup_cpu_s"]
    w = (out or sys.stdout).write
    w(f"{p['n_tasks']} tasks; measured wall of the driver stages {p['measured_wall_s']:.1f} s\n\n")
    w("| part | tasks | CPU [s] | share | mean [s] | longest [s] |\n|---|---|---|---|---|---|\n")
    for k, v in p["kinds"].items():
        w(
            f"| {k} | {v['n']} | {v['cpu_s']:.1f} | {v['cpu_s'] / total:.1%} | "
            f"{v['mean_s']:.2f} | {v['max_s']:.2f} |\n"
        )
    w(f"| driver (serial) | | {p['driver_cpu_s']:.1f} | {p['driver_cpu_s'] / total:.1%} | | |\n")
    w(
        f"| worker start-up | {p['n_workers_started']} | {p['startup_cpu_s']:.1f} | "
        f"{p['startup_cpu_s'] / total:.1%} | | |\n| total | | {total:.1f} | | | |\n\n"
    )
    w("| inside the tasks | CPU [s] |\n|---|---|\n")
    for k, v in list(p["parts"].items())[:20]:
        w(f"| {k} | {v:.1f} |\n")
    w("\n| driver stage | CPU [s] |\n|---|---|\n")
    for k, v in p["driver"].items():
        w(f"| {k} | {v:.2f} |\n")
    lt = p["longest_task"]
    if lt is not None:
        w(f"\nlongest task: {lt['kind']} {lt['key']}, {lt['cpu_s']:.1f} s\n")
    w(f"critical path (unlimited workers, driver included): {p['critical_path_s']:.1f} s\n\n")
    w("| workers | LPT makespan [s] | FIFO makespan [s] | speed-up (LPT) |\n|---|---|---|---|\n")
    lpt, fifo = p["projection_s"]["lpt"], p["projection_s"]["fifo"]
    base = lpt[min(lpt)]
    for n in lpt:
        w(f"| {n} | {lpt[n]:.1f} | {fifo[n]:.1f} | {base / lpt[n]:.2f} |\n")
    w(
        f"serial fraction (Amdahl fit of the LPT projection): {p['serial_fraction']:.3f}; "
        f"driver share of the 1-worker time: {p['driver_cpu_s'] / base:.3f}\n"
    )


def parse_workers(text: str) -> list[int]:
    try:
        counts = sorted({int(s) for s in text.split(",")})
    except ValueError:
        raise invalid("--workers", text, "comma-separated integers >= 1, e.g. 1,2,4") from None
    if not counts or counts[0] < 1 or 1 not in counts:
        raise invalid("--workers", text, "comma-separated integers >= 1, 1 among them")
    return counts


def main(argv: list[str] | None = None) -> int:
    p = command_parser(
        "bench.task_profile",
        (__doc__ or "").split("\n\n")[0],
        (
            ("results/tracks", "every track of a leaderboard run, projected on 1-16 workers"),
            ("STORE --workers 1,2 --json profile.json", "one store, two worker counts, as JSON"),
        ),
    )
    p.add_argument("paths", nargs="+", help=f"{TIMINGS_FILE} files or directories holding them")
    p.add_argument("--workers", default="1,2,4,8,16", help="worker counts, 1 among them")
    p.add_argument("--json", default=None, metavar="PATH", help="write the profile as JSON")
    return run_command(p, _report, argv)


def _report(args: argparse.Namespace) -> int:
    workers = parse_workers(args.workers)
    records = [r for f in timing_files(args.paths) for r in read_timings(f)]
    prof = profile(records, workers)
    print_profile(prof)
    if args.json is not None:
        atomic_write(args.json, json.dumps(prof, indent=2, allow_nan=True) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
