"""Input-noise lab: how much of a relation's held-out error comes from noisy measured inputs, and
how much a causal step-tracking input filter removes. Training seeds 1000+, validation 5000+.

    python lab/input_filter_lab.py --output T_rg1 --epochs 1500
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from diagnosers.networks.lrgf_net import LRGF
from diagnosers.networks.training import fit_lrgf
from evaluation.tracks import TRACKS
from evaluation.tracks.track_data import TrackData
from fcc_env.params import MEASUREMENT_NAMES

CH = list(MEASUREMENT_NAMES)
RELATIONS = {
    "T_rx": ["T_rg2", "T_fp"],
    "T_rg1": ["T_ar", "R_ar", "T_fp"],
    "T_rg2": ["T_rg1", "T_ar", "R_ar"],
}


def step_filter(x: np.ndarray, sigma: np.ndarray, k_jump: float = 4.0, h: float = 5.0,
                drift: float = 0.5) -> np.ndarray:  # fmt: skip
    """Causal piecewise-constant tracker per column (segment mean, reset on a jump or CUSUM)."""
    out = np.empty_like(x)
    n_ch = x.shape[1]
    for c in range(n_ch):
        s = sigma[c]
        total, n = x[0, c], 1
        gp = gm = 0.0
        since = 0  # samples since the CUSUM last left zero
        buf_start = 0
        for t in range(x.shape[0]):
            v = x[t, c]
            if t > 0:
                m = total / n
                z = (v - m) / s
                if abs(z) > k_jump * np.sqrt(1 + 1 / n):
                    total, n, gp, gm = v, 1, 0.0, 0.0
                    buf_start = t
                else:
                    gp = max(0.0, gp + z - drift)
                    gm = max(0.0, gm - z - drift)
                    if gp == 0.0 and gm == 0.0:
                        since = t
                    if gp > h or gm > h:
                        start = max(since, buf_start)
                        seg = x[start : t + 1, c]
                        total, n, gp, gm = float(seg.sum()), seg.size, 0.0, 0.0
                        buf_start = start
                    else:
                        total += v
                        n += 1
            out[t, c] = total / n
    return out


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--output", default="T_rg1")
    p.add_argument("--epochs", type=int, default=1500)
    p.add_argument("--n-train", type=int, default=9)
    p.add_argument("--n-val", type=int, default=10)
    a = p.parse_args()
    track = TRACKS["paper"].with_seeds(test=5000, validation=9000).replace(n_train=a.n_train)
    data = TrackData(track=track)
    train = data.train_episodes()
    ui = [CH.index(c) for c in RELATIONS[a.output]]
    yi = CH.index(a.output)
    noise = np.array([0.3 if c != "R_ar" else 0.005 for c in RELATIONS[a.output]])
    t0 = time.perf_counter()
    val = []
    for s in range(5000, 5000 + a.n_val):
        le = data.load_test("nominal", s)
        val.append((le.episode.y, le.episode.y_clean))
    print(f"simulated in {time.perf_counter() - t0:.0f} s")

    def sig(y):
        u = y[:, ui]
        scale = u.copy()
        scale[:, :] = 1.0
        if "R_ar" in RELATIONS[a.output]:
            j = RELATIONS[a.output].index("R_ar")
            scale[:, j] = np.abs(u[:, j])
        return noise * np.median(scale, axis=0)

    t0 = time.perf_counter()
    filt_train = [step_filter(e.y[:, ui], sig(e.y)) for e in train]
    filt_val = [step_filter(y[:, ui], sig(y)) for y, _ in val]
    print(f"filtered in {time.perf_counter() - t0:.1f} s")
    for y, yc in val[:3]:
        fv = step_filter(y[:, ui], sig(y))
        print(
            "input rms err raw", np.sqrt(np.mean((y[:, ui] - yc[:, ui]) ** 2, axis=0)),
            "filtered", np.sqrt(np.mean((fv - yc[:, ui]) ** 2, axis=0)),
        )  # fmt: skip
    for label, u_tr in (("raw", [e.y[:, ui] for e in train]), ("filtered", filt_train)):
        net = LRGF(len(ui), 5, 2, 1, initial_state="steady", steady_window=100, seed=101).double()
        t0 = time.perf_counter()
        fit_lrgf(net, u_tr, [e.y[:, [yi]] for e in train], lr=0.03, max_epochs=a.epochs,
                 patience=max(50, a.epochs // 5), seed=101)  # fmt: skip
        net.eval()
        print(f"trained on {label} inputs in {time.perf_counter() - t0:.0f} s")
        for ulabel in ("raw", "filtered", "true"):
            errs = []
            for (y, yc), fv in zip(val, filt_val, strict=True):
                u = {"raw": y[:, ui], "filtered": fv, "true": yc[:, ui]}[ulabel]
                e = yc[100:, yi] - net.predict(u)[100:, 0]
                errs.append(e)
            e = np.concatenate(errs)
            print(
                f"  model({label}) on {ulabel} inputs: error vs noise-free output RMS "
                f"{np.sqrt(np.mean(e**2)):.3f} °C (mean {e.mean():+.3f})"
            )


if __name__ == "__main__":
    main()
