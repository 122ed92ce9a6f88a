"""Baseline lab: ``lrgf-glr``'s alarm stage with and without the held baseline, against the
physical-limit row, on validation seeds only (5000+ for episodes, 9000+ for the oracle's
calibration). The bank is trained once per track (training seeds 1000+) and cached with its
out-of-fold calibration records; the alarm-stage variants are re-calibrated from them.

    python lab/baseline_lab.py train --track paper
    python lab/baseline_lab.py train --track paper --tag=_rg1x10 --params '{"n_hidden": [5, 10, 5]}'
    python lab/baseline_lab.py eval --track paper --lambdas 0,0.005,0.01,0.02 --holds 0.5,1
"""

from __future__ import annotations

import argparse
import json
import re
import time
from pathlib import Path

import numpy as np

import diagnosers
from diagnosers.lrgf.lrgf_glr import LRGFGLR
from evaluation.metrics import episode_scores
from evaluation.tracks import TRACKS
from evaluation.tracks.oracle import PhysicalLimit
from evaluation.tracks.track_data import TrackData

OUT = Path("results/baseline_lab")
FAULTS = ("f1", "f2", "f3", "f4")


def parse_set(text: str) -> dict:
    """``--set`` text ``k=v,k=v`` with JSON values; a comma inside a value (a list) stays.

    Raises ValueError naming the piece that is not ``key=<JSON value>``.
    """
    out = {}
    for kv in (kv for kv in re.split(r",(?=[A-Za-z_]\w*=)", text) if kv):
        key, sep, value = kv.partition("=")
        try:
            if not sep or not key.isidentifier():
                raise ValueError
            out[key] = json.loads(value)
        except ValueError:
            raise ValueError(
                f"--set {kv!r}; allowed: key=value pairs with JSON values, "
                "e.g. slow_ewma_lambda=[0.08,0.02],false_alarm_target=0.03"
            ) from None
    return out


def at_least(low: int):
    """An argparse type: an integer >= ``low``, refused by value and range otherwise."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            value = None
        if value is None or value < low:
            raise argparse.ArgumentTypeError(f"{text!r}; allowed: an integer >= {low}")
        return value

    return parse


def shares(text: str) -> list[float]:
    """An argparse type: comma-separated numbers in (0, 1), refused by value and range."""
    out = []
    for piece in text.split(","):
        try:
            value = float(piece)
        except ValueError:
            value = float("nan")
        if not 0.0 < value < 1.0:
            raise argparse.ArgumentTypeError(
                f"{piece!r}; allowed: numbers in (0, 1), comma-separated"
            )
        out.append(value)
    return out


def val_track(name: str, n_healthy: int, n_faulty: int):
    return (
        TRACKS[name]
        .with_seeds(test=5000, validation=9000)
        .replace(n_healthy=n_healthy, n_faulty=n_faulty)
    )


class _Stash(LRGFGLR):
    """lrgf-glr that keeps its out-of-fold calibration records."""

    def _calibrate(self, cal_parts, w, novelty=None):
        self.stash_ = (cal_parts, w, novelty)
        super()._calibrate(cal_parts, w, novelty)


def train(track: str, epochs: int, tag: str, n_train: int | None, params: dict) -> None:
    tr = val_track(track, 1, 1)
    data = TrackData(track=tr if n_train is None else tr.replace(n_train=n_train))
    det = _Stash(max_epochs=epochs, n_jobs=2, **params)
    t0 = time.perf_counter()
    det.fit(data.train_episodes())
    print(f"{track}{tag}: trained in {time.perf_counter() - t0:.0f} s", flush=True)
    d = OUT / f"{track}{tag}"
    d.mkdir(parents=True, exist_ok=True)
    cal_parts, w, novelty = det.stash_
    det.__class__ = LRGFGLR  # saved as the registered diagnoser, so that it loads
    np.savez(d / "cal.npz", **{f"r{i}": r for i, (r, _) in enumerate(cal_parts)},
             **{f"e{i}": e for i, (_, e) in enumerate(cal_parts)},
             **{f"d{i}": x for i, x in enumerate(novelty or [])}, w=w)  # fmt: skip
    det.save(d / "model")


def load(track: str, tag: str = ""):
    d = OUT / f"{track}{tag}"
    det = diagnosers.Diagnoser.load(d / "model")
    z = np.load(d / "cal.npz")
    n = sum(1 for k in z.files if k.startswith("r"))
    cal = [(z[f"r{i}"], z[f"e{i}"]) for i in range(n)]
    # a bank stored before the novelty records: the calibration sees none
    novelty = [z[f"d{i}"] for i in range(n)] if "d0" in z.files else None
    return det, cal, int(z["w"]), novelty


def calibration_records(track: str, cal: list) -> list[np.ndarray] | None:
    """The measurements of a bank's out-of-fold calibration records, in order (its training
    episodes; ``baseline_filters`` needs them), or None when the count differs (a bank trained
    with ``--n-train``)."""
    ys = [e.y for e in TrackData(track=val_track(track, 1, 1)).train_episodes()]
    return ys if len(ys) == len(cal) else None


def episodes(track: str, n_healthy: int, n_faulty: int, eval_track: str | None = None):
    name = eval_track or track
    path = OUT / f"episodes-{name}-{n_healthy}-{n_faulty}.npz"
    if path.exists():
        z = np.load(path)
        return {k: z[k] for k in z.files}
    data = TrackData(track=val_track(name, n_healthy, n_faulty))
    oracle = PhysicalLimit(data).fit()
    arrays = {}
    for sc, seed in data.cells():
        ep = data.load_test(sc, seed).episode
        key = f"{sc}/{seed}"
        arrays[f"y:{key}"] = ep.y
        arrays[f"onset:{key}"] = np.array(-1 if ep.fault_onset is None else ep.fault_onset)
        s = episode_scores(oracle.detect(ep).alarm, ep.fault_onset)
        arrays[f"oracle:{key}"] = np.array([s["r_fd"], s["r_td"], s["t_dt"]])
    np.savez(path, **arrays)
    return arrays


def evaluate(det, eps) -> dict:
    rows: dict[str, list] = {}
    for k in eps:
        if not k.startswith("y:"):
            continue
        key = k[2:]
        sc = key.split("/")[0]
        onset = int(eps[f"onset:{key}"])
        ep = diagnosers.Episode(
            eps[k], det.channels_, 10.0, fault_onset=None if onset < 0 else onset
        )
        s = episode_scores(det.detect(ep).alarm, ep.fault_onset)
        rows.setdefault(sc, []).append((s["r_fd"], s["r_td"], s["t_dt"], *eps[f"oracle:{key}"]))
    out = {}
    for sc, r in rows.items():
        a = np.array(r, dtype=float)
        if sc == "nominal":
            per = a[:, 0]
            out[sc] = {
                "r_fd": float(per.mean()),
                "r_fd_max": float(per.max()),
                "oracle_r_fd": float(np.nanmean(a[:, 3])),
            }
        else:
            out[sc] = {
                "r_td": float(np.nanmean(a[:, 1])),
                "t_dt": float(np.nanmean(a[:, 2])),
                "oracle_r_td": float(np.nanmean(a[:, 4])),
                "oracle_t_dt": float(np.nanmean(a[:, 5])),
                "r_fd_pre": float(np.nanmean(a[:, 0])),
            }
    return out


def main() -> None:
    ap = argparse.ArgumentParser()
    sub = ap.add_subparsers(dest="cmd", required=True)
    t = sub.add_parser("train")
    t.add_argument("--track", default="paper")
    t.add_argument("--epochs", type=int, default=800)
    t.add_argument("--n-train", type=int, default=None, help="healthy training episodes")
    t.add_argument("--params", default="{}", help="hyperparameters as JSON, e.g. "
                   '\'{"n_hidden": [5, 10, 5]}\'')  # fmt: skip
    for p in (t, e := sub.add_parser("eval")):
        p.add_argument("--tag", default="", help="the bank's name suffix")
    e.add_argument("--track", default="paper", help="the trained bank's track")
    e.add_argument("--eval-tracks", default=None, help="tracks whose episodes to score")
    e.add_argument("--lambdas", default="0,0.01")
    e.add_argument("--holds", default="0.5")
    e.add_argument("--n-healthy", type=int, default=60)
    e.add_argument("--n-faulty", type=int, default=10)
    e.add_argument("--set", default="", help="extra hyperparameters k=v,k=v (JSON values)")
    a = ap.parse_args()
    if a.cmd == "train":
        train(a.track, a.epochs, a.tag, a.n_train, json.loads(a.params))
        return
    try:
        extra = parse_set(a.set)
    except ValueError as err:
        ap.error(str(err))
    det, cal, w, novelty = load(a.track, a.tag)
    cal_ys = calibration_records(a.track, cal)
    tracks = (a.eval_tracks or a.track).split(",")
    eps = {tr: episodes(a.track, a.n_healthy, a.n_faulty, tr) for tr in tracks}
    results = []
    for lam in [float(x) for x in a.lambdas.split(",")]:
        for hold in [float(x) for x in a.holds.split(",")]:
            det.set_params(baseline_lambda=lam, baseline_hold=hold, **extra)
            det._calibrate(cal, w, novelty, cal_ys)
            det._fitted_ = True  # the lab re-calibrates the stored bank in place
            for tr in tracks:
                res = evaluate(det, eps[tr])
                nom = res.get("nominal", {})
                line = f"{tr:9s} lam={lam:<6} hold={hold:<4}"
                if nom:
                    line += f" r_fd {nom['r_fd']:.4f} (max {nom['r_fd_max']:.3f}; oracle {nom['oracle_r_fd']:.4f})"
                for f in FAULTS:
                    if f in res:
                        r = res[f]
                        line += (f" | {f} {r['r_td']:.3f}/{r['t_dt']:.0f} "
                                 f"(o {r['oracle_r_td']:.3f}/{r['oracle_t_dt']:.0f})")  # fmt: skip
                print(line, flush=True)
                results.append({"track": tr, "lambda": lam, "hold": hold, **extra, "res": res})
    (OUT / f"eval-{a.track}{a.tag}-{int(time.time())}.json").write_text(
        json.dumps(results, indent=1)
    )


if __name__ == "__main__":
    main()
