"""Time a track run twice into one ``--out``: the first computes (or finds) everything, the
second finds every detector cell and every reference-row record stored (issue 44 item 1:
a fully stored track re-runs in 10 s or less).

    python lab/reference_rows_timing.py --track paper --diagnosers limits,pca,arx-band \\
        --workers 2 --out /tmp/refstore-paper

Prints, per run, the wall time and the CPU time of the command and its workers
(``resource.getrusage(RUSAGE_CHILDREN)``) and the track's own line (cells computed and
reused). On a shared machine the wall time is contention-bound: read the CPU time too.
"""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import time
from pathlib import Path


def timed_run(argv: list[str]) -> tuple[float, float, str]:
    """(wall s, CPU s of the command and its children, the track lines of its stderr)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1])}
    proc = subprocess.run(argv, capture_output=True, text=True, env=env, check=False)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if proc.returncode != 0:
        sys.exit(f"{' '.join(argv)} failed ({proc.returncode}):\n{proc.stderr[-3000:]}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    lines = "\n".join(ln for ln in proc.stderr.splitlines() if ln.startswith("track "))
    return wall, cpu, lines


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--track", default="paper")
    ap.add_argument("--diagnosers", default="limits,pca,arx-band")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--runs", type=int, default=2)
    args = ap.parse_args()
    argv = [
        sys.executable,
        "-m",
        "evaluation.leaderboard",
        "--track",
        args.track,
        "--diagnosers",
        args.diagnosers,
        "--workers",
        str(args.workers),
        "--out",
        str(args.out),
        "--no-figures",
        "--no-progress",
    ]
    for i in range(args.runs):
        wall, cpu, lines = timed_run(argv)
        print(f"run {i + 1}: wall {wall:.1f} s, CPU {cpu:.1f} s\n  {lines}")


if __name__ == "__main__":
    main()
