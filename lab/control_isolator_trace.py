"""Why the isolator-driven supervisor loses money on f1 (issue 35): its diagnoses over time.

Trains the supervisor on ``lrgf-iso`` around ``lrgf-glr-closed`` as ``python -m
evaluation.control`` does (training seeds 1000..), then runs it on f1 (and the other faults)
on VALIDATION seeds 5000.. and prints, per episode, each change of the diagnosis the
supervisor reads and of the set points it targets, with the sample and the fault's onset.

    PYTHONPATH=. python lab/control_isolator_trace.py [--seeds 5] [--faults f1,f2,f3,f4]
"""

from __future__ import annotations

import argparse

from evaluation.control.returns import run_episode, supervisor


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--faults", default="f1,f2,f3,f4")
    args = ap.parse_args()
    sup = supervisor("lrgf-iso", params={"detector_name": "lrgf-glr-closed"})
    for fault in args.faults.split(","):
        for seed in range(5000, 5000 + args.seeds):
            trace: dict = {}
            score = run_episode(sup, fault, seed, 3999, trace=trace)
            changes = [e for e in sup.history if e.k > sup.arm_after or e.k == 1]
            print(f"{fault} seed {seed} onset {trace['onset'][0]} return {score.return_usd:,.0f}")
            for k, alarm, named, target in changes[:25]:
                print(f"   k={k:5d} alarm={int(alarm)} diagnosis={named} target={target}")


if __name__ == "__main__":
    main()
