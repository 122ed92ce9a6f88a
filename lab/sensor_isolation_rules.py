"""Compare channel rules of ``sensor-validation`` on the records of ``sensor_isolation_replay.py``.

Each rule names a channel per alarmed sample from what the bank gave (whitened innovations,
dedicated residuals, consistency statistics); the channel CDR per episode is the share of
alarmed samples after the onset naming the true channel. Limits of new statistics come from
the healthy training records saved beside (their largest value after the warm-up).

    PYTHONPATH=$PWD python lab/sensor_isolation_rules.py /tmp/replay-train
"""

from __future__ import annotations

import argparse
from collections import defaultdict
from pathlib import Path

import numpy as np

from fcc_env.params import MEASUREMENT_NAMES

WARMUP = 200
LAM = 0.02


def ewma(x: np.ndarray, lam: float) -> np.ndarray:
    """EWMA along axis 0 from 0; a NaN sample leaves the average unchanged."""
    out = np.empty_like(x, dtype=np.float64)
    a = np.zeros(x.shape[1:])
    for k in range(x.shape[0]):
        v = x[k]
        a = np.where(np.isfinite(v), (1.0 - lam) * a + lam * np.nan_to_num(v), a)
        out[k] = a
    return out


def left_out_white(white: np.ndarray) -> np.ndarray:
    """(T, 9, 8) with each leave-out filter's own channel zeroed (it is ~1/1000 anyway)."""
    w = np.nan_to_num(white.astype(np.float64)).copy()
    for c in range(w.shape[2]):
        w[:, c + 1, c] = 0.0
    return w


def slow_consistency(white: np.ndarray, lam: float) -> np.ndarray:
    a = ewma(left_out_white(white), lam)
    return np.sum(a * a, axis=2) * (2.0 - lam) / lam


def nis_since_alarm(white: np.ndarray, alarm: np.ndarray) -> np.ndarray:
    """(T, 9) the whitened innovations' squares (the left-out channel dropped) less their
    mean (7; filter 0: 8), summed since the alarm began (0 while not alarmed)."""
    w = left_out_white(white)
    excess = np.sum(w * w, axis=2) - np.array([8.0] + [7.0] * (w.shape[1] - 1))
    out = np.zeros_like(excess)
    acc = np.zeros(excess.shape[1])
    for k in range(excess.shape[0]):
        acc = acc + excess[k] if alarm[k] else np.zeros_like(acc)
        out[k] = acc
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("dir", type=Path)
    ap.add_argument("--lams", default="0.02,0.005,0.002")
    args = ap.parse_args()
    lim = np.load(args.dir / "limits.npz")
    lim_e = lim["dedicated"]
    lams = [float(v) for v in args.lams.split(",")]
    healthy = [np.load(p) for p in sorted(args.dir.glob("healthy-*.npz"))]
    slow_lim = {
        lam: np.max([slow_consistency(h["white"], lam)[WARMUP:].max(axis=0) for h in healthy], 0)
        for lam in lams
    }
    for lam in lams:
        print(f"slow limit lam={lam}: " + " ".join(f"{v:.1f}" for v in slow_lim[lam]))
    res: dict[str, dict[str, list[float]]] = defaultdict(lambda: defaultdict(list))
    for p in sorted(args.dir.glob("*-*.npz")):
        if p.name.startswith("healthy"):
            continue
        r = np.load(p)
        true, onset = int(r["true"]), int(r["onset"])
        alarm = r["kind"][onset:] > 0
        if not alarm.any():
            continue
        name = MEASUREMENT_NAMES[true]
        cons = r["cons"][onset:, 1:]
        z = np.abs(ewma(r["ded"], LAM))[onset:] / lim_e
        rules: dict[str, np.ndarray] = {"saved": r["channel"][onset:]}
        for f in (0.01, 0.1, 0.3, 1.0):
            rules[f"z/max(cons,{f})"] = np.argmax(z / np.maximum(cons, f), axis=1)
        rules["argmin cons"] = np.argmin(cons, axis=1)
        full_alarm = r["kind"] > 0
        nis = nis_since_alarm(r["white"], full_alarm)[onset:, 1:]
        rules["argmin NIS since alarm"] = np.argmin(nis, axis=1)
        for lam in lams:
            e = ewma(left_out_white(r["white"]) ** 2, lam).sum(axis=2)[onset:, 1:]
            rules[f"argmin ewma NIS({lam})"] = np.argmin(e, axis=1)
        for lam in lams:
            s = slow_consistency(r["white"], lam)[onset:, 1:] / slow_lim[lam][1:]
            rules[f"argmin slow({lam})"] = np.argmin(s, axis=1)
            rules[f"z/max(slow({lam}),0.1)"] = np.argmax(z / np.maximum(s, 0.1), axis=1)
            rules[f"z/max(slow({lam}),1)"] = np.argmax(z / np.maximum(s, 1.0), axis=1)
        for key, named in rules.items():
            res[key][name].append(float(np.mean(named[alarm] == true)))
    channels = sorted({c for d in res.values() for c in d})
    print("| rule | all | " + " | ".join(channels) + " |")
    print("|---|---|" + "---|" * len(channels))
    for key, d in res.items():
        allv = [v for c in channels for v in d[c]]
        cells = [f"{np.mean(d[c]):.2f}" for c in channels]
        print(f"| {key} | {np.mean(allv):.3f} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
