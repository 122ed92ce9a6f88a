"""The posterior-driven supervisor (issue 42 item 7b): its return table and a short study.

``python lab/posterior_supervisor.py table --seeds 1000,1001 --out T.json``: ``R_h(sp)`` on
training seeds (``merge T1.json T2.json`` prints the averaged table of several runs, to paste
into ``evaluation.control.posterior_policy.RETURN_TABLE``).
``python -m evaluation.control --policies fixed,posterior ...`` runs the study (the record:
``lab/posterior_supervisor.md``).
"""

from __future__ import annotations

import json
import sys
import time

import numpy as np

from evaluation.control.posterior_policy import measure_return_table


def main(argv: list[str]) -> None:
    if argv[0] == "table":
        seeds = [int(s) for s in argv[argv.index("--seeds") + 1].split(",")]
        out = argv[argv.index("--out") + 1]
        t = time.process_time()
        table = measure_return_table(seeds=seeds)
        print(json.dumps(table, indent=1), f"\n{time.process_time() - t:.0f} s CPU")
        with open(out, "w") as f:
            json.dump(table, f)
    elif argv[0] == "merge":
        tables = [json.load(open(p)) for p in argv[1:]]
        merged = {
            h: {c: round(float(np.mean([t[h][c] for t in tables])), 1) for c in tables[0][h]}
            for h in tables[0]
        }
        print(json.dumps(merged, indent=4))


if __name__ == "__main__":
    main(sys.argv[1:])
