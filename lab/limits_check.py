"""Check proposed per-fault maximum magnitudes on 100 seeds (nominal plant) and 40 drawn plants.

Counts, per criterion, episodes that leave the envelope at or after the fault onset (a healthy
trip before the onset is reported apart). 'abs' = max(T_d1, T_dg) > 790 °C instead of gap > 80.
"""

import numpy as np

import fcc_env
from fcc_env.uncertainty import PlantUncertainty


def crit(r):
    X = r.states
    on = r.fault_onsets[0] or 0
    gap = X[:, :, 9] - X[:, :, 4]
    td = np.maximum(X[:, :, 9], X[:, :, 10])
    common = (X[:, :, 8] < 3000) | (X[:, :, 4] < 600) | ~np.isfinite(X).all(2)
    out = {}
    for name, bad in (("gap80", common | (gap > 80)), ("abs790", common | (td > 790))):
        pre = int(bad[:, :on].any(1).sum())
        post = int((~bad[:, :on].any(1) & bad[:, on:].any(1)).sum())
        out[name] = (pre, post)
    return out, float(X[:, on:, 8].min()), float(td.max())


for sc, m in (
    ("f1", 0.13),
    ("f2", 0.35),
    ("f2", 0.5),
    ("f3", 0.03),
    ("f3", 0.08),
    ("f3", 0.1),
    ("f4", 0.7),
):
    a = fcc_env.simulate_episodes(
        range(100), 4000, fault=fcc_env.FaultSpec(scenario=sc, magnitude=m)
    )
    b = fcc_env.simulate_episodes(
        range(40),
        4000,
        fault=fcc_env.FaultSpec(scenario=sc, magnitude=m),
        plant_uncertainty=PlantUncertainty(),
    )
    ca, wa, ta = crit(a)
    cb, wb, tb = crit(b)
    print(
        f"{sc} m={m}: nominal plant 100 seeds (pre-onset, post-onset trips) {ca} min W_sp {wa:.0f} "
        f"max T_d {ta:.0f} | drawn plants 40 seeds {cb} min W_sp {wb:.0f} max T_d {tb:.0f}"
    )
