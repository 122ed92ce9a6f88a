"""Can a feed-coking rise be told from the closed-loop program's own drift? (issue 42; record:
``lab/discover_drift.md``, 2026-12-07).

``feed_coking_drift`` multiplies the feed coking factor by (1 + rise·t); the default closed-loop
program drifts the same factor (APRBS levels in 1 ± 3 %, held 200-600 samples, through a
150-sample lag) and no instrument reads it. Over one record the program's drift has a straight
line of its own, and a rise adds to that line. This script draws the program's true coking
factor (the plant's own set-point stream, no simulation: ``fcc_env.regulatory.SetpointStream``
with each seed's generators) on many training seeds and measures the per-record least-squares
trend (1/day) it has without any effect: the spread a rise has to stand out from, even for an
observer who knew f_coke exactly.

Printed: the trend's mean, standard deviation and quantiles; the threshold that keeps a
given share of clean records from being named (false-alarm rate); and the share of records
with a hidden rise of ``--rise`` per day whose trend crosses that threshold (the best naming
rate of a rule that reads the trend, the loop's joint fit included).

    PYTHONPATH=. python lab/drift_trend_limit.py [--seeds 1000:3000] [--samples 4000]
        [--rise 0.05] [--check]   # --check: the stream against a simulated record's f_coke
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import fcc_env
from fcc_env.excitation import episode_generators
from fcc_env.regulatory import SetpointStream

SECONDS_PER_DAY = 86_400.0


def program_f_coke(seed: int, n: int) -> np.ndarray:
    """The default program's coking factor of ``seed``'s closed-loop episode (n,)."""
    plant = fcc_env.PlantConfig.build(regulatory=True)
    gens = episode_generators(np.random.default_rng(seed), closed_loop=True)
    stream = SetpointStream(plant.regulatory.program, np.zeros(2), gens["setpoints"])
    return stream.take(n)[1]


def trend_per_day(f: np.ndarray, sample_time_s: float) -> np.ndarray:
    """Least-squares slope (1/day) of each row of ``f`` (R, n) against time."""
    t = np.arange(f.shape[-1]) * sample_time_s / SECONDS_PER_DAY
    tc = t - t.mean()
    return (f - f.mean(axis=-1, keepdims=True)) @ tc / float(tc @ tc)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="1000:3000", help="training seeds, start:stop")
    ap.add_argument("--samples", type=int, default=4000)
    ap.add_argument("--rise", type=float, default=0.05, help="hidden rise, 1/day")
    ap.add_argument("--check", action="store_true")
    args = ap.parse_args()
    lo, hi = (int(x) for x in args.seeds.split(":"))
    dt = fcc_env.PlantConfig().sample_time_s
    t0 = time.process_time()
    if args.check:  # the stream is the plant's: compare with a simulated record's truth
        plant = fcc_env.PlantConfig.build(regulatory=True)
        batch = fcc_env.simulate_episodes([lo], 500, plant=plant)
        truth = batch.inputs[0, :, fcc_env.INPUT_NAMES.index("f_coke")]
        print(
            f"seed {lo}: max |stream - simulated f_coke| = "
            f"{np.max(np.abs(program_f_coke(lo, 500) - truth)):.2e}"
        )
    F = np.stack([program_f_coke(s, args.samples) for s in range(lo, hi)])
    t_day = np.arange(args.samples) * dt / SECONDS_PER_DAY
    b0 = trend_per_day(F, dt)
    b1 = trend_per_day(F * (1.0 + args.rise * t_day), dt)
    q = np.quantile(b0, [0.005, 0.025, 0.5, 0.975, 0.995])
    print(
        f"{hi - lo} seeds {lo}-{hi - 1}, {args.samples} samples of {dt:g} s "
        f"({args.samples * dt / 3600:.1f} h): program trend mean {b0.mean():+.4f}/day, "
        f"std {b0.std():.4f}/day; quantiles 0.5/2.5/50/97.5/99.5 %: "
        + " ".join(f"{v:+.4f}" for v in q)
    )
    print(f"a rise of {args.rise}/day adds {args.rise * t_day[-1]:.4f} over the record")
    for fa in (0.01, 0.05):
        thr = float(np.quantile(np.abs(b0), 1.0 - fa))
        power = float(np.mean(b1 > thr))
        k = int(np.sum(b1 > thr))
        half = 1.96 * np.sqrt(power * (1 - power) / b1.size)
        print(
            f"false alarms {fa:.0%} of clean records (|trend| > {thr:.4f}/day): a rise of "
            f"{args.rise}/day crosses it on {k} of {b1.size} ({power:.1%} ± {half:.1%})"
        )
    print(f"CPU {time.process_time() - t0:.1f} s")


if __name__ == "__main__":
    main()
