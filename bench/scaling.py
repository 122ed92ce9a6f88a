"""How the benchmark scales with workers: ``python -m bench.scaling [--workers 1,2,4]``.

Runs one fixed workload (:data:`WORKLOADS`, ``--workload``) from scratch (a new result store
and relation cache each time) at 1, 2, 4, ... workers (up to this machine's cores, or
``--workers``), on the local process pool or a Ray cluster (``--backend ray --address
ADDR``; there ``n`` workers means at most ``n`` tasks at once), and prints per worker count the
wall time, the speed-up ``S(n) = T(1) / T(n)``, the efficiency ``S(n) / n``, and the serial
fraction ``f`` of Amdahl's law ``1 / S(n) = f + (1 - f) / n``, fitted by least squares
(:func:`amdahl_fit`), with the speed-up it projects on 16 cores and on the ``--project``
cores.

Every run's results are hashed (:func:`results_digest`: every cell record but its wall time);
the runs must give the same digest, whatever the worker count or backend, or the command
fails. ``--json`` and ``--csv`` write the table in machine-readable form (``-``: stdout).

It lives beside the other speed benchmarks, not in :mod:`evaluation.sweep`: it runs whole
tracks (:mod:`evaluation.tracks`), a layer above the sweep.
"""

from __future__ import annotations

import argparse
import csv
import hashlib
import io
import json
import math
import resource
import sys
import tempfile
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from bench.amdahl import amdahl_fit, amdahl_speedup
from diagnosers.registry import available, diagnoser_class
from evaluation.sweep.config import BASELINES, DiagnoserSpec, SweepConfig, default_specs
from evaluation.sweep.records import CellResult
from evaluation.sweep.runner import run_sweep
from evaluation.tracks.board import applicable, run_track, track_channels
from evaluation.tracks.catalogue import parse_tracks
from evaluation.tracks.track import Track
from evaluation.tracks.track_data import TrackData
from fcc_common.invocation import command_parser, run_command
from fcc_common.io import atomic_write
from fcc_common.validation import invalid
from fcc_common.workers import cpu_count

__all__ = [
    "WORKLOADS",
    "ScalingRow",
    "Workload",
    "amdahl_fit",
    "amdahl_speedup",
    "measure",
    "results_digest",
]


@dataclass(frozen=True, kw_only=True)
class Workload:
    """A fixed amount of benchmark work.

    Attributes:
        about: one line for the help.
        track: the catalogue track whose data it runs (:mod:`evaluation.tracks.catalogue`).
        sizes: ``(n_healthy, n_faulty, n_train)`` replacing the track's, or ``None`` (the
            track's own; ``(6, 3, 3)`` are the leaderboard's ``--quick`` sizes).
        diagnosers: the diagnosers (with their settings), or ``None`` for every registered
            one that reads the track's channels, with its defaults, as the leaderboard runs them.
        whole_track: run the track as the leaderboard does (:func:`run_track`: the reference
            rows too), not only its sweep.
    """

    about: str
    track: str = "small"
    sizes: tuple[int, int, int] | None = (6, 3, 3)
    diagnosers: tuple[DiagnoserSpec, ...] | None = None
    whole_track: bool = False

    def the_track(self) -> Track:
        track = parse_tracks(self.track)[0]
        if self.sizes is None:
            return track
        n_healthy, n_faulty, n_train = self.sizes
        return track.replace(n_healthy=n_healthy, n_faulty=n_faulty, n_train=n_train)


def _fast(name: str, **extra: Any) -> DiagnoserSpec:
    return DiagnoserSpec(name, {**diagnoser_class(name).fast_params(), **extra})


#: The workloads of ``--workload``.
WORKLOADS: dict[str, Workload] = {
    "tiny": Workload(
        about="a smoke run for busy machines and tests: 2 healthy and 1 faulty episode per fault "
        "of the small track, limits and a bank detector with a few epochs (the sweep)",
        sizes=(2, 1, 3),
        diagnosers=(DiagnoserSpec("limits"), _fast("lrgf-mem", max_epochs=5, mem_max_epochs=2)),
    ),
    "baselines": Workload(about="the baselines on the small track's --quick sizes (the sweep)"),
    "banks": Workload(
        about="baselines and two bank detectors (short trainings) on the small track's --quick "
        "sizes (the sweep): scoring and relation-training tasks",
        diagnosers=(
            *default_specs(BASELINES),
            _fast("lrgf-mem", max_epochs=200),
            _fast("lrgf-glr", max_epochs=200),
        ),
    ),
    "small": Workload(
        about="the small track, every registered detector, as the leaderboard runs it (the "
        "issue's goal workload: hours on two cores)",
        sizes=None,
        whole_track=True,
    ),
}


@dataclass(frozen=True)
class ScalingRow:
    """One run of the workload: its worker count, wall and CPU seconds (CPU: this process and
    its reaped workers; ``nan`` on Ray, whose workers are not this process's children), the
    speed-up and efficiency against one worker, and the digest of its results."""

    workers: int
    wall_s: float
    cpu_s: float
    speedup: float
    efficiency: float
    digest: str


def results_digest(records: Sequence[CellResult]) -> str:
    """SHA-256 of the records in a canonical order, wall times left out: equal digests, the
    same table bit for bit (floats are written exactly, NaN as NaN)."""
    rows = []
    for r in records:
        d = r.to_json()
        d.pop("detect_wall_s", None)
        rows.append(json.dumps(d, sort_keys=True, allow_nan=True))
    return hashlib.sha256("\n".join(sorted(rows)).encode()).hexdigest()


def _cpu_s() -> float:
    own = resource.getrusage(resource.RUSAGE_SELF)
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


def _specs(workload: Workload, track: Track) -> tuple[DiagnoserSpec, ...]:
    if workload.diagnosers is not None:
        return workload.diagnosers
    names, _ = applicable(available(), track_channels(track), f"on track {track.name}")
    return default_specs(names)


def run_once(
    workload: Workload, n_workers: int, backend: str, ray_address: str | None = None
) -> tuple[float, float, str]:
    """``(wall s, CPU s, results digest)`` of the workload from scratch on ``n_workers``."""
    track = workload.the_track()
    specs = _specs(workload, track)
    with tempfile.TemporaryDirectory(prefix="fcc-scaling-") as d:
        c0, t0 = _cpu_s(), time.perf_counter()
        if workload.whole_track:
            run = run_track(
                track,
                [s.name for s in specs],
                Path(d) / track.name,
                backend=backend,
                workers=n_workers,
                ray_address=ray_address,
                progress=False,
                figures=False,
                relation_cache=Path(d) / "relations",
            )
            records = run.records
        else:
            config = SweepConfig(diagnosers=specs, data=TrackData(track=track))
            records = run_sweep(
                config,
                Path(d) / "store",
                backend=backend,
                n_workers=n_workers,
                ray_address=ray_address,
                progress=False,
                relation_cache=Path(d) / "relations",
            ).records
        wall, cpu = time.perf_counter() - t0, _cpu_s() - c0
    return wall, (cpu if backend == "local" else math.nan), results_digest(records)


def measure(
    workload: Workload,
    workers: Sequence[int],
    backend: str = "local",
    ray_address: str | None = None,
) -> list[ScalingRow]:
    """Run the workload once per worker count (``1`` among them: the speed-ups' base)."""
    if 1 not in workers:
        raise invalid("workers", list(workers), "worker counts that include 1 (the base)")
    runs = {n: run_once(workload, n, backend, ray_address) for n in workers}
    base = runs[1][0]
    return [
        ScalingRow(n, wall, cpu, base / wall, base / wall / n, digest)
        for n, (wall, cpu, digest) in runs.items()
    ]


def default_workers(cores: int) -> list[int]:
    """1, 2, 4, ... up to ``cores``, and ``cores`` itself."""
    out = [1]
    while out[-1] * 2 <= cores:
        out.append(out[-1] * 2)
    return sorted({*out, cores})


# ---- the command -------------------------------------------------------------------------------
def main(argv: list[str] | None = None) -> int:
    p = command_parser(
        "bench.scaling",
        (__doc__ or "").split("\n\n")[0],
        (
            ("", "the baselines workload at 1, 2, 4, ... workers, up to this machine's cores"),
            ("--workload banks --workers 1,2", "relation trainings too, at 1 and 2 workers"),
            (
                "--workers 1,2,4,8,16 --workload small --json scaling.json",
                "the goal workload on a 16-core machine, the table also as JSON",
            ),
            (
                "--backend ray --address 127.0.0.1:6379 --workers 1,2",
                "on a running Ray cluster",
            ),
        ),
    )
    p.add_argument(
        "--workload",
        default="baselines",
        choices=sorted(WORKLOADS),
        help="what to run: " + "; ".join(f"{k}: {w.about}" for k, w in WORKLOADS.items()),
    )
    p.add_argument(
        "--workers",
        default=None,
        help="comma-separated worker counts, 1 among them (default: 1, 2, 4, ... cores)",
    )
    p.add_argument("--backend", default="local", choices=("local", "ray"))
    p.add_argument("--address", default=None, help="a running Ray cluster (with --backend ray)")
    p.add_argument("--project", type=int, default=16, help="cores to project the speed-up to")
    p.add_argument(
        "--json", default=None, metavar="PATH", help="write the table as JSON (- stdout)"
    )
    p.add_argument("--csv", default=None, metavar="PATH", help="write the table as CSV (- stdout)")
    return run_command(p, _report, argv)


def _parse_workers(text: str | None) -> list[int]:
    if text is None:
        return default_workers(cpu_count())
    try:
        counts = sorted({int(s) for s in text.split(",")})
    except ValueError:
        raise invalid("--workers", text, "comma-separated integers >= 1, e.g. 1,2,4") from None
    if not counts or counts[0] < 1 or 1 not in counts:
        raise invalid("--workers", text, "comma-separated integers >= 1, 1 among them (the base)")
    return counts


def _report(args: argparse.Namespace) -> int:
    """The work of :func:`main`: its failures (and a Ctrl-C) are reported by :func:`run_command`."""
    workers = _parse_workers(args.workers)
    if args.address is not None and args.backend != "ray":
        raise invalid("--address", args.address, "an address with --backend ray only")
    if args.project < 1:
        raise invalid("--project", args.project, "an integer >= 1")
    workload = WORKLOADS[args.workload]
    ray_started = False
    if args.backend == "ray":
        import ray

        from evaluation.sweep.backends import ray_runtime_env

        # one connection (or one local instance, sized for the most workers) for every run:
        # starting Ray is not part of the workload
        if args.address is not None:
            ray.init(address=args.address, log_to_driver=False)
        else:
            ray.init(
                num_cpus=max(workers),
                include_dashboard=False,
                log_to_driver=False,
                runtime_env=ray_runtime_env(),
            )
        ray_started = True
    try:
        rows = measure(workload, workers, args.backend, args.address)
    finally:
        if ray_started:
            ray.shutdown()
    f = amdahl_fit([r.workers for r in rows], [r.speedup for r in rows])
    summary = {
        "workload": args.workload,
        "backend": args.backend,
        "address": args.address,
        "cores": cpu_count(),
        "serial_fraction": f,
        "projected_speedup": {str(args.project): amdahl_speedup(f, args.project)},
        "same_results": len({r.digest for r in rows}) == 1,
        "rows": [asdict(r) for r in rows],
    }
    _print_table(summary, rows, args.project)
    if args.json is not None:
        _write(args.json, json.dumps(summary, indent=2, allow_nan=True) + "\n")
    if args.csv is not None:
        buf = io.StringIO()
        w = csv.DictWriter(buf, fieldnames=list(asdict(rows[0])))
        w.writeheader()
        w.writerows(asdict(r) for r in rows)
        _write(args.csv, buf.getvalue())
    if not summary["same_results"]:
        print("the runs' results differ (digests above): a bug, please report it", file=sys.stderr)
        return 1
    return 0


def _write(target: str, text: str) -> None:
    if target == "-":
        sys.stdout.write(text)
    else:
        atomic_write(target, text)


def _print_table(summary: dict[str, Any], rows: list[ScalingRow], project: int) -> None:
    where = summary["address"] or "this machine"
    print(
        f"workload {summary['workload']}, {summary['backend']} backend on {where} "
        f"({summary['cores']} cores here)"
    )
    print("| workers | wall [s] | CPU [s] | speed-up | efficiency | results |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        print(
            f"| {r.workers} | {r.wall_s:.2f} | {r.cpu_s:.1f} | {r.speedup:.2f} | "
            f"{r.efficiency:.2f} | {r.digest[:12]} |"
        )
    f = summary["serial_fraction"]
    print(
        f"serial fraction (Amdahl, least squares): {f:.3f}; projected speed-up on {project} "
        f"cores: {amdahl_speedup(f, project):.2f}"
    )
    print("results identical across runs: " + ("yes" if summary["same_results"] else "NO"))


if __name__ == "__main__":
    raise SystemExit(main())
