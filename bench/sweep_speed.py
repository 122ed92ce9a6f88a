"""Wall-time benchmark of the harness: ``python -m bench.sweep_speed [--seeds 1,2,5,10,50]``.

Measures, on this machine:

1. ``python -m evaluation.leaderboard --quick`` in a fresh process (start-up, training, 45
   cells, figures), as a user runs it;
2. the default leaderboard sweep restricted to the baselines (10 test seeds per scenario), also
   in a fresh process;
3. :func:`evaluation.sweep.run_sweep` with the baselines on all five scenarios for a growing
   number of test seeds, each in a new store (nothing reused), with 1 and with all worker
   processes. ``cores`` is (CPU time of this process and its workers) / wall time, i.e. how many
   cores the sweep kept busy; a least-squares line ``wall = a + b·seeds`` separates the fixed
   cost (worker start-up, training) from the cost per seed.

This is a CLI module: it prints its table to stdout.
"""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from evaluation.leaderboard.arguments import check_counts
from evaluation.sweep.config import BASELINES, SweepConfig, default_specs
from evaluation.sweep.runner import run_sweep
from evaluation.sweep.sources import SimulatedData
from fcc_common.invocation import command_parser, run_command
from fcc_common.validation import Integer, check, invalid

ROOT = Path(__file__).resolve().parents[1]


def _cpu_s() -> float:
    """CPU seconds (user + system) of this process and its reaped children."""
    own = resource.getrusage(resource.RUSAGE_SELF)
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


def time_cli(args: list[str]) -> float:
    """Wall time of ``python -m evaluation.leaderboard ARGS`` in a fresh process."""
    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]),
    }
    with tempfile.TemporaryDirectory() as out:
        t0 = time.perf_counter()
        subprocess.run(
            [sys.executable, "-m", "evaluation.leaderboard", *args, "--out", out, "--no-progress"],
            cwd=ROOT,
            env=env,
            check=True,
            capture_output=True,
        )
        return time.perf_counter() - t0


def time_sweep(n_seeds: int, n_workers: int) -> tuple[float, float]:
    """(wall s, cores busy) of a fresh baseline sweep with ``n_seeds`` test seeds per scenario."""
    config = SweepConfig(
        diagnosers=default_specs(BASELINES),
        data=SimulatedData(test_seeds=tuple(range(n_seeds)), train_seeds=(1000, 1001, 1002)),
    )
    with tempfile.TemporaryDirectory() as store:
        c0, t0 = _cpu_s(), time.perf_counter()
        run_sweep(config, store, n_workers=n_workers, progress=False)
        wall = time.perf_counter() - t0
        cpu = _cpu_s() - c0
    return wall, cpu / wall


def main(argv: list[str] | None = None) -> int:
    p = command_parser(
        "bench.sweep_speed",
        (__doc__ or "").split("\n\n")[0],
        (
            ("", "the CLI timings, then sweeps of 1, 2, 5, 10 and 50 test seeds per scenario"),
            ("--seeds 1,5 --skip-cli", "two sweep sizes only"),
        ),
    )
    p.add_argument("--seeds", default="1,2,5,10,50", help="test seeds per scenario to time")
    p.add_argument("--skip-cli", action="store_true", help="skip the fresh-process CLI timings")
    return run_command(p, _report, argv)


def _report(args: argparse.Namespace) -> int:
    """The work of :func:`main`: its failures (and a Ctrl-C) are reported by :func:`run_command`."""
    try:
        seeds = [int(s) for s in args.seeds.split(",")]
    except ValueError:
        raise invalid("--seeds", args.seeds, "comma-separated integers, e.g. 1,2,5") from None
    for n in seeds:  # test seeds 0..n-1 of five scenarios, as the leaderboard counts them
        check_counts(
            seeds=check("--seeds", n, Integer(1)),
            seed_base=0,
            train_episodes=None,
            n_samples=4000,
            n_cells_per_seed=5 * len(BASELINES),
        )
    n_cpu = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    print(f"machine: {n_cpu} cores, Python {sys.version.split()[0]}")
    if not args.skip_cli:
        print(f"leaderboard --quick (fresh process):            {time_cli(['--quick']):6.1f} s")
        full = time_cli(["--diagnosers", ",".join(BASELINES), "--no-figures"])
        print(f"leaderboard default sweep, baselines, 10 seeds: {full:6.1f} s (no figures)")
    print()
    print("| seeds/scenario | cells | workers | wall [s] | cores busy |")
    print("|---|---|---|---|---|")
    walls = {}
    for w in sorted({1, n_cpu}):
        for n in seeds:
            wall, cores = time_sweep(n, w)
            walls[(w, n)] = wall
            print(f"| {n} | {n * 5 * len(BASELINES)} | {w} | {wall:.2f} | {cores:.2f} |")
    for w in sorted({1, n_cpu}):
        x = np.array(seeds, dtype=float)
        y = np.array([walls[(w, n)] for n in seeds])
        b, a = np.polyfit(x, y, 1)
        r = np.corrcoef(x, y)[0, 1] if len(seeds) > 2 else float("nan")
        print(f"workers={w}: wall ≈ {a:.2f} s + {b * 1000:.0f} ms × seeds (r = {r:.3f})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
