"""Optimiser lab: Adam against L-BFGS on one relation of the bank (validation seeds).

Trains the relation's LRGF network (the bank's settings: order 2, steady start, 10 neurons for
T_rg1 and 5 otherwise, seed 101 unless ``--seed``, early stopping on the last quarter of every
training episode unless ``--val-fraction``) on the paper track's healthy training episodes (seeds 1000+) with Adam (``adam:N``, N epochs)
or with ``torch.optim.LBFGS`` (``lbfgs:N``, about N loss evaluations: strong-Wolfe line search,
20 inner steps and a history of 50 per outer step). It prints the wall time and the held-out
error against the noise-free output on ten healthy validation episodes (seeds 5000-5009, the
measured inputs). The L-BFGS loop replaces :func:`diagnosers.networks.training.fit_lrgf`'s Adam loop for
the run only (same data, scaling, loss and early stopping); the library is not changed.

    python lab/optimizer_lab.py --output T_rg1 --variants adam:3000,lbfgs:600,lbfgs:1500
    python lab/optimizer_lab.py --output T_rg1 --variants adam:3000 --val-fraction 0 --seed 7
    python lab/optimizer_lab.py --output T_rg1 --variants adam:3000 --weight-decay 1e-3
    python lab/optimizer_lab.py --output T_rg1 --variants adam:3000 --input-noise 0.05

Two regularisers against the gap between the training episodes and fresh ones (issue 11: more
training episodes were what reduced T_rg1's model error): ``--weight-decay`` runs Adam as
``torch.optim.AdamW`` with that decoupled decay, and ``--input-noise`` adds fresh white noise of
that standard deviation (in the network's standardised input units) to the inputs at every epoch
(the validation loss then sees it too, so early stopping is noisier).

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

from diagnosers.networks import training
from diagnosers.networks.lrgf_net import LRGF
from diagnosers.networks.optimisers import EarlyStopping, FitResult
from diagnosers.networks.training import fit_lrgf
from evaluation.tracks import TRACKS
from evaluation.tracks.track_data import TrackData
from fcc_env.params import MEASUREMENT_NAMES

RELATIONS = {
    "T_rx": ["T_rg2", "T_fp"],
    "T_rg1": ["T_ar", "R_ar", "T_fp"],
    "T_rg2": ["T_rg1", "T_ar", "R_ar"],
}
INNER_STEPS, HISTORY = 20, 50
ADAM_LOOP = training.adam_loop


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
    best = EarlyStopping(model, max(3, patience // INNER_STEPS))
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


def adamw_loop(weight_decay: float) -> Callable[..., FitResult]:
    """``fit_lrgf``'s Adam loop with ``torch.optim.AdamW`` (decoupled weight decay)."""

    def loop(*args, **kwargs) -> FitResult:
        # the loop builds its optimiser by name; swapping that name for the call keeps the lab
        # out of the library (a throwaway experiment, not an option fit_lrgf should carry)
        adam = torch.optim.Adam
        torch.optim.Adam = lambda params, lr: torch.optim.AdamW(  # type: ignore[misc,assignment]
            params, lr=lr, weight_decay=weight_decay
        )
        try:
            return ADAM_LOOP(*args, **kwargs)
        finally:
            torch.optim.Adam = adam  # type: ignore[misc]

    return loop


def with_input_noise(net: LRGF, std: float, seed: int) -> None:
    """Make ``net.forward_normalized`` add fresh white noise of ``std`` to its inputs while
    gradients are on (training); prediction (no gradients) is left exact."""
    gen = torch.Generator().manual_seed(seed)
    forward = net.forward_normalized

    def noisy(u: torch.Tensor) -> torch.Tensor:
        if torch.is_grad_enabled():
            u = u + std * torch.randn(u.shape, generator=gen, dtype=u.dtype)
        return forward(u)

    net.forward_normalized = noisy  # type: ignore[method-assign]


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
    ap.add_argument("--weight-decay", type=float, default=0.0, help="AdamW's decay (0: Adam)")
    ap.add_argument("--input-noise", type=float, default=0.0, help="standardised units")
    ap.add_argument(
        "--train-inputs",
        choices=("measured", "true"),
        default="measured",
        help="train on the measured inputs or (an oracle, to bound an input smoother) the true ones",
    )
    ap.add_argument(
        "--products",
        action="store_true",
        help="add the pairwise products of the inputs' deviations from their training means",
    )
    a = ap.parse_args()
    if a.weight_decay < 0 or a.input_noise < 0:
        ap.error(f"--weight-decay {a.weight_decay}, --input-noise {a.input_noise}; allowed: >= 0")
    if not 0.0 <= a.val_fraction < 1.0:
        ap.error(f"--val-fraction {a.val_fraction}; allowed: a number in [0, 1)")
    track = TRACKS["paper"].with_seeds(test=5000, validation=9000).replace(n_train=a.n_train)
    data = TrackData(track=track)
    train = data.train_episodes()
    ui = [MEASUREMENT_NAMES.index(c) for c in RELATIONS[a.output]]
    yi = MEASUREMENT_NAMES.index(a.output)
    val = [data.load_test("nominal", s).episode for s in range(5000, 5010)]
    hidden = a.hidden or (10 if a.output == "T_rg1" else 5)
    centre = np.mean(np.concatenate([e.y[:, ui] for e in train]), axis=0)

    def features(u: np.ndarray) -> np.ndarray:
        """The relation's inputs, with their deviations' pairwise products under --products."""
        if not a.products:
            return u
        d = u - centre
        pairs = [d[:, i] * d[:, j] for i in range(d.shape[1]) for j in range(i, d.shape[1])]
        return np.column_stack([u, *pairs])

    n_in = features(train[0].y[:2, ui]).shape[1]
    for kind, n in a.variants:
        net = LRGF(n_in, hidden, 2, 1, initial_state="steady", steady_window=100, seed=a.seed)
        net = net.double()
        if a.input_noise > 0:
            with_input_noise(net, a.input_noise, a.seed)
        if kind == "lbfgs":
            training.adam_loop = lbfgs_loop  # type: ignore[assignment]
        elif a.weight_decay > 0:
            training.adam_loop = adamw_loop(a.weight_decay)  # type: ignore[assignment]
        try:
            t0 = time.perf_counter()
            res = fit_lrgf(net, [features((e.y if a.train_inputs == "measured" else e.y_clean)[:, ui]) for e in train], [e.y[:, [yi]] for e in train], lr=0.03,
                     max_epochs=n, patience=max(50, n // 5), seed=a.seed,
                     val_fraction=a.val_fraction)  # fmt: skip
            wall = time.perf_counter() - t0
        finally:
            training.adam_loop = ADAM_LOOP
        net.eval()
        rms = {}
        for inputs in ("measured", "true"):
            u_of = (lambda e: e.y) if inputs == "measured" else (lambda e: e.y_clean)
            err = np.concatenate(
                [e.y_clean[100:, yi] - net.predict(features(u_of(e)[:, ui]))[100:, 0] for e in val]  # type: ignore[index]
            )
            rms[inputs] = math.sqrt(float(np.mean(err**2)))
        print(f"{a.output}, {a.n_train} episodes, {kind}:{n}, val_fraction {a.val_fraction}, "
              f"weight decay {a.weight_decay:g}, input noise {a.input_noise:g}, "
              f"trained on the {a.train_inputs} inputs, products {a.products}, "
              f"validation loss {res.best_val_loss:.6g} (best epoch {res.best_epoch} of {res.n_epochs}), "
              f"seed {a.seed}: {wall:.0f} s, held-out error against the noise-free output "
              f"{rms['measured']:.3f} °C RMS from the measured inputs, {rms['true']:.3f} °C "
              "from the true inputs", flush=True)  # fmt: skip


if __name__ == "__main__":
    main()
