"""Which N4SID orders give a stable predictor on the ``closed`` track's training episodes
(seeds 1000+), by choice of inputs: ``n4sid-glr``'s defaults (the feed and air readings, among
them the T_rg1 loop's output R_ar) against the set points (the loop's exogenous inputs).

    python lab/n4sid_closed_poles.py

Prints the largest predictor pole magnitude per (inputs, order, horizon) and the fit's CPU
time; ``fit`` refuses a magnitude >= 1. Record: ``lab/monitors-lab.md``.
"""

from __future__ import annotations

import re
import time
import warnings

import diagnosers
from evaluation.tracks import TRACKS
from evaluation.tracks.track_data import TrackData

INPUTS = {
    "defaults (R_ar, T_ar, T_fp)": ["R_ar", "T_ar", "T_fp"],
    "set points": ["T_rx_sp", "T_rg1_sp"],
    "set points, T_ar, T_fp": ["T_rx_sp", "T_rg1_sp", "T_ar", "T_fp"],
}
ORDERS = ((20, 20), (12, 15), (8, 20), (4, 10))


def main() -> None:
    warnings.simplefilter("ignore")  # no training faults passed: the T² alone, said per fit
    episodes = TrackData(track=TRACKS["closed"]).train_episodes()
    for label, inputs in INPUTS.items():
        for order, horizon in ORDERS:
            det = diagnosers.make("n4sid-glr", inputs=inputs, order=order, horizon=horizon)
            t0 = time.process_time()
            try:
                det.fit(episodes)
                radius = float(abs(det.model_.predictor_poles()).max())
            except ValueError as err:  # the unstable predictor fit refuses
                found = re.search(r"magnitude ([0-9.]+)", str(err))
                radius = float(found.group(1)) if found else float("nan")
            cpu = time.process_time() - t0
            print(f"{label:28s} order {order:2d} horizon {horizon:2d}: {radius:.4f} ({cpu:.1f} s)")


if __name__ == "__main__":
    main()
