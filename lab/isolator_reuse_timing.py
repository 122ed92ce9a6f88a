"""CPU time of scoring the isolators with and without reusing their inner detector's detection
(issue 44: the isolators re-ran their inner detector's detection).

    python lab/isolator_reuse_timing.py --before /tmp/before-checkout --out /tmp/isoreuse-timing \\
        [--workers 0] [--repeat 2]

A small sweep (validation seeds 5000+, fast trainings): ``lrgf-mem`` and the isolators
``lrgf-iso`` and ``lrgf-lda`` wrapping it. Each checkout (``--before``: an export of the code
before the change; the code of this file's checkout after it) trains once into its own store,
then the cells are deleted and scored again, timed: the scoring pass alone, as CPU seconds of
the process and its workers (``getrusage``), since wall times on a shared machine measure the
contention. The after side is timed twice: every cell scored (the isolators take the detection
of ``lrgf-mem``'s cell in the same episode task), and the isolators' cells alone scored from
the stored inner detections (``inner/`` of the store).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import resource
import shutil
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

N_SAMPLES, ONSET = 2400, 1200
SEEDS = tuple(range(5000, 5006))  # validation seeds: never test seeds


def _config() -> Any:  # built in the checkout under test
    from diagnosers.lrgf.lrgf_mem import LRGFMEM
    from evaluation.sweep import DiagnoserSpec, SimulatedData, SweepConfig
    from fcc_env.scenarios import FaultSpec

    mem = {**LRGFMEM.fast_params(), "max_epochs": 30, "mem_max_epochs": 5}
    specs = (
        DiagnoserSpec("lrgf-mem", mem),
        DiagnoserSpec("lrgf-iso", {"detector": mem}),
        DiagnoserSpec("lrgf-lda", {"detector": mem}),
    )
    data = SimulatedData(
        scenarios=("nominal", "f1", "f2", "f3", "f4"),
        test_seeds=SEEDS,
        train_seeds=(1000, 1001, 1002),
        n_samples=N_SAMPLES,
        fault=FaultSpec(onset=ONSET),
    )
    return SweepConfig(diagnosers=specs, data=data)


def _cpu() -> float:
    s, c = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return s.ru_utime + s.ru_stime + c.ru_utime + c.ru_stime


def child(store: Path, phase: str, workers: int) -> None:
    """One phase in this process (run with the checkout under test on PYTHONPATH)."""
    from evaluation.sweep import run_sweep

    config = _config()
    if phase == "train":
        run_sweep(config, store, n_workers=1, progress=False)
        return
    drop = (
        ["lrgf-iso", "lrgf-lda"] if phase == "isolators" else ["lrgf-mem", "lrgf-iso", "lrgf-lda"]
    )
    for label in drop:
        shutil.rmtree(store / "cells" / label, ignore_errors=True)
    if phase == "all":
        shutil.rmtree(store / "inner", ignore_errors=True)
    t0, c0 = time.perf_counter(), _cpu()
    res = run_sweep(config, store, n_workers=workers, progress=False)
    digest = sorted(
        json.dumps(
            {k: v for k, v in r.to_json().items() if not k.endswith("wall_s")}, sort_keys=True
        )
        for r in res.records
    )
    print(
        json.dumps(
            {
                "phase": phase,
                "cpu_s": round(_cpu() - c0, 2),
                "wall_s": round(time.perf_counter() - t0, 2),
                "n_computed": res.n_computed,
                "records_digest": hashlib.sha256("".join(digest).encode()).hexdigest()[:12],
            }
        )
    )


def run(code: Path, store: Path, phase: str, workers: int = 1) -> dict:
    env = {**os.environ, "PYTHONPATH": str(code)}
    argv = [sys.executable, __file__, "--child", phase, "--store", str(store)]
    argv += ["--workers", str(workers)]
    proc = subprocess.run(argv, capture_output=True, text=True, env=env, check=False)
    if proc.returncode != 0:
        sys.exit(f"{phase} in {code} failed:\n{proc.stderr[-3000:]}")
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("{")]
    return json.loads(lines[-1]) if lines else {}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--before", type=Path, help="a checkout of the code before the change")
    ap.add_argument("--out", type=Path, default=Path("/tmp/isoreuse-timing"))
    ap.add_argument(
        "--workers", type=int, default=1, help="scoring workers (0: in the process; default 1)"
    )
    ap.add_argument("--repeat", type=int, default=1, help="timed scoring passes per phase")
    ap.add_argument("--child", help=argparse.SUPPRESS)
    ap.add_argument("--store", type=Path, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        child(args.store, args.child, args.workers)
        return
    after = Path(__file__).resolve().parents[1]
    sides = [("after", after)] + ([("before", args.before.resolve())] if args.before else [])
    for name, code in sides:
        store = args.out / name
        shutil.rmtree(store, ignore_errors=True)
        run(code, store, "train")
        phases = ["all", "isolators"] if name == "after" else ["all"]
        for _ in range(args.repeat):
            for phase in phases:
                print(name, json.dumps(run(code, store, phase, args.workers)), flush=True)


if __name__ == "__main__":
    main()
