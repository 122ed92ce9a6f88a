"""Plant-mismatch lab: what part of each relation's error an episode's own inputs explain.

For the healthy validation episodes of a track (seeds 5000+) and a lab bank of
``lab/baseline_lab.py`` (``--tag``), prints the remaining error of every relation
(measured output minus the bank's centre) in °C RMS from sample ``--from`` on, after removing
per episode: nothing; its mean; a static linear function of the relation's inputs and network
output; a centred moving average of 200 samples; and, causally, an online regression
(:class:`diagnosers.stages.baseline.RegressionBaseline`, no forgetting, ridge ``--ridge``) on
first-order lags (``--lags``, samples) of the relation's standardised inputs and network
output, started at sample 300 and scored from ``--from``. Validation seeds only.

    python lab/plant_mismatch_lab.py --track uncertain --tag=_vf0 --n-healthy 30
    python lab/plant_mismatch_lab.py --track paper --tag=_vf0 --n-healthy 30
"""

from __future__ import annotations

import argparse

import numpy as np
from baseline_lab import at_least, episodes, load
from scipy.ndimage import uniform_filter1d

from diagnosers.stages.baseline import RegressionBaseline

START = 300  # the warm-up and the start of the online fit


def lags(text: str) -> tuple[float, ...]:
    """An argparse type: comma-separated time constants >= 1, refused by value otherwise."""
    try:
        out = tuple(float(t) for t in text.split(","))
    except ValueError:
        out = ()
    if not out or min(out) < 1:
        raise argparse.ArgumentTypeError(f"{text!r}; allowed: comma-separated numbers >= 1")
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--track", default="uncertain")
    ap.add_argument("--tag", default="_vf0", help="the lab bank's name suffix")
    ap.add_argument("--n-healthy", type=at_least(1), default=30)
    ap.add_argument("--lags", type=lags, default=(1.0, 10.0, 50.0, 200.0, 1000.0))
    ap.add_argument("--ridge", type=float, default=1.0)
    ap.add_argument("--from", dest="score_from", type=at_least(START + 1), default=1000)
    a = ap.parse_args()
    if not a.ridge > 0:
        ap.error(f"--ridge {a.ridge}; allowed: a number > 0")
    det, *_ = load(a.track, a.tag)
    det.set_params(baseline_lambda=1e-4, baseline_filters=list(a.lags), baseline_ridge=a.ridge)
    det._reset_baseline()  # the signal layout (the networks' scalers)
    eps = episodes(a.track, 60, 30 if a.track == "uncertain" else 10)
    keys = [k for k in eps if k.startswith("y:nominal/")][: a.n_healthy]
    names = ("nothing", "mean", "static linear", "moving average 200", "online lags (causal)")
    sq: dict[str, list[np.ndarray]] = {n: [] for n in names}
    s0 = a.score_from - START
    for key in keys:
        y = eps[key]
        y_m, centre = det._outputs_and_centre(y)
        r = (y[:, det.out_idx_] - centre)[START:]
        sig = det._signals(y, y_m)
        rb = RegressionBaseline(
            [len(i) + 1 for i in det.in_idx_], a.lags, forgetting_lambda=0.0, ridge=a.ridge
        )
        phi = rb.features_batch(sig)[START:]
        online = np.empty_like(r)
        for k in range(len(r)):
            online[k] = r[k] - rb.predict(phi[k])
            rb.adapt(phi[k], r[k])
        static = np.empty_like(r)
        for j in range(r.shape[1]):
            x = np.column_stack([np.ones(len(r)), sig[START:, j] - sig[START:, j].mean(0)])
            static[:, j] = r[:, j] - x @ np.linalg.lstsq(x, r[:, j], rcond=None)[0]
        for n, v in zip(
            names,
            (
                r,
                r - r.mean(0),
                static,
                r - uniform_filter1d(r, 200, axis=0, mode="nearest"),
                online,
            ),
            strict=True,
        ):
            sq[n].append(np.mean(v[s0:] ** 2, axis=0))
    outputs = ", ".join(det.channels_[i] for i in det.out_idx_)
    print(f"{a.track}, bank {a.tag}, {len(keys)} healthy validation episodes, samples "
          f"{a.score_from}.., °C RMS per relation ({outputs}):")  # fmt: skip
    for n in names:
        print(f"  {n:22s} " + " / ".join(f"{v:.3f}" for v in np.sqrt(np.mean(sq[n], axis=0))))


if __name__ == "__main__":
    main()
