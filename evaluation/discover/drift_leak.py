"""The filter re-run per candidate: the drift estimate without the candidate's effect.

The state estimator explains what it can with the coking factor, so a hidden effect leaks into
the drift estimate, and not only as a level or a trend (the correction line of
:mod:`evaluation.discover.drift_joint`): a catalyst deactivation fitted with the line still lost
to a T_fp sensor drift (validation seed 5000: held-out score 29 611 against 29 812), while fed
the plant's true coking factor it won by far (96 057, the T_fp drift not among the first five;
``lab/discover_drift.md``). So for the best candidates of a round (:data:`RERANK`, by their
score with the estimate as it is) the filter is run again on the record *with the candidate's
effect taken out*:

1. The candidate at its fitted value θ₁ (its typical value when the fit left it at its null)
   changes the model's outputs by Δy = y(θ₁) − y(null); the record less Δy on the output
   channels is what the plant would have recorded without the effect (to first order, with the
   estimate fed).
2. The filter run on it gives f̃₁; ``g = (f̂_raw − f̃₁)/(θ₁ − null)``, shifted and smoothed as the
   estimate is, is the estimate's response per unit of the parameter (the leak).
3. The candidate is fitted again (the line free, as always) with the fed coking factor
   ``f̂ − (θ − null)·g``: at its value the drift is the one the filter would have estimated
   without the effect (:meth:`PhysicsModel.set_drift_response`), and scored as before against
   the same baseline.

All the re-runs of a round are one batched filter call. The leak is taken as linear in the
parameter (one re-run per candidate); a single-parameter candidate only (every library effect).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from evaluation.discover.base import Candidate
from evaluation.discover.data import TABLE1
from evaluation.discover.drift import filter_coking, shift_and_smooth
from evaluation.discover.selection import FitContext

__all__ = ["RERANK", "drift_responses", "rerank_rows"]

#: Candidates of a round re-fitted with the filter re-run (the best by score without it).
#: The hidden effect was first to fourth in every miss measured on validation seeds 5000-5001.
RERANK = 4


def drift_responses(
    ctx: FitContext,
    effects: Sequence[Candidate],
    theta: np.ndarray,
    trials: Sequence[tuple[Candidate, float]],
    lag: int,
) -> list[np.ndarray]:
    """The drift estimate's response (n_episodes, n_samples) per unit parameter of each
    candidate of ``trials`` (candidate, value θ₁) added to the model as it stands (``effects``
    at ``theta``); the estimate's lag ``lag`` undone as for the estimate itself."""
    model, data = ctx.model, ctx.data
    T = data.n_samples
    table1 = data.stack(TABLE1)
    out_idx = [TABLE1.index(c) for c in model.output_channels]
    base = model.predict(data, effects, theta[None], T)[0]
    batches, units = [table1], []
    for cand, th1 in trials:
        if len(cand.params) != 1:
            raise ValueError(f"{cand.id!r} has {len(cand.params)} parameters; the re-run needs 1")
        p = cand.params[0]
        step = float(th1) - p.null
        if abs(step) < 1e-3 * abs(p.typical - p.null):  # the fit found nothing: its typical size
            step = p.typical - p.null
        with_ = model.predict(data, [*effects, cand], np.r_[theta, p.null + step][None], T)[0]
        without = table1.copy()
        without[..., out_idx] -= with_ - base
        batches.append(without)
        units.append(step)
    raw = filter_coking(data, np.concatenate(batches)).reshape(len(batches), data.n_episodes, T)
    return [shift_and_smooth((raw[0] - raw[k + 1]) / u, lag) for k, u in enumerate(units)]


def rerank_rows(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The rows of a round re-fitted with the filter re-run: the :data:`RERANK` best by score
    among single-parameter candidates with a finite score."""
    ok = [r for r in rows if r["k"] == 1 and np.isfinite(r["score"])]
    return sorted(ok, key=lambda r: -r["score"])[:RERANK]
