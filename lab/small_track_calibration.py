"""Calibrate the ``small`` track's sizes on the physical-limit row (never on test seeds).

For each fault and candidate size, the physical-limit observer (:mod:`evaluation.tracks.oracle`) is run on
12 faulty episodes with seeds 7000+ (outside the test, training and validation ranges) and its
r_td and t_dt are printed; the track takes the size whose r_td is about 0.85-0.93.

    python lab/small_track_calibration.py
"""

from evaluation.sweep.records import summarize
from evaluation.tracks import TRACKS, Fixed
from evaluation.tracks.oracle import oracle_records
from evaluation.tracks.track_data import TrackData

GRID = {
    "f1": [0.003, 0.005, 0.008],
    "f2": [0.01, 0.015, 0.02, 0.03],
    "f3": [0.008, 0.012, 0.016, 0.02],
    "f4": [0.004, 0.006, 0.008, 0.01],
}

if __name__ == "__main__":
    base = TRACKS["small"]
    for fault, sizes in GRID.items():
        for m in sizes:
            track = base.replace(
                faults=(fault,), magnitudes={fault: Fixed(m)}, n_healthy=1, n_faulty=12
            ).with_seeds(test=7000)
            recs = oracle_records(TrackData(track=track))
            s = next(x for x in summarize(recs) if x.scenario == fault)
            print(fault, m, round(s.r_td, 3), round(s.t_dt, 1), s.misses, flush=True)
