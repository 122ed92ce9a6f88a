"""How much a drifting T_ar transmitter tells from its own reading (issue 43, the sensor-drift
delay): an information limit of the model, or a gap of the method?

A T_ar fault changes no other measurement (no loop reads T_ar, and the air temperature moves
the regenerator too little: ``lab/sensor-validation.md``), so what the model-based bank cannot
see is not in the other seven sensors. The plant's air temperature is an exogenous input held
between programmed steps (``fcc_env.excitation``: levels uniform in ±10 °C, held 20-200
samples; the state estimator's input model is a walk with a step gate, the same belief), so a
reading that ramps while its level is held is the transmitter's, not the air's. This script
measures that information with the plainest test of it: over the latest ``--window`` samples,
one slope common to every held stretch (stretches split where the reading's 5-sample means either side differ by more than
``--step`` °C), its t statistic with the channel's noise std (0.3 °C, Table 1), alarmed while
``|t|`` passes the limit. The limit is set on healthy validation episodes (``--tune-seeds``)
at the largest healthy ``|t|`` × ``--margin``; healthy ``--seed-start``.. and T_ar drifts of
``--seed-start + 1000``.. (rate U(0.5, 2) °C/h, onset U(1000, 3000), the track's column) are
then scored with it. Not a detector of the project (it reads one channel); a measurement.

    PYTHONPATH=$PWD python lab/tar_drift_information.py --seed-start 6400 --healthy 40 \\
        --faulty 20
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

import fcc_env
from diagnosers import Episode
from evaluation.metrics.detection_metrics import r_fd, r_td, t_dt
from evaluation.metrics.intervals import bootstrap_ci

SAMPLES = 4000
NOISE_C = 0.3  # T_ar's noise std, °C (fcc_env.params, Table 1)


def slope_t(y: np.ndarray, window: int, step: float, every: int = 5) -> np.ndarray:
    """Per sample, the t statistic of one slope common to the held stretches of the latest
    ``window`` samples of ``y`` (module docstring), evaluated every ``every`` samples and held
    in between; 0 before a full window."""
    out = np.zeros(y.shape[0])
    # a stretch starts where the means of the 5 samples after and before differ by > step
    # (a 5-sample look-ahead, 50 s: it catches the program's small steps, which a slope
    # common to the stretches reads as a ramp)
    c = np.r_[0.0, np.cumsum(y)]
    k = np.arange(y.shape[0])
    ahead = (c[np.minimum(k + 5, y.shape[0])] - c[k]) / np.maximum(np.minimum(5, y.shape[0] - k), 1)
    behind = (c[k] - c[np.maximum(k - 5, 0)]) / np.maximum(np.minimum(5, k), 1)
    breaks = np.abs(ahead - behind) > step
    breaks[0] = True
    last = 0.0
    for t in range(y.shape[0]):
        if t + 1 >= window and (t + 1 - window) % every == 0:
            seg = np.cumsum(breaks[t + 1 - window : t + 1])
            seg[0] = max(seg[0], 1)
            tau = np.arange(window, dtype=np.float64)
            w = y[t + 1 - window : t + 1]
            counts = np.bincount(seg)
            keep = counts[seg] >= 3  # a stretch of one or two samples carries no slope
            mt = np.bincount(seg, tau) / np.maximum(counts, 1)
            my = np.bincount(seg, w) / np.maximum(counts, 1)
            dt, dy = (tau - mt[seg])[keep], (w - my[seg])[keep]
            sxx = float(dt @ dt)
            last = float(dt @ dy) / sxx / (NOISE_C / math.sqrt(sxx)) if sxx > 0 else 0.0
        out[t] = last
    return out


def tar(seeds: list[int], drift: bool) -> list[tuple[np.ndarray, int | None]]:
    """T_ar readings of closed-loop episodes (healthy, or a drift drawn as the track draws)."""
    plant = fcc_env.PlantConfig.build(regulatory=True)
    faults = None
    if drift:
        faults = []
        for s in seeds:
            rng = np.random.default_rng([s, 43])
            faults.append(
                fcc_env.FaultSpec(
                    scenario="sensor-drift",
                    magnitude=float(rng.uniform(0.5, 2.0)),
                    onset=int(rng.integers(1000, 3001)),
                    channel="T_ar",
                )
            )
    eps = Episode.from_batch(fcc_env.simulate_episodes(seeds, SAMPLES, fault=faults, plant=plant))
    i = list(eps[0].channels).index("T_ar")
    return [
        (np.asarray(ep.y, dtype=np.float64)[:, i], None if not drift else int(ep.fault_onset))
        for ep in eps
    ]


def ci(values: list[float], fmt: str) -> str:
    iv = bootstrap_ci(values)
    return "–" if iv.n == 0 else f"{iv.estimate:{fmt}} [{iv.low:{fmt}}, {iv.high:{fmt}}]"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed-start", type=int, default=6400)
    ap.add_argument("--tune-seeds", type=int, default=5000)
    ap.add_argument("--tune", type=int, default=20, help="healthy episodes that set the limit")
    ap.add_argument("--healthy", type=int, default=40)
    ap.add_argument("--faulty", type=int, default=20)
    ap.add_argument("--window", type=int, default=600)
    ap.add_argument("--step", type=float, default=0.6)
    ap.add_argument("--margin", type=float, default=1.2)
    args = ap.parse_args()
    if min(args.seed_start, args.tune_seeds) < 5000:
        raise SystemExit("use validation seeds (5000+)")
    c0 = time.process_time()
    tune = [
        slope_t(y, args.window, args.step)
        for y, _ in tar(list(range(args.tune_seeds, args.tune_seeds + args.tune)), False)
    ]
    limit = args.margin * max(float(np.abs(t).max()) for t in tune)
    print(
        f"window {args.window}, step {args.step} °C: healthy |t| max over {args.tune} tuning "
        f"episodes {limit / args.margin:.2f}; limit {limit:.2f}"
    )
    healthy = tar(list(range(args.seed_start, args.seed_start + args.healthy)), False)
    rates = [r_fd(np.abs(slope_t(y, args.window, args.step)) > limit, SAMPLES) for y, _ in healthy]
    print(
        f"healthy ({len(rates)}, seeds {args.seed_start}..): r_fd {ci(rates, '.4f')}; "
        f"episodes alarmed {sum(r > 0 for r in rates)}/{len(rates)}"
    )
    start = args.seed_start + 1000
    rtd, tdt = [], []
    for y, onset in tar(list(range(start, start + args.faulty)), True):
        a = np.abs(slope_t(y, args.window, args.step)) > limit
        rtd.append(r_td(a, onset))
        tdt.append(t_dt(a, onset))
    missed = sum(math.isnan(v) for v in tdt)
    print(
        f"T_ar drift ({args.faulty}, seeds {start}..): r_td {ci(rtd, '.3f')}; t_dt "
        f"{ci(tdt, '.0f')}; missed {missed}; delays {sorted(v for v in tdt if not math.isnan(v))}"
    )
    print(f"CPU {time.process_time() - c0:.0f} s")


if __name__ == "__main__":
    main()
