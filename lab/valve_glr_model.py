"""What ``valve-glr`` stands on: the riser outlet's regression on the valve command and the
riser's measured inputs (which regressors, how white the residual), and how fast a sticking
valve's position leaves its command after the onset (the information a test of "the valve does
not follow its command" has).

Training seeds only (1000-1003 healthy, 3000 samples, closed loop; 1010-1015 with
``valve-stiction`` at ``--sizes``, onset 2000):

* ``--model``: per regressor set, the least-squares coefficients of T_rx on the recorded
  command u_F and the set (noisy records), the residual's std and lag-1 / lag-10
  autocorrelation, and the same fit on the noise-free records (``y_clean``; the command is
  exact in both) with the std of its change over 30 samples;
* ``--information``: the true position − command δ (kg/s) 5, 10, 20, 40 and 80 samples after
  the onset, and the known-path log-likelihood ratio Σ (gain δ)² / (2 σ²) 12, 24 and 48 samples
  after it (gain and σ: the adopted regression's, σ the white part of its residual).

    PYTHONPATH=$PWD python lab/valve_glr_model.py --model --information
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

import fcc_env
from fcc_env import FaultSpec, simulate_episodes
from fcc_env.closed_loop import CLOSED_LOOP_CHANNELS

IX = {c: i for i, c in enumerate(CLOSED_LOOP_CHANNELS)}
SETS = (
    [],
    ["T_rg2"],
    ["T_rg2", "T_fp"],
    ["T_rg2", "T_fp", "T_rg1"],
    ["T_rg2", "T_fp", "T_d1"],
    ["T_rg2", "T_fp", "T_dg"],
)
ONSET = 2000


def fit(batch, regressors: list[str], clean: bool) -> tuple[np.ndarray, np.ndarray]:
    """Coefficients (u_F, regressors, intercept) and the residuals ``(B, T)``."""
    x, y = [], []
    for b in range(batch.observations.shape[0]):
        rec = batch.y_clean[b] if clean else batch.observations[b]
        cols = [batch.observations[b, :, IX["u_F"]]] + [rec[:, IX[c]] for c in regressors]
        x.append(np.column_stack([*cols, np.ones(rec.shape[0])]))
        y.append(rec[:, IX["T_rx"]])
    coef, *_ = np.linalg.lstsq(np.concatenate(x), np.concatenate(y), rcond=None)
    return coef, np.stack([yy - xx @ coef for xx, yy in zip(x, y, strict=True)])


def lag(r: np.ndarray, k: int) -> float:
    return float(np.corrcoef(r[:, :-k].ravel(), r[:, k:].ravel())[0, 1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--model", action="store_true")
    ap.add_argument("--information", action="store_true")
    ap.add_argument("--sizes", type=float, nargs="*", default=[0.02, 0.1, 0.3])
    args = ap.parse_args()
    t0 = time.process_time()
    plant = fcc_env.PlantConfig.build(regulatory=True)
    healthy = simulate_episodes(list(range(1000, 1004)), 3000, plant=plant)
    if args.model:
        print(
            "| regressors | coefficients (u_F, …) | std | lag 1 / 10 | clean std | clean lag 10 "
            "| clean 30-sample change std |"
        )
        print("|---|---|---|---|---|---|---|")
        for regs in SETS:
            coef, r = fit(healthy, regs, clean=False)
            _, rc = fit(healthy, regs, clean=True)
            d30 = (rc[:, 30:] - rc[:, :-30]).std()
            print(
                f"| {', '.join(regs) or 'none'} | {', '.join(f'{c:.3f}' for c in coef[:-1])} | "
                f"{r.std():.3f} | {lag(r, 1):.2f} / {lag(r, 10):.2f} | {rc.std():.3f} | "
                f"{lag(rc, 10):.2f} | {d30:.3f} |"
            )
    if args.information:
        coef, r = fit(healthy, ["T_rg2", "T_fp"], clean=False)
        gain, sigma = coef[0], float(np.diff(r, axis=1).std() / math.sqrt(2.0))
        print(f"gain {gain:.4f} °C per kg/s, σ {sigma:.3f} °C")
        for size in args.sizes:
            spec = FaultSpec(scenario="valve-stiction", magnitude=size, onset=ONSET)
            b = simulate_episodes(list(range(1010, 1016)), ONSET + 100, plant=plant, fault=spec)
            delta = b.inputs[:, :, 0] - b.observations[:, :, IX["u_F"]]
            after = delta[:, ONSET:]
            llr = np.cumsum((gain * after) ** 2, axis=1) / (2 * sigma**2)
            for i, seed in enumerate(b.seeds):
                print(
                    f"S={size:g} seed {seed}: δ at +5/10/20/40/80 "
                    f"{np.round(after[i, [5, 10, 20, 40, 80]], 1).tolist()} kg/s; "
                    f"known-path LLR at +12/24/48 {np.round(llr[i, [12, 24, 48]], 1).tolist()}"
                )
    print(f"{time.process_time() - t0:.0f} s CPU")


if __name__ == "__main__":
    main()
