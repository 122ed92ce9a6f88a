"""Searching for a form when no library effect explains the residual (sparse regression + gate).

One *form round* of :func:`~evaluation.discover.loop.discover`:

1. *Sensitivities.* The declared model (with the effects accepted so far) is simulated on the
   training part; every candidate term of :class:`~evaluation.discover.terms.TermLibrary`,
   added to each target state equation with a small coefficient, is simulated too (batched, the
   model's own simulator), and the change of every output per unit coefficient is that term's
   regressor. A measurement term's regressor is its value on its channel. Regressing the
   training residual on these is the first Gauss–Newton step of the simulation-error fit from
   "no correction": selection by simulation error, not by differentiated noisy data.
2. *Sparse selection.* PySINDy's sequentially thresholded least squares
   (:class:`pysindy.STLSQ`, or :class:`pysindy.SR3` with an ℓ0 penalty), run over a path of
   thresholds on the regression's triangular factor (the same least-squares problem in K rows
   instead of N), gives the best support of each size up to ``max_terms``.
3. *Fit and gate.* The ``n_fit`` best (target, support) pairs by penalised training gain are
   fitted by simulation-error least squares (:func:`~evaluation.discover.fitting.fit_effects`)
   and scored on the held-out part exactly as library candidates are:
   ``score = ΔSSE_w − n_terms·ln(N_held)``, significant when the block test's p-value is below
   ``alpha / n_fit`` (Bonferroni) and the reduction at least ``min_rel_reduction``.
4. *Stability.* A significant form is accepted only when the corrected model, simulated over
   the whole record, stays finite and inside the plant's envelope, and a 5 °C push on the four
   temperatures decays over the record at least as :data:`DECAY_LIMIT` says.

MIOSR (PySINDy's exact mixed-integer selector) needs Gurobi, which is not a dependency here;
with at most three terms, the STLSQ path finds the supports that matter (lab/form_lab.md).
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from threadpoolctl import threadpool_limits

from evaluation.discover.base import Candidate, FitResult, ParamInfo
from evaluation.discover.corrected_sim import term_values, with_lags
from evaluation.discover.data import TABLE1, MeasuredData
from evaluation.discover.fitting import ar1_inflation, fit_effects
from evaluation.discover.form_shapes import refine_shapes
from evaluation.discover.scoring import heldout_comparison
from evaluation.discover.terms import (
    N_BASE_SIGNALS,
    SIGNALS,
    STATE_TARGETS,
    FormCandidate,
    Term,
    TermLibrary,
)
from fcc_common.progress import progress_bar
from fcc_common.validation import Integer, Options, check, invalid
from fcc_env.plant import envelope_codes

__all__ = ["DECAY_LIMIT", "OPTIMIZERS", "FormSearch", "form_round", "stability"]

#: Temperature state equations searched by default, with the channel each one is measured by.
TEMPERATURE_STATES = ("T_rg1", "T_rg2", "T_d1", "T_dg")
OPTIMIZERS = ("stlsq", "sr3")
#: A push of the initial temperatures must have decayed to this share of its size by the end
#: of the record (the declared model's own push decays to about 1 % over 11 h).
DECAY_LIMIT = 0.25
PUSH_C = 5.0
#: Coefficient step of the sensitivity simulations, per unit of a (standardised) term, relative
#: to the target state's mean: small enough to stay linear, far above rounding.
REL_STEP = 1e-7
MAX_TERMS = Integer(1, 5)
#: Ridge weights of the STLSQ path (relative, columns normalised): the candidate terms are
#: strongly collinear (every temperature follows the same inputs), and without a ridge the
#: thresholded path jumps from one term to many; each weight gives another path.
RIDGE_ALPHAS = (1e-3, 1e-2, 1e-1)


@dataclass(frozen=True)
class FormSearch:
    """Settings of the form search (one object, passed whole).

    ``library``: the candidate terms; ``max_terms``: at most this many terms in a form (1–5,
    default 3); ``targets``: state equations to search (default: the four temperatures) — the
    measurement of each channel with structure left is always searched too; ``optimizer``:
    ``"stlsq"`` or ``"sr3"``; ``n_fit``: how many (equation, support) pairs are fitted by
    simulation and tested on the held-out part (the Bonferroni count); ``stride``: every
    ``stride``-th training sample enters the selection regression; ``fit_shapes``: fit the
    selected terms' shape parameters (centres, scales, time constants:
    :mod:`~evaluation.discover.form_shapes`) with the coefficients, kept where they lower the
    training error by more than ln N per shape parameter.
    """

    library: TermLibrary = field(default_factory=TermLibrary)
    max_terms: int = 3
    targets: tuple[str, ...] = TEMPERATURE_STATES
    optimizer: str = "stlsq"
    n_fit: int = 6
    stride: int = 2
    fit_shapes: bool = True

    def __post_init__(self) -> None:
        check("max_terms", self.max_terms, MAX_TERMS)
        check("optimizer", self.optimizer, Options(OPTIMIZERS))
        check("n_fit", self.n_fit, Integer(1, 50))
        check("stride", self.stride, Integer(1, 50))
        if not isinstance(self.fit_shapes, bool):
            raise invalid("fit_shapes", self.fit_shapes, "True or False")
        for t in self.targets:
            check("target", t, Options(tuple(STATE_TARGETS)))
        if not isinstance(self.library, TermLibrary):
            raise invalid("library", self.library, "a TermLibrary")


def _support_path(R: np.ndarray, b: np.ndarray, max_terms: int, optimizer: str) -> dict:
    """Best support of each size ≤ ``max_terms`` along the optimiser's threshold path.

    ``R`` (K, K) and ``b`` (K,): the triangular least-squares problem ‖R·x − b‖².
    Returns {size: (support tuple, coefficients, SSE reduction)}.
    """
    import pysindy as ps  # optional dependency (extra "forms"): imported when a search runs

    norms = np.linalg.norm(R, axis=0)
    norms = np.where(norms > 0, norms, 1.0)
    uni = np.abs((R / norms).T @ b)
    best: dict[int, tuple[tuple[int, ...], np.ndarray, float]] = {}
    if not np.isfinite(uni).all() or uni.max() <= 0:
        return best
    seen: set[tuple[int, ...]] = set()
    grid = [(float(t), a) for a in RIDGE_ALPHAS for t in uni.max() * np.geomspace(1.0, 1e-5, 30)]
    for thr, ridge in grid:
        if optimizer == "stlsq":
            opt = ps.STLSQ(threshold=thr, alpha=ridge, normalize_columns=True, max_iter=30)
        else:
            opt = ps.SR3(reg_weight_lam=thr**2 / 2, regularizer="L0", normalize_columns=True)
        with np.errstate(all="ignore"), warnings.catch_warnings():
            warnings.simplefilter("ignore")  # "eliminated all coefficients": the path's top end
            opt.fit(R, b[:, None])
        S = tuple(int(i) for i in np.flatnonzero(np.abs(np.ravel(opt.coef_)) > 0))
        if not S or len(S) > max_terms or S in seen:
            continue
        seen.add(S)
        x, *_ = np.linalg.lstsq(R[:, S], b, rcond=None)
        gain = float(b @ b - np.sum((b - R[:, S] @ x) ** 2))
        if len(S) not in best or gain > best[len(S)][2]:
            best[len(S)] = (S, x, gain)
    return best


def _regressors(
    model: Any,
    data: MeasuredData,
    effects: Sequence[Candidate],
    theta: np.ndarray,
    terms: tuple[Term, ...],
    target: str,
    n_train: int,
    base: np.ndarray,
    step: float,
) -> np.ndarray:
    """Output change per unit coefficient of each term in ``target``'s equation, from batched
    simulations with one coefficient at ``step``: (K, E, n_train, C)."""
    probe = FormCandidate(target, terms, _params(len(terms)))
    K, chunk = len(terms), 24
    out = np.empty((K, *base.shape))
    for start in range(0, K, chunk):
        ks = np.arange(start, min(K, start + chunk))
        rows = np.zeros((ks.size, K))
        rows[np.arange(ks.size), ks] = step
        th = np.hstack([np.tile(theta, (ks.size, 1)), rows])
        out[ks] = (model.predict(data, [*effects, probe], th, n_train) - base) / step
    return out


def form_round(
    model: Any,
    data: MeasuredData,
    effects: Sequence[Candidate],
    theta: np.ndarray,
    Y: np.ndarray,
    n_train: int,
    sqrt_w: np.ndarray,
    channels: Sequence[str],
    *,
    search: FormSearch,
    block_len: int,
    alpha: float,
    min_rel_reduction: float,
    progress: bool | None = False,
) -> tuple[dict[str, Any], tuple[FormCandidate, FitResult] | None]:
    """One form round: propose, fit, test, check stability. Returns (the round's table, the
    accepted (form, fit) or None). ``channels``: those with structure left (their measurement
    equations are searched)."""
    T = data.n_samples
    chans = list(model.output_channels)
    P0 = model.predict(data, effects, theta[None], T)[0]
    e0 = Y - P0
    _, Z = model.signals(data, effects, theta, n_train)
    Zb = Z[:, :, :N_BASE_SIGNALS].reshape(-1, N_BASE_SIGNALS)
    centers = dict(zip(SIGNALS, Zb.mean(axis=0).tolist(), strict=True))
    sd = Zb.std(axis=0)
    scales = {
        s: float(v if v > 1e-9 * max(abs(centers[s]), 1e-12) else max(abs(centers[s]), 1.0))
        for s, v in zip(SIGNALS, sd, strict=True)
    }
    terms = search.library.build(centers, scales)
    r = (e0[:, :n_train] * sqrt_w)[:, :: search.stride].ravel()
    infl = ar1_inflation(e0[:, :n_train])
    pen = math.log(r.size) * infl
    base = P0[:, :n_train]
    proposals: list[tuple[float, FormCandidate, np.ndarray]] = []
    targets = [*search.targets, *(f"y:{c}" for c in channels if c in TABLE1)]
    for tgt in progress_bar(targets, desc="form search", unit="equation", progress=progress):
        if tgt.startswith("y:"):
            j = chans.index(tgt[2:])
            V = model.form_table([FormCandidate(tgt, terms, _params(len(terms)))])
            cols = term_values(V, with_lags(V, Z, data.sample_time_s)) * sqrt_w[j]
            A = cols[:, :: search.stride].reshape(-1, len(terms))
            y = (e0[:, :n_train, j] * sqrt_w[j])[:, :: search.stride].ravel()
        else:
            step = REL_STEP * max(abs(centers[tgt]), 1e-12)
            A = _regressors(model, data, effects, theta, terms, tgt, n_train, base, step)
            A = (A * sqrt_w)[:, :, :: search.stride].reshape(len(terms), -1).T
            y = r
        mag = np.abs(A).max(axis=0)
        ok = np.isfinite(A).all(axis=0) & (mag > 1e-8 * np.max(mag, initial=0.0))
        idx = np.flatnonzero(ok)
        # small dense problems: one BLAS thread (many threads only contend with the simulator)
        with threadpool_limits(1):
            Q, R = np.linalg.qr(A[:, idx])
            b = Q.T @ y
            path = _support_path(R, b, search.max_terms, search.optimizer)
        for k, (S, x, gain) in path.items():
            sel = [int(idx[i]) for i in S]
            form = FormCandidate(tgt, tuple(terms[i] for i in sel), _params(k, x))
            proposals.append((gain - k * pen, form, np.asarray(x, float)))
    proposals.sort(key=lambda p: -p[0])
    proposals = [p for p in proposals if p[0] > 0][: search.n_fit]
    rows: list[dict[str, Any]] = []
    n_hold = T - n_train
    # per shape parameter, the training error must fall by more than this (ln N, AR(1)-inflated)
    shape_pen = math.log(e0[:, :n_train].size) * infl
    for lin_score, form, x in progress_bar(proposals, desc="forms", unit="form", progress=progress):
        th0 = np.concatenate([theta, x])
        free = np.r_[np.zeros(theta.size, bool), np.ones(x.size, bool)]
        fit = fit_effects(model, data, [*effects, form], th0, free, Y, n_train, sqrt_w, grid=False)
        shaped = None
        if search.fit_shapes:
            c = fit.theta[theta.size :]
            ref = refine_shapes(model, data, effects, theta, form, c, Y, n_train, sqrt_w)
            if ref is not None and fit.cost - ref[1].cost > ref[2]["n_shapes"] * shape_pen:
                form, fit, shaped = ref
        e1 = Y - model.predict(data, [*effects, form], fit.theta[None], T)[0]
        cmp = heldout_comparison(e0[:, n_train:], e1[:, n_train:], sqrt_w, block_len)
        # the ln N penalty counts every fitted parameter: coefficients and shapes
        k = len(form.terms) + (shaped["n_shapes"] if shaped else 0)
        score = (cmp["sse0"] - cmp["sse1"]) - k * math.log(data.n_episodes * n_hold)
        rows.append(
            {
                "form": form,
                "fit": fit,
                "score": score,
                "train_score": lin_score,
                "shapes_fitted": shaped,
                **cmp,
            }
        )
    thresh = alpha / max(1, len(rows))
    for row in rows:
        row["significant"] = bool(
            row["p_value"] < thresh
            and row["rel_reduction"] >= min_rel_reduction
            and row["score"] > 0
        )
    rows.sort(key=lambda row: -row["score"] if np.isfinite(row["score"]) else np.inf)
    winner = None
    for row in rows:
        if not row["significant"]:
            continue
        row["stability"] = stability(model, data, [*effects, row["form"]], row["fit"].theta, T)
        if row["stability"]["stable"]:
            winner = (row["form"], row["fit"])
            break
    table = {
        "kind": "form",
        "p_threshold": thresh,
        "n_terms_searched": len(terms),
        "targets": targets,
        "candidates": rows,
        "accepted": winner[0].id if winner else None,
    }
    return table, winner


def _params(k: int, x: np.ndarray | None = None) -> tuple[ParamInfo, ...]:
    """Coefficients of a k-term form: unbounded, the selection's estimate sets the step."""
    typ = np.ones(k) if x is None else np.maximum(np.abs(x), 1e-12)
    return tuple(ParamInfo(f"c{i}", float(typ[i]), -math.inf, math.inf, 0.0) for i in range(k))


def stability(
    model: Any,
    data: MeasuredData,
    effects: Sequence[Candidate],
    theta: np.ndarray,
    n_samples: int,
) -> dict[str, Any]:
    """Whether the corrected model is stable over the record: finite, inside the plant's
    envelope, and a :data:`PUSH_C` °C push of the four temperatures at the start decays to at
    most :data:`DECAY_LIMIT` of its size over the last tenth of the record."""
    Y, Z = model.signals(data, effects, theta, n_samples)
    shift = np.zeros(11)
    shift[[STATE_TARGETS[s] for s in TEMPERATURE_STATES]] = PUSH_C
    Yp, _ = model.signals(data, effects, theta, n_samples, x0_shift=shift)
    finite = bool(np.isfinite(Y).all() and np.isfinite(Yp).all())
    inside = bool(finite and not envelope_codes(np.ascontiguousarray(Z[..., :11])).any())
    temps = [TABLE1.index(c) for c in ("T_rx", *TEMPERATURE_STATES)]
    d = np.abs(Yp[..., temps] - Y[..., temps]).max(axis=-1)  # (E, n)
    tail = d[:, -max(1, n_samples // 10) :].max() if finite else math.inf
    decay = float(tail / PUSH_C)
    return {
        "stable": bool(finite and inside and decay <= DECAY_LIMIT),
        "finite": finite,
        "inside_envelope": inside,
        "push_decay": decay if math.isfinite(decay) else None,
    }
