"""The FCC state estimator's innovations: whiteness when healthy, and how far each fault moves
them (issue 42 item 1). Training and validation seeds only.

    python lab/filter_lab.py whiteness --seeds 1000-1019
    python lab/filter_lab.py whiteness --seeds 1000-1019 --set input_walk_std_C=0.05
    python lab/filter_lab.py faults --seeds 5000-5019
    python lab/filter_lab.py whiteness --seeds 1000-1009 --closed

``whiteness``: per channel, the mean, variance and lag-1 autocorrelation of the standardised
innovations of healthy episodes (samples from ``--skip`` on), the normalised innovation squared
(8 when the model is right), the RMSE of the estimated true inputs against the readings', and
the steps declared per 1000 samples.

``faults``: per fault f1-f4 at the paper's sizes and onsets, the mean standardised innovation
per channel over the ``--window`` samples after onset, and its signal-to-noise: that shift over
the standard deviation of the same window's mean in the healthy episodes of the same seeds.
``--set name=value`` changes a :class:`diagnosers.filters.UKFConfig` field (repeatable;
``parameters=A_cr,k_cb``); ``--uncertain`` draws each episode's plant as the ``uncertain``
track does (the filter keeps the nominal parameters it is given).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import fcc_env
from diagnosers.filters import FCCStateEstimator, UKFConfig
from fcc_env.uncertainty import PlantUncertainty

INPUT_COLUMNS = {"R_ar": 1, "T_ar": 2, "T_fp": 3}


def seed_range(text: str) -> list[int]:
    lo, _, hi = text.partition("-")
    seeds = list(range(int(lo), int(hi or lo) + 1))
    if min(seeds) < 1000:
        raise argparse.ArgumentTypeError(f"{text!r}: test seeds (0-999) are not for the lab")
    return seeds


def config_of(a: argparse.Namespace, plant: fcc_env.PlantConfig) -> UKFConfig:
    changes = {}
    for item in a.set:
        name, _, value = item.partition("=")
        if name == "parameters":
            changes[name] = tuple(v for v in value.split(",") if v)
        else:
            words = {"None": None, "True": True, "False": False}
            changes[name] = words[value] if value in words else float(value)
    return UKFConfig.matching(plant, **changes)


def simulate(a: argparse.Namespace, plant: fcc_env.PlantConfig, **kw) -> fcc_env.BatchResult:
    draw = PlantUncertainty() if a.uncertain else None
    return fcc_env.simulate_episodes(a.seeds, a.samples, plant=plant, plant_uncertainty=draw, **kw)


def lag1(x: np.ndarray) -> np.ndarray:
    """Lag-1 autocorrelation per channel of (B, T, C), pooled over episodes."""
    x = x - x.mean(axis=1, keepdims=True)
    return (x[:, 1:] * x[:, :-1]).sum(axis=(0, 1)) / (x**2).sum(axis=(0, 1))


def whiteness(a: argparse.Namespace) -> None:
    plant = fcc_env.PlantConfig.build(regulatory=True if a.closed else None)
    b = simulate(a, plant)
    est = FCCStateEstimator(fcc_env.FCCParams(), config_of(a, plant))
    t0 = time.perf_counter()
    out = est.filter(b.observations)
    dt = time.perf_counter() - t0
    s = out.standardized[:, a.skip :]
    print(f"{len(a.seeds)} healthy episodes x {a.samples}, from sample {a.skip}; {dt:.1f} s")
    print(f"{'channel':<8} {'mean':>7} {'var':>6} {'lag1':>6}")
    for j, ch in enumerate(out.channels):
        print(f"{ch:<8} {s[..., j].mean():>7.3f} {s[..., j].var():>6.3f} {lag1(s)[j]:>6.3f}")
    print(f"NIS mean {out.nis[:, a.skip :].mean():.3f} (8 when white)")
    for name, col in INPUT_COLUMNS.items():
        true = b.inputs[:, a.skip :, col]
        err_est = out.state(name)[:, a.skip :] - true
        err_read = b.observations[:, a.skip :, col - 1] - true
        print(
            f"{name}: RMSE estimate {np.sqrt(np.mean(err_est**2)):.4f}, "
            f"reading {np.sqrt(np.mean(err_read**2)):.4f}"
        )
    if a.uncertain:
        drawn = [PlantUncertainty().draw(s).params for s in a.seeds]
        for name in est.config.parameters:
            true = np.array([getattr(p, name) for p in drawn])
            nominal = getattr(fcc_env.FCCParams(), name)
            last = out.state(name)[:, -1]
            print(
                f"{name}: drawn/nominal − 1 RMS {np.sqrt(np.mean((true / nominal - 1) ** 2)):.4f}, "
                f"estimate/drawn − 1 at the end RMS {np.sqrt(np.mean((last / true - 1) ** 2)):.4f}"
            )
    if "f_coke" in out.state_names:
        true = b.inputs[:, a.skip :, 5]
        err = out.state("f_coke")[:, a.skip :] - true
        print(f"f_coke: RMSE {np.sqrt(np.mean(err**2)):.5f} (drift std {true.std():.5f})")
    per_k = out.steps[:, a.skip :].mean(axis=(0, 1)) * 1000
    print("steps per 1000 samples (R_ar, T_ar, T_fp):", np.round(per_k, 2))
    print("status counts:", np.bincount(out.status.ravel(), minlength=4))


def faults(a: argparse.Namespace) -> None:
    plant = fcc_env.PlantConfig.build(regulatory=True if a.closed else None)
    est = FCCStateEstimator(fcc_env.FCCParams(), config_of(a, plant))
    healthy = est.filter(simulate(a, plant).observations)
    chans = healthy.channels
    print(f"{len(a.seeds)} episodes x {a.samples} per fault; window {a.window} samples after onset")
    print("healthy whole-episode standardised innovations (from sample 100):")
    s = healthy.standardized[:, 100:]
    print("  mean " + " ".join(f"{v:>7.3f}" for v in s.mean(axis=(0, 1))))
    print("  var  " + " ".join(f"{v:>7.3f}" for v in s.var(axis=(0, 1))))
    print("  lag1 " + " ".join(f"{v:>7.3f}" for v in lag1(s)))
    head = " ".join(f"{c:>7}" for c in chans)
    for name in ("f1", "f2", "f3", "f4"):
        spec = fcc_env.FaultSpec(scenario=name)
        b = simulate(a, plant, fault=spec)
        onset = b.fault_onsets[0]
        win = slice(onset, onset + a.window)
        out = est.filter(b.observations)
        shift = out.standardized[:, win].mean(axis=1)  # (B, C)
        noise = healthy.standardized[:, win].mean(axis=1).std(axis=0, ddof=1)
        trips = sum(t >= 0 for t in b.terminated_at)
        print(f"{name} (onset {onset}, {trips} episodes end outside the envelope)")
        print(f"  {'':<12} {head}")
        print(f"  {'shift [sd]':<12} " + " ".join(f"{v:>7.3f}" for v in shift.mean(axis=0)))
        print(f"  {'SNR':<12} " + " ".join(f"{v:>7.1f}" for v in shift.mean(axis=0) / noise))
        early = out.standardized[:, onset : onset + 30].mean(axis=(0, 1))
        print(f"  {'first 30':<12} " + " ".join(f"{v:>7.3f}" for v in early))
        nis = out.nis[:, win].mean()
        print(f"  NIS over the window {nis:.2f} (healthy {healthy.nis[:, win].mean():.2f})")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("what", choices=("whiteness", "faults"))
    ap.add_argument("--seeds", type=seed_range, default=seed_range("1000-1019"))
    ap.add_argument("--samples", type=int, default=4000)
    ap.add_argument("--skip", type=int, default=100, help="samples left out (whiteness)")
    ap.add_argument("--window", type=int, default=300, help="samples after onset (faults)")
    ap.add_argument("--closed", action="store_true", help="the closed-loop plant")
    ap.add_argument("--uncertain", action="store_true", help="each episode's plant drawn")
    ap.add_argument("--set", action="append", default=[], help="UKFConfig field=value")
    a = ap.parse_args()
    whiteness(a) if a.what == "whiteness" else faults(a)


if __name__ == "__main__":
    main()
