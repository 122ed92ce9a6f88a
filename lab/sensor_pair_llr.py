"""The information limit of naming a biased sensor on the ``sensor`` track (issue 43).

Per validation seed (5000.., never a test seed) and true channel, the track's ``sensor-bias``
episode (its drawn size and onset, the channel set to the one studied) is scored by
:func:`evaluation.tracks.sensor_bound.bias_profiles`: the exact model's log-likelihood of a
bias on each channel from the known onset, size profiled. Prints per episode the nearest rival
and ``LLR(true vs rival)`` per window, then per true channel the median and least LLR over
the seeds against each rival; ``LLR vs healthy`` (the true hypothesis against no fault) per
window. Record in ``lab/sensor-validation.md``.

    PYTHONPATH=$PWD python lab/sensor_pair_llr.py --seeds 3 --channels T_fp,T_rx,R_ar,T_ar
"""

from __future__ import annotations

import argparse
import dataclasses
import time
from collections import defaultdict

import numpy as np

from diagnosers.filters import FCCStateEstimator, UKFConfig
from evaluation.tracks.catalogue import TRACKS
from evaluation.tracks.sensor_bound import bias_profiles
from evaluation.tracks.track_data import TrackData
from fcc_env.params import MEASUREMENT_NAMES


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--seed-start", type=int, default=5000)
    ap.add_argument("--channels", default=",".join(MEASUREMENT_NAMES), help="true channels")
    ap.add_argument("--hypotheses", default=",".join(MEASUREMENT_NAMES))
    ap.add_argument("--windows", default="30,100,300")
    ap.add_argument("--size", type=float, default=None, help="fixed size (default: drawn)")
    ap.add_argument("--grid", default="-40,40,2.5", help="sizes profiled: low,high,step")
    args = ap.parse_args()
    c0 = time.process_time()
    track = TRACKS["sensor"]
    data = TrackData(track=track)
    plant = track.test_plant
    est = FCCStateEstimator(plant.params, UKFConfig.matching(plant))
    hyps = args.hypotheses.split(",")
    windows = tuple(int(w) for w in args.windows.split(","))
    lo, hi, step = (float(v) for v in args.grid.split(","))
    grid = np.arange(lo, hi + step / 2, step)
    table: dict[str, list[dict[str, np.ndarray]]] = defaultdict(list)
    print("| true | seed | size | onset | b̂ (true hyp.) | nearest rival (b̂) | LLR per "
          f"window {windows} | LLR vs healthy per window |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|")
    for true in args.channels.split(","):
        for seed in range(args.seed_start, args.seed_start + args.seeds):
            spec = dataclasses.replace(track.fault_spec("sensor-bias", seed), channel=true)
            if args.size is not None:
                spec = dataclasses.replace(spec, magnitude=args.size)
            [le] = data.simulate([seed], spec, test=True)
            ep = le.episode
            onset = ep.fault_onset
            if onset is None or onset + max(windows) > ep.n_samples:
                print(f"| {true} | {seed} | – | – | – | ended before the window | – | – |")
                continue
            idx = [ep.channels.index(c) for c in est.channels]
            prof = bias_profiles(est, np.asarray(ep.y)[:, idx], onset, hyps, windows, grid)
            llr = prof.llr(true)
            table[true].append(llr)
            rival = min(llr, key=lambda c: llr[c][-1])
            i = prof.channels.index(true)
            vs_h = prof.loglik[i] - prof.healthy
            print(
                f"| {true} | {seed} | {spec.magnitude:.2f} | {onset} | {prof.size[i]:.2f} | "
                f"{rival} ({prof.size[prof.channels.index(rival)]:.1f}) | {', '.join(f'{v:.1f}' for v in llr[rival])} | "
                f"{', '.join(f'{v:.1f}' for v in vs_h)} |",
                flush=True,
            )
    print(f"\nPer true channel: median [least] over the seeds of LLR(true vs rival), window "
          f"{windows[-1]} (and {windows[0]})")  # fmt: skip
    rivals = list(hyps)
    print("| true | " + " | ".join(rivals) + " |")
    print("|---|" + "---|" * len(rivals))
    for true, rows in table.items():
        cells = []
        for r in rivals:
            if r == true or r not in rows[0]:
                cells.append("–")
                continue
            v = np.array([row[r] for row in rows])  # (seeds, windows)
            cells.append(
                f"{np.median(v[:, -1]):.1f} [{v[:, -1].min():.1f}] "
                f"({np.median(v[:, 0]):.1f} [{v[:, 0].min():.1f}])"
            )
        print(f"| {true} | " + " | ".join(cells) + " |")
    print(f"\n{time.process_time() - c0:.0f} s CPU (this process)")


if __name__ == "__main__":
    main()
