"""The optimisers of the trainers: full-batch Adam and SPSA loops with early stopping.

Both loops minimise a loss closure over a module's parameters and restore the parameters with the
best validation loss. :func:`training_context` makes a training run reproducible: it forks the
global torch RNG (left untouched afterwards) and sets the thread count for the duration of the
call (one thread by default: the networks are tiny and thread hand-offs cost more than they save).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from enum import StrEnum

import numpy as np
import torch
from torch import nn
from tqdm.auto import tqdm

from fcc_common.progress import auto_progress  # re-exported: the trainers' progress option

__all__ = [
    "EarlyStopping",
    "FitResult",
    "Method",
    "SPSAOptions",
    "adam_loop",
    "auto_progress",
    "snapshot",
    "spsa_loop",
    "torch_threads",
    "training_context",
]

#: a closure that runs the model on the training data: (training loss with its graph, validation
#: loss; NaN without validation data)
LossFn = Callable[[], tuple[torch.Tensor, float]]


class Method(StrEnum):
    """Optimiser of :func:`diagnosers.networks.training.fit_lrgf`: ``ADAM`` (backprop through time) or ``SPSA`` (the paper's)."""

    ADAM = "adam"
    SPSA = "spsa"


@dataclass(frozen=True, kw_only=True)
class SPSAOptions:
    """Simultaneous-perturbation stochastic approximation (Spall, 1998) settings.

    Gains ``a_k = a / (k + 1 + A)^alpha`` and ``c_k = c / (k + 1)^gamma``; the gradient estimate is
    ``(J(θ + c_k Δ) - J(θ - c_k Δ)) / (2 c_k) · Δ^{-1}`` with Rademacher ``Δ``.

    Attributes:
        a: step gain; ``None`` calibrates it so that the first step moves the parameters by about
            ``initial_step`` (Spall's guideline), from ``calibration_samples`` gradient estimates.
        c: perturbation size in parameter units (the loss is deterministic, so it can be small).
        stability_constant: ``A``; ``None`` means 10 % of the iteration budget.
        alpha: decay exponent of ``a_k`` (0.602, Spall's practical value).
        gamma: decay exponent of ``c_k`` (0.101).
        initial_step: target mean absolute first step, for the calibration of ``a``.
        calibration_samples: gradient estimates averaged for the calibration.
        blocking: reject a step that increases the training loss (one extra loss evaluation).
    """

    a: float | None = None
    c: float = 0.01
    stability_constant: float | None = None
    alpha: float = 0.602
    gamma: float = 0.101
    initial_step: float = 0.05
    calibration_samples: int = 8
    blocking: bool = True


@dataclass
class FitResult:
    """What a trainer did; losses are mean squared errors in standardised units.

    Attributes:
        method: optimiser used.
        n_epochs: epochs (Adam) or iterations (SPSA) run.
        best_epoch: epoch whose parameters were restored.
        best_val_loss: validation loss of the restored parameters (training loss without
            validation data).
        train_loss, val_loss: loss history (``val_loss`` holds one entry per evaluation).
        wall_time_s: training wall time.
        stopped_early: whether patience ran out before ``max_epochs``.
    """

    method: str
    n_epochs: int
    best_epoch: int
    best_val_loss: float
    train_loss: list[float] = field(default_factory=list)
    val_loss: list[float] = field(default_factory=list)
    wall_time_s: float = 0.0
    stopped_early: bool = False


@contextmanager
def torch_threads(num_threads: int | None) -> Iterator[None]:
    """Set torch's intra-op thread count for the block (``None``: leave it), then restore it."""
    prev = torch.get_num_threads()
    if num_threads is not None:
        torch.set_num_threads(num_threads)
    try:
        yield
    finally:
        torch.set_num_threads(prev)


@contextmanager
def training_context(seed: int, num_threads: int | None) -> Iterator[None]:
    """Fork the global torch RNG and set the thread count, restoring both afterwards."""
    with torch.random.fork_rng(devices=[]), torch_threads(num_threads):
        torch.manual_seed(seed)
        yield


def snapshot(module: nn.Module) -> dict[str, torch.Tensor]:
    """A detached copy of the module's state dict."""
    return {k: v.detach().clone() for k, v in module.state_dict().items()}


class EarlyStopping:
    """Early-stopping bookkeeping: keeps the best snapshot and counts epochs without progress."""

    def __init__(self, module: nn.Module, patience: int) -> None:
        self.module, self.patience = module, patience
        self.loss, self.epoch, self.state, self.since = math.inf, -1, snapshot(module), 0

    def update(self, loss: float, epoch: int, state: dict[str, torch.Tensor] | None = None) -> bool:
        """Record ``loss`` of the current (or given) parameters; return True when out of patience."""
        if math.isfinite(loss) and loss < self.loss:
            self.loss, self.epoch, self.since = loss, epoch, 0
            self.state = state if state is not None else snapshot(self.module)
            return False
        self.since += 1
        return self.since >= self.patience

    def restore(self) -> None:
        self.module.load_state_dict(self.state)


def adam_loop(
    model: nn.Module,
    losses: LossFn,
    max_epochs: int,
    lr: float,
    patience: int,
    progress: bool,
) -> FitResult:
    """Full-batch Adam (backprop through time) on the training loss, early stopping on
    validation; restores the best parameters into ``model``."""
    opt = torch.optim.Adam(model.parameters(), lr=lr)
    best = EarlyStopping(model, patience)
    res = FitResult(method="adam", n_epochs=0, best_epoch=-1, best_val_loss=math.inf)
    bar = tqdm(range(max_epochs), disable=not progress, desc="LRGF adam", leave=False)
    for epoch in bar:
        opt.zero_grad(set_to_none=True)
        train, val = losses()
        train.backward()
        tr = float(train.detach())
        res.train_loss.append(tr)
        res.val_loss.append(val)
        sel = tr if math.isnan(val) else val
        # the losses belong to the parameters *before* this step, so snapshot before stepping
        stop = best.update(sel, epoch)
        res.n_epochs = epoch + 1
        if progress and epoch % 20 == 0:
            bar.set_postfix(train=f"{tr:.4g}", val=f"{val:.4g}")
        if stop:
            res.stopped_early = True
            break
        opt.step()
    bar.close()
    best.restore()
    res.best_epoch, res.best_val_loss = best.epoch, best.loss
    return res


def spsa_loop(
    model: nn.Module,
    losses: LossFn,
    max_iter: int,
    patience: int,
    opts: SPSAOptions,
    seed: int,
    progress: bool,
) -> FitResult:
    """SPSA (:class:`SPSAOptions`) on the training loss, early stopping on validation; restores
    the best parameters into ``model``."""
    params = [p for p in model.parameters() if p.requires_grad]
    gen = torch.Generator().manual_seed(seed)
    theta = nn.utils.parameters_to_vector(params).detach().to(torch.float64)

    def set_theta(t: torch.Tensor) -> None:
        nn.utils.vector_to_parameters(t.to(params[0].dtype), params)

    def evaluate(t: torch.Tensor) -> tuple[float, float]:
        set_theta(t)
        tr, va = losses()
        return float(tr), va

    def delta() -> torch.Tensor:
        return torch.randint(0, 2, theta.shape, generator=gen, dtype=torch.float64) * 2.0 - 1.0

    big_a = opts.stability_constant if opts.stability_constant is not None else 0.1 * max_iter
    res = FitResult(method="spsa", n_epochs=0, best_epoch=-1, best_val_loss=math.inf)
    with torch.no_grad():
        a = opts.a
        if a is None:
            mags = []
            for _ in range(opts.calibration_samples):
                d = delta()
                j_plus, j_minus = evaluate(theta + opts.c * d)[0], evaluate(theta - opts.c * d)[0]
                mags.append(abs(j_plus - j_minus) / (2 * opts.c))
            a = opts.initial_step * (big_a + 1.0) ** opts.alpha / max(float(np.mean(mags)), 1e-12)
        best = EarlyStopping(model, patience)
        current, cur_val = evaluate(theta)
        bar = tqdm(range(max_iter), disable=not progress, desc="LRGF spsa", leave=False)
        for k in bar:
            res.train_loss.append(current)
            res.val_loss.append(cur_val)
            sel = current if math.isnan(cur_val) else cur_val
            res.n_epochs = k + 1
            set_theta(theta)
            if best.update(sel, k):
                res.stopped_early = True
                break
            a_k = a / (k + 1 + big_a) ** opts.alpha
            c_k = opts.c / (k + 1) ** opts.gamma
            d = delta()
            j_plus, j_minus = evaluate(theta + c_k * d)[0], evaluate(theta - c_k * d)[0]
            # Δ_i = ±1, so dividing by Δ_i equals multiplying by it
            cand = theta - a_k * (j_plus - j_minus) / (2 * c_k) * d
            cand_loss, cand_val = evaluate(cand)
            if not opts.blocking or (math.isfinite(cand_loss) and cand_loss <= current):
                theta, current, cur_val = cand, cand_loss, cand_val
            if progress and k % 50 == 0:
                bar.set_postfix(train=f"{current:.4g}", val=f"{cur_val:.4g}")
        bar.close()
    best.restore()
    res.best_epoch, res.best_val_loss = best.epoch, best.loss
    return res
