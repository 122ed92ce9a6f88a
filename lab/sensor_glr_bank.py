"""The GLR bank of bias hypotheses (``diagnosers.sensors.glr_bank``), offline on the records of
``sensor_kinds_lab.py``.

Per saved faulty episode, the bank starts from the all-sensor filter's prior at the first
alarm after the onset (``--delay`` samples before it, to study a start nearer the onset) and
names the channel of the largest GLR over the next ``--window`` samples, where it is ``--margin``
nats and ``--ratio`` times ahead of the second (else the saved rule names); the diagnoser's own rule
(``decide_run``, replayed as ``sensor_kinds_replay.py`` does) then decides the kind for the
channel named. Prints the tables of ``sensor_kinds_replay.py`` (kind and channel CDR per kind
and channel, 95 % BCa intervals over the episodes), and per episode the window's channel CDR
of the saved rule and of the bank and the bank's size estimate.

What it grants beyond the diagnoser: the bank starts at the first alarm after the onset only
(the diagnoser starts it at every alarm's start, a false alarm before the onset too).

    NUMBA_NUM_THREADS=1 PYTHONPATH=$PWD python lab/sensor_glr_bank.py /tmp/sk/val --window 300
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from diagnosers.filters import FCCStateEstimator, UKFConfig
from diagnosers.sensors.glr_bank import GLRBank
from fcc_env.params import MEASUREMENT_NAMES, FCCParams

# ``python lab/<script>.py`` puts lab/ first on the path, not the repository root
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from lab.sensor_kinds_replay import decide, load, score


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("dir", type=Path)
    ap.add_argument("--window", type=int, default=300)
    ap.add_argument("--delay", type=int, default=0, help="samples before the alarm to start")
    ap.add_argument("--b1", type=float, default=5.0)
    ap.add_argument("--margin", type=float, default=0.0, help="nats ahead of the second")
    ap.add_argument("--ratio", type=float, default=1.0, help="times the second's GLR")
    ap.add_argument("--kinds", default="sensor-bias,sensor-drift")
    ap.add_argument("--ramp", type=float, default=0.0,
                    help="nats a ramp must add for a drift (0: the residual's tests decide)")  # fmt: skip
    ap.add_argument("--quiet", action="store_true")
    args = ap.parse_args()
    p, lim = load(args.dir, None)
    meta = json.loads((args.dir / "meta.json").read_text())
    config = UKFConfig(
        noise_scale=p["noise_scale"], sample_time_s=meta["sample_time_s"], closed_loop=True
    )
    bank = GLRBank(FCCStateEstimator(FCCParams(), config), args.b1)

    def rule(rec, path: Path) -> tuple[np.ndarray, np.ndarray]:
        t_a, onset, true = int(rec["t_alarm"]), int(rec["onset"]), int(rec["true"])
        T = len(rec["kind"])
        named = np.full(T, -1, dtype=np.int64)
        named_kind = np.zeros(T, dtype=np.int64)
        k0 = int(rec["prior_k0"])
        s = max(t_a - args.delay, k0)
        if t_a >= 0 and s - k0 < len(rec["prior_m"]):
            state = bank.start(rec["prior_m"][s - k0], rec["prior_p"][s - k0])
            e = min(t_a + args.window, T)
            white0 = np.asarray(rec["white"][s:e, 0], dtype=np.float64)
            gain, ramp, size = bank.run(state, rec["y_all"][s:e], white0)
            top2 = np.sort(gain, axis=1)[:, -2:]
            sure = (top2[:, 1] - top2[:, 0] >= args.margin) & (
                top2[:, 1] >= args.ratio * top2[:, 0]
            )
            pick = np.where(sure, np.argmax(gain, axis=1), -1)
            named[t_a:e] = pick[t_a - s :]
            if args.ramp > 0:
                rc = ramp[np.arange(len(pick)), np.maximum(pick, 0)]
                named_kind[t_a:e] = np.where(pick < 0, 0, np.where(rc > args.ramp, 2, 1))[t_a - s :]
            if not args.quiet:
                win = slice(t_a, e)
                al = rec["kind"][win] > 0
                old = np.mean(rec["channel"][win][al] == true) if al.any() else np.nan
                new = np.mean(np.where(pick[t_a - s :] >= 0, pick[t_a - s :],
                                       rec["channel"][win])[al] == true) if al.any() else np.nan  # fmt: skip
                order = np.argsort(gain[-1])[::-1]
                print(
                    f"{path.stem} {MEASUREMENT_NAMES[true]} size {float(rec['size']):.2f} "
                    f"delay {t_a - onset}: window channel CDR rule {old:.3f} bank {new:.3f}; "
                    f"b̂ {size[-1, true]:.2f}; GLR {MEASUREMENT_NAMES[order[0]]} "
                    f"{gain[-1, order[0]]:.0f}, {MEASUREMENT_NAMES[order[1]]} "
                    f"{gain[-1, order[1]]:.0f}; ramp (true) at 30/100/300/end "
                    + "/".join(
                        f"{ramp[min(i, len(ramp) - 1), true]:.0f}" for i in (30, 100, 300, 10**6)
                    ),
                    flush=True,
                )
        kind, channel, _ = decide(rec, p, lim, named, named_kind)
        return kind, channel

    print(
        f"window {args.window}, delay {args.delay}, b1 {args.b1}, margin {args.margin}, "
        f"ratio {args.ratio}, ramp {args.ramp}"
    )
    score(args.dir, rule, tuple(args.kinds.split(",")))


if __name__ == "__main__":
    main()
