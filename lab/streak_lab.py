"""Where ``lrgf-glr``'s healthy false alarms come from (validation seeds, the baseline lab's bank):
which statistic fires, how long the streaks are, and the operating point there (inputs against
their training range, the afterburn margin T_d1 − T_rg1).

    python lab/streak_lab.py --track paper
"""

from __future__ import annotations

import argparse

import numpy as np
from baseline_lab import episodes, load

from diagnosers import Episode
from evaluation.tracks import TRACKS
from evaluation.tracks.track_data import TrackData


def streaks(a: np.ndarray) -> list[tuple[int, int]]:
    d = np.diff(np.concatenate([[0], a.astype(int), [0]]))
    return list(zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1), strict=True))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--track", default="paper")
    a = ap.parse_args()
    det, cal, w, novelty = load(a.track)
    det._calibrate(cal, w, novelty)
    det._fitted_ = True
    eps = episodes(a.track, 60, 10, a.track)
    ch = list(det.channels_)
    train = TrackData(track=TRACKS[a.track]).train_episodes()
    ytr = np.concatenate([e.y[100:] for e in train])
    lo, hi = np.percentile(ytr, 1, axis=0), np.percentile(ytr, 99, axis=0)
    ab = ch.index("T_d1"), ch.index("T_rg1")
    rows = []
    for k in eps:
        if not k.startswith("y:nominal"):
            continue
        y = eps[k]
        d = det.detect(Episode(y, det.channels_, 10.0))
        al = d.alarm
        if not al.any():
            continue
        fired = (d.signal > d.upper)[al].mean(axis=0)
        st = streaks(al)
        longest = max(e - s for s, e in st)
        outside = ((y < lo) | (y > hi))[al].mean(axis=0)
        margin = (y[:, ab[0]] - y[:, ab[1]])[al]
        rows.append((al.mean(), k, len(st), longest, fired, outside, margin.max()))
    rows.sort(key=lambda r: -r[0])
    names = det.signal_names_
    print(f"{len(rows)} of 60 healthy episodes alarm; signals {names}")
    for r in rows[:8]:
        print(
            f"{r[1]}: {r[0]:.4f} in alarm, {r[2]} streaks, longest {r[3]}; fired "
            f"{np.round(r[4], 2).tolist()}; outside training 1-99% "
            + ", ".join(f"{c} {v:.2f}" for c, v in zip(ch, r[5], strict=True) if v > 0.05)
            + f"; max T_d1-T_rg1 {r[6]:.1f} °C"
        )
    print(
        f"training T_d1 - T_rg1 99th percentile {np.percentile(ytr[:, ab[0]] - ytr[:, ab[1]], 99):.1f}"
    )


if __name__ == "__main__":
    main()
