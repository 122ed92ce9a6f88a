"""Run the closed-loop fault tracks (issue 43 item 5) small, on validation seeds.

The published tracks have 200 healthy and 20 faulty test episodes per fault; on the shared
2-core machine one closed-loop track with its six reference rows does not fit a few minutes,
so this script runs the same track definitions with fewer episodes, its test seeds moved to
the validation range (``--seed-start``, default 5100: above the tracks' own validation seeds
5000-5019, never a test seed) and prints the track's compact table (r_fd with its 95 %
interval, per fault r_td / t_dt / delay) plus the wide table's path. ``--no-references``
scores the diagnosers alone (the sweep, without the six reference rows, whose calibration on
validation episodes and filter dominate the time): what fits the loaded machine. Record in
``lab/fault-tracks.md``.

    PYTHONPATH=$PWD python lab/fault_tracks.py --tracks actuator --healthy 20 --faulty 4 \
        --diagnosers limits,pca,arx-band
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from evaluation.sweep.config import SweepConfig, default_specs
from evaluation.sweep.runner import run_sweep
from evaluation.sweep.store import canonical_hash
from evaluation.tracks.board import run_track
from evaluation.tracks.board_tables import track_table, write_track
from evaluation.tracks.catalogue import TRACKS
from evaluation.tracks.rows import TrackRun, track_rows
from evaluation.tracks.track import Track
from evaluation.tracks.track_data import TrackData


def diagnosers_only(track: Track, names: list[str], out: Path, workers: int) -> TrackRun:
    """The track's sweep without the reference rows (their columns read '–')."""
    t0 = time.perf_counter()
    data = TrackData(track=track)
    config = SweepConfig(diagnosers=default_specs(names), data=data)
    config.validate()
    store = out / "store" / canonical_hash(data.store_key())[:12]
    res = run_sweep(config, store, n_workers=workers, progress=False)
    rows = track_rows(res.records, [s.key for s in config.diagnosers], track.faults)
    return TrackRun(
        track=track,
        records=tuple(res.records),
        rows=tuple(rows),
        wall_s=time.perf_counter() - t0,
        n_computed=res.n_computed,
        n_reused=res.n_reused,
    )


def _ci(c: dict, fmt: str) -> str:
    if c["estimate"] is None:
        return "–"
    return f"{c['estimate']:{fmt}} [{c['low']:{fmt}}, {c['high']:{fmt}}]"


def summary(path: Path) -> str:
    """A compact Markdown table of a written track (``leaderboard.json``): r_fd, and per
    fault r_td and t_dt, each with its 95 % interval, misses and early ends."""
    import json

    data = json.loads(path.read_text())
    rows = data["rows"]
    faults = list(rows[0]["faults"])
    out = ["| row | r_fd | fault | r_td | t_dt | missed/ended |", "|---|---|---|---|---|---|"]
    for r in rows:
        for i, f in enumerate(faults):
            c = r["faults"][f]
            head = f"| {r['label']} | {_ci(r['r_fd'], '.4f')} " if i == 0 else "| | "
            out.append(
                f"{head}| {f} | {_ci(c['r_td'], '.3f')} | {_ci(c['t_dt'], '.0f')} | "
                f"{c['misses']}/{c['terminated']} |"
            )
    return "\n".join(out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tracks", default="sensor,actuator,concurrent")
    ap.add_argument("--diagnosers", default="limits,pca,arx-band")
    ap.add_argument("--healthy", type=int, default=20)
    ap.add_argument("--faulty", type=int, default=4)
    ap.add_argument("--train", type=int, default=9)
    ap.add_argument(
        "--train-faults", type=int, default=None, help="labelled training faults per fault"
    )
    ap.add_argument("--seed-start", type=int, default=5100)
    ap.add_argument("--out", type=Path, default=Path("/tmp/fault-tracks"))
    ap.add_argument("--no-references", action="store_true")
    ap.add_argument("--workers", type=int, default=0)
    args = ap.parse_args()
    for name in args.tracks.split(","):
        track = TRACKS[name].replace(
            n_healthy=args.healthy, n_faulty=args.faulty, n_train=args.train
        )
        if args.train_faults is not None:
            track = track.replace(n_train_faults=args.train_faults)
        track = track.with_seeds(test=args.seed_start)
        t0, c0 = time.perf_counter(), time.process_time()
        names = args.diagnosers.split(",")
        if args.no_references:
            run = diagnosers_only(track, names, args.out / name, args.workers)
        else:
            run = run_track(
                track,
                names,
                args.out / name,
                workers=args.workers,
                progress=False,
                figures=False,
                model_cache=args.out / "models",
            )
        write_track(run, args.out / name)
        print(track_table(run))
        print(summary(args.out / name / "leaderboard.json"))
        print(
            f"track {name}: {time.perf_counter() - t0:.0f} s wall, "
            f"{time.process_time() - c0:.0f} s CPU (this process; contention-bound), "
            f"seeds {track.test_seed_start}.., wide table {args.out / name / 'leaderboard.md'}",
            flush=True,
        )


if __name__ == "__main__":
    main()
