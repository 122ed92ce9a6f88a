"""Benchmark of the modelling loop: ``python -m bench.loop_speed [--quick]``.

Prints the wall time of a full :func:`evaluation.discover.discover` run on a 4000-sample record
with the whole effect library (target: under 60 s on the project's 2-core machine), then how the
time grows with the number of candidates (at 4000 samples) and with the record length (whole
library). The data carry one undeclared effect (``sensor_bias:T_fp,bias=3``), so the loop runs two
rounds (find + confirm nothing else), which is the typical case.
"""

from __future__ import annotations

import argparse
import time

import fcc_env
from evaluation import discover as d
from fcc_common.invocation import command_parser, run_command

EFFECT = "sensor_bias:T_fp,bias=3"


def run(n_samples: int, candidates: list[str] | None, seed: int = 0) -> tuple[float, int, int]:
    data = d.from_batch(fcc_env.simulate_episodes([seed], n_samples, plant_effects=[EFFECT]))
    t0 = time.perf_counter()
    rep = d.discover(data, candidates=candidates)
    dt = time.perf_counter() - t0
    return dt, len(rep.rounds), rep.settings["n_candidates"]


def main(argv: list[str] | None = None) -> int:
    ap = command_parser(
        "bench.loop_speed",
        (__doc__ or "").split("\n\n")[0],
        (
            ("", "the full benchmark: one 4000-sample run, then the scaling curves"),
            ("--quick", "fewer points on the scaling curves"),
        ),
    )
    ap.add_argument("--quick", action="store_true", help="fewer points")
    return run_command(ap, _report, argv)


def _report(args: argparse.Namespace) -> int:
    """The work of :func:`main`: its failures (and a Ctrl-C) are reported by :func:`run_command`."""
    run(500, ["sensor_bias:T_fp"])  # compile / warm caches
    all_ids = sorted(d.PhysicsModel().candidates())
    dt, rounds, n = run(4000, None)
    verdict = "OK" if dt < 60 else "OVER TARGET"
    print(
        f"full loop, 4000 samples, whole library ({n} candidates, {rounds} rounds): "
        f"{dt:.1f} s  [target < 60 s: {verdict}]"
    )
    print("\ngrowth with the number of candidates (4000 samples):")
    print(f"{'candidates':>10} {'time_s':>8} {'s/candidate':>12}")
    # the true effect plus a mix of process (simulating) and sensor (no re-simulation) effects
    others = [c for c in all_ids if c != "sensor_bias:T_fp"]
    sizes = (1, 8, 16, len(all_ids)) if not args.quick else (1, len(all_ids))
    for k in sizes:
        ids = ["sensor_bias:T_fp", *others[: k - 1]]
        dt, _, _ = run(4000, ids)
        print(f"{k:>10} {dt:>8.1f} {dt / k:>12.2f}")
    print("\ngrowth with the record length (whole library):")
    print(f"{'samples':>10} {'time_s':>8} {'ms/sample':>10}")
    for n_s in (1000, 2000, 4000, 8000) if not args.quick else (1000, 4000):
        dt, _, _ = run(n_s, None)
        print(f"{n_s:>10} {dt:>8.1f} {1e3 * dt / n_s:>10.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
