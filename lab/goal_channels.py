"""Issue 43's detection goal per channel, from a track that ``lab/goal_table.py`` wrote.

The goal table gives one row per fault class; on the ``sensor`` track a class's episodes each
draw their own channel, and a class can miss the goal through one channel only. The records
(``<out>/<track>/results.json``) do not name the channel, so this reader redraws each faulty
episode's fault from its seed (:meth:`evaluation.tracks.track.Track.fault_spec`, deterministic
in the track's name, the class and the seed) and writes, per class:

* per channel and row (the detectors and the optimal reference row the goal table used):
  episodes, misses (95 % Wilson interval), r_td (mean over the episodes, 95 % BCa), t_dt
  (mean over the detected episodes, 95 % BCa), t_dt/optimal (the harness's paired
  ``mean(t_dt + 1) / mean(optimal t_dt + 1)`` over the episodes both detected, 95 % BCa);
* per episode: seed, channel, size, onset, each row's t_dt and r_td.

    PYTHONPATH=$PWD python lab/goal_channels.py --out /tmp/goal --track sensor \\
        --faults sensor-bias,sensor-drift

Reads only the written files (no simulation); writes ``<out>/<track>/channels.md`` and prints
it.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections import defaultdict
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from scipy.stats import binomtest

from evaluation.metrics.intervals import Interval, bootstrap_ci, limit_ratio_ci
from evaluation.tracks.catalogue import TRACKS

# ``python lab/<script>.py`` puts lab/ first on the path, not the repository root
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from lab.goal_table import BLIND_R_TD, R_TD_MARGIN, TIME_FACTOR, rows_from_json, verdict


def wilson(k: int, n: int) -> str:
    """``k/n`` with its 95 % Wilson score interval (scipy's, the lab scripts' hand copies
    aside)."""
    if n == 0:
        return "–"
    ci = binomtest(k, n).proportion_ci(confidence_level=0.95, method="wilson")
    return f"{k}/{n} [{ci.low:.2f}, {ci.high:.2f}]"


def _ci(iv: Interval, fmt: str) -> str:
    if not math.isfinite(iv.estimate):
        return "–"
    if iv.n == 1:
        return f"{iv.estimate:{fmt}}"
    return f"{iv.estimate:{fmt}} [{iv.low:{fmt}}, {iv.high:{fmt}}]"


def _missed(rec: dict) -> bool:
    # the harness's CellResult.missed: scored faulty samples and no alarm from the onset on
    return rec["n_fault_samples"] > 0 and math.isnan(_value(rec, "t_dt"))


def _value(rec: dict | None, key: str) -> float:
    v = None if rec is None else rec.get(key)
    return math.nan if v is None else float(v)


def detector_table(out: Path, track_name: str) -> str:
    """Every detector on every class of the written track against the goal (Markdown): the
    goal table shows only the best detector per class."""
    track, rows, optimal = rows_from_json(out / track_name / "leaderboard.json")
    lines = [
        f"### `{track_name}` per detector: {track.n_healthy} healthy, {track.n_faulty} faulty "
        f"per class, seeds {track.test_seed_start}..",
        "",
    ]
    if optimal is None:
        return "\n".join([*lines, "No reference row meets the r_fd goal.", ""])
    lines += [
        f"| fault class | row | r_fd [95 %] | r_td [95 %] | optimal r_td − {R_TD_MARGIN} | "
        f"t_dt/optimal (<= {TIME_FACTOR:g}) [95 %] | missed [95 %] | goal |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for f in track.faults:
        o = optimal.faults[f]
        for r in [*(r for r in rows if not r.reference), optimal]:
            c = r.faults[f]
            t_ok, r_ok = verdict(c, o)
            bad = [w for w, b in (("r_fd", not r.meets_r_fd_goal), ("delay", not t_ok)) if b]
            bad += ["r_td"] if not r_ok else []
            goal = (
                "(optimal row)"
                if r is optimal
                else "met"
                if not bad
                else "not met: " + ", ".join(bad)
            )
            if r is not optimal and o.r_td.estimate < BLIND_R_TD:
                goal += " (vacuous)"
            lines.append(
                f"| {f} | {r.label} | {_ci(r.r_fd, '.4f')} | {_ci(c.r_td, '.3f')} | "
                f"{o.r_td.estimate - R_TD_MARGIN:.3f} | "
                f"{_ci(c.ratio_optimal, '.2f')} (n={c.ratio_optimal.n}) | "
                f"{wilson(c.misses, c.n)} | {goal} |"
            )
    return "\n".join([*lines, ""])


def channel_tables(out: Path, track_name: str, faults: Sequence[str]) -> str:
    """The per-channel and per-episode tables (Markdown) of ``faults`` on the written track."""
    board = json.loads((out / track_name / "leaderboard.json").read_text())
    records = json.loads((out / track_name / "results.json").read_text())["records"]
    track = TRACKS[track_name]
    optimal = board["optimal_reference"]
    labels = [r["label"] for r in board["rows"] if not r["reference"]]
    if optimal is not None:
        labels.append(optimal)
    by_cell: dict[tuple[str, str, int], dict] = {
        (r["diagnoser"], r["scenario"], r["seed"]): r for r in records
    }
    t = board["track"]
    lines = [
        f"### `{track_name}` per channel: {t['n_faulty']} faulty per class, seeds "
        f"{t['test_seed_start']}.. (optimal row: `{optimal}`)",
        "",
    ]
    for fault in faults:
        seeds = sorted({s for (_, f, s) in by_cell if f == fault})
        specs = {s: track.fault_spec(fault, s) for s in seeds}
        channels: dict[str, list[int]] = defaultdict(list)
        for s in seeds:
            channels[str(specs[s].channel)].append(s)
        lines += [
            f"#### `{fault}`",
            "",
            "| channel | row | episodes | missed [95 %] | r_td [95 %] | t_dt [95 %] | "
            "t_dt/optimal [95 %] |",
            "|---|---|---|---|---|---|---|",
        ]
        for ch in sorted(channels):
            ss = channels[ch]
            opt_t = [_value(by_cell.get((optimal, fault, s)), "t_dt") for s in ss]
            for label in labels:
                recs = [by_cell.get((label, fault, s)) for s in ss]
                recs_ok = [r for r in recs if r is not None]
                t_dt = [_value(r, "t_dt") for r in recs]
                r_td = [_value(r, "r_td") for r in recs]
                ratio = (
                    limit_ratio_ci(t_dt, opt_t)
                    if optimal is not None and label != optimal
                    else None
                )
                lines.append(
                    f"| {ch} | {label} | {len(recs_ok)} | "
                    f"{wilson(sum(_missed(r) for r in recs_ok), len(recs_ok))} | "
                    f"{_ci(bootstrap_ci(r_td), '.3f')} | {_ci(bootstrap_ci(t_dt), '.0f')} | "
                    f"{'' if ratio is None else _ci(ratio, '.2f')} |"
                )
        lines += [
            "",
            "| seed | channel | size | onset | "
            + " | ".join(f"{label} t_dt / r_td" for label in labels)
            + " |",
            "|---|---|---|---|" + "---|" * len(labels),
        ]
        for s in seeds:
            sp = specs[s]
            cells = []
            for label in labels:
                rec = by_cell.get((label, fault, s))
                t_dt, r_td = _value(rec, "t_dt"), _value(rec, "r_td")
                cells.append(
                    ("missed" if np.isnan(t_dt) else f"{t_dt:.0f}")
                    + ("" if np.isnan(r_td) else f" / {r_td:.3f}")
                )
            lines.append(
                f"| {s} | {sp.channel} | {sp.magnitude:.2f} | {sp.onset} | "
                + " | ".join(cells)
                + " |"
            )
        lines.append("")
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True, help="goal_table.py's --out")
    ap.add_argument("--track", default="sensor")
    ap.add_argument(
        "--faults", default="sensor-bias,sensor-drift", help="classes for the channel rows; '' none"
    )
    args = ap.parse_args()
    if args.track not in TRACKS:
        ap.error(f"--track {args.track!r}; allowed: one of {sorted(TRACKS)}")
    faults = [f for f in args.faults.split(",") if f]
    bad = [f for f in faults if f not in TRACKS[args.track].faults]
    if bad:
        ap.error(f"--faults {bad}; allowed: classes of {args.track}: {TRACKS[args.track].faults}")
    where = args.out / args.track
    missing = [p for p in ("leaderboard.json", "results.json") if not (where / p).is_file()]
    if missing:
        ap.error(f"--out {args.out}: {where} lacks {missing}; allowed: a goal_table.py --out")
    text = detector_table(args.out, args.track) + (
        "\n" + channel_tables(args.out, args.track, faults) if faults else ""
    )
    (where / "channels.md").write_text(text)
    print(text)


if __name__ == "__main__":
    main()
