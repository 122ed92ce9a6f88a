"""Afterburn margin: healthy gap distribution, and what an f3 afterburn looks like (runaway?)."""

import numpy as np

import fcc_env

seeds = list(range(100))
h = fcc_env.simulate_episodes(seeds, 4000)
gap = h.states[:, :, 9] - h.states[:, :, 4]
print(
    "healthy 100 seeds: terminated",
    sum(1 for x in h.termination_reasons if x),
    f" max gap per episode: median {np.median(gap.max(1)):.1f} p90 {np.percentile(gap.max(1), 90):.1f} max {gap.max():.1f}; nominal steady gap {gap[:, 0].mean():.1f}",
)
ex = fcc_env.simulate_episodes([0], 4000, plant=fcc_env.PlantConfig.build(excitation=False))
for sc, m in (
    ("f3", 0.03),
    ("f3", 0.05),
    ("f3", 0.1),
    ("f3", 0.2),
    ("f2", 0.35),
    ("f1", 0.13),
    ("f4", 0.7),
):
    r = fcc_env.simulate_episodes(seeds, 4000, fault=fcc_env.FaultSpec(scenario=sc, magnitude=m))
    g = r.states[:, :, 9] - r.states[:, :, 4]
    bad = [i for i, x in enumerate(r.termination_reasons) if x]
    ne = fcc_env.simulate_episodes(
        [0],
        4000,
        fault=fcc_env.FaultSpec(scenario=sc, magnitude=m),
        plant=fcc_env.PlantConfig.build(excitation=False),
    )
    gne = (ne.states[:, :, 9] - ne.states[:, :, 4]).max()
    print(
        f"{sc} m={m}: 100 seeds terminated {len(bad)} {sorted(set(r.termination_reasons[i] for i in bad))};"
        f" max gap median {np.median(g.max(1)):.1f} max {g.max():.1f}; min W_sp {r.states[:, :, 8].min():.0f};"
        f" no excitation: max gap {gne:.1f} min W_sp {ne.states[0, :, 8].min():.0f} term {ne.termination_reasons[0]}"
    )
    if bad and sc == "f3":
        b = bad[0]
        k = r.terminated_at[b]
        print(
            "   seed",
            seeds[b],
            "gap around termination:",
            np.round(g[b, k - 30 : k + 300 : 30], 1),
            "R_ar",
            np.round(r.inputs[b, k - 30 : k + 1 : 10, 1], 1),
        )
