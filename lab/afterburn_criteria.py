"""Post-hoc envelope criteria for the afterburn: gap > 80 °C (today) vs absolute T_d1/T_dg.

States after a termination are the true continuation (the batch simulator does not stop), so
other criteria can be evaluated on the same runs.
"""

import numpy as np

import fcc_env

seeds = list(range(20))
for sc, mags in (
    ("nominal", [None]),
    ("f2", [0.3, 0.4, 0.5, 0.6, 0.65, 0.7]),
    ("f3", [0.03, 0.05, 0.1, 0.15, 0.2, 0.25, 0.3, 0.4, 0.5, 0.7, 0.9]),
):
    for m in mags:
        r = fcc_env.simulate_episodes(
            seeds, 4000, fault=fcc_env.FaultSpec(scenario=sc, magnitude=m)
        )
        X = r.states
        gap = X[:, :, 9] - X[:, :, 4]
        td = np.maximum(X[:, :, 9], X[:, :, 10])
        n_gap = int((gap.max(1) > 80).sum())
        n_abs = int((td.max(1) > 790).sum())
        n_well = int((X[:, :, 8].min(1) < 3000).sum())
        n_ext = int((X[:, :, 4].min(1) < 600).sum())
        print(
            f"{sc} m={m}: gap>80 {n_gap}/20, max(T_d1,T_dg)>790 {n_abs}/20 (max {td.max():.0f} °C),"
            f" well<3t {n_well}/20, T_rg1<600 {n_ext}/20 (min {X[:, :, 4].min():.0f}); "
            f"max gap {gap.max():.0f}"
        )
