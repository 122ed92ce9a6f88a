"""Per-field sensitivity: RMS(perturbed − nominal) on the 5 temperatures, ± a relative step.

python lab/field_sensitivity.py FIELD=h [FIELD=h ...]
"""

import sys

import numpy as np

import fcc_env
from fcc_env import FCCParams

seeds = list(range(20))
nom = fcc_env.simulate_episodes(seeds, 4000)
print("nominal max(T_d1-T_rg1):", (nom.states[:, :, 9] - nom.states[:, :, 4]).max().round(1))
for arg in sys.argv[1:]:
    f, h = arg.split("=")
    h = float(h)
    for sgn in (+1, -1):
        p = FCCParams().replace(**{f: getattr(FCCParams(), f) * (1 + sgn * h)})
        r = fcc_env.simulate_episodes(seeds, 4000, plant=fcc_env.PlantConfig.build(params=p))
        d = r.y_clean - nom.y_clean
        rms = np.sqrt((d[:, :, 3:8] ** 2).mean(axis=1)).mean(axis=0)
        nt = sum(1 for x in r.termination_reasons if x)
        ab = (r.states[:, :, 9] - r.states[:, :, 4]).max()
        print(
            f"{f:8s} {sgn * h:+.3f}: RMS T_rx..T_dg {np.round(rms, 2)}  term {nt}  max afterburn {ab:.1f}"
        )
