"""Re-score ``sensor-validation``'s decision rule on the records of ``sensor_kinds_lab.py``.

Runs :func:`diagnosers.sensors.sensor_checks.decide_run` (the diagnoser's own rule, compiled)
on each saved episode's bank outputs with the fitted limits and the hyperparameters saved
beside them, some changed by ``--set key=value`` (``t_drift``, ``step_ratio``, ``settle``,
``lam_iso``: its limits are re-learned from the saved healthy training records as ``fit``
does), and prints per kind and per channel: r_td, t_dt, the kind CDR (the share of alarmed
samples after the onset with the right label: what the track scores) and the channel CDR,
each with a 95 % BCa interval over the episodes, plus the misnamed samples by what they were
called. Without ``--set`` the replay reproduces the saved decisions (checked per episode);
records of a run with the GLR bank on (``glr_window`` > 0) are scored as saved, and
``--set glr_window=0`` replays them without it.

    PYTHONPATH=$PWD python lab/sensor_kinds_replay.py /tmp/sk/val --set step_ratio=5
"""

from __future__ import annotations

import argparse
import json
from collections import Counter, defaultdict
from pathlib import Path

import numpy as np

from diagnosers.sensors.sensor_checks import KINDS, decide_run, new_state
from evaluation.metrics.detection_metrics import r_td, t_dt
from evaluation.metrics.intervals import bootstrap_ci
from fcc_env.params import MEASUREMENT_NAMES

KIND_NAMES = KINDS


def _ci(values: list[float], fmt: str) -> str:
    iv = bootstrap_ci(values, rng=0)
    if iv.n == 0:
        return "–"
    return f"{iv.estimate:{fmt}} [{iv.low:{fmt}}, {iv.high:{fmt}}]"


def decide(
    rec, p: dict, lim: dict, named: np.ndarray | None = None, named_kind: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(kind, channel, slow)`` of a saved record under hyperparameters ``p``, limits ``lim``,
    the channel ``named`` by another test where it is ≥ 0 and the kind ``named_kind`` it says
    where > 0 (default: nowhere)."""
    white = np.ascontiguousarray(rec["white"], dtype=np.float64)
    T, H, C = white.shape
    s = new_state(H, C)
    signal, cons, slow = np.empty((T, 1 + 2 * C)), np.empty((T, H)), np.empty((T, H))
    kind, channel = np.empty(T, dtype=np.int64), np.empty(T, dtype=np.int64)
    decide_run(
        white,
        np.ascontiguousarray(rec["ded"], dtype=np.float64),
        np.ascontiguousarray(rec["y"], dtype=np.float64),
        p["lam"],
        p["lam_iso"],
        p["lam_noise"],
        p["hold_decay"],
        float(p["warmup"]),
        lim["consistency"],
        lim["slow"],
        lim["noise"],
        lim["clip"],
        lim["dedicated"],
        p["t_drift"],
        p["step_ratio"],
        float(p["settle"]),
        *(s[k] for k in ("count", "ewma", "slow", "prev", "diff", "held", "breaks")),
        *(s[k] for k in ("last_held", "reg", "regj", "alarmed", "ded_fast", "ded_slow", "pre")),
        np.full(T, -1, dtype=np.int64) if named is None else named,
        np.zeros(T, dtype=np.int64) if named_kind is None else named_kind,
        signal,
        cons,
        slow,
        kind,
        channel,
    )
    return kind, channel, slow


def load(directory: Path, overrides: dict[str, float] | None) -> tuple[dict, dict]:
    """The saved hyperparameters with ``overrides`` and the limits (``lim_s`` re-learned from
    the healthy records when ``lam_iso`` changed)."""
    p = json.loads((directory / "params.json").read_text())
    lim = {k: np.asarray(v, dtype=np.float64) for k, v in np.load(directory / "limits.npz").items()}
    if overrides:
        unknown = set(overrides) - set(p)
        if unknown:
            raise SystemExit(f"--set {sorted(unknown)}: not among {sorted(p)}")
        relearn = "lam_iso" in overrides and overrides["lam_iso"] != p["lam_iso"]
        p.update(overrides)
        if relearn:
            ones = dict(lim, slow=np.ones_like(lim["slow"]))
            top = np.zeros_like(lim["slow"])
            for h in sorted(directory.glob("healthy-*.npz")):
                slow = decide(np.load(h), p, ones)[2]
                top = np.maximum(top, slow[int(p["warmup"]) :].max(axis=0))
            lim["slow"] = np.maximum(top, 1e-9)
    return p, lim


def summarise(directory: Path, overrides: dict[str, float] | None) -> None:
    """Replay the rule under ``overrides`` and print the tables (module docstring)."""
    p, lim = load(directory, overrides)

    def rule(rec, path: Path) -> tuple[np.ndarray, np.ndarray]:
        if p.get("glr_window", 0) > 0:  # the bank's filters are not in the record: as saved
            return rec["kind"], rec["channel"]
        kind, channel, _ = decide(rec, p, lim)
        if not overrides and not (
            np.array_equal(kind, rec["kind"]) and np.array_equal(channel, rec["channel"])
        ):
            raise SystemExit(f"{path.name}: the replay differs from the saved decisions")
        return kind, channel

    score(directory, rule)


def score(directory: Path, rule, kinds: tuple[str, ...] = KIND_NAMES) -> None:
    """Print per kind and per channel the scores of ``rule(rec, path) -> (kind, channel)`` on
    the saved faulty records of ``kinds``."""
    rows: dict[str, list[tuple[float, ...]]] = defaultdict(list)
    chans: dict[tuple[str, str], list[tuple[float, ...]]] = defaultdict(list)
    wrong: dict[str, Counter] = defaultdict(Counter)
    for path in sorted(p for col in kinds for p in directory.glob(f"{col}-*.npz")):
        rec = np.load(path)
        col, true, onset = KIND_NAMES[int(rec["col"])], int(rec["true"]), int(rec["onset"])
        kind, channel = rule(rec, path)
        a = kind > 0
        al = a[onset:]
        k_ok = kind[onset:][al] == KIND_NAMES.index(col) + 1
        c_ok = channel[onset:][al] == true
        kc = float(np.mean(k_ok)) if al.any() else np.nan
        cc = float(np.mean(c_ok)) if al.any() else np.nan
        row = (r_td(a, onset), t_dt(a, onset), kc, cc)
        rows[col].append(row)
        chans[(col, MEASUREMENT_NAMES[true])].append(row)
        bad = ~(k_ok & c_ok)
        for k, c in zip(kind[onset:][al][bad], channel[onset:][al][bad], strict=True):
            wrong[col][f"{KIND_NAMES[k - 1].removeprefix('sensor-')}@{MEASUREMENT_NAMES[c]}"] += 1
    print("| column | episodes | r_td | t_dt | kind CDR | channel CDR | missed |")
    print("|---|---|---|---|---|---|---|")
    for col in KIND_NAMES:
        if col not in rows:
            continue
        r = np.array(rows[col])
        print(
            f"| {col} | {len(r)} | {_ci(list(r[:, 0]), '.3f')} | {_ci(list(r[:, 1]), '.0f')} | "
            f"{_ci(list(r[:, 2]), '.3f')} | {_ci(list(r[:, 3]), '.3f')} | "
            f"{int(np.isnan(r[:, 1]).sum())}/{len(r)} |"
        )
    print("\n| column | channel | episodes | r_td | kind CDR | channel CDR | least kind CDR |")
    print("|---|---|---|---|---|---|---|")
    for (col, ch), rs in sorted(chans.items()):
        r = np.array(rs)
        k = r[:, 2][np.isfinite(r[:, 2])]
        c = r[:, 3][np.isfinite(r[:, 3])]
        least = f"{k.min():.3f}" if k.size else "–"
        print(
            f"| {col} | {ch} | {len(r)} | {np.mean(r[:, 0]):.3f} | "
            f"{k.mean() if k.size else np.nan:.3f} | {c.mean() if c.size else np.nan:.3f} | "
            f"{least} |"
        )
    print("\nMisnamed samples after the onset (kind@channel: count), per column:")
    for col, cnt in wrong.items():
        print(f"  {col}: " + ", ".join(f"{k} {v}" for k, v in cnt.most_common(8)))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("dir", type=Path)
    ap.add_argument("--set", action="append", default=[], help="key=value, repeatable")
    args = ap.parse_args()
    overrides = {kv.split("=")[0]: float(kv.split("=")[1]) for kv in args.set}
    summarise(args.dir, overrides or None)


if __name__ == "__main__":
    main()
