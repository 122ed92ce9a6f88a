"""Why ``lrgf-glr-closed`` is far from the measured-input reference on f3 in closed loop.

On validation seeds (6000+; never the test range), for each fault the trace it leaves, read as
each reader reads it:

* the reference (a perfect model driven by the measured inputs) sees, per channel, the noise-free
  faulty minus healthy measurement of the same seed (the twin), against the sensor noise σ;
* the detector sees, per relation, its residual on the faulty episode minus its residual on the
  healthy twin (same noise, so what is left is the fault), against the spread of its residual on
  healthy episodes (its model error plus noise).

Both as a signal-to-noise ratio averaged over a window after the onset. The detector's networks
are trained exactly as on the ``closed`` track (its 9 training seeds).

    PYTHONPATH=. python lab/closed_f3_limit.py [--seeds 20] [--window 20]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from diagnosers import make
from evaluation.tracks.catalogue import TRACKS
from evaluation.tracks.track_data import TrackData
from fcc_env.scenarios import FaultSpec

FIRST_VALIDATION_SEED = 6000


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--window", type=int, default=20, help="samples after the onset")
    ap.add_argument("--faults", default="f2,f3,f4")
    args = ap.parse_args()
    track = TRACKS["closed"]
    data = TrackData(track)
    t0 = time.perf_counter()
    det = make("lrgf-glr-closed").fit(data.train_episodes())
    print(f"trained in {time.perf_counter() - t0:.0f} s")
    seeds = range(FIRST_VALIDATION_SEED, FIRST_VALIDATION_SEED + args.seeds)
    healthy = {s: data.simulate([s], FaultSpec())[0].episode for s in seeds}
    res_h = {s: det.detect(ep) for s, ep in healthy.items()}
    names = res_h[seeds[0]].signal_names
    warm = 200
    spread = np.std(np.concatenate([r.residual[warm:] for r in res_h.values()]), axis=0)
    ep0 = healthy[seeds[0]]
    noise = np.std(
        np.concatenate([ep.y[warm:] - ep.y_clean[warm:] for ep in healthy.values()]), axis=0
    )
    print("detector residual spread per relation:", dict(zip(names, spread.round(3), strict=True)))
    print("sensor noise σ per channel:", dict(zip(ep0.channels, noise.round(3), strict=True)))
    for fault in args.faults.split(","):
        snr_ref, snr_det = [], []
        for s in seeds:
            spec = track.fault_spec(fault, s)
            ep = data.simulate([s], spec)[0].episode
            k0 = ep.fault_onset
            win = slice(k0, k0 + args.window)
            trace = ep.y_clean[win] - healthy[s].y_clean[win]
            snr_ref.append(np.mean(np.abs(trace), axis=0) / noise)
            r = det.detect(ep).residual[win] - res_h[s].residual[win]
            snr_det.append(np.mean(np.abs(r), axis=0) / spread)
        ref, dt = np.mean(snr_ref, axis=0), np.mean(snr_det, axis=0)
        print(f"\n{fault}: mean |trace| / spread over the {args.window} samples after the onset")
        print("  reference (noise-free trace / sensor noise):")
        for c, v in sorted(zip(ep0.channels, ref, strict=True), key=lambda x: -x[1]):
            print(f"    {c:8s} {v:7.2f}")
        print("  lrgf-glr-closed (residual trace / healthy residual spread):")
        for c, v in sorted(zip(names, dt, strict=True), key=lambda x: -x[1]):
            print(f"    {c:8s} {v:7.2f}")


if __name__ == "__main__":
    main()
