"""Old default against ``glr_names="kind"`` of ``sensor-validation``, on the same episodes.

Reads the records of a ``lab/sensor_kinds_lab.py`` run made with the bank on and
``--glr-names kind`` (the saved decisions are the combination's: the bank's kind, the slow
rule's sensor) and replays the rule without the bank (``glr_window`` 0, the shipped default)
on the same saved bank outputs. Per column and per true channel it prints the kind CDR, the
channel CDR and the both-right CDR (the share of alarmed samples after the onset whose kind,
channel, or both are right) of each setting and their paired difference, each with a 95 %
bootstrap (BCa) interval over the episodes, and the same with the T_ar episodes left out.
It checks that the combination's sensor and alarms are the old rule's, sample for sample.

``--affected G`` instead lists the records where ``glr_restart`` = G would start the bank
afresh (an alarm after G quiet samples or more inside a window): only those change with it
(the alarms do not depend on the bank), so deleting them from a copy of the records and
running ``lab/sensor_kinds_lab.py --glr-restart G`` on the copy re-simulates only them.

    PYTHONPATH=$PWD python lab/sensor_combo_compare.py /tmp/cdrcombo/fresh
    PYTHONPATH=$PWD python lab/sensor_combo_compare.py /tmp/cdrcombo/val --affected 200
"""

from __future__ import annotations

import argparse
import sys
from collections import defaultdict
from pathlib import Path

import numpy as np

from evaluation.metrics.intervals import bootstrap_ci
from fcc_env.params import MEASUREMENT_NAMES

# ``python lab/<script>.py`` puts lab/ first on the path, not the repository root
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from lab.sensor_kinds_replay import KIND_NAMES, decide, load

#: The scores per episode, in this order.
SCORES = ("kind", "channel", "both")


def _ci(values) -> str:
    v = [x for x in values if np.isfinite(x)]
    if not v:
        return "–"
    if np.ptp(v) == 0:  # every episode the same: no interval to draw
        return f"{v[0]:.3f}"
    iv = bootstrap_ci(v, rng=0)
    return f"{iv.estimate:.3f} [{iv.low:.3f}, {iv.high:.3f}]"


def _scores(kind, channel, onset: int, true: int, col: int) -> tuple[float, float, float]:
    al = kind[onset:] > 0
    if not al.any():
        return (np.nan, np.nan, np.nan)
    k_ok = kind[onset:][al] == col + 1
    c_ok = channel[onset:][al] == true
    return (float(np.mean(k_ok)), float(np.mean(c_ok)), float(np.mean(k_ok & c_ok)))


def compare(directory: Path) -> dict[str, list[tuple]]:
    """Per column, ``(true channel, old scores, combination scores)`` of each saved episode."""
    p, lim = load(directory, None)
    rows: dict[str, list[tuple]] = defaultdict(list)
    for path in sorted(directory.glob("sensor-*-*.npz")):
        rec = np.load(path)
        col, true, onset = int(rec["col"]), int(rec["true"]), int(rec["onset"])
        old_kind, old_channel, _ = decide(rec, p, lim)
        if not np.array_equal(old_channel, rec["channel"]):
            raise SystemExit(f"{path.name}: the combination's sensor is not the slow rule's")
        if not np.array_equal(old_kind > 0, rec["kind"] > 0):
            raise SystemExit(f"{path.name}: the combination's alarms are not the old rule's")
        old = _scores(old_kind, old_channel, onset, true, col)
        new = _scores(rec["kind"], rec["channel"], onset, true, col)
        rows[KIND_NAMES[col]].append((MEASUREMENT_NAMES[true], old, new))
    return rows


def affected(directory: Path, quiet: int) -> list[str]:
    """The faulty records where ``glr_restart`` = ``quiet`` restarts the bank (docstring)."""
    window = int(load(directory, None)[0]["glr_window"])
    names = []
    for path in sorted(directory.glob("sensor-*-*.npz")):
        a = np.load(path)["kind"] > 0
        end, last = -1, None  # the window's end; the last alarmed sample
        for k in np.flatnonzero(a):
            new = last is None or k > last + 1
            if new and k < end and k - last - 1 >= quiet:
                names.append(path.name)
                break
            if new and k >= end:
                end = k + window
            last = k
    return names


def _table(title: str, groups: dict[str, list[tuple]]) -> None:
    print(f"\n{title}")
    print("| group | episodes | score | old default | glr_names=kind | difference |")
    print("|---|---|---|---|---|---|")
    for name, eps in groups.items():
        for i, score in enumerate(SCORES):
            old = [e[1][i] for e in eps]
            new = [e[2][i] for e in eps]
            diff = [b - a for a, b in zip(old, new, strict=True)]
            print(f"| {name} | {len(eps)} | {score} | {_ci(old)} | {_ci(new)} | {_ci(diff)} |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("dir", type=Path)
    ap.add_argument("--affected", type=int, default=None, help="glr_restart G: list records")
    args = ap.parse_args()
    if args.affected is not None:
        print("\n".join(affected(args.dir, args.affected)))
        return
    rows = compare(args.dir)
    _table("Per column", dict(rows))
    _table(
        "Per column, T_ar episodes left out",
        {col: [e for e in eps if e[0] != "T_ar"] for col, eps in rows.items()},
    )
    per_channel = {
        f"{col} {ch}": [e for e in eps if e[0] == ch]
        for col, eps in rows.items()
        for ch in sorted({e[0] for e in eps})
    }
    _table("Per column and true channel", per_channel)


if __name__ == "__main__":
    main()
