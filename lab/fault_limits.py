"""Part B: largest fault magnitude without termination, and detectability magnitudes.

python lab/fault_limits.py limits   |   python lab/fault_limits.py detect
"""

import sys
from collections import Counter

import numpy as np

import fcc_env
from fcc_env.scenarios import FAULTS, Scenario

SEEDS = list(range(20))
T = 4000


def run(sc, m, seeds=SEEDS, n=T, **kw):
    fault, plant = fcc_env.env_request(scenario=sc, fault_magnitude=m, **kw)
    return fcc_env.simulate_episodes(seeds, n, fault=fault, plant=plant)


def summary(r):
    reasons = Counter(x for x in r.termination_reasons if x)
    onset = r.fault_onsets[0]
    after = [int(k) - onset for k in r.terminated_at if k >= 0]
    return reasons, after


def limits():
    for sc in ("f1", "f2", "f3", "f4"):
        onset = FAULTS[Scenario(sc)].default_onset
        grid = np.round(np.arange(0.01, 0.91, 0.01), 3)
        last_ok, first_bad = 0.0, None
        rows = []
        for m in grid:
            r = run(sc, float(m))
            reasons, after = summary(r)
            rows.append((m, reasons, after))
            if not reasons:
                if first_bad is None:
                    last_ok = m
            elif first_bad is None:
                first_bad = m
            if first_bad is not None and m >= first_bad + 0.1:
                break
        # refine between last_ok and first_bad
        lo, hi = last_ok, first_bad
        if hi is not None:
            for _ in range(7):
                mid = 0.5 * (lo + hi)
                if summary(run(sc, mid))[0]:
                    hi = mid
                else:
                    lo = mid
        print(f"== {sc} (onset {onset}): no termination up to {lo:.4f}; first termination at {hi}")
        for m, reasons, after in rows:
            if reasons or m in (last_ok,):
                med = int(np.median(after)) if after else None
                print(
                    f"   m={m:.2f}: {sum(reasons.values())}/20 {dict(reasons)} "
                    f"samples after onset min/med/max {min(after) if after else '-'}/{med}/"
                    f"{max(after) if after else '-'}"
                )


def detect():
    """Magnitude at which max over 5 temps |faulty − healthy| (noise-free) reaches 1/2/3 × 0.3 °C."""
    healthy = run("nominal", None)
    mags = np.array([0.0025, 0.005, 0.01, 0.02, 0.03, 0.05, 0.075, 0.1, 0.15, 0.2, 0.3])
    for sc in ("f1", "f2", "f3", "f4"):
        onset = FAULTS[Scenario(sc)].default_onset
        out = {}
        for lag in (50, 200):
            eff = []
            for m in mags:
                r = run(sc, float(m), n=onset + lag + 1)
                d = np.abs(r.y_clean[:, onset + lag, 3:8] - healthy.y_clean[:, onset + lag, 3:8])
                dw = np.abs(
                    r.y_clean[:, onset : onset + lag + 1, 3:8]
                    - healthy.y_clean[:, onset : onset + lag + 1, 3:8]
                ).max(axis=(1, 2))
                eff.append(
                    (
                        np.median(d.max(axis=1)),
                        np.median(dw),
                        fcc_env.MEASUREMENT_NAMES[3 + int(np.argmax(np.median(d, axis=0)))],
                    )
                )
            out[lag] = eff
        print(f"== {sc} onset {onset}")
        for lag, eff in out.items():
            at = np.array([e[0] for e in eff])
            win = np.array([e[1] for e in eff])

            def m_for(level, curve):
                idx = np.nonzero(curve >= level)[0]
                if len(idx) == 0:
                    return None
                i = idx[0]
                if i == 0:
                    return mags[0]
                # linear interpolation in m
                return float(np.interp(level, [curve[i - 1], curve[i]], [mags[i - 1], mags[i]]))

            print(
                f"   +{lag}: |Δ| at sample (max of 5 temps, median over seeds) per m: "
                + ", ".join(f"{m:g}:{a:.2f}({c})" for m, (a, _, c) in zip(mags, eff, strict=True))
            )
            print(
                "        m for 1/2/3σ (at sample): "
                + " / ".join(
                    str(None if (v := m_for(k * 0.3, at)) is None else round(v, 4))
                    for k in (1, 2, 3)
                )
                + "   (peak within window): "
                + " / ".join(
                    str(None if (v := m_for(k * 0.3, win)) is None else round(v, 4))
                    for k in (1, 2, 3)
                )
            )


if __name__ == "__main__":
    {"limits": limits, "detect": detect}[sys.argv[1]]()
