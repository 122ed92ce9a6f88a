"""Round 1's candidate table of the modelling loop on one closed-loop record (issue 42; record:
``lab/discover_drift.md``, 2026-12-07): why an effect was or was not named first.

One 4000-sample record of ``FCC-closedloop-v0``'s plant under its default program with one hidden
library effect (``lab/discover_drift.py``'s ``closed_data``), the loop's library round
(``max_effects=1``, ``forms="never"``) with the drift estimate fed ``--drift-fit joint|fixed``, or,
with ``--oracle``, the plant's *true* coking factor fed instead (a diagnosis only: the loop never
reads it). Printed: the fitted drift line and the six best candidates with their held-out score,
relative reduction, p-value and estimate.

    PYTHONPATH=. python lab/discover_round_table.py catalyst_deactivation,loss_per_day=0.1 5000
        [--drift-fit joint|fixed] [--oracle]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import fcc_env
from evaluation import discover as d
from fcc_env import effects as fx

# ``python lab/<script>.py`` puts lab/ first on the path, not the repository root
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from lab.discover_drift import N, closed_data


class OracleModel(d.PhysicsModel):
    """The declared model fed the plant's true coking factor (diagnosis only)."""

    def __init__(self, f_coke) -> None:
        super().__init__()
        self._truth = f_coke

    def prepare(self, data, n_train: int) -> None:
        super().prepare(data, n_train)
        self.set_drift(self._truth)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("effect", help="a library effect, e.g. catalyst_deactivation,loss_per_day=0.1")
    ap.add_argument("seed", type=int, help="training (1000+) or validation (5000+) seed")
    ap.add_argument("--drift-fit", choices=("joint", "fixed"), default="joint")
    ap.add_argument("--oracle", action="store_true", help="feed the true f_coke instead")
    args = ap.parse_args()
    t0 = time.process_time()
    if args.oracle:
        plant = fcc_env.PlantConfig.build(regulatory=True)
        batch = fcc_env.simulate_episodes(
            [args.seed], N, plant=plant, plant_effects=[fx.parse(args.effect)]
        )
        truth = batch.inputs[:, :, fcc_env.INPUT_NAMES.index("f_coke")]
        data, model, drift = d.from_batch(batch), OracleModel(truth), "off"
    else:
        data, model, drift = closed_data(args.effect, args.seed), None, "auto"
    rep = d.discover(
        data,
        model=model,
        max_effects=1,
        plots=False,
        forms="never",
        drift=drift,
        drift_fit=args.drift_fit,
    ).to_json()
    how = "true f_coke (oracle)" if args.oracle else f"estimate, fit {args.drift_fit}"
    line = (rep.get("drift") or {}).get("line")
    print(f"{args.effect}, seed {args.seed}, {how}; drift line {line}")
    for r in rep["rounds"][0]["candidates"][:6]:
        print(
            f"  {r['id']:28s} score {r['score']:9.1f} reduction {r['rel_reduction']:.3f} "
            f"p {r['p_value']:.2g} {r['params']}"
        )
    print(f"CPU {time.process_time() - t0:.1f} s")


if __name__ == "__main__":
    main()
