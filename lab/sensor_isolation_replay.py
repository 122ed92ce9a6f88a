"""Record ``sensor-validation``'s bank on sensor-bias episodes, to compare channel rules offline.

Fits ``sensor-validation`` as ``lab/sensor_validation_lab.py`` does (the track's healthy
training seeds plus one labelled episode per kind), then for each seed and true channel runs
the track's ``sensor-bias`` episode (drawn size and onset, the channel set) once and saves what
the channel rule reads: the bank's whitened innovations and dedicated residuals, the
consistency statistics, the alarm and the channel named, the limits. Rules are then compared on
the saved arrays (:func:`rank`), each a few milliseconds, instead of a bank run each.
Tune on training seeds (``--seed-start 1100``), confirm on validation seeds (5000..).

    PYTHONPATH=$PWD python lab/sensor_isolation_replay.py --seed-start 1100 --seeds 2 \
        --out /tmp/replay-train
"""

from __future__ import annotations

import argparse
import dataclasses
import time
from pathlib import Path

import numpy as np

import diagnosers
from diagnosers import Episode
from evaluation.tracks.catalogue import TRACKS
from evaluation.tracks.track_data import TrackData
from fcc_env import FaultSpec, simulate_episodes
from fcc_env.params import MEASUREMENT_NAMES


def fitted(n_train: int, **params):
    track = TRACKS["sensor"].replace(n_train=n_train)
    data = TrackData(track=track)
    labelled = [
        ep
        for kind in track.faults
        for ep in Episode.from_batch(
            simulate_episodes(
                [1000], 400, fault=FaultSpec(scenario=kind, onset=300), plant=track.plant
            )
        )
    ]
    return (
        track,
        data,
        diagnosers.make("sensor-validation", **params).fit(data.train_episodes() + labelled),
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=2)
    ap.add_argument("--seed-start", type=int, default=1100)
    ap.add_argument("--channels", default=",".join(MEASUREMENT_NAMES))
    ap.add_argument("--train", type=int, default=4)
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--skip-healthy", action="store_true", help="save no healthy records")
    args = ap.parse_args()
    c0 = time.process_time()
    track, data, det = fitted(args.train)
    args.out.mkdir(parents=True, exist_ok=True)
    np.savez(args.out / "limits.npz", **det.limits_)
    print(f"fitted: {time.process_time() - c0:.0f} s CPU", flush=True)
    stash = {}
    run = det.bank_.run

    def keep(M, P, Y):
        stash["out"] = out = run(M, P, Y)
        return out

    det.bank_.run = keep
    healthy = [] if args.skip_healthy else data.train_episodes()
    for i, ep in enumerate(healthy):  # the healthy records the limits came from
        det._reset()
        _, cons, kind, channel, _, _ = det._checks(np.asarray(ep.y, dtype=np.float64))
        out = stash["out"]
        np.savez_compressed(
            args.out / f"healthy-{i}.npz",
            white=out.white.astype(np.float32),
            ded=out.dedicated,
            cons=cons,
            kind=kind,
        )
    for true in args.channels.split(","):
        for seed in range(args.seed_start, args.seed_start + args.seeds):
            spec = dataclasses.replace(track.fault_spec("sensor-bias", seed), channel=true)
            [le] = data.simulate([seed], spec, test=True)
            ep = le.episode
            if ep.fault_onset is None or ep.fault_onset >= ep.n_samples:
                continue
            det._reset()
            _, cons, kind, channel, _, _ = det._checks(np.asarray(ep.y, dtype=np.float64))
            out = stash["out"]
            np.savez_compressed(
                args.out / f"{true}-{seed}.npz",
                white=out.white.astype(np.float32),
                ded=out.dedicated,
                cons=cons,
                kind=kind,
                channel=channel,
                true=MEASUREMENT_NAMES.index(true),
                onset=ep.fault_onset,
                size=spec.magnitude,
            )
            after = kind[ep.fault_onset :] > 0
            named = channel[ep.fault_onset :][after]
            hit = np.mean(named == MEASUREMENT_NAMES.index(true)) if named.size else np.nan
            print(f"{true} {seed}: size {spec.magnitude:.2f}, channel CDR {hit:.3f}", flush=True)
    print(f"{time.process_time() - c0:.0f} s CPU")


if __name__ == "__main__":
    main()
