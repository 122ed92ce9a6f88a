"""Training of the LRGF nominal model and the NNARX model error model.

The paper's configurations and the modules' persistence live in :mod:`diagnosers.networks.modules`, the
optimisers in :mod:`diagnosers.networks.optimisers`, the data plumbing in :mod:`diagnosers.networks.training_data`.

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
from collections.abc import Callable
from typing import Any

import torch
from tqdm.auto import tqdm

from diagnosers.networks.lrgf_net import LRGF
from diagnosers.networks.mem_net import NNARXErrorModel
from diagnosers.networks.optimisers import (
    EarlyStopping,
    FitResult,
    Method,
    SPSAOptions,
    adam_loop,
    auto_progress,
    spsa_loop,
    training_context,
)
from diagnosers.networks.training_data import (
    ArrayLike,
    EpisodeGroup,
    make_groups,
    mean_scale,
    squared_error_sum,
    train_val_split,
    training_pairs,
)
from fcc_common.validation import Integer, Real, check_params

__all__ = ["TRAINING_CONSTRAINTS", "fit_lrgf", "fit_mem"]


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
            :func:`diagnosers.networks.optimisers.auto_progress`).

    Returns:
        the training record; ``model`` holds the best parameters found.
    """
    try:
        method = Method(method)
    except ValueError:
        raise ValueError(f"method={method!r}; choose one of {[m.value for m in Method]}") from None
    check_params(
        {
            "max_epochs": max_epochs,
            "patience": patience,
            "val_fraction": val_fraction,
            "washout": washout,
        },
        TRAINING_CONSTRAINTS,
    )
    us, ys, uvs, yvs = training_pairs(u, y, u_val, y_val, model.n_inputs, model.n_outputs, "y")
    has_val = uvs is not None
    split = train_val_split(val_fraction, washout, has_val)
    if standardize:
        heads = [split(e.shape[0])[0] for e in us]
        u_stats = mean_scale([e[: s.stop] for e, s in zip(us, heads, strict=True)])
        y_stats = mean_scale([e[: s.stop] for e, s in zip(ys, heads, strict=True)])
        model.set_scaler(u_stats[0], u_stats[1], y_stats[0], y_stats[1])
    else:
        u_stats = (model.input_mean.double().numpy(), model.input_scale.double().numpy())
        y_stats = (model.output_mean.double().numpy(), model.output_scale.double().numpy())
    dtype = model.weight_in.dtype
    groups = make_groups(us, ys, u_stats, y_stats, dtype, split)
    if has_val:
        val_groups = make_groups(
            uvs, yvs, u_stats, y_stats, dtype, lambda t: (slice(0, 0), slice(washout, t))
        )
        groups = groups + val_groups

    def losses() -> tuple[torch.Tensor, float]:
        tr_sse, tr_n, va_sse, va_n = 0.0, 0, 0.0, 0
        for g in groups:
            pred = model.forward_normalized(g.u)
            s, n = squared_error_sum(pred, g.y, g.train)
            tr_sse, tr_n = tr_sse + s, tr_n + n
            s, n = squared_error_sum(pred.detach(), g.y, g.val)
            va_sse, va_n = va_sse + float(s), va_n + n
        train = tr_sse / max(tr_n, 1)
        val = va_sse / va_n if va_n else float("nan")
        return train, val

    progress = auto_progress(progress)
    with training_context(seed, num_threads):
        t0 = time.perf_counter()
        if method is Method.ADAM:
            result = adam_loop(model, losses, max_epochs, lr, patience, progress)
        else:
            result = spsa_loop(
                model, losses, max_epochs, patience, spsa or SPSAOptions(), seed, progress
            )
        result.wall_time_s = time.perf_counter() - t0
    return result


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
            :func:`diagnosers.networks.optimisers.auto_progress`).

    Returns:
        the training record; ``mem`` holds the best parameters found.
    """
    check_params(
        {
            "max_epochs": max_epochs,
            "patience": patience,
            "val_fraction": val_fraction,
            "window": window,
            "val_every": val_every,
            "pretrain_epochs": pretrain_epochs,
        },
        TRAINING_CONSTRAINTS,
    )
    us, rs, uvs, rvs = training_pairs(u, r, u_val, r_val, mem.n_inputs, mem.n_outputs, "r")
    has_val = uvs is not None
    split = train_val_split(val_fraction, 0, has_val)
    if standardize:
        heads = [split(e.shape[0])[0] for e in us]
        u_stats = mean_scale([e[: s.stop] for e, s in zip(us, heads, strict=True)])
        r_stats = mean_scale([e[: s.stop] for e, s in zip(rs, heads, strict=True)])
        mem.set_scaler(u_stats[0], u_stats[1], r_stats[0], r_stats[1])
    else:
        u_stats = (mem.input_mean.double().numpy(), mem.input_scale.double().numpy())
        r_stats = (mem.output_mean.double().numpy(), mem.output_scale.double().numpy())
    dtype = mem.hidden.weight.dtype
    groups = make_groups(us, rs, u_stats, r_stats, dtype, split)
    val_groups = [g for g in groups if g.val.stop > g.val.start]
    if has_val:
        val_groups = make_groups(
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
                s, n = squared_error_sum(pred, g.y, g.val)
                sse, cnt = sse + float(s), cnt + n
        return sse / cnt if cnt else float("nan")

    progress = auto_progress(progress)
    with training_context(seed, num_threads):
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
                    s, n = squared_error_sum(pred, g.y, g.train)
                    sse, cnt = sse + s, cnt + n
                (sse / cnt).backward()
                pre_opt.step()
        best = EarlyStopping(mem, patience=max(1, math.ceil(patience / val_every)))
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
    groups: list[EpisodeGroup],
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
