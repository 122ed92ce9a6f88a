"""The effects a run has accepted, and their joint re-fit (the greedy selection's repair).

:class:`Accepted` holds one accepted effect (or form) with its fitted values; a *nuisance* entry
(the drift correction line of :mod:`evaluation.discover.drift_joint`) is fitted with every
candidate and every re-fit but is never a finding: it is not reported as an effect, never
dropped by :func:`backward_elimination`, and not counted as one. :func:`refit_all` re-fits
everything accepted jointly and then drops earlier effects made redundant by later ones.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from evaluation.discover.base import Candidate, ModelAdapter
from evaluation.discover.data import MeasuredData
from evaluation.discover.fitting import fit_effects
from evaluation.discover.scoring import heldout_comparison

__all__ = [
    "Accepted",
    "FitContext",
    "assign",
    "backward_elimination",
    "findings",
    "nuisance_mask",
    "refit_all",
    "stacked",
]


@dataclass(frozen=True)
class FitContext:
    """What every joint re-fit of a run reads: the model, the data, the held-out split and the
    weights, and the significance level of the block test (fixed for the run)."""

    model: ModelAdapter
    data: MeasuredData
    Y: np.ndarray
    n_train: int
    sqrt_w: np.ndarray
    block_len: int
    alpha: float
    min_rel: float


@dataclass
class Accepted:
    """An accepted effect with its values; ``nuisance``: fitted always, never a finding."""

    cand: Candidate
    theta: np.ndarray
    stderr: np.ndarray
    round: int
    stats: dict[str, float]
    nuisance: bool = False


def stacked(accepted: Sequence[Accepted]) -> tuple[list[Candidate], np.ndarray]:
    """The candidates in order and their values concatenated (what ``predict`` takes)."""
    effs = [a.cand for a in accepted]
    theta = np.concatenate([a.theta for a in accepted]) if accepted else np.zeros(0)
    return effs, theta


def nuisance_mask(accepted: Sequence[Accepted]) -> np.ndarray:
    """Over the concatenated values: True where they belong to a nuisance entry."""
    parts = [np.full(len(a.cand.params), a.nuisance) for a in accepted]
    return np.concatenate(parts) if parts else np.zeros(0, bool)


def findings(accepted: Sequence[Accepted]) -> list[Accepted]:
    """The accepted effects that are findings (the nuisance entries left out)."""
    return [a for a in accepted if not a.nuisance]


def assign(
    accepted: Sequence[Accepted], theta: np.ndarray, stderr: np.ndarray, nuisance_only: bool
) -> None:
    """Write fitted values (concatenated in ``accepted`` order) back, in place; with
    ``nuisance_only`` to the nuisance entries alone (the others were held fixed in the fit)."""
    j = 0
    for a in accepted:
        n_p = len(a.cand.params)
        if a.nuisance or not nuisance_only:
            a.theta, a.stderr = theta[j : j + n_p].copy(), stderr[j : j + n_p].copy()
        j += n_p


def backward_elimination(ctx: FitContext, accepted: list[Accepted]) -> list[str]:
    """Drop earlier effects made redundant by later ones (greedy forward selection's repair).

    For each accepted effect but the newest (nuisance entries excepted), the others are re-fitted
    jointly without it; if the held-out test no longer finds it significant (same level and
    minimum reduction as for adding), it is removed and the others keep their re-fitted values.
    """
    model, data, Y, n_train, sqrt_w = ctx.model, ctx.data, ctx.Y, ctx.n_train, ctx.sqrt_w
    dropped: list[str] = []
    T = data.n_samples
    for a in findings(accepted)[:-1]:
        if len(findings(accepted)) < 2:
            break
        full_e, full_th = stacked(accepted)
        rest = [x for x in accepted if x is not a]
        rest_e, th = stacked(rest)
        fit = fit_effects(
            model, data, rest_e, th, np.ones(th.size, bool), Y, n_train, sqrt_w, grid=False
        )
        e_without = Y - model.predict(data, rest_e, fit.theta[None], T)[0]
        e_with = Y - model.predict(data, full_e, full_th[None], T)[0]
        cmp = heldout_comparison(e_without[:, n_train:], e_with[:, n_train:], sqrt_w, ctx.block_len)
        n_found = len(findings(accepted))
        if cmp["p_value"] < ctx.alpha / n_found and cmp["rel_reduction"] >= ctx.min_rel:
            continue
        accepted.remove(a)
        dropped.append(a.cand.id)
        assign(rest, fit.theta, fit.stderr, nuisance_only=False)
    return dropped


def refit_all(
    ctx: FitContext, accepted: list[Accepted], round_table: dict, excluded: set[str]
) -> None:
    """Joint re-fit of everything accepted so far, then backward elimination (in place). With a
    single finding there is nothing to re-fit: its own fit had the nuisance free already."""
    if len(findings(accepted)) < 2:
        return
    effs, th = stacked(accepted)
    fit = fit_effects(
        ctx.model,
        ctx.data,
        effs,
        th,
        np.ones(th.size, bool),
        ctx.Y,
        ctx.n_train,
        ctx.sqrt_w,
        grid=False,
    )
    assign(accepted, fit.theta, fit.stderr, nuisance_only=False)
    dropped = backward_elimination(ctx, accepted)
    if dropped:
        round_table["dropped"] = dropped
        excluded.update(dropped)
