"""Speed of ``mmae``'s 5-hypothesis filter bank streaming: ``python -m bench.bank_speed``.

Samples per second (per wall second and per CPU second of the process) of one episode, as the
mean and the range over --repeats runs, for:

* ``5 estimators, update each``: the five hypotheses' :class:`FCCStateEstimator` streamed one
  ``update`` each per sample (what the bank would cost as five separate filters);
* ``bank, one call per sample``: :meth:`FilterBank.run` on one sample at a time (the five
  filters in one compiled call);
* ``mmae.update``: the registered diagnoser's streaming path (the bank, the posterior and the
  decision per sample);
* ``mmae.detect``: the whole record in one call (batch).

Issue 42's goal: the 5-hypothesis bank streaming at >= 2,000 samples/s. Figures, not
assertions: the machine may be shared (compare the CPU-second figures there).
"""

from __future__ import annotations

import argparse
from collections.abc import Callable

import diagnosers
import fcc_env
from bench.filter_speed import timed
from diagnosers.episode.record import Episode
from fcc_common.invocation import command_parser, run_command
from fcc_common.validation import Integer, check

#: Issue 42's goal for the 5-hypothesis bank, streaming, samples/s.
STREAM_GOAL = 2_000


def _line(what: str, rates: list[tuple[float, ...]]) -> None:
    cells = [f"{m:>8,.0f} [{lo:>6,.0f}, {hi:>6,.0f}]" for m, lo, hi in rates]
    print(f"  {what:<34} " + "  ".join(cells))


def bench(a: argparse.Namespace) -> None:
    healthy = Episode.from_batch(fcc_env.simulate_episodes([1000], 400))
    faulty = [
        Episode.from_batch(
            fcc_env.simulate_episodes([1000], 40, fault=fcc_env.FaultSpec(scenario=f, onset=20))
        )[0]
        for f in fcc_env.PAPER_FAULTS
    ]
    m = diagnosers.make("mmae").fit(healthy + faulty)
    spec = fcc_env.FaultSpec(scenario="f3", onset=a.samples // 2)
    ep = Episode.from_batch(fcc_env.simulate_episodes([5000], a.samples, fault=spec))[0]
    Y = ep.y
    bank = m.bank_
    m.detect(Episode.from_batch(fcc_env.simulate_episodes([5001], 5))[0])  # compiled code loads
    print(
        f"{len(bank.hypotheses)} hypotheses {bank.hypotheses}, states "
        f"{[e.n_states for e in bank.estimators]}, {a.samples} samples of one episode"
    )
    print(f"  {'':<34} {'per wall second':>26}  {'per CPU second':>24}")

    def separate() -> int:
        for e in bank.estimators:
            e.reset()
        for row in Y:
            for e in bank.estimators:
                e.update(row)
        return len(Y)

    def per_sample() -> int:
        Ms, Ps = bank.start()
        for k in range(len(Y)):
            bank.run(Ms, Ps, Y[k : k + 1])
        return len(Y)

    def stream() -> int:
        m.reset()
        for row in Y:
            m.update(row)
        return len(Y)

    def batch() -> int:
        m.detect(ep)
        return len(Y)

    runs: list[tuple[str, Callable[[], int]]] = [
        ("5 estimators, update each", separate),
        ("bank, one call per sample", per_sample),
        ("mmae.update (streaming)", stream),
        ("mmae.detect (one call)", batch),
    ]
    for what, run in runs:
        _line(what, timed(run, a.repeats))
    print(f"goal: >= {STREAM_GOAL:,} samples/s streaming (mmae.update)")


def main(argv: list[str] | None = None) -> int:
    p = command_parser(
        "bench.bank_speed",
        (__doc__ or "").split("\n")[0],
        (("--samples 1000 --repeats 3", "a shorter run"),),
    )
    p.add_argument("--samples", type=int, default=2000, help="samples of the episode")
    p.add_argument("--repeats", type=int, default=3, help="runs of each measurement")
    return run_command(p, _bench, argv)


def _bench(a: argparse.Namespace) -> int:
    a.samples = check("--samples", a.samples, Integer(50, 100_000))
    a.repeats = check("--repeats", a.repeats, Integer(1, 100))
    bench(a)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
