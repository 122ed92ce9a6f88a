"""Operating regimes (issue 42 item 6): false alarms on a wider set-point program than training.

Each detector is fitted on the ``closed`` track's training episodes (the training program, set
points T_rx ± 4 °C, T_rg1 ± 6 °C; the ``regimes`` track shares them) and run on healthy
*validation* episodes (seeds 5000+, never test seeds) under the training program (``closed``)
and under the ``regimes`` track's wider test program (± 8 °C, ± 12 °C). Per program it reports
r_fd (mean over episodes, 95 % BCa interval), the share of samples outside the training range
of the set points (:class:`diagnosers.stages.operating_range.OperatingRange`), the share of the
alarmed samples that range flags (the goal: ≥ 90 %), and r_fd with the flagged samples scored
as novel, not as false alarms (:func:`evaluation.metrics.detection_metrics.episode_scores`).

    PYTHONPATH=$PWD python lab/regimes_lab.py --n 60 --detectors limits,pca --hold 0,300

Contention-bound machine: CPU times, not wall times, are printed.
"""

from __future__ import annotations

import argparse
import json
import time

import diagnosers
from diagnosers.stages.operating_range import OperatingRange
from evaluation.metrics.detection_metrics import episode_scores
from evaluation.metrics.intervals import bootstrap_ci
from evaluation.tracks.catalogue import TRACKS
from evaluation.tracks.track_data import TrackData
from fcc_env.scenarios import FaultSpec


def _ci(values: list[float]) -> str:
    iv = bootstrap_ci(values)
    return f"{iv.estimate:.4f} [{iv.low:.4f}, {iv.high:.4f}]"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=60, help="healthy validation episodes per program")
    ap.add_argument("--detectors", default="limits,pca")
    ap.add_argument("--hold", default="0,300", help="OperatingRange hold values to try")
    ap.add_argument(
        "--fast",
        action="store_true",
        help="each detector at its fast_params() (small training; for a detector whose full "
        "training does not fit the time at hand), fault-learning ones on 3 fault seeds",
    )
    ap.add_argument(
        "--set",
        action="append",
        default=[],
        help="a hyperparameter of one detector, NAME.key=JSON (e.g. n4sid-glr-novelty.order=8)",
    )
    args = ap.parse_args()
    overrides: dict[str, dict[str, object]] = {}
    for item in args.set:
        key, value = item.split("=", 1)
        det_name, param = key.rsplit(".", 1)
        overrides.setdefault(det_name, {})[param] = json.loads(value)
    data = TrackData(track=TRACKS["regimes"])
    train = data.train_episodes()
    seeds = list(range(5000, 5000 + args.n))
    t0 = time.process_time()
    programs = {
        "closed (training program)": [le.episode for le in data.simulate(seeds, FaultSpec())],
        "regimes (wider program)": [
            le.episode for le in data.simulate(seeds, FaultSpec(), test=True)
        ],
    }
    print(f"simulated {2 * len(seeds)} episodes in {time.process_time() - t0:.1f} s CPU")
    holds = [int(h) for h in args.hold.split(",")]
    ranges = {h: OperatingRange(hold=h).fit(train) for h in holds}
    for name in args.detectors.split(","):
        t0 = time.process_time()
        cls = diagnosers.diagnoser_class(name)
        params = {**(cls.fast_params() if args.fast else {}), **overrides.get(name, {})}
        det = diagnosers.make(name, **params)
        faults = []
        if det.learns_from_faults or det.isolates:
            seeds_f = list(data.track.train_fault_seeds)[: 3 if args.fast else None]
            faults = data.train_fault_episodes(seeds_f)
        det.fit(train + faults)
        print(f"\n## {name} {params or ''} (fit {time.process_time() - t0:.1f} s CPU)")
        for prog, eps in programs.items():
            dets = [det.detect(ep) for ep in eps]
            r_fd = [episode_scores(d.alarm, None)["r_fd"] for d in dets]
            print(f"{prog}: r_fd {_ci(r_fd)}")
            if dets[0].novelty is not None:  # the detector's own flag
                own = [episode_scores(d.alarm, None, novelty=d.novelty) for d in dets]
                alarms = sum(int(d.alarm.sum()) for d in dets)
                covered = sum(int((d.alarm & d.novel).sum()) for d in dets)
                print(
                    f"  own novelty: novel share {_ci([s['novelty'] for s in own])}, alarms "
                    f"flagged novel {covered / max(alarms, 1):.3f} ({covered}/{alarms}), "
                    f"r_fd outside novelty {_ci([s['r_fd'] for s in own])}"
                )
                continue
            for h, rng in ranges.items():
                flags = [rng.flag(ep) for ep in eps]
                alarms = sum(int(d.alarm.sum()) for d in dets)
                covered = sum(int((d.alarm & f).sum()) for d, f in zip(dets, flags, strict=True))
                scored = [
                    episode_scores(d.alarm, None, novelty=f)
                    for d, f in zip(dets, flags, strict=True)
                ]
                share = covered / alarms if alarms else float("nan")
                print(
                    f"  hold {h}: novel share {_ci([s['novelty'] for s in scored])}, "
                    f"alarms flagged novel {share:.3f} ({covered}/{alarms}), "
                    f"r_fd outside novelty {_ci([s['r_fd'] for s in scored])}"
                )


if __name__ == "__main__":
    main()
