"""Lab script of ``mmae`` (issue 42 item 5): tuning and goal figures on validation seeds.

Record: ``lab/mmae-lab.md``. Two steps, so that the decision settings are swept without filtering
again:

``python lab/mmae_lab.py filter --track small --seeds 5000-5009 --rate 0.05 --cache /tmp/mmae``
    runs the 5-hypothesis bank on every fault of the track and on healthy episodes of the seeds
    and keeps each filter's innovation log-likelihood and NIS per sample (plus the healthy
    filter's whitened innovations) in ``<cache>/<track>-<rate>-<initial>.npz``; prints CPU s.

``python lab/mmae_lab.py score --cache /tmp/mmae/small-0.05-0.01.npz --set switch_prob=1e-3,3e-3``
    scores ``mmae``'s decisions for every combination of the ``--set`` values (comma lists):
    per fault CDR, t_dt, t_it (the study's indexes), the Brier score after onset and on the
    healthy episodes, and the false-alarm rate r_fd there.

Validation seeds 5000+ and training seeds 1000+ only, never test seeds.
"""

from __future__ import annotations

import argparse
import itertools
import sys
import time
from pathlib import Path

import numpy as np

import diagnosers
import fcc_env
from diagnosers.episode.record import Episode
from evaluation.metrics.detection_metrics import r_fd, t_dt
from evaluation.metrics.isolation_metrics import cdr, t_it
from evaluation.metrics.probability_metrics import brier_samples
from evaluation.tracks.catalogue import TRACKS
from evaluation.tracks.track_data import TrackData


def _seeds(text: str) -> list[int]:
    lo, _, hi = text.partition("-")
    return list(range(int(lo), int(hi or lo) + 1))


def _fitted(params: dict) -> diagnosers.Diagnoser:
    """An mmae fitted on tiny episodes: it learns nothing but its classes from them."""
    healthy = Episode.from_batch(fcc_env.simulate_episodes([1000], 1500))
    faulty = [
        Episode.from_batch(
            fcc_env.simulate_episodes([1000], 40, fault=fcc_env.FaultSpec(scenario=f, onset=20))
        )[0]
        for f in fcc_env.PAPER_FAULTS
    ]
    return diagnosers.make("mmae", **params).fit(healthy + faulty)


def cmd_filter(a: argparse.Namespace) -> None:
    tr = TRACKS[a.track]
    data = TrackData(track=tr)
    seeds = _seeds(a.seeds)
    eps = [data.simulate([s], tr.fault_spec(f, s))[0].episode for f in tr.faults for s in seeds]
    eps += [le.episode for le in data.simulate(seeds, fcc_env.FaultSpec())]
    m = _fitted({"tracking_rate": a.rate, "fault_initial_std": a.initial})
    print("walks", dict(zip(m.classes_, m.walks_, strict=True)))
    out: dict[str, np.ndarray] = {}
    cpu = 0.0
    n = 0
    for i, ep in enumerate(eps):
        Ms, Ps = m.bank_.start()
        c0 = time.process_time()
        white, loglik = m.bank_.run(Ms, Ps, ep.y)
        cpu += time.process_time() - c0
        n += ep.n_samples
        out[f"loglik_{i}"] = loglik
        out[f"nis_{i}"] = np.sum(white * white, axis=2)
        out[f"res_{i}"] = white[:, 0, :]
        out[f"onset_{i}"] = np.array(-1 if ep.fault_onset is None else ep.fault_onset)
        out[f"scenario_{i}"] = np.array(ep.scenario)
    path = Path(a.cache) / f"{a.track}-{a.rate:g}-{a.initial:g}.npz"
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez(path, n=np.array(len(eps)), **out)
    print(f"{path}: {len(eps)} episodes, {n / cpu:,.0f} bank samples per CPU second")


def _grid(sets: list[str]) -> list[dict]:
    axes = {}
    for item in sets:
        k, _, v = item.partition("=")
        axes[k] = [int(x) if k == "window" else float(x) for x in v.split(",")]
    return [dict(zip(axes, combo, strict=True)) for combo in itertools.product(*axes.values())]


def cmd_score(a: argparse.Namespace) -> None:
    z = np.load(a.cache)
    n = int(z["n"])
    for params in _grid(a.set or []):
        m = _fitted(params)
        per: dict[str, dict[str, list[float]]] = {}
        brier_f, brier_h, fd = [], [], []
        for i in range(n):
            m.reset()
            det = m.decide(z[f"loglik_{i}"], z[f"nis_{i}"], z[f"res_{i}"])
            onset, sc = int(z[f"onset_{i}"]), str(z[f"scenario_{i}"])
            assert det.posterior is not None and det.diagnosis is not None
            if onset < 0:
                fd.append(r_fd(det.alarm, len(det.alarm)))
                brier_h.append(brier_samples(det.posterior, det.hypothesis_names, "nominal"))
                continue
            d = per.setdefault(sc, {"cdr": [], "t_dt": [], "t_it": []})
            d["cdr"].append(cdr(det.diagnosis, sc, onset))
            d["t_dt"].append(t_dt(det.alarm, onset))
            d["t_it"].append(t_it(det.diagnosis, sc, onset))
            brier_f.append(brier_samples(det.posterior, det.hypothesis_names, sc, onset))
        cells = []
        for sc, d in per.items():
            c, td, ti = (np.array(d[k]) for k in ("cdr", "t_dt", "t_it"))
            cells.append(
                f"{sc} CDR {np.nanmean(c):.3f} t_dt {np.nanmean(td):.0f} t_it {np.nanmean(ti):.0f}"
                f" ({int(np.isnan(ti).sum())} not)"
            )
        all_c = [np.nanmean(d["cdr"]) for d in per.values()]
        gap = [np.nanmean(d["t_it"]) - np.nanmean(d["t_dt"]) for d in per.values()]
        print(
            f"{params}: CDR {np.mean(all_c):.3f}, gap {np.mean(gap):.0f}, Brier faulty "
            f"{np.mean(np.concatenate(brier_f)):.4f} healthy {np.mean(np.concatenate(brier_h)):.4f}"
            f", r_fd {np.mean(fd):.4f}\n    " + " | ".join(cells)
        )
        sys.stdout.flush()


def main() -> None:
    p = argparse.ArgumentParser(description=(__doc__ or "").split("\n")[0])
    sub = p.add_subparsers(dest="cmd", required=True)
    f = sub.add_parser("filter")
    f.add_argument("--track", default="small")
    f.add_argument("--seeds", default="5000-5009")
    f.add_argument("--rate", type=float, default=0.05)
    f.add_argument("--initial", type=float, default=0.01)
    f.add_argument("--cache", default="/tmp/mmae")
    s = sub.add_parser("score")
    s.add_argument("--cache", required=True)
    s.add_argument("--set", action="append", help="name=v1,v2 (a decision hyperparameter)")
    a = p.parse_args()
    cmd_filter(a) if a.cmd == "filter" else cmd_score(a)


if __name__ == "__main__":
    main()
