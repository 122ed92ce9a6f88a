"""Screening of relations over valves and flows for the Santander FCCU data (issue 31, item 6).

Only the healthy training file ``NOC_varyingFeedFlow`` is read: the first 7000 samples fit a
linear ARX relation (``arx-band``, run in simulation as the LRGF networks are), the last 3080
samples score it (``fit_percent`` of the free run, 100 = perfect, 0 = the mean). The fault files
and the healthy test file are not read, so the choice cannot be tuned on what is scored.

    python lab/santander_relations.py
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from diagnosers import Episode, make
from diagnosers.classical.arx_band import fit_percent

DATA = Path(__file__).resolve().parents[2] / "shared/data/fccu-santander-mlpse"
N_FIT = 7000

CANDIDATES: list[tuple[str, list[str]]] = [
    ("Tr", ["T2", "Treg", "Frgc"]),
    ("Tr", ["Frgc", "Treg", "T2", "F3"]),
    ("Tr", ["V2", "Treg", "T2", "F3"]),
    ("Frgc", ["V2"]),
    ("Frgc", ["V2", "Lsp"]),
    ("Fsc", ["V3"]),
    ("Fsc", ["V3", "Lsp"]),
    ("Treg", ["Frgc", "Tr", "Fair", "F3"]),
    ("Treg", ["V6", "Frgc", "F3"]),
    ("Fair", ["V6"]),
    ("Fair", ["V6", "V7"]),
    ("Fair", ["V6", "V7", "Tatm"]),
    ("F7", ["V6", "V7", "Tatm"]),
    ("ACAB", ["V6", "V7", "Tatm"]),
    ("P2", ["V6", "V7", "Tatm"]),
    ("T2", ["F5", "T1", "F3"]),
    ("T2", ["V1", "T1", "F3"]),
    ("T3", ["F5", "F3", "T1"]),
    ("F5", ["V1"]),
    ("Lsp", ["V2", "V3", "F3"]),
    ("Tcyc", ["Treg", "Fair", "F3"]),
    ("Cco_sg", ["Fair", "Frgc", "F3", "Treg"]),
    ("FHN", ["V10", "F3"]),
    ("FHN", ["V10", "F3", "T20"]),
    ("Tfra", ["V9", "FReflux", "F3"]),
    ("FReflux", ["V9", "F3"]),
    ("AWGC", ["V4", "F3"]),
]


def main() -> None:
    with (DATA / "columns.csv").open(newline="") as fh:
        names = [r["symbol"] for r in csv.DictReader(fh)]
    data = np.loadtxt(DATA / "NOC_varyingFeedFlow_outputs.csv", delimiter=",")

    def episode(rows: slice) -> Episode:
        return Episode(data[rows, 1:], tuple(names[1:]), 60.0, None, "noc")

    fit, held = episode(slice(0, N_FIT)), episode(slice(N_FIT, None))
    print(f"{'output':8s} {'inputs':28s} {'fit% train':>10s} {'fit% held-out':>13s}")
    for output, inputs in CANDIDATES:
        for na in (2, 1, 0):  # the first stable model (a relation is only screened here)
            try:
                det = make("arx-band", output=output, inputs=inputs, na=na, nb=10).fit([fit])
            except ValueError:
                continue
            break
        else:
            print(f"{output:8s} {','.join(inputs):28s} no stable ARX model")
            continue
        d = det.detect(held)
        y = held.y[:, held.channels.index(output)]
        r = d.residual[:, 0]
        n0 = det.n_warmup_
        print(
            f"{output:8s} {','.join(inputs):28s} {det.train_fit_percent_:10.1f} "
            f"{fit_percent(y[n0:], (y - r)[n0:]):13.1f}  na={na}"
        )


if __name__ == "__main__":
    main()
