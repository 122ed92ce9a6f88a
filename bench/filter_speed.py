"""Speed of the FCC state estimator: ``python -m bench.filter_speed``.

Prints samples per second of the FCC state estimator (diagnosers.filters) per core, for the
batched filter (episodes in one numba thread, then on every thread) and the streaming update
(one episode, one call per sample), as the mean and the range over --repeats runs, for three
set-ups: the open-loop plant (14 states), the closed loop (15, with the coking
factor) and the open loop with three parameters estimated (17). Issue 42's goal: >= 10,000
samples/s per core batched over episodes.

--filterpy also times filterpy's UnscentedKalmanFilter (if installed; it is not a
dependency) on the same open-loop model, its sigma points through the same compiled model
functions one call each, per sample of one episode. Figures, not assertions: the machine may
be shared, so run it more than once.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable

import numba
import numpy as np

import fcc_env
from diagnosers.filters import FCCStateEstimator, UKFConfig
from diagnosers.filters.ukf_model import fcc_measure, fcc_transition, work_vectors
from fcc_common.invocation import command_parser, run_command
from fcc_common.validation import Integer, check

#: Issue 42's goal for the batched filter, samples/s per core.
BATCH_GOAL = 10_000
#: Parameters estimated in the third set-up (the ``uncertain`` track's kinetics and valve).
PARAMETERS = ("A_cr", "k_cb", "rho_b0")


def timed(run: Callable[[], int], repeats: int, cores: int = 1) -> list[tuple[float, ...]]:
    """Samples/s of ``run`` (which returns its sample count) per wall second per core and per
    CPU second (the process's, all threads): ``[(mean, lowest, highest)]`` of each."""
    wall, cpu = [], []
    for _ in range(repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        n = run()
        wall.append(n / (time.perf_counter() - t0) / cores)
        cpu.append(n / (time.process_time() - c0))
    return [(float(np.mean(r)), float(min(r)), float(max(r))) for r in (wall, cpu)]


def _line(what: str, rates: list[tuple[float, ...]]) -> None:
    cells = [f"{m:>9,.0f} [{lo:>7,.0f}, {hi:>7,.0f}]" for m, lo, hi in rates]
    print(f"  {what:<32} " + "  ".join(cells))


def bench_setup(name: str, plant, config: UKFConfig, a: argparse.Namespace) -> None:
    b = fcc_env.simulate_episodes(list(range(1000, 1000 + a.episodes)), a.samples, plant=plant)
    Y = b.observations
    est = FCCStateEstimator(fcc_env.FCCParams(), config)
    est.filter(Y[:1, :5])  # the compiled kernels' cache load
    print(f"{name}: {est.n_states} states, {a.episodes} episodes x {a.samples} samples")

    def batch() -> int:
        est.filter(Y)
        return Y.shape[0] * Y.shape[1]

    threads = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        _line("batch filter, 1 thread", timed(batch, a.repeats))
    finally:
        numba.set_num_threads(threads)
    _line(f"batch filter, {threads} threads", timed(batch, a.repeats, threads))

    def stream() -> int:
        est.reset()
        for row in Y[0, : a.stream_samples]:
            est.update(row)
        return a.stream_samples

    _line("streaming update, 1 episode", timed(stream, a.repeats))


def bench_filterpy(a: argparse.Namespace) -> None:
    """filterpy's UKF on the same model and noise, one episode, per sample."""
    try:
        from filterpy.kalman import MerweScaledSigmaPoints, UnscentedKalmanFilter
    except ImportError:
        print("filterpy: not installed (pip install filterpy to compare)")
        return
    est = FCCStateEstimator(fcc_env.FCCParams(), UKFConfig(step_gate=None))
    m = est.filter_model
    Y = fcc_env.simulate_episodes([1000], a.stream_samples).observations[0].astype(float)
    x, u, p = work_vectors(m.model, np.empty(m.n_scratch))
    obs = Y[0]  # the model reads only the valve command from it, in closed loop

    def fx(z: np.ndarray, dt: float) -> np.ndarray:
        out = np.empty_like(z)
        fcc_transition(z, obs, m.model, x, u, p, out)
        return out

    def hx(z: np.ndarray) -> np.ndarray:
        out = np.empty(len(fcc_env.MEASUREMENT_NAMES))
        fcc_measure(z, obs, m.model, x, u, p, out)
        return out

    points = MerweScaledSigmaPoints(m.n, alpha=1.0, beta=2.0, kappa=0.0)
    ukf = UnscentedKalmanFilter(m.n, 8, 10.0, hx, fx, points)

    def run() -> int:
        M, P = est.initial_prior()
        ukf.x, ukf.P, ukf.Q = M[0].copy(), P[0].copy(), np.diag(m.q)
        for y in Y:
            ukf.predict()
            ukf.update(y, R=np.diag((m.r_abs + m.r_rel * np.abs(y)) ** 2))
        return Y.shape[0]

    fx(np.zeros(m.n), 10.0), hx(np.zeros(m.n))  # the compiled functions' cache load
    _line("filterpy UKF, 1 episode", timed(run, a.repeats))


def main(argv: list[str] | None = None) -> int:
    ap = command_parser(
        "bench.filter_speed",
        (__doc__ or "").split("\n\n")[1],
        (
            ("", "the three set-ups: batched (1 thread, all threads) and streaming"),
            ("--filterpy --repeats 3", "also filterpy's UKF on the same model, if installed"),
        ),
    )
    ap.add_argument("--episodes", type=int, default=8, help="episodes of the batch (8)")
    ap.add_argument("--samples", type=int, default=2000, help="samples per episode (2000)")
    ap.add_argument("--stream-samples", type=int, default=500, help="samples streamed (500)")
    ap.add_argument("--repeats", type=int, default=5, help="runs of each timing (5)")
    ap.add_argument("--filterpy", action="store_true", help="also time filterpy's UKF")
    return run_command(ap, _report, argv)


def _report(a: argparse.Namespace) -> int:
    """The work of :func:`main`: its failures (and a Ctrl-C) are reported by :func:`run_command`."""
    check("--episodes", a.episodes, Integer(1, 10_000))
    check("--samples", a.samples, Integer(10, 100_000))
    check("--stream-samples", a.stream_samples, Integer(10, 100_000))
    check("--repeats", a.repeats, Integer(1, 1000))
    print(
        f"samples/s per core, mean [lowest, highest] over {a.repeats} runs: per wall second "
        f"(divided by the threads), then per CPU second; goal >= {BATCH_GOAL:,} per core"
    )
    open_plant = fcc_env.PlantConfig()
    closed = fcc_env.PlantConfig.build(regulatory=True)
    for name, plant, config in (
        ("open loop", open_plant, UKFConfig()),
        ("closed loop, coking factor", closed, UKFConfig.matching(closed)),
        (
            f"open loop, parameters {', '.join(PARAMETERS)}",
            open_plant,
            UKFConfig(parameters=PARAMETERS),
        ),
    ):
        bench_setup(name, plant, config, a)
    if a.filterpy:
        bench_filterpy(a)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
