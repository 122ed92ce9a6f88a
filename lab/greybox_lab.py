"""Lab script of the grey-box tier (issue 42 item 3): ``ukf-glr`` against the reachable bound.

    python lab/greybox_lab.py compare --track paper --healthy 40 --faulty 10 --seed-start 6000
    python lab/greybox_lab.py fit --track paper
    python lab/greybox_lab.py fit --shifted --records 3 [--method ml]

``compare``: ``ukf-glr`` (fitted on the track's training episodes, as the harness fits it) and
the reference row ``optimal filter (exact model, measured channels)`` (calibrated on the
track's validation seeds 5000-5099) scored on fresh seeds from ``--seed-start`` (neither test,
training nor calibration seeds); prints r_fd and per fault r_td and t_dt with 95 % intervals
and t_dt's ratio to the bound. ``fit``: the fitted values, noise scale and online decision, and
the CPU time of each fit method. Records in ``lab/greybox-lab.md``.
"""

from __future__ import annotations

import argparse
import json
import time
from typing import Any

import numpy as np

import diagnosers
import fcc_env
from diagnosers.filters import FCCStateEstimator, UKFConfig
from diagnosers.filters.parameter_fit import (
    estimate_noise_scale,
    fit_augmented,
    fit_maximum_likelihood,
)
from evaluation.sweep.records import score_episode
from evaluation.tracks import TRACKS
from evaluation.tracks.filter_bound import FILTER_LABEL
from evaluation.tracks.oracle import OracleConfig, reference_records
from evaluation.tracks.rows import track_rows
from evaluation.tracks.track_data import TrackData
from fcc_env.params import FCCParams


def _cell(i: Any, digits: int = 1) -> str:
    return f"{i.estimate:.{digits}f} [{i.low:.{digits}f}, {i.high:.{digits}f}]"


def compare(args: argparse.Namespace) -> None:
    track = TRACKS[args.track].replace(n_healthy=args.healthy, n_faulty=args.faulty)
    data = TrackData(track=track.with_seeds(test=args.seed_start))
    params = dict(p.split("=", 1) for p in args.set)
    det = diagnosers.make("ukf-glr", **{k: json.loads(v) for k, v in params.items()})
    t0 = time.process_time()
    det.fit(data.train_episodes())
    fit_s = time.process_time() - t0
    print(f"ukf-glr fit: {fit_s:.1f} s CPU; noise {det.noise_scale_:.3f}, online {det.online_}")
    t0 = time.process_time()
    records = [score_episode(det, data.load_test(sc, s)) for sc, s in data.cells()]
    print(f"ukf-glr scoring: {time.process_time() - t0:.1f} s CPU")
    if not args.skip_bound:
        t0 = time.process_time()
        records += reference_records(data, [OracleConfig(inputs="measured", stage="filter")])
        print(f"bound fit + scoring: {time.process_time() - t0:.1f} s CPU")
    rows = track_rows(records, ["ukf-glr"], track.faults)
    print(f"\n{args.track}, seeds {args.seed_start}+ ({args.healthy} healthy, {args.faulty}/fault)")
    print("| row | r_fd [95 %] | " + " | ".join(f"{f} t_dt (r_td)" for f in track.faults) + " |")
    print("|---|---|" + "---|" * len(track.faults))
    for row in rows:
        label = "ukf-glr" if row.label == "ukf-glr" else FILTER_LABEL
        cells = [
            f"{_cell(c.t_dt)} ({_cell(c.r_td, 2)}; /bound {c.ratio_filter.estimate:.2f})"
            for c in row.faults.values()
        ]
        print(f"| {label} | {_cell(row.r_fd, 4)} | " + " | ".join(cells) + " |")


#: ``fit --shifted``: a plant unlike the nominal one in the three identifiable parameters
SHIFT = {"UA_2": 1.06, "UA_dg": 0.93, "UA_d1": 1.05}


def fit(args: argparse.Namespace) -> None:
    prior = FCCParams()
    if args.shifted:
        true = prior.replace(**{n: getattr(prior, n) * m for n, m in SHIFT.items()})
        print("true", {n: round(getattr(true, n), 4) for n in SHIFT})
        obs = fcc_env.simulate_episodes(
            list(range(1000, 1000 + args.records)), 4000, plant=fcc_env.PlantConfig(params=true)
        ).observations
        records = [np.asarray(y, dtype=np.float64) for y in obs]
    else:
        data = TrackData(track=TRACKS[args.track])
        records = [np.asarray(ep.y, dtype=np.float64) for ep in data.train_episodes()]
    config = UKFConfig()
    names = ("UA_2", "UA_dg", "UA_d1")
    t0 = time.process_time()
    scale = estimate_noise_scale(prior, config, records)
    print(f"noise scale {scale:.4f} ({time.process_time() - t0:.1f} s CPU)")
    config = config.replace(noise_scale=scale)
    t0 = time.process_time()
    if args.method == "augmented":
        out = fit_augmented(prior, config, records, names)
        print("record values\n", out.record_values.round(4), "\nstd\n", out.record_std.round(4))
        print("homogeneity p", out.homogeneity_p, "varies", out.varies)
    else:
        out = fit_maximum_likelihood(prior, config, records, names)
    print(
        f"{args.method}: {dict(zip(names, out.values.round(4), strict=True))} "
        f"({time.process_time() - t0:.1f} s CPU)"
    )
    est = FCCStateEstimator(out.params, config)
    nis = np.mean(est.filter(np.stack(records), innovation_cov=False).nis[:, 100:])
    print(f"NIS on the fitted model {nis:.3f}")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__)
    sub = p.add_subparsers(dest="cmd", required=True)
    c = sub.add_parser("compare")
    c.add_argument("--track", default="paper")
    c.add_argument("--healthy", type=int, default=40)
    c.add_argument("--faulty", type=int, default=10)
    c.add_argument("--seed-start", type=int, default=6000)
    c.add_argument("--set", action="append", default=[], help="ukf-glr hyperparameter k=v")
    c.add_argument("--skip-bound", action="store_true", help="ukf-glr alone (no bound row)")
    f = sub.add_parser("fit")
    f.add_argument("--track", default="paper")
    f.add_argument("--method", choices=("augmented", "ml"), default="augmented")
    f.add_argument("--records", type=int, default=9)
    f.add_argument("--shifted", action="store_true", help="records of a plant with SHIFT")
    args = p.parse_args()
    compare(args) if args.cmd == "compare" else fit(args)


if __name__ == "__main__":
    main()
