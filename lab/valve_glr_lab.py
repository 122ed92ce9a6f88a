"""``valve-glr`` (a slide valve that stops following its command, from the riser's balance) on
the closed-loop plant: false alarms on healthy loops, the delay on the ``actuator`` track's
valve faults, and what it does on a drifting T_rx transmitter (issue 43, the stiction detector
within 2x the optimal row's delay).

Validation seeds only (never a test seed), 4000 samples, the closed-loop plant, trained on
``--train`` healthy training episodes (seeds 1000..). The faults are drawn as the tracks draw
their columns (``lab/stiction_detection.py``'s ``drawn``: size uniform in the column's range,
onset U(1000, 3000), from each seed's own generator): ``valve-stiction`` U(0.02, 0.3),
``valve-bias`` U(0.05, 0.2), ``valve-stuck`` U(0.5, 1), ``sensor-drift`` on T_rx U(0.5, 2)
°C/h. Healthy seeds ``--seed-start``.., faulty ``--seed-start + 1000``...

Each episode is run once; the alarm for each pair of limits of ``--limits`` (stuck GLR, bias
GLR) is the statistics against them, so a sweep costs no more runs (the alarm is exactly
``stuck > limit or bias > bias limit or held > hold limit``, as the detector's, but the held
step GLR starts where the detector's own ``bias_threshold`` is passed: sweep that with
``--set``). Per pair: r_fd over the healthy
episodes with its 95 % BCa interval and the episodes alarmed at least once (Wilson); per fault
column r_td, t_dt (samples of 10 s) with intervals and the misses; for the drift, the episodes
alarmed after the onset. Record in ``lab/stiction-detection.md``.

    PYTHONPATH=$PWD python lab/valve_glr_lab.py --seed-start 5000 --healthy 20 --faulty 10 \
        --limits 10,30 15,30 20,30
"""

from __future__ import annotations

import argparse
import math
import pickle
import time
from pathlib import Path

import numpy as np

import diagnosers
import fcc_env
from diagnosers import Episode
from evaluation.metrics.detection_metrics import r_fd, r_td, t_dt
from evaluation.metrics.intervals import bootstrap_ci

SAMPLES = 4000
COLUMNS = {  # the actuator track's valve columns and the sensor track's drift, on T_rx
    "valve-stiction": (0.02, 0.3, None),
    "valve-bias": (0.05, 0.2, None),
    "valve-stuck": (0.5, 1.0, None),
    "sensor-drift": (0.5, 2.0, "T_rx"),
}


def wilson(k: int, n: int, z: float = 1.96) -> str:
    """``k/n`` with its 95 % Wilson score interval."""
    if n == 0:
        return "0/0"
    p = k / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return f"{k}/{n} [{max(centre - half, 0.0):.3f}, {min(centre + half, 1.0):.3f}]"


def ci(values: list[float], fmt: str) -> str:
    iv = bootstrap_ci(values)
    if iv.n == 0:
        return "–"
    return f"{iv.estimate:{fmt}} [{iv.low:{fmt}}, {iv.high:{fmt}}]"


def drawn(scenario: str, seed: int) -> fcc_env.FaultSpec:
    """The fault of ``seed`` for a column (module docstring)."""
    low, high, channel = COLUMNS[scenario]
    rng = np.random.default_rng([seed, 43])
    kw = {"channel": channel} if channel else {}
    return fcc_env.FaultSpec(
        scenario=scenario,
        magnitude=float(rng.uniform(low, high)),
        onset=int(rng.integers(1000, 3001)),
        **kw,
    )


def episodes(seeds: list[int], scenario: str | None, cache: Path | None) -> list[Episode]:
    """The episodes of ``seeds`` (healthy when ``scenario`` is None), from ``cache`` if there."""
    path = None if cache is None else cache / f"{scenario or 'healthy'}-{seeds[0]}-{len(seeds)}.pkl"
    if path is not None and path.exists():
        with path.open("rb") as f:
            return pickle.load(f)
    plant = fcc_env.PlantConfig.build(regulatory=True)
    faults = None if scenario is None else [drawn(scenario, s) for s in seeds]
    out = Episode.from_batch(fcc_env.simulate_episodes(seeds, SAMPLES, fault=faults, plant=plant))
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        with path.open("wb") as f:
            pickle.dump(out, f)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--healthy", type=int, default=40)
    ap.add_argument("--faulty", type=int, default=10, help="episodes per fault column")
    ap.add_argument("--seed-start", type=int, default=6000)
    ap.add_argument("--train", type=int, default=4, help="healthy training episodes, 1000..")
    ap.add_argument("--columns", nargs="*", default=list(COLUMNS), choices=list(COLUMNS))
    ap.add_argument(
        "--limits", nargs="*", default=[], metavar="STUCK,BIAS", help="limit pairs to sweep"
    )
    ap.add_argument("--set", nargs="*", default=[], metavar="KEY=VALUE", help="a variant")
    ap.add_argument("--cache", type=Path, default=None, help="keep the simulated episodes here")
    args = ap.parse_args()
    if args.seed_start < 5000:
        raise SystemExit(f"--seed-start={args.seed_start}: use validation seeds (5000+)")
    params = {}
    for item in args.set:
        key, _, value = item.partition("=")
        try:
            params[key] = float(value) if "." in value else int(value)
        except ValueError:
            ap.error(f"--set {item!r}: allowed KEY=NUMBER")
    t0 = time.process_time()
    train = episodes(list(range(1000, 1000 + args.train)), None, args.cache)
    d = diagnosers.make("valve-glr", **params).fit(train)
    print(f"valve-glr {params or 'defaults'}: gain {d.gain_:.4f} °C per kg/s, σ {d.sigma_:.3f} °C")
    limits = [tuple(float(v) for v in p.split(",")) for p in args.limits] or [
        (float(d.threshold), float(d.bias_threshold))
    ]

    def alarms(det, lim):
        # the held step GLR (column 4) was taken from the detector's own bias limit
        held = det.signal[:, 4] > float(d.hold_threshold)
        return (det.signal[:, 0] > lim[0]) | (det.signal[:, 1] > lim[1]) | held

    t_sim = time.process_time()
    healthy = episodes(
        list(range(args.seed_start, args.seed_start + args.healthy)), None, args.cache
    )
    start = args.seed_start + 1000
    faulty = {
        c: episodes(list(range(start, start + args.faulty)), c, args.cache) for c in args.columns
    }
    t_sim = time.process_time() - t_sim
    t_det = time.process_time()
    h_det = [d.detect(ep) for ep in healthy]
    f_det = {c: [d.detect(ep) for ep in eps] for c, eps in faulty.items()}
    t_det = time.process_time() - t_det
    n_det = len(h_det) + sum(len(v) for v in f_det.values())
    for lim in limits:
        print(f"\n## limits stuck {lim[0]:g}, bias {lim[1]:g}")
        if h_det:
            rates = [
                r_fd(alarms(x, lim), ep.n_samples) for x, ep in zip(h_det, healthy, strict=True)
            ]
            k = sum(r > 0 for r in rates)
            print(
                f"healthy ({len(rates)}, seeds {args.seed_start}..): r_fd {ci(rates, '.4f')}; "
                f"episodes alarmed {wilson(k, len(rates))}"
            )
        for c, dets in f_det.items():
            rtd, tdt = [], []
            for x, ep in zip(dets, faulty[c], strict=True):
                a, onset = alarms(x, lim), int(ep.fault_onset)
                rtd.append(r_td(a, onset))
                tdt.append(t_dt(a, onset))
            missed = sum(math.isnan(v) for v in tdt)
            early = sum(
                bool(alarms(x, lim)[: int(ep.fault_onset)].any())
                for x, ep in zip(dets, faulty[c], strict=True)
            )
            print(
                f"{c} ({len(dets)}): r_td {ci(rtd, '.3f')}; t_dt {ci(tdt, '.0f')}; missed "
                f"{missed}/{len(dets)} (alarmed after the onset {wilson(len(dets) - missed, len(dets))}); "
                f"alarmed before the onset {early}; delays {sorted(v for v in tdt if not math.isnan(v))}"
            )
    print(
        f"\nCPU: simulation {t_sim:.0f} s, detection {t_det:.1f} s for {n_det} episodes "
        f"({t_det / max(n_det, 1):.2f} s each); total {time.process_time() - t0:.0f} s"
    )


if __name__ == "__main__":
    main()
