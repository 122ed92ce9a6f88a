"""How far the perfect-model T² rows' calibration mean lies from zero (issue 41 item 2).

The T² reference rows of :mod:`evaluation.tracks.oracle` centre their T² on the calibration mean
of the EWMA of the exact model's residual; a detector's stage does not. This prints, per track
and per input (true, measured), that mean in units of each channel's healthy EWMA standard
deviation, its own T² (``mean' S^-1 mean``) and the row's limit, on the track's validation
seeds (the rows' calibration episodes). Run from the repository root::

    python lab/oracle_t2_centre.py paper small
"""

from __future__ import annotations

import argparse

import numpy as np

from evaluation.tracks import TRACKS
from evaluation.tracks.oracle import OracleConfig, PhysicalLimit
from evaluation.tracks.track_data import TrackData


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(prog="python lab/oracle_t2_centre.py")
    ap.add_argument("tracks", nargs="+", choices=sorted(TRACKS))
    args = ap.parse_args(argv)
    print("| track | inputs | seeds | mean / sd of the EWMA per channel | mean' S⁻¹ mean | limit |")
    print("|---|---|---|---|---|---|")
    for name in args.tracks:
        data = TrackData(track=TRACKS[name])
        for inputs in ("true", "measured"):
            row = PhysicalLimit(data, OracleConfig(inputs=inputs)).fit()
            stage = row.stage_
            sd = np.sqrt(np.diag(np.linalg.pinv(stage.s_inv_)))
            mean = stage.mean_
            seeds = row.config.calibration_seeds(data.track)
            print(
                f"| {name} | {inputs} | {seeds.start}-{seeds.stop - 1} | "
                f"{', '.join(f'{x:+.3f}' for x in mean / sd)} | "
                f"{float(mean @ stage.s_inv_ @ mean):.3f} | {float(stage.h_[0]):.2f} |"
            )


if __name__ == "__main__":
    main()
