"""How the realised false detection rate of ``lrgf-glr`` and its interval depend on the declared
target, on many healthy validation episodes (seeds 5000+; never test seeds). Uses a bank stored by
``scripts/baseline_lab.py train`` and re-calibrates its alarm stage per target.

    python scripts/fd_tail_lab.py --tag=_rg1x10 --targets 0.02,0.03,0.04 --n-healthy 200
"""

from __future__ import annotations

import argparse

import numpy as np
from baseline_lab import load

import diagnosers
import fcc_env
from evaluation.intervals import bootstrap_ci
from evaluation.metrics import episode_scores


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--track", default="paper")
    ap.add_argument("--tag", default="")
    ap.add_argument("--targets", default="0.02,0.03,0.04")
    ap.add_argument("--n-healthy", type=int, default=200)
    ap.add_argument("--set", default="", help="extra hyperparameters k=v,k=v (floats)")
    a = ap.parse_args()
    det, cal, w = load(a.track, a.tag)
    extra = {kv.split("=")[0]: float(kv.split("=")[1]) for kv in a.set.split(",") if kv}
    batch = fcc_env.simulate_episodes(range(5000, 5000 + a.n_healthy), fcc_env.DEFAULT_N_SAMPLES)
    episodes = diagnosers.Episode.from_batch(batch)
    for target in (float(t) for t in a.targets.split(",")):
        det.set_params(false_alarm_target=target, **extra)
        det._calibrate(cal, w)
        det._fitted_ = True  # the lab re-calibrates the stored bank in place
        r_fd = np.array([episode_scores(det.detect(ep).alarm, None)["r_fd"] for ep in episodes])
        ci = bootstrap_ci(r_fd, rng=0)
        print(
            f"target {target}: r_fd {r_fd.mean():.4f} [{ci.low:.4f}, {ci.high:.4f}] over "
            f"{len(r_fd)} episodes; any alarm {np.mean(r_fd > 0):.2f}; worst {r_fd.max():.3f} "
            f"(seed {5000 + int(r_fd.argmax())}); episodes over 2 %: {int(np.sum(r_fd > 0.02))}",
            flush=True,
        )


if __name__ == "__main__":
    main()
