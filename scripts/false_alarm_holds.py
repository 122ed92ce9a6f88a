"""Does ``lrgf-glr``'s false-alarm rate hold on fresh seeds? Validation seeds only.

Scores the lab bank of ``scripts/baseline_lab.py`` (trained on a track's training seeds, with its
out-of-fold calibration records) on ``--n-healthy`` healthy episodes of validation seeds 5000+
for each declared ``false_alarm_target``, re-calibrated from the stored records. It prints the
realised r_fd with its 95 % BCa interval over all episodes and over disjoint blocks of
``--block`` episodes (a track has 50 healthy test episodes, so a block's upper end is what a
leaderboard on fresh seeds would show), the share of episodes with any alarm and the worst one.

    python scripts/baseline_lab.py train --track paper --epochs 3000 --tag=_rg1x10
    python scripts/false_alarm_holds.py --tag=_rg1x10 --targets 0.03,0.02 --n-healthy 200
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np
from baseline_lab import OUT, load, val_track
from tqdm import tqdm

import diagnosers
from evaluation.intervals import bootstrap_ci
from evaluation.metrics import episode_scores
from evaluation.sources import TrackData


def healthy_episodes(track: str, n_healthy: int) -> np.ndarray:
    """Measurements ``(n, T, channels)`` of the track's healthy validation episodes (cached)."""
    path = OUT / f"healthy-{track}-{n_healthy}.npy"
    if path.exists():
        return np.load(path)
    data = TrackData(track=val_track(track, n_healthy, 1))
    cells = [(sc, seed) for sc, seed in data.cells() if sc == "nominal"]
    ys = np.stack([data.load_test(sc, seed).episode.y for sc, seed in tqdm(cells, "simulate")])
    np.save(path, ys)
    return ys


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--track", default="paper")
    ap.add_argument("--tag", default="", help="the lab bank's name suffix")
    ap.add_argument("--targets", default="0.03", help="false_alarm_target values, comma-separated")
    ap.add_argument("--n-healthy", type=int, default=200)
    ap.add_argument("--block", type=int, default=50, help="episodes per block (a track's 50)")
    ap.add_argument("--set", default="", help="extra hyperparameters k=v,k=v (JSON values)")
    a = ap.parse_args()
    det, cal, w = load(a.track, a.tag)
    extra = {kv.split("=")[0]: json.loads(kv.split("=")[1]) for kv in a.set.split(",") if kv}
    ys = healthy_episodes(a.track, a.n_healthy)
    out = []
    for target in [float(t) for t in a.targets.split(",")]:
        det.set_params(false_alarm_target=target, **extra)
        det._calibrate(cal, w)
        det._fitted_ = True  # the lab re-calibrates the stored bank in place
        r_fd = np.array(
            [
                episode_scores(det.detect(diagnosers.Episode(y, det.channels_, 10.0)).alarm, None)[
                    "r_fd"
                ]
                for y in tqdm(ys, f"target {target}", leave=False)
            ]
        )
        ci = bootstrap_ci(r_fd, method="BCa", rng=0)
        blocks = [r_fd[i : i + a.block] for i in range(0, len(r_fd) - a.block + 1, a.block)]
        block_ci = [bootstrap_ci(b, method="BCa", rng=0) for b in blocks]
        print(
            f"target {target}: r_fd {ci.estimate:.4f} [{ci.low:.4f}, {ci.high:.4f}] over "
            f"{len(r_fd)} episodes; any alarm {np.mean(r_fd > 0):.2f}; worst {r_fd.max():.3f}; "
            f"blocks of {a.block}: "
            + ", ".join(f"{b.estimate:.4f} [{b.low:.4f}, {b.high:.4f}]" for b in block_ci),
            flush=True,
        )
        out.append({"target": target, **extra, "r_fd": r_fd.tolist()})
    (OUT / f"false-alarm-{a.track}{a.tag}-{int(time.time())}.json").write_text(json.dumps(out))


if __name__ == "__main__":
    main()
