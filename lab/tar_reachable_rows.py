"""T_ar's detection bound on the ``sensor`` track: the reachable filter row against the
optimal CUSUM row and two detectors, on episodes whose fault channel is forced (issue 43).

The ``sensor`` track draws a sensor fault's channel uniformly among the eight measured ones;
here the track's drawn size, onset and profile of each ``--kinds`` episode are kept and its
channel is replaced by ``--channel`` on seeds ``--seed-start``.. (validation seeds, never a
test seed), and by ``--control`` on the ``--control-seeds`` seeds after them. Scored on each:

* ``optimal filter (exact model, measured channels)`` (:mod:`evaluation.tracks.filter_bound`):
  its signatures from the track's labelled training faults (channels drawn, as in the track),
  its limits on ``--calibration`` healthy validation episodes from ``--calibration-start``
  (the track's default is 100 from 5000);
* ``optimal CUSUM (known fault)`` (:mod:`evaluation.tracks.optimal`): its bank's signatures are
  the scored seed's faults, so on a forced seed they are the forced channel's; its limit on
  the same healthy episodes (the track's default is its 20 validation seeds);
* the detectors ``--diagnosers``, fitted as the sweep fits them (``--train`` healthy training
  episodes, ``--train-faults`` labelled training faults per kind).

With ``--healthy`` N, the N seeds after them healthy: each row's r_fd at these limits.
Prints per episode r_td and t_dt of every row, then per (channel, kind) the mean r_td (95 %
bootstrap interval), the mean t_dt of the detected episodes (95 % bootstrap) and the misses.
Record in ``lab/sensor-validation.md``.

    PYTHONPATH=$PWD python lab/tar_reachable_rows.py --faulty 10 --control-seeds 3 \\
        --healthy 10 --calibration 20 --calibration-start 5400
"""

from __future__ import annotations

import argparse
import dataclasses
import time
from collections import defaultdict

import numpy as np

import diagnosers
from diagnosers.episode.record import Episode
from evaluation.metrics.detection_metrics import r_fd, r_td, t_dt
from evaluation.metrics.intervals import bootstrap_ci
from evaluation.sweep.sources import LoadedEpisode
from evaluation.tracks.catalogue import TRACKS
from evaluation.tracks.oracle import OracleConfig, PhysicalLimit
from evaluation.tracks.track_data import TrackData
from fcc_env.faults import NOMINAL
from fcc_env.params import MEASUREMENT_NAMES


@dataclasses.dataclass(frozen=True, kw_only=True)
class ForcedChannelData(TrackData):
    """The track's episodes, the fault channel of the seeds in ``forced`` (seed, channel)
    replaced (every sensor kind of that seed, so an optimal row's bank holds the forced
    channel's signatures); every other seed, the training faults and the healthy episodes
    as the track draws them."""

    forced: tuple[tuple[int, str], ...] = ()

    def load_test(self, scenario: str, seed: int) -> LoadedEpisode:
        channel = dict(self.forced).get(seed)
        if channel is None or scenario == NOMINAL:
            return super().load_test(scenario, seed)
        spec = dataclasses.replace(self.track.fault_spec(scenario, seed), channel=channel)
        return self.simulate([seed], spec, test=True)[0]


def _mean_ci(values: list[float], fmt: str) -> str:
    v = [x for x in values if np.isfinite(x)]
    if not v:
        return "–"
    if len(v) < 2 or np.ptp(v) == 0:
        return f"{np.mean(v):{fmt}}"
    ci = bootstrap_ci(v)
    return f"{np.mean(v):{fmt}} [{ci.low:{fmt}}, {ci.high:{fmt}}]"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--channel", default="T_ar", choices=MEASUREMENT_NAMES)
    ap.add_argument("--control", default="T_rx", choices=MEASUREMENT_NAMES)
    ap.add_argument("--kinds", default="sensor-bias,sensor-drift")
    ap.add_argument("--seed-start", type=int, default=5100)
    ap.add_argument("--faulty", type=int, default=10, help="episodes per kind, --channel")
    ap.add_argument("--control-seeds", type=int, default=3, help="episodes per kind, --control")
    ap.add_argument("--healthy", type=int, default=0, help="healthy episodes scored for r_fd")
    ap.add_argument("--calibration", type=int, default=20)
    ap.add_argument("--calibration-start", type=int, default=5400)
    ap.add_argument("--diagnosers", default="ukf-glr,sensor-validation")
    ap.add_argument("--train", type=int, default=4)
    ap.add_argument("--train-faults", type=int, default=5)
    args = ap.parse_args()
    c0 = time.process_time()
    track = TRACKS["sensor"].replace(n_train=args.train, n_train_faults=args.train_faults)
    n_all = args.faulty + args.control_seeds
    calib = range(args.calibration_start, args.calibration_start + args.calibration)
    seeds = range(args.seed_start, args.seed_start + n_all)
    healthy = range(seeds.stop, seeds.stop + args.healthy)
    if set(calib) & set(seeds) | set(calib) & set(healthy):
        ap.error(
            f"--calibration-start {args.calibration_start} puts calibration seeds {calib.start}..{calib.stop - 1} among "
            f"the scored seeds {seeds.start}..{healthy.stop - 1}; allowed: a start outside them"
        )
    forced = tuple(
        (s, args.channel if i < args.faulty else args.control) for i, s in enumerate(seeds)
    )
    data = ForcedChannelData(track=track, forced=forced)
    rows: dict[str, object] = {}
    for cfg in (OracleConfig(inputs="measured", stage="filter"), OracleConfig(stage="cusum")):
        t0 = time.process_time()
        rows[cfg.label] = PhysicalLimit(data, cfg).fit(list(calib))
        print(f"fitted {cfg.label}: {time.process_time() - t0:.0f} s CPU", flush=True)
    for name in args.diagnosers.split(","):
        t0 = time.process_time()
        det = diagnosers.make(name)
        train: list[Episode] = data.train_episodes()
        if det.isolates or det.learns_from_faults:
            train = train + data.train_fault_episodes()
        rows[name] = det.fit(train)
        print(f"fitted {name}: {time.process_time() - t0:.0f} s CPU", flush=True)
    if args.healthy:
        fd: dict[str, list[float]] = defaultdict(list)
        for seed in healthy:
            ep = data.load_test(NOMINAL, seed).episode
            for label, row in rows.items():
                a = np.asarray(row.detect(ep).alarm)  # type: ignore[attr-defined]
                fd[label].append(r_fd(a, len(a)))
        print(f"r_fd over the healthy seeds {healthy.start}..{healthy.stop - 1}:")
        for label, v in fd.items():
            print(f"  {label}: {_mean_ci(v, '.4f')}, {sum(x > 0 for x in v)} alarmed", flush=True)
    kinds = args.kinds.split(",")
    res: dict[tuple[str, str, str], list[tuple[float, float]]] = defaultdict(list)
    print("| channel | kind | seed | size | onset | " + " | ".join(rows) + " |")
    print("|---|---|---|---|---|" + "---|" * len(rows))
    for kind in kinds:
        for seed, channel in forced:
            le = data.load_test(kind, seed)
            ep = le.episode
            onset = ep.fault_onset
            spec = track.fault_spec(kind, seed)
            if onset is None or onset >= ep.n_samples:
                print(f"| {channel} | {kind} | {seed} | ended before the onset |")
                continue
            cells = []
            for label, row in rows.items():
                a = np.asarray(row.detect(ep).alarm)  # type: ignore[attr-defined]
                v = (r_td(a, onset), t_dt(a, onset))
                res[(channel, kind, label)].append(v)
                cells.append(f"{v[0]:.3f} / {v[1]:.0f}")
            print(
                f"| {channel} | {kind} | {seed} | {spec.magnitude:.2f} | {onset} | "
                + " | ".join(cells)
                + " |",
                flush=True,
            )
    print("\n| channel | kind | row | episodes | r_td | t_dt (detected) | missed |")
    print("|---|---|---|---|---|---|---|")
    for (channel, kind, label), v in res.items():
        td = [x[0] for x in v]
        dt = [x[1] for x in v]
        missed = sum(not np.isfinite(x) for x in dt)
        print(
            f"| {channel} | {kind} | {label} | {len(v)} | {_mean_ci(td, '.3f')} | "
            f"{_mean_ci(dt, '.0f')} | {missed}/{len(v)} |"
        )
    print(f"\n{time.process_time() - c0:.0f} s CPU (this process)")


if __name__ == "__main__":
    main()
