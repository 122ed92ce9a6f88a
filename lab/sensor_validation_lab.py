"""``sensor-validation`` on the ``sensor`` track (closed loop), small, on validation seeds.

Builds the track's own episodes (``evaluation.tracks.catalogue.TRACKS["sensor"]``: its plant,
its fault templates with the channel, size and onset each seed draws) on validation seeds
5000.. (never a test seed), trains on the track's healthy training seeds (1000..) plus one short
labelled episode per kind (they only name the classes: the diagnoser learns nothing from fault
data), and prints r_fd (healthy episodes) and per column r_td, t_dt, the kind CDR (what the
track scores: the registry label) and the channel CDR (the sensor named), each with a 95 % BCa
interval over the seeds, plus a per-channel breakdown. Record in ``lab/sensor-validation.md``.

    PYTHONPATH=$PWD python lab/sensor_validation_lab.py --healthy 10 --faulty 8 --train 4
"""

from __future__ import annotations

import argparse
import time
from collections import defaultdict

import numpy as np

import diagnosers
from diagnosers import Episode
from evaluation.metrics.detection_metrics import r_fd, r_td, t_dt
from evaluation.metrics.intervals import bootstrap_ci
from evaluation.metrics.isolation_metrics import cdr
from evaluation.tracks.catalogue import TRACKS
from evaluation.tracks.track_data import TrackData
from fcc_env import FaultSpec, simulate_episodes


def _ci(values: list[float], fmt: str) -> str:
    iv = bootstrap_ci(values, rng=0)
    if iv.n == 0:
        return "–"
    return f"{iv.estimate:{fmt}} [{iv.low:{fmt}}, {iv.high:{fmt}}]"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--healthy", type=int, default=10)
    ap.add_argument("--faulty", type=int, default=8)
    ap.add_argument("--train", type=int, default=4)
    ap.add_argument("--seed-start", type=int, default=5000)
    ap.add_argument("--columns", default="")
    args = ap.parse_args()
    c0, w0 = time.process_time(), time.perf_counter()
    track = TRACKS["sensor"].replace(n_train=args.train)
    data = TrackData(track=track)
    plant = track.plant
    labelled = [
        ep
        for kind in track.faults
        for ep in Episode.from_batch(
            simulate_episodes([1000], 400, fault=FaultSpec(scenario=kind, onset=300), plant=plant)
        )
    ]
    det = diagnosers.make("sensor-validation").fit(data.train_episodes() + labelled)
    print(f"fitted on {args.train} healthy: {time.process_time() - c0:.0f} s CPU", flush=True)
    seeds = range(args.seed_start, args.seed_start + args.healthy)
    fd = []
    for le in data.simulate(list(seeds), FaultSpec(), test=True):
        a = det.detect(le.episode).alarm
        fd.append(r_fd(a, len(a)))
    print(f"r_fd over {len(fd)} healthy: {_ci(fd, '.4f')}; max {max(fd):.4f}", flush=True)
    cols = args.columns.split(",") if args.columns else list(track.faults)
    print("| column | r_td | t_dt | kind CDR | channel CDR | missed | r_fd before onset |")
    print("|---|---|---|---|---|---|---|")
    per_channel: dict[tuple[str, str], list[tuple[float, float, float]]] = defaultdict(list)
    for col in cols:
        td, dt, kc, cc, pre, missed = [], [], [], [], [], 0
        for seed in range(args.seed_start, args.seed_start + args.faulty):
            spec = track.fault_spec(col, seed)
            [le] = data.simulate([seed], spec, test=True)
            ep = le.episode
            onset = ep.fault_onset
            if onset is None or onset >= ep.n_samples:
                continue
            d = det.detect(ep)
            sensors = det.sensors(ep)
            a = d.alarm
            td.append(r_td(a, onset))
            dt.append(t_dt(a, onset))
            pre.append(r_fd(a, onset))
            k = cdr(d.diagnosis, col, onset)
            c = cdr(np.where(sensors == spec.channel, "hit", sensors), "hit", onset)
            kc.append(k)
            cc.append(c)
            missed += int(np.isnan(dt[-1]))
            per_channel[(col, str(spec.channel))].append((td[-1], k, c))
        print(
            f"| {col} | {_ci(td, '.3f')} | {_ci(dt, '.0f')} | {_ci(kc, '.3f')} | "
            f"{_ci(cc, '.3f')} | {missed}/{len(td)} | {_ci(pre, '.4f')} |",
            flush=True,
        )
    print("\n| column | channel | episodes | r_td | kind CDR | channel CDR |")
    print("|---|---|---|---|---|---|")
    for (col, ch), rows in sorted(per_channel.items()):
        r = np.array(rows)
        print(
            f"| {col} | {ch} | {len(rows)} | {np.mean(r[:, 0]):.3f} | "
            f"{np.nanmean(r[:, 1]) if np.isfinite(r[:, 1]).any() else float('nan'):.3f} | "
            f"{np.nanmean(r[:, 2]) if np.isfinite(r[:, 2]).any() else float('nan'):.3f} |"
        )
    print(
        f"\n{time.perf_counter() - w0:.0f} s wall, {time.process_time() - c0:.0f} s CPU "
        "(this process; the machine is shared, so wall is contention-bound)"
    )


if __name__ == "__main__":
    main()
