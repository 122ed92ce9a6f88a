"""Training of the LRGF nominal model and the NNARX model error model.

The paper's configurations and the modules' persistence live in :mod:`diagnosers.modules` (also
importable from here).

Both trainers minimise the *simulation* (free-run) error: the model is driven by the measured
inputs only and its whole output sequence is compared with the measurements, which is how the
models are used for detection. Signals are standardised with statistics of the training data; the
scaler is stored in the modules' buffers, so trained modules take and return physical units.

Validation: either explicit validation episodes, or the last ``val_fraction`` of every training
episode. In the second case one free run over the whole episode gives both losses (training on the
head, validation on the tail), so the tail starts from the correct model state. Early stopping
restores the parameters with the best validation loss.

Reproducibility: every trainer takes a ``seed`` and runs inside ``torch.random.fork_rng`` with local
generators, so the global torch and numpy RNG states are left untouched, and two runs with the same
seed give bit-identical weights. ``num_threads`` (default 1: the networks are tiny and thread
hand-offs cost more than they save) is set for the duration of the call and then restored.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Any

import numpy as np
import torch
from torch import nn
from tqdm.auto import tqdm

from diagnosers.base import auto_progress
from diagnosers.lrgf import LRGF
from diagnosers.mem import NNARXErrorModel
from diagnosers.modules import build_module, export_module, paper_lrgf, paper_mem
from fcc_env.validation import Integer, Real, check_params

__all__ = [
    "FitResult",
    "Method",
    "SPSAOptions",
    "build_module",
    "export_module",
    "fit_lrgf",
    "fit_mem",
    "paper_lrgf",
    "paper_mem",
    "torch_threads",
]

ArrayLike = np.ndarray | Sequence[np.ndarray]


class Method(StrEnum):
    """Optimiser of :func:`fit_lrgf`: ``ADAM`` (backprop through time) or ``SPSA`` (the paper's)."""

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


# ---- shared plumbing ---------------------------------------------------------------------------
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
def _training_context(seed: int, num_threads: int | None) -> Iterator[None]:
    """Fork the global torch RNG and set the thread count, restoring both afterwards."""
    with torch.random.fork_rng(devices=[]), torch_threads(num_threads):
        torch.manual_seed(seed)
        yield


def _episodes(x: ArrayLike, n_channels: int, name: str) -> list[np.ndarray]:
    """Normalise ``(T, c)``, ``(B, T, c)`` or a list of ``(T_i, c)`` arrays to a list of float64 2-D arrays."""
    if isinstance(x, np.ndarray | torch.Tensor):
        arr = np.asarray(x, dtype=np.float64)
        if arr.ndim == 2:
            eps = [arr]
        elif arr.ndim == 3:
            eps = list(arr)
        else:
            raise ValueError(
                f"{name} must be (T, {n_channels}), (B, T, {n_channels}) or a list; got {arr.shape}"
            )
    else:
        eps = [np.asarray(e, dtype=np.float64) for e in x]
    if not eps:
        raise ValueError(f"{name} holds no episode")
    for i, e in enumerate(eps):
        if e.ndim != 2 or e.shape[1] != n_channels:
            raise ValueError(f"{name}[{i}] must have shape (T, {n_channels}); got {e.shape}")
        if not np.isfinite(e).all():
            raise ValueError(f"{name}[{i}] contains NaN or inf")
    return eps


def _training_pairs(
    u: ArrayLike,
    y: ArrayLike,
    u_val: ArrayLike | None,
    y_val: ArrayLike | None,
    n_in: int,
    n_out: int,
    y_name: str,
) -> tuple[list[np.ndarray], list[np.ndarray], list[np.ndarray] | None, list[np.ndarray] | None]:
    """Training (and optional validation) episodes as checked (input, output) lists."""
    us = _episodes(u, n_in, "u")
    ys = _episodes(y, n_out, y_name)
    _check_pairs(us, ys, f"u/{y_name}")
    if u_val is None and y_val is None:
        return us, ys, None, None
    if u_val is None or y_val is None:
        raise ValueError(f"give both u_val and {y_name}_val, or neither")
    uvs = _episodes(u_val, n_in, "u_val")
    yvs = _episodes(y_val, n_out, f"{y_name}_val")
    _check_pairs(uvs, yvs, f"u_val/{y_name}_val")
    return us, ys, uvs, yvs


def _check_pairs(us: list[np.ndarray], ys: list[np.ndarray], names: str) -> None:
    if len(us) != len(ys):
        raise ValueError(f"{names}: {len(us)} input episodes but {len(ys)} output episodes")
    for i, (a, b) in enumerate(zip(us, ys, strict=True)):
        if a.shape[0] != b.shape[0]:
            raise ValueError(
                f"{names}: episode {i} has {a.shape[0]} input and {b.shape[0]} output samples"
            )


def _mean_scale(eps: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    cat = np.concatenate(eps, axis=0)
    std = cat.std(axis=0)
    # a constant channel carries no information; scale 1 keeps it finite instead of dividing by 0
    return cat.mean(axis=0), np.where(std > 1e-12 * (1.0 + np.abs(cat.mean(axis=0))), std, 1.0)


@dataclass
class _Group:
    """Equal-length episodes stacked for one batched free run."""

    u: torch.Tensor  # (B, T, n) standardised
    y: torch.Tensor  # (B, T, m) standardised
    train: slice  # time range entering the training loss
    val: slice  # time range entering the validation loss


def _make_groups(
    us: list[np.ndarray],
    ys: list[np.ndarray],
    u_stats: tuple[np.ndarray, np.ndarray],
    y_stats: tuple[np.ndarray, np.ndarray],
    dtype: torch.dtype,
    split: Callable[[int], tuple[slice, slice]],
) -> list[_Group]:
    by_len: dict[int, list[int]] = {}
    for i, e in enumerate(us):
        by_len.setdefault(e.shape[0], []).append(i)
    groups = []
    for t_len, idx in sorted(by_len.items()):
        u = np.stack([(us[i] - u_stats[0]) / u_stats[1] for i in idx])
        y = np.stack([(ys[i] - y_stats[0]) / y_stats[1] for i in idx])
        tr, va = split(t_len)
        groups.append(
            _Group(torch.as_tensor(u, dtype=dtype), torch.as_tensor(y, dtype=dtype), tr, va)
        )
    return groups


def _sse(pred: torch.Tensor, target: torch.Tensor, sl: slice) -> tuple[torch.Tensor, int]:
    d = pred[:, sl] - target[:, sl]
    return (d * d).sum(), d.numel()


def _split_fn(
    val_fraction: float, washout: int, has_val: bool
) -> Callable[[int], tuple[slice, slice]]:
    def split(t_len: int) -> tuple[slice, slice]:
        if has_val or val_fraction == 0.0:
            return slice(washout, t_len), slice(0, 0)
        cut = round(t_len * (1.0 - val_fraction))
        if cut - washout < 1 or cut >= t_len:
            raise ValueError(
                f"episode of {t_len} samples is too short for washout={washout} and "
                f"val_fraction={val_fraction}"
            )
        return slice(washout, cut), slice(cut, t_len)

    return split


#: constraints shared by :func:`fit_lrgf` and :func:`fit_mem`
TRAINING_CONSTRAINTS: dict[str, Any] = {
    "max_epochs": Integer(1),
    "patience": Integer(1),
    "val_fraction": Real(0, 1, closed="left"),
    "washout": Integer(0),
    "window": Integer(2),
    "val_every": Integer(1),
    "pretrain_epochs": Integer(0),
}


def _snapshot(module: nn.Module) -> dict[str, torch.Tensor]:
    return {k: v.detach().clone() for k, v in module.state_dict().items()}


# ---- LRGF --------------------------------------------------------------------------------------
def fit_lrgf(
    model: LRGF,
    u: ArrayLike,
    y: ArrayLike,
    *,
    u_val: ArrayLike | None = None,
    y_val: ArrayLike | None = None,
    method: Method | str = Method.ADAM,
    max_epochs: int = 2000,
    lr: float = 0.01,
    patience: int = 200,
    val_fraction: float = 0.25,
    washout: int = 0,
    standardize: bool = True,
    spsa: SPSAOptions | None = None,
    seed: int = 0,
    num_threads: int | None = 1,
    progress: bool | None = False,
) -> FitResult:
    """Train ``model`` in place on free-run (simulation) error; returns a :class:`FitResult`.

    The model keeps its current parameters as the starting point (its own ``seed`` decides the
    initialisation); the scaler buffers are overwritten when ``standardize`` is true.

    Args:
        model: the network to train (float32 or float64).
        u: inputs, physical units: ``(T, n)``, ``(B, T, n)`` or a list of ``(T_i, n)`` episodes.
        y: measured outputs, matching ``u`` with ``m`` channels.
        u_val, y_val: optional validation episodes (same forms). Without them the last
            ``val_fraction`` of every training episode validates.
        method: ``"adam"`` (full-batch Adam, backprop through time) or ``"spsa"``.
        max_epochs: Adam epochs (one full-batch step each) or SPSA iterations.
        lr: Adam learning rate (ignored by SPSA).
        patience: stop when the validation loss has not improved for this many epochs/iterations.
        val_fraction: fraction of each episode held out for validation when no ``u_val`` is given;
            0 disables validation (the training loss selects the parameters).
        washout: initial samples of every episode left out of the training loss (start-up transient
            of a zero initial state).
        standardize: compute and store the scaler from the training data; if false the current
            buffers are used as they are.
        spsa: SPSA settings (``None``: defaults).
        seed: seed of all randomness in training (SPSA perturbations).
        num_threads: torch intra-op threads during training (``None`` leaves them alone).
        progress: show a tqdm progress bar (``None``: when run interactively,
            :func:`diagnosers.base.auto_progress`).

    Returns:
        the training record; ``model`` holds the best parameters found.
    """
    try:
        method = Method(method)
    except ValueError:
        raise ValueError(f"method={method!r}; choose one of {[m.value for m in Method]}") from None
    check_params(
        {"max_epochs": max_epochs, "patience": patience, "val_fraction": val_fraction,
         "washout": washout},
        TRAINING_CONSTRAINTS,
    )  # fmt: skip
    us, ys, uvs, yvs = _training_pairs(u, y, u_val, y_val, model.n_inputs, model.n_outputs, "y")
    has_val = uvs is not None
    split = _split_fn(val_fraction, washout, has_val)
    if standardize:
        heads = [split(e.shape[0])[0] for e in us]
        u_stats = _mean_scale([e[: s.stop] for e, s in zip(us, heads, strict=True)])
        y_stats = _mean_scale([e[: s.stop] for e, s in zip(ys, heads, strict=True)])
        model.set_scaler(u_stats[0], u_stats[1], y_stats[0], y_stats[1])
    else:
        u_stats = (model.input_mean.double().numpy(), model.input_scale.double().numpy())
        y_stats = (model.output_mean.double().numpy(), model.output_scale.double().numpy())
    dtype = model.weight_in.dtype
    groups = _make_groups(us, ys, u_stats, y_stats, dtype, split)
    if has_val:
        val_groups = _make_groups(
            uvs, yvs, u_stats, y_stats, dtype, lambda t: (slice(0, 0), slice(washout, t))
        )
        groups = groups + val_groups

    def losses() -> tuple[torch.Tensor, float]:
        tr_sse, tr_n, va_sse, va_n = 0.0, 0, 0.0, 0
        for g in groups:
            pred = model.forward_normalized(g.u)
            s, n = _sse(pred, g.y, g.train)
            tr_sse, tr_n = tr_sse + s, tr_n + n
            s, n = _sse(pred.detach(), g.y, g.val)
            va_sse, va_n = va_sse + float(s), va_n + n
        train = tr_sse / max(tr_n, 1)
        val = va_sse / va_n if va_n else float("nan")
        return train, val

    progress = auto_progress(progress)
    with _training_context(seed, num_threads):
        t0 = time.perf_counter()
        if method is Method.ADAM:
            result = _adam_loop(model, losses, max_epochs, lr, patience, progress)
        else:
            result = _spsa_loop(
                model, losses, max_epochs, patience, spsa or SPSAOptions(), seed, progress
            )
        result.wall_time_s = time.perf_counter() - t0
    return result


class _Best:
    """Early-stopping bookkeeping: keeps the best snapshot and counts epochs without progress."""

    def __init__(self, module: nn.Module, patience: int) -> None:
        self.module, self.patience = module, patience
        self.loss, self.epoch, self.state, self.since = math.inf, -1, _snapshot(module), 0

    def update(self, loss: float, epoch: int, state: dict[str, torch.Tensor] | None = None) -> bool:
        """Record ``loss`` of the current (or given) parameters; return True when out of patience."""
        if math.isfinite(loss) and loss < self.loss:
            self.loss, self.epoch, self.since = loss, epoch, 0
            self.state = state if state is not None else _snapshot(self.module)
            return False
        self.since += 1
        return self.since >= self.patience

    def restore(self) -> None:
        self.module.load_state_dict(self.state)


def _adam_loop(
    model: LRGF,
    losses: Callable[[], tuple[torch.Tensor, float]],
    max_epochs: int,
    lr: float,
    patience: int,
    progress: bool,
) -> FitResult:
    opt = torch.optim.Adam(model.parameters(), lr=lr)
    best = _Best(model, patience)
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


def _spsa_loop(
    model: LRGF,
    losses: Callable[[], tuple[torch.Tensor, float]],
    max_iter: int,
    patience: int,
    opts: SPSAOptions,
    seed: int,
    progress: bool,
) -> FitResult:
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
        best = _Best(model, patience)
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


# ---- model error model -------------------------------------------------------------------------
def fit_mem(
    mem: NNARXErrorModel,
    u: ArrayLike,
    r: ArrayLike,
    *,
    u_val: ArrayLike | None = None,
    r_val: ArrayLike | None = None,
    max_epochs: int = 400,
    lr: float = 0.01,
    patience: int = 60,
    val_fraction: float = 0.25,
    window: int = 128,
    val_every: int = 5,
    pretrain_epochs: int = 300,
    standardize: bool = True,
    seed: int = 0,
    num_threads: int | None = 1,
    progress: bool | None = False,
) -> FitResult:
    """Train the model error model on the nominal model's residual ``r = y - y_m``.

    After an optional one-step-ahead warm start (``pretrain_epochs``), training minimises the
    *simulation* error over windows: each epoch cuts the training part of
    every episode into windows of ``window`` samples (a random offset per epoch, from ``seed``) and
    free-runs the MEM over all windows in parallel, starting each window with the measured residual
    as its past outputs (the measured values are only initial conditions, inside a window the model
    feeds back its own outputs). Stepping ``window`` samples instead of the whole episode keeps an
    epoch cheap. Validation, every ``val_every`` epochs, free-runs whole episodes from the
    deployment start (zero past outputs), exactly as the detector runs the MEM, and early stopping
    on it restores the best weights.

    Args:
        mem: the model to train in place.
        u: process inputs, physical units, ``(T, n)``, ``(B, T, n)`` or a list of episodes.
        r: residuals of the nominal model on the same episodes, ``m`` channels.
        u_val, r_val: optional validation episodes; otherwise the last ``val_fraction`` of each.
        max_epochs: Adam epochs (one step over all windows each).
        lr: Adam learning rate.
        patience: epochs without validation improvement before stopping.
        val_fraction: held-out tail fraction when no validation episodes are given (0: none).
        window: window length in samples (clipped to the shortest training part).
        val_every: epochs between validation runs.
        pretrain_epochs: Adam steps of one-step-ahead (series-parallel) training before the
            simulation-error epochs. They are fully vectorised (about a millisecond each) and give
            the simulation training a warm start; the measured residual appears in the regressor
            only here, never in the returned model's use. 0 disables.
        standardize: compute and store the scaler from the training data.
        seed: seed of the window offsets.
        num_threads: torch intra-op threads during training (``None`` leaves them alone).
        progress: show a tqdm progress bar (``None``: when run interactively,
            :func:`diagnosers.base.auto_progress`).

    Returns:
        the training record; ``mem`` holds the best parameters found.
    """
    check_params(
        {"max_epochs": max_epochs, "patience": patience, "val_fraction": val_fraction,
         "window": window, "val_every": val_every, "pretrain_epochs": pretrain_epochs},
        TRAINING_CONSTRAINTS,
    )  # fmt: skip
    us, rs, uvs, rvs = _training_pairs(u, r, u_val, r_val, mem.n_inputs, mem.n_outputs, "r")
    has_val = uvs is not None
    split = _split_fn(val_fraction, 0, has_val)
    if standardize:
        heads = [split(e.shape[0])[0] for e in us]
        u_stats = _mean_scale([e[: s.stop] for e, s in zip(us, heads, strict=True)])
        r_stats = _mean_scale([e[: s.stop] for e, s in zip(rs, heads, strict=True)])
        mem.set_scaler(u_stats[0], u_stats[1], r_stats[0], r_stats[1])
    else:
        u_stats = (mem.input_mean.double().numpy(), mem.input_scale.double().numpy())
        r_stats = (mem.output_mean.double().numpy(), mem.output_scale.double().numpy())
    dtype = mem.hidden.weight.dtype
    groups = _make_groups(us, rs, u_stats, r_stats, dtype, split)
    val_groups = [g for g in groups if g.val.stop > g.val.start]
    if has_val:
        val_groups = _make_groups(
            uvs, rvs, u_stats, r_stats, dtype, lambda t: (slice(0, 0), slice(0, t))
        )
    win = min(window, *(g.train.stop - g.train.start for g in groups))
    na, m = mem.output_delays, mem.n_outputs
    # the regressors do not depend on the parameters: built once, not in every epoch
    lagged_u = [mem.lagged_inputs(g.u) for g in groups]
    lagged_val = [mem.lagged_inputs(g.u) for g in val_groups]

    def windows(
        offset: int,
    ) -> tuple[list[torch.Tensor], torch.Tensor, torch.Tensor]:
        """Start indices per group, stacked initial past outputs and targets."""
        starts_all, past, target = [], [], []
        for g in groups:
            stop = g.train.stop
            starts = list(
                range(offset % win if stop - offset % win >= win else 0, stop - win + 1, win)
            )
            st = torch.as_tensor(starts, dtype=torch.long)
            starts_all.append(st)
            # past outputs y(s-1), ..., y(s-na); before the episode start they are 0 (deployment)
            ypad = torch.cat([g.y.new_zeros((g.y.shape[0], na, m)), g.y], dim=1)
            for s in starts:
                past.append(ypad[:, s : s + na].flip(1))
                target.append(g.y[:, s : s + win])
        return starts_all, torch.cat(past), torch.cat(target)

    def val_loss() -> float:
        sse, cnt = 0.0, 0
        with torch.no_grad():
            for g, lagged in zip(val_groups, lagged_val, strict=True):
                pred = mem.run_normalized(mem.input_drive(g.u, lagged))
                s, n = _sse(pred, g.y, g.val)
                sse, cnt = sse + float(s), cnt + n
        return sse / cnt if cnt else float("nan")

    progress = auto_progress(progress)
    with _training_context(seed, num_threads):
        t0 = time.perf_counter()
        gen = torch.Generator().manual_seed(seed)
        opt = torch.optim.Adam(mem.parameters(), lr=lr)
        if pretrain_epochs:
            pre_opt = torch.optim.Adam(mem.parameters(), lr=lr)
            lagged_y = [mem.lagged_outputs(g.y) if na else None for g in groups]
            for _ in range(pretrain_epochs):
                pre_opt.zero_grad(set_to_none=True)
                sse, cnt = 0.0, 0
                for g, lu, ly in zip(groups, lagged_u, lagged_y, strict=True):
                    pred = mem.one_step_normalized(mem.input_drive(g.u, lu), g.y, ly)
                    s, n = _sse(pred, g.y, g.train)
                    sse, cnt = sse + s, cnt + n
                (sse / cnt).backward()
                pre_opt.step()
        best = _Best(mem, patience=max(1, math.ceil(patience / val_every)))
        res = FitResult(method="adam", n_epochs=0, best_epoch=-1, best_val_loss=math.inf)
        bar = tqdm(range(max_epochs), disable=not progress, desc="MEM", leave=False)
        for epoch in bar:
            if epoch % val_every == 0:
                if val_groups:
                    vl = val_loss()
                else:
                    with torch.no_grad():
                        vl = float(_window_loss(mem, groups, windows, win, 0, lagged_u))
                res.val_loss.append(vl)
                if best.update(vl, epoch):
                    res.stopped_early = True
                    break
                if progress:
                    bar.set_postfix(val=f"{vl:.4g}")
            offset = int(torch.randint(0, win, (1,), generator=gen))
            opt.zero_grad(set_to_none=True)
            loss = _window_loss(mem, groups, windows, win, offset, lagged_u)
            loss.backward()
            opt.step()
            res.train_loss.append(float(loss.detach()))
            res.n_epochs = epoch + 1
        else:
            # judge the parameters of the last step too
            if val_groups:
                vl = val_loss()
            else:
                with torch.no_grad():
                    vl = float(_window_loss(mem, groups, windows, win, 0, lagged_u))
            res.val_loss.append(vl)
            best.update(vl, max_epochs)
        bar.close()
        best.restore()
        res.best_epoch, res.best_val_loss = best.epoch, best.loss
        res.wall_time_s = time.perf_counter() - t0
    return res


def _window_loss(
    mem: NNARXErrorModel,
    groups: list[_Group],
    windows: Callable[[int], tuple[list[torch.Tensor], torch.Tensor, torch.Tensor]],
    win: int,
    offset: int,
    lagged_u: list[torch.Tensor],
) -> torch.Tensor:
    starts_all, past, target = windows(offset)
    drives = []
    for g, lagged, starts in zip(groups, lagged_u, starts_all, strict=True):
        # whole episodes: the input delays need no window padding
        drive = mem.input_drive(g.u, lagged)
        for s in starts.tolist():
            drives.append(drive[:, s : s + win])
    pred = mem.run_normalized(torch.cat(drives), past)
    return ((pred - target) ** 2).mean()
