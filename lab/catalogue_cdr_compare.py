"""CDR per column on stored member outputs (``lab/catalogue_members.py``): the union
(``Composition``, recomputed) against each claiming member alone on the same episodes.

    PYTHONPATH=$PWD python lab/catalogue_cdr_compare.py /tmp/catalogue/final_sensor
"""

from __future__ import annotations

import argparse
from collections import defaultdict
from pathlib import Path

import numpy as np

from diagnosers.isolation.composition import Composition
from evaluation.metrics.isolation_metrics import cdr, episode_label


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("store", type=Path)
    ap.add_argument("--confirm", type=int, default=30)
    args = ap.parse_args()
    files = sorted(args.store.glob("*.npz"))
    loaded = [dict(np.load(p)) for p in files]
    loaded = [f for f in loaded if str(f["column"]) != "nominal"]
    classes = tuple(sorted({str(f["column"]) for f in loaded}))
    rows: dict[str, dict[str, list[float]]] = defaultdict(lambda: defaultdict(list))
    for f in loaded:
        col, on = str(f["column"]), int(f["onsets"][0])
        claims = [tuple(str(c).split("|")) for c in f["claims"]]
        comp = Composition(
            claims,
            classes,
            confirm=args.confirm,
            hold=True,
            several=[bool(x) for x in f["several"]],
            defers=[tuple(int(i) for i in str(d).split("|") if i) for d in f["defers"]],
            confirms=[int(c) or None for c in f["confirms"]],
        )
        alarm, names = f["alarm"], f["diagnosis"]
        d = np.array(
            [
                comp.step([bool(a) for a in alarm[:, k]], [str(n) for n in names[:, k]])[1]
                for k in range(alarm.shape[1])
            ]
        )
        r = rows[col]
        r["union CDR"].append(cdr(d, col, on))
        r["union label right"].append(float(episode_label(d, on) == col))
        for m, diag, own in zip(f["member_names"], names, claims, strict=True):
            if col in own:
                r[f"{m} alone CDR"].append(cdr(diag, col, on))
                r[f"{m} alone label right"].append(float(episode_label(diag, on) == col))
    for col, r in rows.items():
        print(col, "; ".join(f"{k} {np.nanmean(v):.2f} (n={len(v)})" for k, v in r.items()))


if __name__ == "__main__":
    main()
