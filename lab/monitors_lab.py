"""The black-box monitors of issue 42 item 4 (``dpca``, ``cva``, ``n4sid-glr``) on validation
seeds: r_fd, r_td and t_dt per fault with 95 % intervals, beside the reachable-bound row's
figures of ``lab/filter-lab.md`` (the same seeds: 6000+, 40 healthy, 10 per fault).

Never reads a test seed (0-999): trains on the track's training seeds (1000+) and its labelled
training faults, scores validation seeds from ``--seed-start`` (default 6000, clear of the
reference rows' calibration seeds 5000-5099).

    python lab/monitors_lab.py --track paper,small --detectors 'dpca' 'cva:{"past": 5}'

Each detector argument is a registry name, optionally ``:`` and a JSON dict of
hyperparameters. ``--out FILE`` appends one JSON line per (track, detector) with every figure.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from functools import cache

import numpy as np

import diagnosers
from evaluation.metrics.detection_metrics import episode_scores
from evaluation.metrics.intervals import bootstrap_ci
from evaluation.tracks import TRACKS
from evaluation.tracks.track_data import TrackData
from fcc_env.scenarios import FaultSpec


@cache
def track_data(name: str) -> TrackData:
    return TrackData(track=TRACKS[name])


@cache
def training(name: str) -> tuple[list, list]:
    data = track_data(name)
    return data.train_episodes(), data.train_fault_episodes()


@cache
def scored(name: str, start: int, n_healthy: int, n_faulty: int) -> list:
    data = track_data(name)
    eps = [le.episode for le in data.simulate(list(range(start, start + n_healthy)), FaultSpec())]
    for f in data.track.faults:
        for s in range(start, start + n_faulty):
            eps.append(data.load_test(f, s).episode)
    return eps


def interval(values: list[float]) -> str:
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return "-"
    if v.size < 3 or np.ptp(v) == 0:
        return f"{v.mean():.4g}"
    ci = bootstrap_ci(v)
    return f"{v.mean():.4g} [{ci.low:.4g}, {ci.high:.4g}]"


def run(track: str, spec: str, a: argparse.Namespace) -> dict:
    name, _, params = spec.partition(":")
    det = diagnosers.make(name, **(json.loads(params) if params else {}))
    train, faults = training(track)
    t0 = time.process_time()
    det.fit(train + faults if det.learns_from_faults else train)
    fit_cpu = time.process_time() - t0
    rows: dict[str, list[dict]] = {}
    t0 = time.process_time()
    for ep in scored(track, a.seed_start, a.healthy, a.faulty):
        s = episode_scores(det.detect(ep).alarm, ep.fault_onset)
        rows.setdefault(ep.scenario if ep.fault_onset is not None else "nominal", []).append(s)
    out = {"track": track, "detector": spec, "fit_cpu_s": round(fit_cpu, 1)}
    out["score_cpu_s"] = round(time.process_time() - t0, 1)
    for extra in ("n_components_", "n_states_"):
        if hasattr(det, extra):
            out[extra] = getattr(det, extra)
    for sc, rs in rows.items():
        if sc == "nominal":
            out["r_fd"] = interval([r["r_fd"] for r in rs])
        else:
            out[sc] = {
                "r_td": interval([r["r_td"] for r in rs]),
                "t_dt": interval([r["t_dt"] for r in rs]),
                "missed": int(sum(not np.isfinite(r["t_dt"]) for r in rs)),
            }
    return out


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--track", default="paper,small")
    p.add_argument("--detectors", nargs="+", default=["dpca", "cva", "n4sid-glr"])
    p.add_argument("--seed-start", type=int, default=6000)
    p.add_argument("--healthy", type=int, default=40)
    p.add_argument("--faulty", type=int, default=10)
    p.add_argument("--out", default=None)
    a = p.parse_args()
    if a.seed_start < 5000:
        sys.exit("--seed-start must be a validation seed (5000+)")
    for track in a.track.split(","):
        for spec in a.detectors:
            res = run(track, spec, a)
            line = json.dumps(res)
            print(line, flush=True)
            if a.out:
                with open(a.out, "a") as fh:
                    fh.write(line + "\n")


if __name__ == "__main__":
    main()
