"""The envelope of the actuator faults (fcc_env.actuator_faults): which sizes keep the plant in
its envelope, in closed loop and (valve-bias, blower-capacity) in open loop, and the limit
cycle of a sticking slide valve (its figure and period: ``lab/stiction_limit_cycle.py``).

Training seeds (1000 onwards), the paper's 4000 samples, onset 2000. Per case: the episodes
that leave the envelope (terminated) against the healthy twins, the true process's mean shift
over the last 1000 samples (riser outlet aux["T_rx"], stage-1 bed state T1), and, in closed
loop, the oscillation of the true riser outlet about its set point after the onset: how often
it crosses the set point (with 0.2 °C of hysteresis, so noise does not count), the period
that gives, and the 95th percentile of |T_rx − T_rx_sp| (a cycle's amplitude; the set-point
steps' brief transients stay above it).

    PYTHONPATH=$PWD python lab/actuator_fault_envelope.py --seeds 10
    PYTHONPATH=$PWD python lab/actuator_fault_envelope.py --cases closed:valve-stiction:0.05
    PYTHONPATH=$PWD python lab/actuator_fault_envelope.py --cases closed:sensor-bias+valve-stiction:1
    PYTHONPATH=$PWD python lab/actuator_fault_envelope.py --signatures --seeds 10
"""

from __future__ import annotations

import argparse
import time
from dataclasses import replace

import numpy as np

import fcc_env
from fcc_env import FaultSpec, simulate_episodes
from fcc_env.params import STATE_NAMES
from fcc_env.physics import AUX_NAMES

ONSET = 2000
HYSTERESIS_C = 0.2

DEFAULT_CASES = [
    *(("closed", "valve-stiction", m) for m in (0.02, 0.05, 0.10, 0.20)),
    *(("closed", "valve-bias", m) for m in (0.05, 0.10, 0.20)),
    *(("open", "valve-bias", m) for m in (0.05, 0.10, 0.20)),
    *(("closed", "valve-stuck", m) for m in (0.5, 1.0)),
    *(("closed", "blower-capacity", m) for m in (0.15, 0.25, 0.35)),
    *(("open", "blower-capacity", m) for m in (0.15, 0.25, 0.35)),
]


def crossings(e: np.ndarray, band: float = HYSTERESIS_C) -> int:
    """Sign changes of ``e`` that go past ``±band`` (a Schmitt trigger: noise inside the band
    does not count)."""
    state, n = 0, 0
    for v in e:
        new = 1 if v > band else -1 if v < -band else state
        if state and new != state:
            n += 1
        state = new
    return n


def oscillation(b, dt_h: float) -> str:
    """The true riser outlet's crossings of its set point after the onset, per episode."""
    trx = b.aux[:, ONSET + 200 :, AUX_NAMES.index("T_rx")]
    e = trx - b.setpoints[:, ONSET + 200 :, 0]
    n = np.array([crossings(row) for row in e])
    hours = e.shape[1] * dt_h
    period = np.where(n > 1, 2.0 * hours * 60.0 / np.maximum(n, 1), np.inf)
    # a cycle's amplitude without the set-point steps' brief transients: |e|'s 95th percentile
    amp = np.percentile(np.abs(e), 95, axis=1)
    return (
        f"crossings {int(n.min())}–{int(n.max())} (period {np.median(period):.0f} min median), "
        f"|T_rx − sp| p95 {np.median(amp):.2f} °C median ({amp.min():.2f}–{amp.max():.2f})"
    )


def _single(name: str, size: float, seeds: list[int], samples: int, plant):
    """``name`` at ``size`` from the onset; a size beyond the registered limit is measured
    too (the lab is where limits are found)."""
    d = fcc_env.FAULTS[name]
    fcc_env.unregister_fault(name)
    fcc_env.register_fault(name, replace(d, max_magnitude=max(size, d.max_magnitude)))
    try:
        spec = FaultSpec(scenario=name, magnitude=size, onset=ONSET)
        return simulate_episodes(seeds, samples, fault=spec, plant=plant)
    finally:
        fcc_env.unregister_fault(name)
        fcc_env.register_fault(name, d)


def signatures(seeds: list[int]) -> None:
    """Each actuator fault at its default: the mean faulty − healthy difference of each
    noise-free observation channel over samples 2500–4000 / its standard deviation over time
    (mean over episodes), in closed and open loop."""
    for mode, plant in (
        ("closed", fcc_env.PlantConfig.build(regulatory=True)),
        ("open", fcc_env.PlantConfig()),
    ):
        h = simulate_episodes(seeds, 4000, plant=plant)
        for name, d in fcc_env.ACTUATOR_FAULTS.items():
            if mode == "open" and d.needs_loop:
                continue  # refused in open loop
            b = simulate_episodes(seeds, 4000, fault=FaultSpec(scenario=name), plant=plant)
            diff = (b.y_clean - h.y_clean)[:, 2500:]
            mean, sd = diff.mean(axis=(0, 1)), diff.std(axis=1).mean(axis=0)
            cells = [
                f"{c} {m:+.2f} / {v:.2f}"
                for c, m, v in zip(b.channels, mean, sd, strict=True)
                if not c.endswith("_sp")
            ]
            print(f"{mode:6s} {name:15s} " + ", ".join(cells), flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--samples", type=int, default=4000)
    ap.add_argument(
        "--cases",
        nargs="*",
        default=None,
        help="MODE:NAME:SIZE (MODE open|closed); NAME A+B: concurrent, both at their defaults "
        "times SIZE, onsets 2000 and 2500",
    )
    ap.add_argument("--signatures", action="store_true", help="the defaults' signatures, then stop")
    args = ap.parse_args()
    if args.signatures:
        signatures(list(range(1000, 1000 + args.seeds)))
        return
    cases = DEFAULT_CASES
    if args.cases:
        cases = [(c.split(":")[0], c.split(":")[1], float(c.split(":")[2])) for c in args.cases]
    seeds = list(range(1000, 1000 + args.seeds))
    plants = {"open": fcc_env.PlantConfig(), "closed": fcc_env.PlantConfig.build(regulatory=True)}
    healthy = {mode: simulate_episodes(seeds, args.samples, plant=p) for mode, p in plants.items()}
    for mode, h in healthy.items():
        term = int((h.terminated_at >= 0).sum())
        extra = f"; {oscillation(h, h.sample_time_s / 3600)}" if mode == "closed" else ""
        print(f"healthy {mode}: {term}/{len(seeds)} terminated{extra}")
    tail = slice(args.samples - 1000, None)
    for mode, name, size in cases:
        t0 = time.process_time()
        if "+" in name:  # two faults at their defaults (SIZE: their scale), onsets 2000 and 2500
            first, second = name.split("+")
            parts = (FaultSpec(scenario=first, onset=ONSET), FaultSpec(scenario=second, onset=2500))
            spec = FaultSpec(scenario="concurrent", parts=parts, magnitude_scale=size)
            b = simulate_episodes(seeds, args.samples, fault=spec, plant=plants[mode])
        else:
            b = _single(name, size, seeds, args.samples, plants[mode])
        h = healthy[mode]
        trx = b.aux[..., AUX_NAMES.index("T_rx")] - h.aux[..., AUX_NAMES.index("T_rx")]
        trg = b.states[..., STATE_NAMES.index("T1")] - h.states[..., STATE_NAMES.index("T1")]
        term = b.terminated_at[b.terminated_at >= 0]
        when = (
            f" at {int(term.min()) - ONSET}–{int(term.max()) - ONSET} after onset"
            if term.size
            else ""
        )
        ok = b.terminated_at < 0  # the shift of the episodes that stayed in
        shift = (
            f"T_rx {trx[ok][:, tail].mean():+.2f} °C, T_rg1 {trg[ok][:, tail].mean():+.2f} °C"
            if ok.any()
            else "none stayed in"
        )
        osc = f"; {oscillation(b, b.sample_time_s / 3600)}" if mode == "closed" else ""
        print(
            f"{mode:6s} {name:15s} m={size:g}: terminated {term.size}/{len(seeds)}{when} "
            f"{sorted({r for r in b.termination_reasons if r})}; true shift over the last 1000 "
            f"samples {shift}{osc}; {time.process_time() - t0:.0f} s CPU",
            flush=True,
        )


if __name__ == "__main__":
    main()
