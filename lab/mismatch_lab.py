"""Lab script: where ``ukf-glr``'s false alarms on a drawn-plant track come from, and what the
remedies do, on validation seeds (5000+), several variants on the same episodes.

    python lab/mismatch_lab.py --track mismatch --n 20 --faulty 3 --per-episode \\
        --variant 'base={}' --variant 'lags={"sensor_lags": ["T_rx", "T_rg1"]}'

Per variant (``label=JSON`` of ``ukf-glr`` hyperparameters): it is fitted on the track's
training episodes, run on ``--n`` healthy episodes (seeds from ``--seed-start``, never test
seeds) and on ``--faulty`` episodes per fault (the same seeds); printed: the healthy alarm
share (mean and the episodes with any alarm), per fault the mean delay and detected share of
the post-onset samples, and with ``--per-episode`` each healthy episode's alarm share, the
statistic that alarms most and how far each went past its limit, beside what the episode's
plant drew (the ``mismatch`` track's undeclared effects: read by the lab only, never by the
detector). Records in ``lab/greybox-lab.md`` (2026-12-07).
"""

from __future__ import annotations

import argparse
import json
import time
from typing import Any

import numpy as np

import diagnosers
from diagnosers.detection import Detection
from evaluation.metrics.detection_metrics import episode_scores
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


def _episode_line(seed: int, d: Detection, track: str) -> str:
    share = float(np.mean(d.alarm))
    over = d.signal > d.upper
    ratio = np.nanmax(d.signal / d.upper, axis=0)
    top = d.signal_names[int(np.argmax(over.sum(axis=0)))] if share > 0 else "-"
    worst = ", ".join(f"{n}:{r:.1f}" for n, r in zip(d.signal_names, ratio, strict=True) if r > 1)
    extra = f" | {_effects(seed)}" if track == "mismatch" else ""
    return f"  {seed} alarm {share:.4f} top {top} | over: {worst or '-'}{extra}"


def run_variant(label: str, params: dict[str, Any], data: TrackData, healthy, faulty, args) -> None:
    det = diagnosers.make("ukf-glr", **params)
    t0 = time.process_time()
    det.fit(data.train_episodes())
    fit_s = time.process_time() - t0
    t0 = time.process_time()
    shares = []
    lines = []
    for seed, ep in healthy:
        d = det.detect(ep)
        shares.append(float(np.mean(d.alarm)))
        lines.append(_episode_line(seed, d, args.track))
    cells = []
    for fault, eps in faulty.items():
        sc = [episode_scores(det.detect(ep).alarm, ep.fault_onset) for ep in eps]
        t_dt = np.array([s["t_dt"] for s in sc])
        r_td = np.nanmean([s["r_td"] for s in sc])
        cells.append(f"{fault} {np.nanmean(t_dt):.1f} ({r_td:.2f}, missed {np.isnan(t_dt).sum()})")
    s = np.array(shares)
    print(
        f"{label}: healthy alarm share {s.mean():.4f}, episodes with alarms "
        f"{int((s > 0).sum())}/{len(s)}, worst {s.max():.4f} | {' | '.join(cells)} | "
        f"noise {det.noise_scale_:.3f}, online {det.online_}; CPU fit {fit_s:.1f} s, "
        f"detect {time.process_time() - t0:.1f} s"
    )
    if args.per_episode:
        print("\n".join(lines))


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--track", default="mismatch")
    p.add_argument("--n", type=int, default=20)
    p.add_argument("--faulty", type=int, default=0)
    p.add_argument("--seed-start", type=int, default=5000)
    p.add_argument("--variant", action="append", default=[], help="label=JSON hyperparameters")
    p.add_argument("--per-episode", action="store_true")
    args = p.parse_args()
    if args.seed_start < 1000:
        raise SystemExit(f"--seed-start {args.seed_start}: test seeds (0-999) are not for the lab")
    data = TrackData(track=TRACKS[args.track])
    seeds = list(range(args.seed_start, args.seed_start + args.n))
    t0 = time.process_time()
    healthy = list(
        zip(seeds, [le.episode for le in data.simulate(seeds, FaultSpec())], strict=True)
    )
    fseeds = seeds[: args.faulty]
    faulty = {
        f: [data.load_test(f, s).episode for s in fseeds] for f in data.track.faults if fseeds
    }
    print(f"{args.track}: simulated in {time.process_time() - t0:.1f} s CPU")
    for v in args.variant or ["base={}"]:
        label, js = v.split("=", 1)
        run_variant(label, json.loads(js), data, healthy, faulty, args)


if __name__ == "__main__":
    main()
