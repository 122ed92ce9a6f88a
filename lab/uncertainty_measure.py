"""Measure the uncertain track's draws: terminations and RMS(drawn − nominal), noise-free.

python lab/uncertainty_measure.py [n_seeds] [group ...]   (group: all, kinetics, ...)
"""

import sys
import time

import numpy as np

import fcc_env
from fcc_env.uncertainty import PlantUncertainty

N = int(sys.argv[1]) if len(sys.argv) > 1 else 100
groups = sys.argv[2:] or ["all"]
seeds = list(range(N))
T = 4000
nom = fcc_env.simulate_episodes(seeds, T)
names = fcc_env.MEASUREMENT_NAMES
zero = PlantUncertainty.none()
for g in groups:
    if g == "all":
        unc = PlantUncertainty()
    elif "=" in g:
        unc = PlantUncertainty(**{k: float(v) for k, v in (a.split("=") for a in g.split(","))})
    elif g == "drift":
        unc = PlantUncertainty(kinetics=0, heat_loss=0, feed=0, valve=0, ambient_amplitude_C=0)
    elif g == "ambient":
        unc = PlantUncertainty(kinetics=0, heat_loss=0, feed=0, valve=0, feed_drift=0)
    else:
        kw = {k: 0 for k in ("kinetics", "heat_loss", "feed", "valve", "feed_drift")}
        kw["ambient_amplitude_C"] = 0
        kw[g] = getattr(PlantUncertainty(), g)
        unc = PlantUncertainty(**kw)
    t0 = time.time()
    r = fcc_env.simulate_episodes(seeds, T, plant_uncertainty=unc)
    dt = time.time() - t0
    d = r.y_clean - nom.y_clean
    rms = np.sqrt((d**2).mean(axis=1))  # (B, 8) per episode
    term = [
        (s, why, int(k))
        for s, why, k in zip(r.seeds, r.termination_reasons, r.terminated_at, strict=True)
        if why
    ]
    # steady offset vs varying part
    off = np.abs(d.mean(axis=1))
    print(f"== {g}: {N} seeds, {dt:.1f}s, terminated {len(term)} {term[:5]}")
    print(
        "   afterburn margin max(T_d1-T_rg1) over episodes: "
        f"{(r.states[:, :, 9] - r.states[:, :, 4]).max():.1f} °C; min W_sp {r.states[:, :, 8].min():.0f} kg; "
        f"min T_rg1 {r.states[:, :, 4].min():.1f}"
    )
    for i in range(3, 8):
        print(
            f"   {names[i]:6s} RMS median {np.median(rms[:, i]):5.2f}  p90 {np.percentile(rms[:, i], 90):5.2f}"
            f"  max {rms[:, i].max():5.2f} °C   |mean| median {np.median(off[:, i]):5.2f}"
            f"   (noise σ {fcc_env.MEASUREMENTS[i].noise_std})"
        )
