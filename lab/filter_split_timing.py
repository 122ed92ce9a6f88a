"""CPU seconds of the filter reference row's fit: one task, against its parts (issue 44: the
filter row's fit was one task of 40-50 s that set the reference rows' critical path).

    python lab/filter_split_timing.py --track paper

Runs in this one process, one part after another, timing each with ``time.process_time``
(the machine is shared: wall times measure the contention). After a warm-up (the filter's
kernels compiled), it times :func:`~evaluation.tracks.reference_runs.fit_task` of the row,
then each part as a task would run it: one signature task per training fault seed, one
statistics task per chunk of calibration seeds, the limits task. It checks that both give the
same directions and limits, bit for bit, and prints the critical path of the split fit on
enough cores (the longest signature task, then the longest chunk, then the limits).
"""

from __future__ import annotations

import argparse
import time

from evaluation.tracks import TRACKS
from evaluation.tracks.filter_bound import SIGNATURE_SEEDS, FilterBound
from evaluation.tracks.oracle import DEFAULT_REFERENCES, OracleStage
from evaluation.tracks.reference_runs import (
    FILTER_CHUNK,
    filter_limits_task,
    filter_signature_task,
    filter_statistics_task,
    fit_task,
)
from evaluation.tracks.track_data import TrackData


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--track", default="paper", choices=sorted(TRACKS))
    args = ap.parse_args()
    track = TRACKS[args.track]
    data = TrackData(track=track)
    config = next(c for c in DEFAULT_REFERENCES if c.stage == OracleStage.FILTER)
    cal = list(config.calibration_seeds(track))
    seeds = list(track.train_fault_seeds[:SIGNATURE_SEEDS])
    terms0 = [filter_signature_task(data, config, seeds[0], _serial=True)]
    filter_statistics_task(data, config, terms0, cal[:1], _serial=True)  # warm-up: compile

    t = time.process_time()
    one = fit_task(data, config, _serial=True).stage_
    single = time.process_time() - t

    sig, terms = [], []
    for s in seeds:
        t = time.process_time()
        terms.append(filter_signature_task(data, config, s, _serial=True))
        sig.append(time.process_time() - t)
    chunk, stats = [], []
    for k in range(0, len(cal), FILTER_CHUNK):
        t = time.process_time()
        stats.append(
            filter_statistics_task(data, config, terms, cal[k : k + FILTER_CHUNK], _serial=True)
        )
        chunk.append(time.process_time() - t)
    t = time.process_time()
    split = filter_limits_task(data, config, terms, stats, _serial=True).stage_
    limits = time.process_time() - t

    assert isinstance(one, FilterBound) and isinstance(split, FilterBound)
    same = (
        one.directions_.tobytes() == split.directions_.tobytes()
        and one.limits_.tobytes() == split.limits_.tobytes()
    )
    print(f"track {args.track}: {len(seeds)} signature seeds, {len(cal)} calibration seeds")
    print(f"one task:            {single:7.1f} s CPU")
    print(f"signature tasks:     {len(sig)} x, sum {sum(sig):6.1f} s, max {max(sig):5.1f} s")
    print(f"statistics tasks:    {len(chunk)} x, sum {sum(chunk):6.1f} s, max {max(chunk):5.1f} s")
    print(f"limits task:         {limits:7.1f} s")
    print(f"all parts:           {sum(sig) + sum(chunk) + limits:7.1f} s CPU")
    print(f"critical path:       {max(sig) + max(chunk) + limits:7.1f} s CPU (enough cores)")
    print(f"bit-identical:       {same}")


if __name__ == "__main__":
    main()
