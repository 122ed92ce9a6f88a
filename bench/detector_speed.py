"""Speed and model quality of the neural detector: ``python -m bench.detector_speed``.

Prints, measured on this machine:

* the LRGF forward pass over a 4000-sample sequence (paper configuration);
* training time of the paper configuration (T_rx from T_rg2, T_fp; 3 neurons, 2nd-order filters)
  on 4000 samples, with Adam (backpropagation through time) and with the paper's SPSA, and the
  held-out fit each reaches;
* the nominal T_rx model's quality on held-out healthy episodes (free-run fit %, RMSE in °C) when
  trained on the leaderboard's 6 training episodes: the ``arx-band`` baseline's linear ARX model
  against the LRGF in the paper's configuration and in ``lrgf-mem``'s;
* streaming ``update`` throughput and whole-episode ``detect`` throughput of ``lrgf-mem-paper``,
  ``lrgf-mem``, ``lrgf-glr`` and ``lrgf-glr-adaptive`` (whose held baseline makes ``detect`` a
  per-sample recursion);
* with ``--bank N``: the wall time of training ``lrgf-mem``, ``lrgf-glr`` and
  ``lrgf-glr-adaptive`` (the last two calibrate by cross-fitting, which trains the bank
  ``n_folds + 1`` times) on N healthy episodes (the tracks train on
  9), with ``--n-jobs`` worker processes (default 2: here a bank trains alone; the diagnosers'
  own default is 1, see :mod:`diagnosers.lrgf.lrgf_mem`), and each relation's held-out free-run fit
  against a linear ARX model of the same relation (``arx-band`` with that output and inputs)
  trained on the same episodes, for ``lrgf-glr``'s networks and for ``lrgf-glr-adaptive``'s
  (trained on every sample, ``val_fraction=0``).

Figures, not assertions: tests check correctness, this script reports speed.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import torch

import diagnosers
import fcc_env
from diagnosers import Episode
from diagnosers.bank.relations import BANK_RELATIONS
from diagnosers.classical.arx_band import fit_percent
from diagnosers.lrgf.bank_detector import BANK_CONSTRAINTS
from diagnosers.networks.lrgf_net import LRGF
from diagnosers.networks.modules import paper_lrgf
from diagnosers.networks.training import fit_lrgf
from fcc_common.invocation import command_parser, run_command
from fcc_common.validation import Integer, check
from fcc_env.scenarios import DEFAULT_N_SAMPLES
from fcc_env.simulation import check_memory

CH = list(fcc_env.MEASUREMENT_NAMES)
U_IDX = [CH.index("T_rg2"), CH.index("T_fp")]
Y_IDX = [CH.index("T_rx")]
#: samples left out of the quality figures: the LRGF's steady-start window (the diagnosers'
#: ``steady_window``) and, for ARX, its measured-output warm-up
WARM_UP = 100


def _episodes(seeds: list[int], n: int = 4000) -> list[Episode]:
    b = fcc_env.simulate_episodes(seeds, n)
    return [
        Episode(b.observations[i].astype(float), fcc_env.MEASUREMENT_NAMES, b.sample_time_s)
        for i in range(len(seeds))
    ]


def _with_faults(seeds: list[int], n_faulty: int = 3) -> list[Episode]:
    """Healthy episodes of ``seeds`` and every registered fault (its default onset and size) on
    the first ``n_faulty`` of them: what the harness gives a detector that learns from faults
    (``lrgf-glr``'s directions pair each with its healthy twin)."""
    out = Episode.from_batch(fcc_env.simulate_episodes(seeds, 4000))
    for f in fcc_env.fault_names():
        faulty = fcc_env.simulate_episodes(
            seeds[:n_faulty], 4000, fault=fcc_env.FaultSpec(scenario=f)
        )
        out += [e for e in Episode.from_batch(faulty) if e.fault_onset is not None]
    return out


def _quality(predict, episodes: list[Episode]) -> tuple[float, float]:
    """Free-run fit % and RMSE after the first WARM_UP samples (the models' start-up)."""
    fits, sq = [], []
    for ep in episodes:
        y = ep.y[WARM_UP:, Y_IDX[0]]
        y_hat = predict(ep)[WARM_UP:]
        fits.append(fit_percent(y, y_hat))
        sq.append(np.mean((y - y_hat) ** 2))
    return float(np.mean(fits)), float(np.sqrt(np.mean(sq)))


def _throughput(d: diagnosers.Diagnoser, ep: Episode, detect_repeats: int) -> tuple[float, float]:
    """(streaming ``update`` samples/s, whole-episode ``detect`` samples/s) of a fitted ``d``."""
    d.reset()
    t0 = time.perf_counter()
    for row in ep.y:
        d.update(row)
    update = ep.n_samples / (time.perf_counter() - t0)
    t0 = time.perf_counter()
    for _ in range(detect_repeats):
        d.detect(ep)
    return update, detect_repeats * ep.n_samples / (time.perf_counter() - t0)


def main(argv: list[str] | None = None) -> int:
    parser = command_parser(
        "bench.detector_speed",
        (__doc__ or "").split("\n\n")[0],
        (
            ("", "the full report: forward pass, training, model quality, throughput"),
            ("--bank 6 --n-jobs 2", "the banks' training time and fit on 6 episodes"),
        ),
    )
    parser.add_argument("--epochs", type=int, default=1500, help="Adam epochs (1500)")
    parser.add_argument("--spsa-iterations", type=int, default=3000, help="SPSA iterations (3000)")
    parser.add_argument(
        "--bank", type=int, default=0, help="train the banks on N episodes and compare (0: skip)"
    )
    parser.add_argument(
        "--n-jobs", type=int, default=2, help="worker processes that train a bank (--bank; 2)"
    )
    return run_command(parser, _report, argv)


def _report(args: argparse.Namespace) -> int:
    """The work of :func:`main`: its failures (and a Ctrl-C) are reported by :func:`run_command`."""
    for flag, value, allowed in (
        ("--epochs", args.epochs, BANK_CONSTRAINTS["max_epochs"]),
        ("--spsa-iterations", args.spsa_iterations, BANK_CONSTRAINTS["max_epochs"]),
        ("--bank", args.bank, Integer(0, 4000, why="training seeds 1000..4999")),
        ("--n-jobs", args.n_jobs, Integer(1, 1024)),
    ):
        check(flag, value, allowed)
    if args.bank:
        try:  # the bank's training episodes are held at once
            check_memory(args.bank, DEFAULT_N_SAMPLES)
        except ValueError as e:
            raise ValueError(f"--bank {args.bank}: {e}") from None
        return _bank_report(args.bank, args.n_jobs)

    train = _episodes([1000])
    held_out = _episodes([6000, 6001, 6002])
    u = train[0].y[:, U_IDX]
    y = train[0].y[:, Y_IDX]

    net = paper_lrgf(seed=0)
    x = torch.as_tensor(u[None], dtype=torch.float32)
    with torch.no_grad():
        net(x)
        t0 = time.perf_counter()
        for _ in range(20):
            net(x)
    print(
        f"LRGF forward, 4000 samples (paper config): {(time.perf_counter() - t0) / 20 * 1e3:.2f} ms"
    )

    _epoch_report()

    results = {}
    for method, kw in (
        ("adam", {"max_epochs": args.epochs, "patience": args.epochs}),
        ("spsa", {"max_epochs": args.spsa_iterations, "patience": args.spsa_iterations}),
    ):
        net = paper_lrgf(seed=0, initial_state="steady", steady_window=WARM_UP).double()
        t0 = time.perf_counter()
        fit_lrgf(net, u, y, method=method, **kw)
        elapsed = time.perf_counter() - t0
        fit, rmse = _quality(lambda ep, net=net: net.predict(ep.y[:, U_IDX])[:, 0], held_out)
        results[method] = (elapsed, fit, rmse)
        print(
            f"train paper config on 4000 samples, {method}: {elapsed:.1f} s; held-out free-run "
            f"fit {fit:.1f} %, RMSE {rmse:.3f} °C"
        )

    # Nominal model quality with the leaderboard's data: 6 healthy training episodes.
    six = _episodes(list(range(1000, 1006)))
    arx = diagnosers.make("arx-band").fit(six)
    fit, rmse = _quality(
        lambda ep: arx.simulate(ep.y[:, U_IDX], ep.y[: arx.n_warmup_, Y_IDX[0]]), held_out
    )
    print(
        f"nominal T_rx model on 6 episodes, held-out free run: arx-band linear ARX fit {fit:.1f} %, RMSE {rmse:.3f} °C"
    )
    for label, kw, lr in (
        ("LRGF paper config (3 neurons)", {}, 0.01),
        ("LRGF lrgf-mem config (5 neurons)", {"n_hidden": 5}, 0.03),
    ):
        net = paper_lrgf(seed=0, initial_state="steady", steady_window=WARM_UP, **kw).double()
        t0 = time.perf_counter()
        fit_lrgf(
            net,
            [e.y[:, U_IDX] for e in six],
            [e.y[:, Y_IDX] for e in six],
            max_epochs=3000,
            patience=600,
            lr=lr,
        )
        elapsed = time.perf_counter() - t0
        fit, rmse = _quality(lambda ep, net=net: net.predict(ep.y[:, U_IDX])[:, 0], held_out)
        print(
            f"nominal T_rx model on 6 episodes, held-out free run: {label} fit {fit:.1f} %, "
            f"RMSE {rmse:.3f} °C (trained in {elapsed:.0f} s)"
        )

    three = _episodes([1000, 1001, 1002])
    paper = diagnosers.make("lrgf-mem-paper").fit(three)
    update, detect = _throughput(paper, held_out[0], detect_repeats=3)
    print(f"lrgf-mem-paper streaming update: {update:,.0f} samples/s (goal >= 10,000)")
    print(f"lrgf-mem-paper detect on a whole episode: {detect:,.0f} samples/s")
    # the bank's throughput does not depend on how well it is trained: a short fit suffices
    bank = diagnosers.make("lrgf-mem", max_epochs=100, mem_max_epochs=20).fit(three)
    update, detect = _throughput(bank, held_out[0], detect_repeats=1)
    print(f"lrgf-mem streaming update ({len(bank.lrgf_)} relations): {update:,.0f} samples/s")
    print(f"lrgf-mem detect on a whole episode: {detect:,.0f} samples/s")
    for name in ("lrgf-glr", "lrgf-glr-adaptive"):
        glr = diagnosers.make(name, max_epochs=100, mem_max_epochs=20)
        glr.fit(_with_faults([1000, 1001, 1002]))
        update, detect = _throughput(glr, held_out[0], detect_repeats=1)
        print(f"{name} streaming update ({glr.statistic}): {update:,.0f} samples/s")
        print(f"{name} detect on a whole episode: {detect:,.0f} samples/s")
    return 0


def _epoch_report(epochs: int = 100) -> None:
    """Adam epochs of a T_rg1-sized network, the fused free run against the torch chain."""
    nine = _episodes(list(range(1000, 1009)))
    ui, yi = [CH.index(c) for c in ("T_ar", "R_ar", "T_fp")], [CH.index("T_rg1")]
    u, y = [e.y[:, ui] for e in nine], [e.y[:, yi] for e in nine]
    for label in ("fused", "torch chain"):
        net = LRGF(3, 10, 2, output_bias=True, initial_state="steady", steady_window=WARM_UP)
        net = net.double()
        if label == "torch chain":
            net.forward_normalized = net.forward_reference  # type: ignore[method-assign]
        # a process's first epochs run slower (allocator warm-up): time a second fit
        fit_lrgf(net, u, y, max_epochs=30, patience=31, lr=0.03)
        res = fit_lrgf(net, u, y, max_epochs=epochs, patience=epochs + 1, lr=0.03)
        print(
            f"LRGF training, 10 neurons on 9 x 4000 samples, {label}: "
            f"{res.wall_time_s / res.n_epochs * 1e3:.1f} ms per Adam epoch ({res.n_epochs} epochs, "
            "1 thread)"
        )


def _bank_report(n: int, n_jobs: int) -> int:
    """Training wall time of the banks on ``n`` episodes and per-relation held-out fit vs ARX."""

    train = _episodes(list(range(1000, 1000 + n)))
    held_out = _episodes(list(range(6000, 6005)))
    fitted = {}
    with_faults = _with_faults(list(range(1000, 1000 + n)))  # the same healthy episodes, seeds kept
    for name in ("lrgf-mem", "lrgf-glr", "lrgf-glr-adaptive"):
        t0 = time.perf_counter()
        det = diagnosers.make(name, n_jobs=n_jobs)
        fitted[name] = det.fit(with_faults if det.learns_from_faults else train)
        print(
            f"{name}: trained on {n} episodes in {time.perf_counter() - t0:.0f} s (n_jobs={n_jobs})"
        )
    for j, (out, ins) in enumerate(BANK_RELATIONS):
        yi = CH.index(out)
        ui = [CH.index(c) for c in ins]
        arx = diagnosers.make("arx-band", output=out, inputs=list(ins)).fit(train)
        rows = []
        for ep in held_out:
            y = ep.y[WARM_UP:, yi]
            y_arx = arx.simulate(ep.y[:, ui], ep.y[: arx.n_warmup_, yi])[WARM_UP:]
            row = [fit_percent(y, y_arx), np.mean((y - y_arx) ** 2)]
            for name in ("lrgf-glr", "lrgf-glr-adaptive"):
                y_nn = fitted[name].lrgf_[j].predict(ep.y[:, ui])[WARM_UP:, 0]
                row += [fit_percent(y, y_nn), np.mean((y - y_nn) ** 2)]
            rows.append(row)
        f_a, m_a, f_n, m_n, f_v, m_v = np.mean(rows, axis=0)
        print(
            f"{out} <- {', '.join(ins)}: held-out free run, ARX fit {f_a:.1f} % (RMSE "
            f"{np.sqrt(m_a):.3f}), LRGF ({fitted['lrgf-glr'].lrgf_[j].n_hidden} neurons) fit "
            f"{f_n:.1f} % (RMSE {np.sqrt(m_n):.3f}); trained on every sample "
            f"(lrgf-glr-adaptive) {f_v:.1f} % (RMSE {np.sqrt(m_v):.3f})"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
