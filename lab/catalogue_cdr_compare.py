"""CDR per column on stored member outputs (``lab/catalogue_members.py``): the union
(``Composition``, recomputed) against each claiming member alone on the same episodes.

    PYTHONPATH=$PWD python lab/catalogue_cdr_compare.py /tmp/catalogue/final_sensor
"""

import glob
import sys
from collections import defaultdict

import numpy as np

from diagnosers.isolation.composition import Composition
from evaluation.metrics.isolation_metrics import cdr, episode_label

rows = defaultdict(lambda: defaultdict(list))
files = sorted(glob.glob(sys.argv[1] + "/*.npz"))
classes = tuple(sorted({str(np.load(p)["column"]) for p in files}))
for p in files:
    f = dict(np.load(p))
    col = str(f["column"])
    on = int(f["onsets"][0])
    claims = [tuple(str(c).split("|")) for c in f["claims"]]
    defers = [tuple(int(i) for i in str(d).split("|") if i) for d in f["defers"]]
    confirms = [int(c) or None for c in f["confirms"]]
    comp = Composition(
        claims,
        classes,
        confirm=30,
        hold=True,
        several=[bool(x) for x in f["several"]],
        defers=defers,
        confirms=confirms,
    )
    T = f["alarm"].shape[1]
    d = np.array(
        [
            comp.step([bool(a) for a in f["alarm"][:, k]], [str(n) for n in f["diagnosis"][:, k]])[
                1
            ]
            for k in range(T)
        ]
    )
    c = cdr(d, col, on)
    rows[col]["composite"].append(c)
    rows[col]["composite label ok"].append(float(episode_label(d, on) == col))
    rows[col]["composite final ok"].append(float(d[-1] == col))
    for m, diag in zip(f["member_names"], f["diagnosis"]):
        if col in str(f["claims"][list(f["member_names"]).index(m)]).split("|"):
            rows[col][f"{m} alone"].append(cdr(diag, col, on))
            rows[col][f"{m} alone label ok"].append(float(episode_label(diag, on) == col))
for col, r in rows.items():
    print(col, "; ".join(f"{k} {np.nanmean(v):.2f} (n={len(v)})" for k, v in r.items()))
