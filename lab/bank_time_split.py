"""Where an ``lrgf-mem`` training spends its time: the data, each relation job, the rest (issue 44).

CPU seconds (time.process_time, this process only), so the split holds on a busy machine:
the training episodes of a track (healthy and labelled faults), then one ``lrgf-mem`` fit with
its relation jobs timed one by one (``--max-epochs`` shortens them: the split is what matters).
Run from the repository root::

    python lab/bank_time_split.py --track small --max-epochs 100
"""

from __future__ import annotations

import argparse
import time

import diagnosers
from diagnosers.bank import parallel
from evaluation.tracks.catalogue import parse_tracks
from evaluation.tracks.track_data import TrackData


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--track", default="small")
    p.add_argument("--max-epochs", type=int, default=100)
    p.add_argument("--mem-max-epochs", type=int, default=20)
    args = p.parse_args()
    data = TrackData(track=parse_tracks(args.track)[0])
    t = time.process_time()
    episodes = data.train_episodes()
    print(f"healthy training episodes: {len(episodes)} in {time.process_time() - t:.2f} s CPU")
    t = time.process_time()
    faults = data.train_fault_episodes()
    print(f"labelled fault episodes:   {len(faults)} in {time.process_time() - t:.2f} s CPU")
    jobs: list[float] = []
    train = parallel._train_relation  # a lab measurement reaches into the module

    def timed(job: parallel.RelationJob) -> parallel.TrainedRelation:
        t0 = time.process_time()
        out = train(job)
        jobs.append(time.process_time() - t0)
        return out

    # every job of an in-process fit goes through _run_relation -> _train_relation: time there
    parallel._train_relation = timed  # a lab measurement, not a library use
    diag = diagnosers.make(
        "lrgf-mem", max_epochs=args.max_epochs, mem_max_epochs=args.mem_max_epochs
    )
    t = time.process_time()
    diag.fit(episodes)
    total = time.process_time() - t
    print(
        f"lrgf-mem fit: {total:.2f} s CPU; relation jobs {[round(j, 2) for j in jobs]} s; "
        f"the rest {total - sum(jobs):.2f} s"
    )


if __name__ == "__main__":
    main()
