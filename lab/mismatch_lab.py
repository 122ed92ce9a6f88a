"""Lab script: where ``ukf-glr``'s false alarms on a drawn-plant track come from, per episode.

    python lab/mismatch_lab.py --track mismatch --n 20 --seed-start 5000 [--set k=v ...]

Fits ``ukf-glr`` (with the ``--set`` hyperparameters, JSON values) on the track's training
episodes, runs it on ``--n`` healthy validation episodes (seeds from ``--seed-start``, 5000+,
never test seeds) and prints, per episode, its alarm share, the statistic that alarms most and
how far each statistic group went past its limit, beside what the episode's plant drew (the
``mismatch`` track's undeclared effects: read here by the lab only, never by the detector).
Records in ``lab/greybox-lab.md`` (2026-12-07).
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

import diagnosers
from evaluation.tracks import TRACKS
from evaluation.tracks.track_data import TrackData
from fcc_env.scenarios import FaultSpec
from fcc_env.uncertainty import PlantMismatch


def _effects(seed: int) -> str:
    """The mismatch draw of ``seed``, short: extra UA per vessel, the lag, the deactivation."""
    parts = []
    for e in PlantMismatch().draw(seed).effects:
        (value,) = e.params.values()
        unit = e.target or ""
        parts.append(f"{e.kind[:4]}{':' + unit[:6] if unit else ''}={value:.3g}")
    return " ".join(parts)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--track", default="mismatch")
    p.add_argument("--n", type=int, default=20)
    p.add_argument("--seed-start", type=int, default=5000)
    p.add_argument("--set", action="append", default=[], help="ukf-glr hyperparameter k=v")
    args = p.parse_args()
    if args.seed_start < 1000:
        raise SystemExit(f"--seed-start {args.seed_start}: test seeds (0-999) are not for the lab")
    data = TrackData(track=TRACKS[args.track])
    params = {k: json.loads(v) for k, v in (s.split("=", 1) for s in args.set)}
    det = diagnosers.make("ukf-glr", **params)
    t0 = time.process_time()
    det.fit(data.train_episodes())
    print(f"fit {time.process_time() - t0:.1f} s CPU; noise {det.noise_scale_:.3f}, ", end="")
    print(f"online {det.online_}, limits {np.round(det.limits_, 1).tolist()}")
    seeds = list(range(args.seed_start, args.seed_start + args.n))
    t0 = time.process_time()
    episodes = [le.episode for le in data.simulate(seeds, FaultSpec())]
    shares, names = [], None
    for seed, ep in zip(seeds, episodes, strict=True):
        d = det.detect(ep)
        names = d.signal_names
        over = d.signal > d.upper
        share = float(np.mean(d.alarm))
        shares.append(share)
        ratio = np.nanmax(d.signal / d.upper, axis=0)
        top = names[int(np.argmax(over.sum(axis=0)))] if share > 0 else "-"
        worst = ", ".join(f"{n}:{r:.1f}" for n, r in zip(names, ratio, strict=True) if r > 1.0)
        extra = f" | {_effects(seed)}" if args.track == "mismatch" else ""
        print(f"{seed} alarm {share:.4f} top {top} | over: {worst or '-'}{extra}")
    print(f"detect {time.process_time() - t0:.1f} s CPU")
    s = np.array(shares)
    print(f"mean alarm share {s.mean():.4f}; episodes with alarms {int((s > 0).sum())}/{len(s)}")


if __name__ == "__main__":
    main()
