"""The envelope of the sensor faults (fcc_env.sensor_faults) in closed loop, at their largest
sizes, on the controlled channels T_rx and T_rg1 (where a sensor fault reaches the process).

Training seeds (1000 onwards), the paper's 4000 samples, onset 2000. Per kind and channel: the
episodes that leave the envelope (terminated) against the healthy twins, and the true process's
mean shift over the last 1000 samples (the riser outlet aux["T_rx"], the stage-1 bed state T1).

    PYTHONPATH=$PWD python lab/sensor_fault_envelope.py --seeds 10
"""

from __future__ import annotations

import argparse
import time
from dataclasses import replace

import fcc_env
from fcc_env import FaultSpec, simulate_episodes
from fcc_env.params import STATE_NAMES
from fcc_env.physics import AUX_NAMES


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--samples", type=int, default=4000)
    ap.add_argument(
        "--cases",
        nargs="*",
        default=None,
        help="NAME:CHANNEL:SIZE cases (default: every kind at its largest size on both loops)",
    )
    args = ap.parse_args()
    cases = [
        (name, channel, d.max_magnitude)
        for name, d in fcc_env.SENSOR_FAULTS.items()
        for channel in ("T_rx", "T_rg1")
    ]
    if args.cases:
        cases = [(c.split(":")[0], c.split(":")[1], float(c.split(":")[2])) for c in args.cases]
    seeds = list(range(1000, 1000 + args.seeds))
    plant = fcc_env.PlantConfig.build(regulatory=True)
    healthy = simulate_episodes(seeds, args.samples, plant=plant)
    print(f"healthy: {int((healthy.terminated_at >= 0).sum())}/{len(seeds)} terminated")
    tail = slice(args.samples - 1000, None)
    for name, channel, size in cases:
        t0 = time.perf_counter()
        # a size beyond the registered limit is measured too: the lab is where limits are found
        d = fcc_env.FAULTS[name]
        top = max(size, d.max_magnitude)
        fcc_env.unregister_fault(name)
        fcc_env.register_fault(name, replace(d, max_magnitude=top))
        try:
            spec = FaultSpec(scenario=name, channel=channel, magnitude=size, onset=2000)
            b = simulate_episodes(seeds, args.samples, fault=spec, plant=plant)
        finally:
            fcc_env.unregister_fault(name)
            fcc_env.register_fault(name, d)
        trx = b.aux[..., AUX_NAMES.index("T_rx")] - healthy.aux[..., AUX_NAMES.index("T_rx")]
        trg = b.states[..., STATE_NAMES.index("T1")] - healthy.states[..., STATE_NAMES.index("T1")]
        term = b.terminated_at[b.terminated_at >= 0]
        when = (
            f" at {int(term.min()) - 2000}–{int(term.max()) - 2000} after onset"
            if term.size
            else ""
        )
        print(
            f"{name:15s} {channel:6s} m={size:g}: terminated {term.size}/{len(seeds)}{when} "
            f"{sorted({r for r in b.termination_reasons if r})}; true shift over the last 1000: "
            f"T_rx {trx[:, tail].mean():+.2f} °C (range {trx[:, tail].min():+.1f} "
            f"{trx[:, tail].max():+.1f}), T_rg1 {trg[:, tail].mean():+.2f} °C (range "
            f"{trg[:, tail].min():+.1f} {trg[:, tail].max():+.1f}); "
            f"{time.perf_counter() - t0:.0f} s"
        )


if __name__ == "__main__":
    main()
