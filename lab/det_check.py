"""Check the registered ``lrgf-glr`` against the lab: its ``fit`` with the lab's cached banks
(fold 0, 1, 2, then all) injected for ``_train_banks``, scored on the lab's validation episodes."""

from __future__ import annotations

import sys

import numpy as np

sys.path.insert(0, ".")
import diagnosers
from diagnosers import Episode
from diagnosers.bank.parallel import TrainedBank
from diagnosers.lrgf.lrgf_glr import LRGFGLR
from evaluation.metrics import episode_scores
from evaluation.metrics.intervals import bootstrap_ci
from evaluation.tracks.track_data import TrackData
from lab.det_lab import N_TRAIN, TRACK_NAMES, _episode_cache, load_models, val_track

banks = iter(["0", "1", "2", "all"])


def injected(self, sets):
    out = []
    for _ in sets:  # the folds' banks, then the bank on all: one call (diagnosers.bank.parallel)
        nets, mems = load_models(next(banks))
        fit = type("F", (), {"best_val_loss": 0.0})()
        out.append(TrainedBank(nets, mems, [0.0] * len(nets), [fit] * len(nets)))
    return out


LRGFGLR._train_banks = injected
train = TrackData(track=val_track("paper").replace(n_train=N_TRAIN)).train_episodes()
det = diagnosers.make("lrgf-glr").fit(train)
print("h", det.h_, "h_dir", det.h_dir_, "use_mem", det.use_mem_)
eps = _episode_cache()
ch = train[0].channels
rfd = [
    episode_scores(det.detect(Episode(eps[f"y:nominal/{s}"], ch, 10.0)).alarm, None)["r_fd"]
    for s in range(5000, 5100)
]
ci = bootstrap_ci(np.array(rfd))
print(f"r_fd {np.mean(rfd):.4f} [{ci.low:.4f}, {ci.high:.4f}] worst {np.max(rfd):.3f}")
for tn in TRACK_NAMES:
    cells = []
    for f in ("f1", "f2", "f3", "f4"):
        td, tt = [], []
        for s in range(5000, 5020):
            key = f"{tn}/{f}/{s}"
            y, on = eps[f"y:{key}"], int(eps[f"onset:{key}"])
            if on < 0 or on >= len(y):
                continue
            sc = episode_scores(det.detect(Episode(y, ch, 10.0)).alarm, on)
            td.append(sc["r_td"])
            tt.append(sc["t_dt"])
        cells.append(f"{f} {np.mean(td):.2f}/{np.nanmean(tt):.0f} m{int(np.isnan(tt).sum())}")
    print(tn, " | ".join(cells), flush=True)
