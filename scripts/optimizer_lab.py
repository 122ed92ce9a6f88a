"""Optimiser lab: Adam against L-BFGS on one relation of the bank (validation seeds).

Trains the relation's LRGF network (the bank's settings: order 2, steady start, 10 neurons for
T_rg1 and 5 otherwise, seed 101 unless ``--seed``, early stopping on the last quarter of every
training episode unless ``--val-fraction``) on the paper track's healthy training episodes (seeds 1000+) with Adam (``adam:N``, N epochs)
or with ``torch.optim.LBFGS`` (``lbfgs:N``, about N loss evaluations: strong-Wolfe line search,
20 inner steps and a history of 50 per outer step). It prints the wall time and the held-out
error against the noise-free output on ten healthy validation episodes (seeds 5000-5009, the
measured inputs). The L-BFGS loop replaces :func:`diagnosers.training.fit_lrgf`'s Adam loop for
the run only (same data, scaling, loss and early stopping); the library is not changed.

    python scripts/optimizer_lab.py --output T_rg1 --variants adam:3000,lbfgs:600,lbfgs:1500
    python scripts/optimizer_lab.py --output T_rg1 --variants adam:3000 --val-fraction 0 --seed 7

``--val-fraction`` is the share of every training episode held out for early stopping (0: train on
every sample and keep the lowest training loss); the held-out error is printed with the measured
inputs and with the true (noise-free) inputs, the latter the model's own error.
"""

from __future__ import annotations

import argparse
import math
import time
from collections.abc import Callable

import numpy as np
import torch
from baseline_lab import at_least

from diagnosers import training
from diagnosers.lrgf_net import LRGF
from diagnosers.training import FitResult, fit_lrgf
from evaluation.sources import TrackData
from evaluation.tracks import TRACKS
from fcc_env.params import MEASUREMENT_NAMES

RELATIONS = {
    "T_rx": ["T_rg2", "T_fp"],
    "T_rg1": ["T_ar", "R_ar", "T_fp"],
    "T_rg2": ["T_rg1", "T_ar", "R_ar"],
}
INNER_STEPS, HISTORY = 20, 50


def lbfgs_loop(
    model: LRGF,
    losses: Callable[[], tuple[torch.Tensor, float]],
    max_epochs: int,
    lr: float,
    patience: int,
    progress: bool,
) -> FitResult:
    """``fit_lrgf``'s loop signature; ``max_epochs`` counts loss evaluations, ``lr`` unused."""
    opt = torch.optim.LBFGS(
        model.parameters(),
        lr=1.0,
        max_iter=INNER_STEPS,
        history_size=HISTORY,
        line_search_fn="strong_wolfe",
        tolerance_grad=1e-12,
        tolerance_change=1e-15,
    )
    best = training._Best(model, max(3, patience // INNER_STEPS))
    n_eval = 0

    def closure() -> torch.Tensor:
        nonlocal n_eval
        opt.zero_grad(set_to_none=True)
        train, _ = losses()
        train.backward()
        n_eval += 1
        return train

    outer = 0
    while n_eval < max_epochs:
        opt.step(closure)
        outer += 1
        with torch.no_grad():
            _, val = losses()
        if best.update(val, outer):
            break
    best.restore()
    res = FitResult(method="lbfgs", n_epochs=n_eval, best_epoch=best.epoch, best_val_loss=best.loss)
    print(f"   L-BFGS: {n_eval} loss evaluations in {outer} outer steps", flush=True)
    return res


def variant(text: str) -> tuple[str, int]:
    """An argparse type: ``adam:N`` or ``lbfgs:N`` with N >= 1, refused by value otherwise."""
    kind, _, n = text.partition(":")
    if kind not in ("adam", "lbfgs") or not n.isdigit() or int(n) < 1:
        raise argparse.ArgumentTypeError(f"{text!r}; allowed: adam:N or lbfgs:N with N >= 1")
    return kind, int(n)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--output", choices=tuple(RELATIONS), default="T_rg1")
    ap.add_argument("--n-train", type=at_least(2), default=9)
    ap.add_argument(
        "--variants",
        type=lambda s: [variant(v) for v in s.split(",")],
        default=[("adam", 3000), ("lbfgs", 600)],
    )
    ap.add_argument("--val-fraction", type=float, default=0.25)
    ap.add_argument("--seed", type=at_least(0), default=101, help="the network's seed")
    ap.add_argument(
        "--hidden", type=at_least(1), default=None, help="neurons (default: the bank's)"
    )
    a = ap.parse_args()
    if not 0.0 <= a.val_fraction < 1.0:
        ap.error(f"--val-fraction {a.val_fraction}; allowed: a number in [0, 1)")
    track = TRACKS["paper"].with_seeds(test=5000, validation=9000).replace(n_train=a.n_train)
    data = TrackData(track=track)
    train = data.train_episodes()
    ui = [MEASUREMENT_NAMES.index(c) for c in RELATIONS[a.output]]
    yi = MEASUREMENT_NAMES.index(a.output)
    val = [data.load_test("nominal", s).episode for s in range(5000, 5010)]
    hidden = a.hidden or (10 if a.output == "T_rg1" else 5)
    adam = training._adam_loop
    for kind, n in a.variants:
        net = LRGF(len(ui), hidden, 2, 1, initial_state="steady", steady_window=100, seed=a.seed)
        net = net.double()
        training._adam_loop = adam if kind == "adam" else lbfgs_loop  # type: ignore[assignment]
        try:
            t0 = time.perf_counter()
            fit_lrgf(net, [e.y[:, ui] for e in train], [e.y[:, [yi]] for e in train], lr=0.03,
                     max_epochs=n, patience=max(50, n // 5), seed=a.seed,
                     val_fraction=a.val_fraction)  # fmt: skip
            wall = time.perf_counter() - t0
        finally:
            training._adam_loop = adam
        net.eval()
        rms = {}
        for inputs in ("measured", "true"):
            u_of = (lambda e: e.y) if inputs == "measured" else (lambda e: e.y_clean)
            err = np.concatenate(
                [e.y_clean[100:, yi] - net.predict(u_of(e)[:, ui])[100:, 0] for e in val]  # type: ignore[index]
            )
            rms[inputs] = math.sqrt(float(np.mean(err**2)))
        print(f"{a.output}, {a.n_train} episodes, {kind}:{n}, val_fraction {a.val_fraction}, "
              f"seed {a.seed}: {wall:.0f} s, held-out error against the noise-free output "
              f"{rms['measured']:.3f} °C RMS from the measured inputs, {rms['true']:.3f} °C "
              "from the true inputs", flush=True)  # fmt: skip


if __name__ == "__main__":
    main()
