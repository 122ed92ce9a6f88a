"""Detector lab: train LRGF banks once, cache residuals of validation episodes, compare alarm
stages offline against the physical-limit row. Validation seeds only (5000+); never test seeds.

    python lab/det_lab.py train --fold 0          # bank trained without fold 0 (of 3)
    python lab/det_lab.py train --fold all        # bank trained on all 20 training episodes
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
import torch

import diagnosers
from diagnosers.networks.modules import build_module, export_module
from evaluation.tracks import TRACKS
from evaluation.tracks.track_data import TrackData

OUT = Path("results/det")
N_FOLDS = 3
#: the lab's training set and epochs: the leaderboard's 9 episodes and 800 epochs, so that four
#: banks train in the time the shared machine allows (the comparisons are between alarm stages
#: and calibrations on the same models)
N_TRAIN, LAB_EPOCHS = 9, 800
#: evaluation on validation seeds: the track's test range moved to 5000, its oracle calibration
#: (validation range) moved to 9000
VAL_TEST, VAL_CAL = 5000, 9000


def val_track(name: str, n_healthy: int = 100, n_faulty: int = 20):
    return (
        TRACKS[name]
        .with_seeds(test=VAL_TEST, validation=VAL_CAL)
        .replace(n_healthy=n_healthy, n_faulty=n_faulty)
    )


def folds(n: int, k: int = N_FOLDS) -> list[np.ndarray]:
    return np.array_split(np.arange(n), k)


def train(fold: str) -> None:
    data = TrackData(track=val_track("paper").replace(n_train=N_TRAIN))
    eps = data.train_episodes()
    n = len(eps)
    if fold == "all":
        idx = np.arange(n)
    else:
        out = folds(n)[int(fold)]
        idx = np.setdiff1d(np.arange(n), out)
    det = diagnosers.make("lrgf-mem", max_epochs=LAB_EPOCHS)
    det.channels_ = eps[0].channels
    ch = {c: i for i, c in enumerate(det.channels_)}
    rel = det._relations()
    det.in_idx_ = [np.array([ch[c] for c in ins]) for _, ins in rel]
    det.out_idx_ = np.array([ch[o] for o, _ in rel])
    t0 = time.perf_counter()
    nets, mems, v_paper, fits = det._train_models([eps[i].y for i in idx])
    wall = time.perf_counter() - t0
    configs, tensors = [], {}
    for j, (net, mem) in enumerate(zip(nets, mems, strict=True)):
        c1, s1 = export_module(net)
        c2, s2 = export_module(mem)
        configs.append({"lrgf": c1, "mem": c2})
        tensors.update({f"{j}.lrgf.{k}": v for k, v in s1.items()})
        tensors.update({f"{j}.mem.{k}": v for k, v in s2.items()})
    d = OUT / "models" / f"fold-{fold}"
    d.mkdir(parents=True, exist_ok=True)
    (d / "models.json").write_text(json.dumps(configs))
    torch.save(tensors, d / "weights.pt")
    meta = {
        "train_idx": idx.tolist(),
        "wall_s": wall,
        "v_paper": v_paper,
        "fit_loss": [f.best_val_loss for f in fits],
    }
    (d / "meta.json").write_text(json.dumps(meta))
    print(f"fold {fold}: trained on {len(idx)} episodes in {wall:.0f} s")


def load_models(fold: str):
    d = OUT / "models" / f"fold-{fold}"
    configs = json.loads((d / "models.json").read_text())
    tensors = torch.load(d / "weights.pt", weights_only=True)
    nets, mems = [], []
    for j, cfg in enumerate(configs):
        for part, store in (("lrgf", nets), ("mem", mems)):
            prefix = f"{j}.{part}."
            sd = {k[len(prefix) :]: v for k, v in tensors.items() if k.startswith(prefix)}
            m = build_module(cfg[part], sd)
            m.eval()
            store.append(m)
    return nets, mems


# ---- validation episodes and the physical-limit row ---------------------------------------------
TRACK_NAMES = ("paper", "small", "incipient")
FAULTS = ("f1", "f2", "f3", "f4")


def _episode_cache() -> dict:
    """Validation episodes (100 healthy, 20 per fault and track) and oracle scores, cached."""
    path = OUT / "episodes.npz"
    if path.exists():
        z = np.load(path, allow_pickle=False)
        return {k: z[k] for k in z.files}
    from evaluation.metrics import episode_scores
    from evaluation.tracks.oracle import PhysicalLimit

    arrays: dict[str, np.ndarray] = {}
    for name in TRACK_NAMES:
        data = TrackData(track=val_track(name))
        oracle = PhysicalLimit(data).fit()
        cells = data.cells() if name == "paper" else [c for c in data.cells() if c[0] != "nominal"]
        for sc, seed in cells:
            le = data.load_test(sc, seed)
            ep = le.episode
            key = f"nominal/{seed}" if sc == "nominal" else f"{name}/{sc}/{seed}"
            arrays[f"y:{key}"] = ep.y
            arrays[f"onset:{key}"] = np.array(-1 if ep.fault_onset is None else ep.fault_onset)
            if sc != "nominal" or name == "paper":
                s = episode_scores(oracle.detect(ep).alarm, ep.fault_onset)
                arrays[f"oracle:{name}:{key}"] = np.array([s["r_fd"], s["r_td"], s["t_dt"]])
        print(f"cached {name}", flush=True)
    # training faults (training seeds only): each fault at its paper size and its healthy twin
    data = TrackData(track=val_track("paper"))
    for sc in FAULTS:
        for seed in range(1000, 1005):
            ep = data.load_test(sc, seed).episode
            arrays[f"y:trainfault/{sc}/{seed}"] = ep.y
            arrays[f"onset:trainfault/{sc}/{seed}"] = np.array(ep.fault_onset or -1)
    np.savez(path, **arrays)
    return arrays


def residual_cache(fold: str) -> dict:
    """(y_out − y_m, y_e) of every cached episode (and the out-of-fold training episodes)."""
    path = OUT / f"resid-{fold}.npz"
    if path.exists():
        z = np.load(path, allow_pickle=False)
        return {k: z[k] for k in z.files}
    nets, mems = load_models(fold)
    det = diagnosers.make("lrgf-mem")
    eps = _episode_cache()
    tr = TrackData(track=val_track("paper").replace(n_train=N_TRAIN)).train_episodes()
    ch = {c: i for i, c in enumerate(tr[0].channels)}
    rel = det._relations()
    in_idx = [np.array([ch[c] for c in ins]) for _, ins in rel]
    out_idx = np.array([ch[o] for o, _ in rel])

    def parts(y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        ym = np.column_stack([n.predict(y[:, i])[:, 0] for n, i in zip(nets, in_idx, strict=True)])
        ye = np.column_stack([m.predict(y[:, i])[:, 0] for m, i in zip(mems, in_idx, strict=True)])
        return y[:, out_idx] - ym, ye

    res = {}
    for k, v in eps.items():
        if k.startswith("y:"):
            res[f"r:{k[2:]}"], res[f"e:{k[2:]}"] = parts(v)
    for i, ep in enumerate(tr):
        res[f"r:train/{i}"], res[f"e:train/{i}"] = parts(ep.y)
    np.savez(OUT / f"resid-{fold}.npz", **res)
    return res


def _main_extra(a) -> None:
    if a.cmd == "cache":
        _episode_cache()
    elif a.cmd == "resid":
        residual_cache(a.fold)


if __name__ == "__main__":
    ap = argparse.ArgumentParser()
    sub = ap.add_subparsers(dest="cmd", required=True)
    t = sub.add_parser("train")
    t.add_argument("--fold", required=True)
    sub.add_parser("cache")
    r = sub.add_parser("resid")
    r.add_argument("--fold", required=True)
    a = ap.parse_args()
    if a.cmd == "train":
        train(a.fold)
    else:
        _main_extra(a)
