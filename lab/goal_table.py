"""Issue 43's detection goal, measured per fault class on the closed-loop tracks.

The goal: "on every new track (sensor, actuator, concurrent), the best detector's r_fd upper
95 % end is <= 0.01. Each fault class is detected within 2x the optimal row's delay, with
r_td >= optimal - 0.05". This script runs, per track, the issue's detectors (and ``pca``,
``limits`` for scale) with the reference rows the goal reads on the same episodes, and writes
one table per track: per fault class the best detector among those whose r_fd upper end is
<= 0.01, its t_dt against the optimal row's (the harness's paired ``t_dt/optimal``, (t_dt + 1) /
(optimal t_dt + 1) over the seeds both detected, with its 95 % BCa interval), its r_td against
the optimal row's − 0.05, and met / not met (both on point estimates; the intervals are shown).
All scoring is the harness's (:func:`evaluation.tracks.rows.track_rows`); this script only
drives it and picks the best row per fault.

Which reference rows. Only the three rows the goal can read: the ``optimal CUSUM (known
fault)`` row (the goal's "optimal row"), its stand-ins in the harness's order when it misses the
r_fd goal (:func:`evaluation.tracks.rows.yardstick`: ``GLR (known type, unknown size)``, then
the physical limit). The directional and filter rows (100 calibration episodes each and a UKF
per cell) are left out: the goal does not read them, and they would not fit the time here.

Seeds: test seeds moved to ``--seed-start`` (default 8000: validation range, fresh for every
detector here; never a test seed 0-999); the rows calibrate on the tracks' validation seeds
5000-5019, the detectors train on seeds 1000-1008. Labelled training faults: the isolators
(``sensor-validation``, ``stiction-ukf``, ``loop-offset``, ``catalogue-isolator``) read only the
labels of their faulty training episodes (which classes to claim), so ``--train-faults 1``
(default) gives the same fitted detectors as the tracks' 20 at a twentieth of the simulation.

Rounds (``--rounds H:F,...``, healthy and faulty episodes per fault): every round runs the
three tracks into the same stores (keyed without the counts, so a later round computes only
its new seeds) and rewrites ``<out>/goal-tables.md`` after each track: stop the process any
time, the last round written is complete. Fitted detectors are cached across tracks
(``<out>/models``; those that learn fault labels per track), the reference rows' fits across
rounds (in this process). Internals: the private model-cache helpers of
:mod:`evaluation.tracks.board`, and ``reference_runs.fit_task`` replaced by a memo while it
runs. Record in ``lab/fault-tracks.md``.

    PYTHONPATH=$PWD python lab/goal_table.py --rounds 1:1 --out /tmp/goal     # time a cell
    PYTHONPATH=$PWD python lab/goal_table.py --rounds 1:1,4:2,10:4 --out /tmp/goal
"""

from __future__ import annotations

import argparse
import json
import math
import os
import time
from collections.abc import Sequence
from pathlib import Path

from diagnosers.registry import diagnoser_class
from evaluation.metrics.intervals import Interval
from evaluation.sweep.config import SweepConfig, default_specs
from evaluation.sweep.runner import run_sweep
from evaluation.sweep.store import canonical_hash
from evaluation.tracks import reference_runs
from evaluation.tracks.board import _models_from_cache, _models_to_cache, applicable, track_channels
from evaluation.tracks.board_tables import write_track
from evaluation.tracks.catalogue import TRACKS
from evaluation.tracks.oracle import OracleConfig, PhysicalLimit
from evaluation.tracks.reference_runs import fit_task as _fit_task
from evaluation.tracks.reference_runs import run_references
from evaluation.tracks.rows import FaultCell, TrackRow, TrackRun, track_rows
from evaluation.tracks.track import Track
from evaluation.tracks.track_data import TrackData

#: the issue's detectors, then two baselines for scale
DETECTORS = (
    "sensor-validation",
    "valve-glr",
    "stiction-ukf",
    "loop-offset",
    "catalogue-isolator",
    "ukf-glr",
    "pca",
    "limits",
)
#: the rows the goal reads: the physical limit, the optimal CUSUM, the GLR (its stand-ins)
REFERENCES = (OracleConfig(), OracleConfig(stage="cusum"), OracleConfig(stage="glr"))
#: the issue's goal: t_dt within this factor of the optimal row's ...
TIME_FACTOR = 2.0
#: ... and r_td at most this far below the optimal row's
R_TD_MARGIN = 0.05
#: an optimal row with a lower r_td does not see the fault (no noise-free signature: added
#: noise, a capacity cap that does not bind): the goal against it is marked vacuous
BLIND_R_TD = 0.5


_FITS: dict[tuple[str, OracleConfig], PhysicalLimit] = {}


def _cached_fit(data: TrackData, config: OracleConfig, _serial: bool = False) -> PhysicalLimit:
    """A reference row's fit, once per track and row in this process: the fit reads the
    track's validation seeds and fault distributions only (the store key, which leaves out the
    counts), so a later round's fit would be the same; the harness refits on every call."""
    key = (canonical_hash(data.store_key()), config)
    if key not in _FITS:
        _FITS[key] = _fit_task(data, config, _serial)
    return _FITS[key]


def goal_run(track: Track, names: Sequence[str], out: Path, models: Path) -> TrackRun:
    """The track's sweep of ``names`` plus :data:`REFERENCES` (resumable, in this process)."""
    t0 = time.perf_counter()
    data = TrackData(track=track)
    names, skipped = applicable(names, track_channels(track), f"on track {track.name}")
    for line in skipped:
        print(line, flush=True)
    config = SweepConfig(diagnosers=default_specs(names), data=data)
    config.validate()
    store = out / "store" / canonical_hash(data.store_key())[:12]
    n_cached = _models_from_cache(config, store, models)
    res = run_sweep(config, store, n_workers=0, progress=False)
    _models_to_cache(config, store, models)
    reference_runs.fit_task = _cached_fit  # in this process (0 workers) the driver calls it
    refs, n_refs = run_references(data, REFERENCES, store, n_workers=0, progress=False)
    records = (*res.records, *refs)
    tiers = {s.key: str(diagnoser_class(s.name).tier) for s in config.diagnosers}
    rows = track_rows(records, [s.key for s in config.diagnosers], track.faults, tiers)
    return TrackRun(
        track=track,
        records=records,
        rows=tuple(rows),
        wall_s=time.perf_counter() - t0,
        n_computed=res.n_computed,
        n_reused=res.n_reused,
        n_trained=res.n_trained,
        n_reused_models=n_cached,
        n_reference_computed=n_refs,
    )


def _ci(iv: Interval, fmt: str) -> str:
    if not math.isfinite(iv.estimate):
        return "–"
    return f"{iv.estimate:{fmt}} [{iv.low:{fmt}}, {iv.high:{fmt}}]"


def verdict(cell: FaultCell, optimal: FaultCell) -> tuple[bool, bool]:
    """(t_dt within :data:`TIME_FACTOR` of the optimal row's, r_td at most :data:`R_TD_MARGIN`
    below it), on the point estimates; an undefined ratio (no seed detected by both) fails."""
    ratio = cell.ratio_optimal.estimate
    time_ok = math.isfinite(ratio) and ratio <= TIME_FACTOR
    r, r_opt = cell.r_td.estimate, optimal.r_td.estimate
    rtd_ok = math.isfinite(r) and math.isfinite(r_opt) and r >= r_opt - R_TD_MARGIN
    return time_ok, rtd_ok


def best_row(rows: Sequence[TrackRow], fault: str, optimal: TrackRow) -> TrackRow | None:
    """Among ``rows`` (detectors meeting the r_fd goal), the best on ``fault``: met first, then
    the r_td criterion met, then the delay criterion, then the lower t_dt/optimal, then the
    higher r_td."""

    def key(row: TrackRow) -> tuple[float, ...]:
        cell = row.faults[fault]
        t_ok, r_ok = verdict(cell, optimal.faults[fault])
        ratio = cell.ratio_optimal.estimate
        r_td = cell.r_td.estimate
        # r_td before the delay: the ratio is over the seeds both detected, so a detector that
        # misses most episodes can still show a small one (a single early blip)
        return (
            -float(t_ok and r_ok),
            -float(r_ok),
            -float(t_ok),
            ratio if math.isfinite(ratio) else math.inf,
            -r_td if math.isfinite(r_td) else math.inf,
        )

    return min(rows, key=key) if rows else None


def goal_table(track: Track, rows: Sequence[TrackRow], optimal: TrackRow | None) -> str:
    """The track's goal table (Markdown): the detectors' r_fd, then per fault the best of
    ``rows`` against ``optimal`` (the run's :attr:`TrackRun.optimal_row`)."""
    dets = [r for r in rows if not r.reference]
    lines = [
        f"### `{track.name}`: {track.n_healthy} healthy, {track.n_faulty} faulty per class, "
        f"seeds {track.test_seed_start}..",
        "",
        "| detector | r_fd [95 %] | upper <= 0.01 | healthy episodes alarmed |",
        "|---|---|---|---|",
    ]
    for r in dets:
        lines.append(
            f"| {r.label} | {_ci(r.r_fd, '.4f')} | {'yes' if r.meets_r_fd_goal else 'no'} | "
            f"{r.alarmed_share:.2f} |"
        )
    if optimal is None:
        return "\n".join([*lines, "", "No reference row meets the r_fd goal: no yardstick.", ""])
    lines += [
        "",
        f"Optimal row: `{optimal.label}` (r_fd {_ci(optimal.r_fd, '.4f')}).",
        "",
        "| fault class | best detector (r_fd <= 0.01) | t_dt | optimal t_dt | "
        "t_dt/optimal (<= 2) | r_td | optimal r_td − 0.05 | missed | goal | also met by |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    ok = [r for r in dets if r.meets_r_fd_goal]
    for f in track.faults:
        o = optimal.faults[f]
        best = best_row(ok, f, optimal)
        if best is None:
            lines.append(
                f"| {f} | none | | {_ci(o.t_dt, '.0f')} | | | {o.r_td.estimate - R_TD_MARGIN:.3f} "
                "| | not met |  |"
            )
            continue
        c = best.faults[f]
        t_ok, r_ok = verdict(c, o)
        others = [r.label for r in ok if r is not best and all(verdict(r.faults[f], o))]
        why = (
            "met"
            if t_ok and r_ok
            else "not met ("
            + ", ".join(w for w, bad in (("delay", not t_ok), ("r_td", not r_ok)) if bad)
            + ")"
        )
        if o.r_td.estimate < BLIND_R_TD:
            why += f" (vacuous: the optimal row's r_td {o.r_td.estimate:.3f})"
        lines.append(
            f"| {f} | {best.label} | {_ci(c.t_dt, '.0f')} | {_ci(o.t_dt, '.0f')} | "
            f"{_ci(c.ratio_optimal, '.2f')} (n={c.ratio_optimal.n}) | {_ci(c.r_td, '.3f')} | "
            f"{o.r_td.estimate - R_TD_MARGIN:.3f} | {c.misses}/{c.n} | {why} | "
            f"{', '.join(others)} |"
        )
    return "\n".join([*lines, ""])


def _interval(d: dict | None) -> Interval:
    if not d:
        return Interval(math.nan, math.nan, math.nan, 0)
    num = [math.nan if d.get(k) is None else float(d[k]) for k in ("estimate", "low", "high")]
    return Interval(*num, int(d.get("n") or 0))


def table_from_json(path: Path) -> str:
    """The goal table again from a written track (``leaderboard.json``), without rerunning."""
    return goal_table(*rows_from_json(path))


def rows_from_json(path: Path) -> tuple[Track, list[TrackRow], TrackRow | None]:
    """A written track (``leaderboard.json``) read back: its track, rows and optimal row."""
    data = json.loads(path.read_text())
    t = data["track"]
    track = TRACKS[t["name"]].replace(n_healthy=t["n_healthy"], n_faulty=t["n_faulty"])
    track = track.with_seeds(test=t["test_seed_start"])
    rows = [
        TrackRow(
            label=r["label"],
            r_fd=_interval(r["r_fd"]),
            alarmed_share=r["alarmed_share"],
            worst_r_fd=r["worst_r_fd"],
            worst_seed=r["worst_seed"],
            faults={
                f: FaultCell(
                    r_td=_interval(c["r_td"]),
                    t_dt=_interval(c["t_dt"]),
                    ratio=_interval(c["t_dt_over_oracle"]),
                    misses=c["misses"],
                    terminated=c["terminated"],
                    n=c["n"],
                    ratio_optimal=_interval(c["t_dt_over_optimal"]),
                )
                for f, c in r["faults"].items()
            },
            tier=r["tier"],
        )
        for r in data["rows"]
    ]
    optimal = next((r for r in rows if r.label == data["optimal_reference"]), None)
    return track, rows, optimal


def parse_rounds(text: str) -> list[tuple[int, int]]:
    out = []
    for part in text.split(","):
        h, _, f = part.partition(":")
        if not (h.isdigit() and f.isdigit() and int(h) >= 1 and int(f) >= 1):
            raise ValueError(f"--rounds {text!r}; allowed: H:F[,H:F...] with integers H, F >= 1")
        out.append((int(h), int(f)))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tracks", default="sensor,actuator,concurrent")
    ap.add_argument("--diagnosers", default=",".join(DETECTORS))
    ap.add_argument("--rounds", default="1:1", help="H:F[,H:F...] healthy:faulty per round")
    ap.add_argument("--train", type=int, default=9)
    ap.add_argument("--train-faults", type=int, default=1)
    ap.add_argument("--seed-start", type=int, default=8000)
    ap.add_argument("--out", type=Path, default=Path("/tmp/goal-table"))
    ap.add_argument(
        "--from-json", action="store_true", help="only rewrite the tables from <out>/<track>/"
    )
    args = ap.parse_args()
    if args.seed_start < 5000:
        ap.error(f"--seed-start {args.seed_start}; allowed: a validation seed, 5000 or more")
    try:
        rounds = parse_rounds(args.rounds)
    except ValueError as e:
        ap.error(str(e))
    bad = [t for t in args.tracks.split(",") if t not in TRACKS]
    if bad:
        ap.error(f"--tracks {bad}; allowed: names of {sorted(TRACKS)}")
    if args.from_json:
        text = "\n".join(
            table_from_json(args.out / t / "leaderboard.json") for t in args.tracks.split(",")
        )
        (args.out / "goal-tables.md").write_text(text)
        print(text)
        return
    names = args.diagnosers.split(",")
    tables: dict[str, str] = {}
    c_start = time.process_time()
    for n_h, n_f in rounds:
        for name in args.tracks.split(","):
            track = TRACKS[name].replace(
                n_healthy=n_h, n_faulty=n_f, n_train=args.train, n_train_faults=args.train_faults
            )
            track = track.with_seeds(test=args.seed_start)
            c0 = time.process_time()
            run = goal_run(track, names, args.out / name, args.out / "models")
            write_track(run, args.out / name)
            cpu = time.process_time() - c0
            load = os.getloadavg()[0]
            tables[name] = goal_table(track, run.rows, run.optimal_row) + (
                f"\n{cpu:.0f} s CPU for this round of the track ({run.n_computed} detector cells "
                f"computed, {run.n_reused} reused, {run.n_trained} trainings, "
                f"{run.n_reference_computed} reference cells computed), {run.wall_s:.0f} s wall, "
                f"load average {load:.1f}; {time.process_time() - c_start:.0f} s CPU in all so "
                "far.\n"
            )
            print(tables[name], flush=True)
            # the latest table of each track (each names its own counts)
            (args.out / "goal-tables.md").write_text("\n".join(tables.values()))
            (args.out / f"goal-tables-{n_h}-{n_f}.md").write_text("\n".join(tables.values()))


if __name__ == "__main__":
    main()
