"""Fingerprint every registered diagnoser's detections on a fixed set of FCC episodes.

Used to prove that a refactor changes no behaviour: run it before and after, then compare::

    python lab/detection_fingerprint.py --out /tmp/before.json
    python lab/detection_fingerprint.py --out /tmp/after.json --compare /tmp/before.json

Each diagnoser is built with its ``fast_params()`` (small, deterministic training), fitted on
three healthy training episodes (isolators also on labelled f1-f4 training episodes; detectors
that learn from faults, ``learns_from_faults``, also on f1-f4 at their paper onset and size on
the same training seeds, the episodes their ``fault_seeds`` once simulated themselves: the
simulation is prefix-invariant, so 2400 samples of them are the first 2400 of the 4000 they
had) and run with ``detect`` on one nominal and one episode per fault. The fingerprint is a SHA-256 of the
alarm, score signal, band and diagnosis arrays, so "identical" means bit-identical. Only the
public API is used (``diagnosers.make``, ``fast_params``, ``fcc_env.simulate_episodes``,
``Episode.from_batch``), so the script runs on both sides of a refactor.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
import time

import numpy as np

import diagnosers
import fcc_env
from diagnosers import Episode
from diagnosers.bank.relations import required_channels

N_SAMPLES = 2400
ONSET = 1200
TRAIN_SEEDS = [1000, 1001, 1002]
TEST_SEED = 5000  # a validation seed: never a test seed
SCENARIOS = ["nominal", "f1", "f2", "f3", "f4"]


def episodes(seeds: list[int], scenario: str, onset: int | None = ONSET) -> list[Episode]:
    """Episodes of ``scenario`` from ``onset`` (None: the fault's paper onset)."""
    onset = None if scenario == "nominal" else onset
    fault = fcc_env.FaultSpec(scenario=scenario, onset=onset)
    res = fcc_env.simulate_episodes(seeds, N_SAMPLES, fault=fault)
    return Episode.from_batch(res)


def digest(arrays: list[np.ndarray | None]) -> str:
    h = hashlib.sha256()
    for a in arrays:
        if a is None:
            h.update(b"none")
            continue
        a = np.asarray(a)
        h.update(str(a.dtype).encode() + str(a.shape).encode())
        h.update(a.tobytes() if a.dtype != object else repr(a.tolist()).encode())
    return h.hexdigest()


def fingerprint(names: list[str]) -> dict[str, dict[str, str]]:
    train = episodes(TRAIN_SEEDS, "nominal")
    faults = [ep for sc in SCENARIOS[1:] for ep in episodes(TRAIN_SEEDS, sc)]
    paper = [ep for sc in SCENARIOS[1:] for ep in episodes(TRAIN_SEEDS, sc, onset=None)]
    paper = [ep for ep in paper if ep.fault_onset is not None]
    tests = {sc: episodes([TEST_SEED], sc)[0] for sc in SCENARIOS}
    out: dict[str, dict[str, str]] = {}
    for name in names:
        t0 = time.perf_counter()
        cls = diagnosers.diagnoser_class(name)
        det = diagnosers.make(name, **cls.fast_params())
        learns = getattr(det, "learns_from_faults", False)  # the flag is newer than the script
        det.fit(train + faults if det.isolates else train + paper if learns else train)
        row = {}
        for sc, ep in tests.items():
            d = det.detect(ep)
            row[sc] = digest(
                [d.alarm, d.signal, d.lower, d.upper, d.residual, getattr(d, "diagnosis", None)]
            )
            row[sc + ":alarms"] = str(int(np.sum(d.alarm)))
        out[name] = row
        print(f"{name}: {time.perf_counter() - t0:.1f} s", file=sys.stderr)
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python lab/detection_fingerprint.py")
    ap.add_argument("--out", required=True, help="JSON file to write")
    ap.add_argument("--compare", help="a fingerprint JSON to compare with (exit 1 on a difference)")
    ap.add_argument("--diagnosers", help="comma-separated names (default: every registered one)")
    args = ap.parse_args(argv)
    names = args.diagnosers.split(",") if args.diagnosers else diagnosers.available()
    # the episodes are FCC-v0's: a diagnoser reading the closed-loop channels (u_F) is left out
    lacking = {n for n in names if not required_channels(n) <= set(fcc_env.MEASUREMENT_NAMES)}
    if lacking:
        print(f"left out (they read closed-loop channels): {sorted(lacking)}", file=sys.stderr)
    names = [n for n in names if n not in lacking]
    fp = fingerprint(names)
    with open(args.out, "w") as f:
        json.dump(fp, f, indent=1, sort_keys=True)
    if args.compare:
        with open(args.compare) as f:
            ref = json.load(f)
        bad = [
            f"{n}/{k}"
            for n in sorted(set(ref) | set(fp))
            for k in sorted(set(ref.get(n, {})) | set(fp.get(n, {})))
            if ref.get(n, {}).get(k) != fp.get(n, {}).get(k)
        ]
        print("identical" if not bad else "DIFFERENT: " + ", ".join(bad))
        return 1 if bad else 0
    return 0


if __name__ == "__main__":
    sys.exit(main())
