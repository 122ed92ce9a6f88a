"""The posterior-driven supervisor (issue 42 item 7b): its return table and a short study.

``python lab/posterior_supervisor.py table --seeds 1000,1001 --out T.json``: ``R_h(sp)`` on
training seeds (``merge T1.json T2.json`` prints the averaged table of several runs, to paste
into ``evaluation.control.posterior_policy.RETURN_TABLE``).
``python lab/posterior_supervisor.py study --seeds 5000 --policies fixed,posterior --out S.json``:
the study's episodes (every scenario; the oracle always, last) on validation seeds, per episode
to JSON; ``summary S1.json S2.json ...`` pools chunks and prints the loss against the oracle,
overall and per scenario (the record: ``lab/posterior_supervisor.md``). ``--policies`` may name
``iso`` for the supervisor on ``lrgf-iso`` around ``lrgf-glr-closed`` (trained as the command
trains it); ``posterior:N:M:B``: trusted after N samples, margin M USD/h (default 20), margin B
back to the healthy set points (default: none); ``posterior:N:M:B:confidence=0.99/confirm_after=300``
adds the supervisor's other keywords;
``--mmae '{"tracking_rate": 0.01}'`` gives ``posterior:N``'s mmae hyperparameters.
"""

from __future__ import annotations

import json
import sys
import time
from typing import Any

import numpy as np

from evaluation.control import make_policy
from evaluation.control.posterior_policy import measure_return_table
from evaluation.control.returns import EpisodeScore, run_study, summarise
from evaluation.metrics.intervals import bootstrap_ci


def posterior_policy(spec: str, mmae: dict | None = None) -> Any:
    """``posterior:N:M:B:K=V/K=V``: trusted after N samples, margin M USD/h (default 20), home
    margin B (default: none), and any further keywords of ``posterior_supervisor`` (``confidence``,
    ``confirm_after``, ``confirmed_margin_usd_per_h``) as numbers or ``none`` (the rule before
    2026-12-07: ``posterior:1200:20:2:confidence=none/confirm_after=none``)."""
    parts = spec.split(":")
    extra = {}
    if len(parts) > 4 and parts[4]:
        for kv in parts[4].split("/"):
            key, value = kv.split("=")
            number = int if key == "confirm_after" else float
            extra[key] = None if value == "none" else number(value)
    return make_policy(
        "posterior",
        trust_after=int(parts[1]),
        params=mmae,
        margin_usd_per_h=float([*parts, "20"][2]),
        home_margin_usd_per_h=(float(parts[3]) if len(parts) > 3 and parts[3] else None),
        **extra,
    )


def paired(scores: list[EpisodeScore], scen: list[str]) -> None:
    """Per policy and scenario, its return minus the best fixed set points' on the same seed:
    the mean [95 % bootstrap over the seeds] and each seed's figure (USD per episode)."""
    fixed = {(s.scenario, s.seed): s.return_usd for s in scores if s.policy.startswith("best")}
    print("\npaired against the best fixed set points, USD per episode [95 %]: per seed")
    for name in dict.fromkeys(s.policy for s in scores):
        if name.startswith(("best", "oracle")):
            continue
        print(f"{name}:")
        for c in scen:
            d = [
                s.return_usd - fixed[(c, s.seed)]
                for s in sorted(scores, key=lambda s: s.seed)
                if s.policy == name and s.scenario == c and (c, s.seed) in fixed
            ]
            ci = bootstrap_ci(d)
            print(
                f"  {c}: {ci.estimate:+,.2f} [{ci.low:+,.2f}, {ci.high:+,.2f}] n={len(d)}: "
                + " ".join(f"{v:+.1f}" for v in d)
            )


def main(argv: list[str]) -> None:
    if argv[0] == "table":
        seeds = [int(s) for s in argv[argv.index("--seeds") + 1].split(",")]
        out = argv[argv.index("--out") + 1]
        t = time.process_time()
        table = measure_return_table(seeds=seeds)
        print(json.dumps(table, indent=1), f"\n{time.process_time() - t:.0f} s CPU")
        with open(out, "w") as f:
            json.dump(table, f)
    elif argv[0] == "study":
        seeds = [int(s) for s in argv[argv.index("--seeds") + 1].split(",")]
        names = argv[argv.index("--policies") + 1].split(",")
        out = argv[argv.index("--out") + 1]
        mmae = json.loads(argv[argv.index("--mmae") + 1]) if "--mmae" in argv else None
        t = time.process_time()
        policies = [
            make_policy("supervisor", name="lrgf-iso", params={"detector_name": "lrgf-glr-closed"})
            if n == "iso"
            else posterior_policy(n, mmae)
            if n.startswith("posterior:")
            else make_policy(n)
            for n in names
        ]
        policies.append(make_policy("oracle"))
        print(f"built in {time.process_time() - t:.0f} s CPU", flush=True)
        scores = run_study(policies, seeds, 3999, ["nominal", "f1", "f2", "f3", "f4"])
        with open(out, "w") as f:
            json.dump([s.__dict__ for s in scores], f)
        print(f"{len(scores)} episodes, {time.process_time() - t:.0f} s CPU")
    elif argv[0] == "summary":
        scores = [EpisodeScore(**d) for p in argv[1:] for d in json.load(open(p))]
        ref = next(s.policy for s in scores if s.policy.startswith("oracle"))
        for s in summarise(scores, ref):
            li = s.loss_vs_oracle_usd
            print(
                f"| {s.policy} | {s.n_episodes} | {s.return_usd.estimate:,.0f} | "
                f"{li.estimate:,.0f} [{li.low:,.0f}, {li.high:,.0f}] |"
            )
        print()
        scen = sorted({s.scenario for s in scores})
        print("| policy | " + " | ".join(scen) + " |")
        for name in dict.fromkeys(s.policy for s in scores):
            row = [
                np.mean([s.return_usd for s in scores if s.policy == name and s.scenario == c])
                for c in scen
            ]
            print(f"| {name} | " + " | ".join(f"{v:,.0f}" for v in row) + " |")
        paired(scores, scen)
    elif argv[0] == "merge":
        tables = [json.load(open(p)) for p in argv[1:]]
        merged = {
            h: {c: round(float(np.mean([t[h][c] for t in tables])), 1) for c in tables[0][h]}
            for h in tables[0]
        }
        print(json.dumps(merged, indent=4))


if __name__ == "__main__":
    main(sys.argv[1:])
