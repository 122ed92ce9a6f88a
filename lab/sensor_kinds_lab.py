"""Record ``sensor-validation`` on every kind of the ``sensor`` track, per kind and channel.

Fits ``sensor-validation`` as ``lab/sensor_validation_lab.py`` does (the track's healthy
training seeds plus one labelled 400-sample episode per kind: they only name the classes),
then runs each kind's track episode (the channel, size and onset each seed draws) on the
seeds given and saves per episode what the rule reads and said: the bank's whitened
innovations and dedicated residuals, the readings, the kind and channel named per sample.
The healthy training records' bank outputs and the fitted limits are saved beside, so that
``lab/sensor_kinds_replay.py`` re-scores the decision rule (``decide_run``) on the saved
arrays in seconds instead of a bank run per episode. Prints the summary of
``lab/sensor_kinds_replay.py`` at the end. Validation seeds 5000.., fresh ones 6300..
(never a test seed). Record in ``lab/sensor-validation.md``. ``--healthy N`` also runs N
healthy test-plant episodes from ``--seed-start`` and prints their false-alarm rate r_fd (the
bank only names, so it is the same with it as without).

    PYTHONPATH=$PWD python lab/sensor_kinds_lab.py --faulty 40 --seed-start 5000 \
        --kinds sensor-bias --out /tmp/sk/val
    PYTHONPATH=$PWD python lab/sensor_kinds_lab.py --faulty 40 --seed-start 6600 \
        --kinds sensor-bias --glr-window 3000 --glr-ramp 20 --glr-names kind --out /tmp/sk/f
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from evaluation.metrics.detection_metrics import r_fd
from evaluation.metrics.intervals import bootstrap_ci
from fcc_env import FaultSpec
from fcc_env.params import MEASUREMENT_NAMES

# ``python lab/<script>.py`` puts lab/ first on the path, not the repository root
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from lab.sensor_isolation_replay import fitted
from lab.sensor_kinds_replay import KIND_NAMES, summarise


def _recorder(det):
    """Wrap ``det.bank_.run`` so that the last bank output stays readable."""
    stash = {}
    run = det.bank_.run

    def keep(M, P, Y):
        stash["out"] = out = run(M, P, Y)
        return out

    det.bank_.run = keep
    return stash


#: Samples before the onset from which the all-sensor filter's prior is kept, and the most
#: samples after it (``lab/sensor_glr_bank.py`` starts its hypotheses from these priors).
BEFORE, AFTER = 10, 300


def _record(det, stash, y: np.ndarray, onset: int | None = None) -> dict[str, np.ndarray]:
    """What the rule reads and said over ``y``; with ``onset``, also the first alarm at or after
    it and the all-sensor filter's priors from ``onset − BEFORE`` to ``onset + AFTER``."""
    det._reset()
    C = det.bank_.n_channels
    Y = np.ascontiguousarray(y, dtype=np.float64)
    _, _, kind, channel, _, _ = det._checks(Y)
    out = stash["out"]
    extra: dict[str, np.ndarray] = {}
    if onset is not None:
        k0 = max(onset - BEFORE, 0)
        k1 = min(onset + AFTER, len(Y))
        after = np.flatnonzero(kind[onset:] > 0)
        extra = {
            "prior_k0": np.array(k0),
            "prior_m": out.prior_m[k0:k1],
            "prior_p": out.prior_p[k0:k1],
            "t_alarm": np.array(onset + after[0] if after.size else -1),
        }
    return {
        "white": out.white.astype(np.float32),
        "ded": out.dedicated,
        "y": np.ascontiguousarray(Y[:, :C]),
        "y_all": Y,
        "kind": kind,
        "channel": channel,
        **extra,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--faulty", type=int, default=8, help="episodes per kind")
    ap.add_argument("--seed-start", type=int, default=5000)
    ap.add_argument("--kinds", default=",".join(KIND_NAMES))
    ap.add_argument("--train", type=int, default=4)
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--glr-window", type=int, default=0, help="sensor-validation's glr_window")
    ap.add_argument("--glr-ramp", type=float, default=0.0, help="sensor-validation's glr_ramp")
    ap.add_argument(
        "--glr-names", choices=("both", "kind"), default="both", help="sensor-validation's"
    )
    ap.add_argument("--glr-restart", type=int, default=0, help="sensor-validation's")
    ap.add_argument("--healthy", type=int, default=0, help="healthy episodes: r_fd")
    args = ap.parse_args()
    if args.seed_start < 1000:
        raise SystemExit(f"--seed-start {args.seed_start}: test seeds 0-999 are not for the lab")
    c0 = time.process_time()
    track, data, det = fitted(
        args.train,
        glr_window=args.glr_window,
        glr_ramp=args.glr_ramp,
        glr_names=args.glr_names,
        glr_restart=args.glr_restart,
    )
    args.out.mkdir(parents=True, exist_ok=True)
    stash = _recorder(det)
    if not (args.out / "limits.npz").exists():
        np.savez(args.out / "limits.npz", **det.limits_)
        params = {k: v for k, v in det.get_params().items() if isinstance(v, int | float)}
        (args.out / "params.json").write_text(json.dumps(params, indent=1))
        meta = {"sample_time_s": det.sample_time_s_, "channels": list(det.channels_)}
        (args.out / "meta.json").write_text(json.dumps(meta, indent=1))
        for i, ep in enumerate(data.train_episodes()):
            np.savez_compressed(args.out / f"healthy-{i}.npz", **_record(det, stash, ep.y))
    print(f"fitted: {time.process_time() - c0:.0f} s CPU", flush=True)
    for col in args.kinds.split(","):
        for seed in range(args.seed_start, args.seed_start + args.faulty):
            path = args.out / f"{col}-{seed}.npz"
            if path.exists():
                continue
            spec = track.fault_spec(col, seed)
            [le] = data.simulate([seed], spec, test=True)
            ep = le.episode
            onset = ep.fault_onset
            if onset is None or onset >= ep.n_samples:
                continue
            rec = _record(det, stash, ep.y, onset)
            np.savez_compressed(
                path,
                **rec,
                true=MEASUREMENT_NAMES.index(str(spec.channel)),
                onset=onset,
                size=spec.magnitude,
                col=KIND_NAMES.index(col),
            )
            after = rec["kind"][onset:]
            al = after > 0
            kc = np.mean(after[al] == KIND_NAMES.index(col) + 1) if al.any() else np.nan
            cc = np.mean(rec["channel"][onset:][al] == MEASUREMENT_NAMES.index(str(spec.channel)))
            print(
                f"{col} {seed} {spec.channel} size {spec.magnitude:.2f}: kind {kc:.3f} "
                f"channel {cc if al.any() else np.nan:.3f}  ({time.process_time() - c0:.0f} s CPU)",
                flush=True,
            )
    if args.healthy:
        _healthy(det, data, range(args.seed_start, args.seed_start + args.healthy))
    summarise(args.out, None)
    print(f"{time.process_time() - c0:.0f} s CPU (this process)")


def _healthy(det, data, seeds: range) -> None:
    """Print the false-alarm rate of ``det`` on healthy test-plant episodes of ``seeds``."""
    rates = []
    for seed in seeds:
        [le] = data.simulate([seed], FaultSpec(), test=True)
        alarm = det.detect(le.episode).alarm
        rates.append(r_fd(alarm, alarm.size))
        print(f"healthy {seed}: r_fd {rates[-1]:.4f}", flush=True)
    iv = bootstrap_ci(rates, rng=0)
    print(f"healthy r_fd over {len(rates)}: {iv.estimate:.4f} [{iv.low:.4f}, {iv.high:.4f}]")


if __name__ == "__main__":
    main()
