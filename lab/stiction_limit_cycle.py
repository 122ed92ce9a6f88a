"""The limit cycle of a sticking regenerated-catalyst slide valve under the T_rx loop (issue 43,
"Realism"): its figure and its period.

The figure (``--figure PATH``, training seed 1000, ``valve-stiction`` at ``--size``, onset 2000,
90 minutes from the onset): the controller's command and the valve's position (what the process
received), the riser outlet (true and measured) about its set point, and two phase plots: the
command against the controlled variable (the OP-PV plot of the stiction literature) and the
command against the valve position (Choudhury, Thornhill & Shah 2005's parallelogram). Every
axis takes its unit from the data (the channels' units of the closed-loop observation, the
sample time).

The period (``--periods``, training seeds 1000.., each size of ``--sizes``) three ways, each the
median over the episodes of samples 2200-4000 (after the first breakaway):

* the true T_rx's crossings of its set point (Schmitt trigger ±0.2 °C, as
  ``lab/actuator_fault_envelope.py``): 2 × duration / crossings;
* the valve's slips: the mean time between two slips in the same direction (a slip is a move of
  the position by more than half the slip jump J = S/2 in one sample);
* ``oscillation-acf``'s period (the ACF's zero crossings, Thornhill et al. 2003), median over
  the samples it alarms on (and how many of them it alarms on).

    PYTHONPATH=$PWD python lab/stiction_limit_cycle.py --figure /tmp/stiction.png --size 0.05
    PYTHONPATH=$PWD python lab/stiction_limit_cycle.py --periods --seeds 10
"""

from __future__ import annotations

import argparse

import numpy as np

import diagnosers
import fcc_env
from fcc_env import FaultSpec, simulate_episodes
from fcc_env.actuator_faults import VALVE_RANGE
from fcc_env.closed_loop import CHANNEL_UNITS
from fcc_env.physics import AUX_NAMES

ONSET = 2000
HYSTERESIS_C = 0.2


def crossings(e: np.ndarray, band: float = HYSTERESIS_C) -> int:
    """Sign changes of ``e`` that go past ``±band`` (a Schmitt trigger)."""
    state, n = 0, 0
    for v in e:
        new = 1 if v > band else -1 if v < -band else state
        if state and new != state:
            n += 1
        state = new
    return n


def slip_period(position: np.ndarray, jump: float) -> float:
    """Mean samples between two slips in the same direction (moves above ``jump / 2``)."""
    step = np.diff(position)
    up = np.flatnonzero(step > jump / 2)
    down = np.flatnonzero(step < -jump / 2)
    gaps = np.concatenate([np.diff(up), np.diff(down)])
    return float(gaps.mean()) if gaps.size else float("nan")


def simulate(seeds: list[int], size: float, samples: int):
    spec = FaultSpec(scenario="valve-stiction", magnitude=size, onset=ONSET)
    return simulate_episodes(
        seeds, samples, fault=spec, plant=fcc_env.PlantConfig.build(regulatory=True)
    )


def figure(path: str, size: float, seed: int = 1000) -> None:
    """Draw the limit cycle (module docstring) to ``path``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    b = simulate([seed], size, 3000)
    ch = b.channels
    u_unit, t_unit = CHANNEL_UNITS["u_F"], CHANNEL_UNITS["T_rx"]
    k = np.arange(ONSET - 60, ONSET + 540)
    t_min = (k - ONSET) * b.sample_time_s / 60.0
    command = b.observations[0, k, ch.index("u_F")]
    position = b.inputs[0, k, fcc_env.INPUT_NAMES.index("u_F")]
    trx_true = b.aux[0, k, AUX_NAMES.index("T_rx")]
    trx_meas = b.observations[0, k, ch.index("T_rx")]
    sp = b.observations[0, k, ch.index("T_rx_sp")]
    s_abs = size * VALVE_RANGE
    fig, ax = plt.subplots(2, 2, figsize=(13, 8))
    ax[0, 0].plot(t_min, command, label="command u_F (controller output, recorded)")
    ax[0, 0].plot(t_min, position, label="valve position (flow the riser receives)")
    ax[0, 0].set(
        xlabel=f"time after the onset [min] (sample {b.sample_time_s:g} s)",
        ylabel=f"regenerated-catalyst flow [{u_unit}]",
        title=f"valve-stiction S = {size:g} of the range ({s_abs:.1f} {u_unit}), J = S/2",
    )
    ax[0, 0].legend(fontsize=8)
    ax[0, 1].plot(t_min, trx_meas, lw=0.6, alpha=0.6, label="T_rx measured")
    ax[0, 1].plot(t_min, trx_true, label="T_rx true")
    ax[0, 1].plot(t_min, sp, "--", label="set point T_rx_sp")
    ax[0, 1].set(
        xlabel=f"time after the onset [min] (sample {b.sample_time_s:g} s)",
        ylabel=f"riser outlet temperature [{t_unit}]",
        title="controlled variable: a pulse train about the set point",
    )
    ax[0, 1].legend(fontsize=8)
    after = k >= ONSET + 30  # after the first breakaway
    ax[1, 0].plot(command[after], (trx_true - sp)[after], ".-", lw=0.4, ms=2)
    ax[1, 0].set(
        xlabel=f"controller output u_F [{u_unit}]",
        ylabel=f"T_rx − set point (true) [{t_unit}]",
        title="OP-PV phase plot",
    )
    ax[1, 1].plot(command[after], position[after], ".-", lw=0.4, ms=2)
    ax[1, 1].set(
        xlabel=f"controller output u_F [{u_unit}]",
        ylabel=f"valve position [{u_unit}]",
        title="command against position (Choudhury et al. 2005)",
    )
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def periods(sizes: list[float], seeds: list[int]) -> None:
    """The period three ways per size (module docstring), printed as a Markdown table."""
    plant = fcc_env.PlantConfig.build(regulatory=True)
    train = diagnosers.Episode.from_batch(simulate_episodes([1000, 1001], 1500, plant=plant))
    osc = diagnosers.make("oscillation-acf").fit(train)
    dt_min = None
    print("| S | T_rx crossings | valve slips | oscillation-acf (alarmed share) |")
    print("|---|---|---|---|")
    for size in sizes:
        b = simulate(seeds, size, 4000)
        dt_min = b.sample_time_s / 60.0
        tail = slice(ONSET + 200, None)
        e = b.aux[:, tail, AUX_NAMES.index("T_rx")] - b.setpoints[:, tail, 0]
        n = np.array([crossings(row) for row in e])
        by_crossings = np.where(n > 1, 2.0 * e.shape[1] / np.maximum(n, 1), np.nan)
        pos = b.inputs[:, tail, fcc_env.INPUT_NAMES.index("u_F")]
        jump = 0.5 * size * VALVE_RANGE
        by_slips = np.array([slip_period(p, jump) for p in pos])
        acf, share = [], []
        for ep in diagnosers.Episode.from_batch(b):
            det = osc.detect(ep)
            alarmed = det.alarm[ONSET + 200 :]
            share.append(alarmed.mean())
            if alarmed.any():
                acf.append(np.median(det.signal[ONSET + 200 :][alarmed, 3]) / 60.0)
        print(
            f"| {size:g} | {np.nanmedian(by_crossings) * dt_min:.1f} min "
            f"({np.nanmin(by_crossings) * dt_min:.1f}–{np.nanmax(by_crossings) * dt_min:.1f}) | "
            f"{np.nanmedian(by_slips) * dt_min:.1f} min "
            f"({np.nanmin(by_slips) * dt_min:.1f}–{np.nanmax(by_slips) * dt_min:.1f}) | "
            f"{np.median(acf) if acf else float('nan'):.1f} min ({np.mean(share):.2f}) |",
            flush=True,
        )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--figure", default=None, help="PATH of the figure (PNG)")
    ap.add_argument("--size", type=float, default=0.05, help="the figure's S")
    ap.add_argument("--periods", action="store_true", help="measure the period per size")
    ap.add_argument("--sizes", type=float, nargs="*", default=[0.02, 0.05, 0.1, 0.2, 0.3])
    ap.add_argument("--seeds", type=int, default=10, help="training seeds 1000..")
    args = ap.parse_args()
    if not args.figure and not args.periods:
        ap.error("nothing to do: give --figure PATH and/or --periods")
    if args.figure:
        figure(args.figure, args.size)
    if args.periods:
        periods(args.sizes, list(range(1000, 1000 + args.seeds)))


if __name__ == "__main__":
    main()
