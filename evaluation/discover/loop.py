"""The residual → missing-effect loop (:func:`discover`) over a pluggable declared model.

0. *Drift*: on closed-loop data the unmeasured feed-coking drift is estimated first by the
   state estimator and fed to the model as a known input when it fluctuates (the gate of
   :mod:`evaluation.discover.drift`; ``drift="off"`` turns it off); "the declared model" below
   is then the model with the drift. With ``drift_fit="joint"`` a correction line of the
   estimate (level and trend, :mod:`evaluation.discover.drift_joint`) is fitted on the model
   alone (the baseline) and again with every candidate, re-fit and elimination step.
1. *Residual*: the model is simulated on the measured inputs (output error, never one-step
   prediction); the residual of every output channel is split in time into a training part (the
   first ``train_fraction`` of every episode) and a held-out part (the rest).
2. *Diagnose*: per channel, :func:`evaluation.discover.residual_tests.diagnose`, before and after, on the
   held-out part.
3. *Trace*: every candidate effect is fitted on the training part by simulation-error least
   squares (:func:`~evaluation.discover.fitting.fit_effects`) with the channels weighted by
   1/σ̂_c², σ̂_c the white-noise level of the declared model's residual. Each fit is scored on
   the held-out part: ``score = ΔSSE_w − n_params·ln(N_held)``.
4. *Significance*: :func:`~evaluation.discover.scoring.heldout_comparison` with blocks of
   ``block_len`` samples (default max(25, N_held/32)). A candidate is significant when its
   p-value is below ``alpha / n_candidates`` (Bonferroni over the candidates of the round) and
   its held-out weighted SSE falls by at least ``min_rel_reduction``. The best-scoring
   significant candidate is added, all accepted effects are re-fitted jointly (and earlier ones
   made redundant are dropped), and the loop repeats until no candidate is significant or
   ``max_effects`` have been added.
5. *Unexplained structure*: ``unexplained`` is set when any channel's held-out residual exceeds
   the calibrated limits of :mod:`evaluation.discover.scoring`. Effects accepted while
   structure remains are flagged ``"explains_structure": false``.
6. *Form*: when structure remains (``forms="auto"``), a form round
   (:func:`~evaluation.discover.form_search.form_round`) proposes a sparse correction of at most
   ``FormSearch.max_terms`` terms to one equation, gated like a candidate; it is searched on top
   of the accepted effects and on the declared model alone, and the better held-out model
   (ln N per parameter) is kept, so library effects that only mimicked the structure are dropped.
7. *Report*: a :class:`~evaluation.discover.report.DiscoveryReport`, written to ``out_dir``.
"""

from __future__ import annotations

import importlib.util
import math
import os
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from evaluation.discover.base import Candidate, ModelAdapter
from evaluation.discover.data import MeasuredData, load_measured
from evaluation.discover.drift import DriftEstimate, apply_drift, check_mode, plot_drift
from evaluation.discover.drift_joint import changes_coking, check_fit, fit_line, line_summary
from evaluation.discover.fitting import fit_effects
from evaluation.discover.form_search import FormSearch, form_round
from evaluation.discover.physics_model import PhysicsModel
from evaluation.discover.report import (
    AcceptedEffect,
    DiscoveryReport,
    finite_or_none,
    named,
    per_channel,
    plot_residuals,
    residual_diagnostics,
)
from evaluation.discover.scoring import (
    LF_LIMIT,
    LF_WINDOW,
    RATIO_LIMIT,
    heldout_comparison,
    noise_levels,
    structure_statistics,
)
from evaluation.discover.selection import (
    Accepted,
    FitContext,
    assign,
    findings,
    nuisance_mask,
    refit_all,
    stacked,
)
from evaluation.discover.terms import FormCandidate, equation, form_to_json
from fcc_common.progress import progress_bar
from fcc_common.validation import Integer, Options, Real, check

__all__ = [
    "ALPHA",
    "MAX_EFFECTS",
    "TRAIN_FRACTION",
    "TRAIN_FRACTION_RANGE",
    "discover",
    "heldout_rmse",
]

TRAIN_FRACTION_RANGE = (0.2, 0.9)  # open interval
TRAIN_FRACTION = Real(*TRAIN_FRACTION_RANGE, closed="neither")
MAX_EFFECTS = Integer(0, 10)
MAX_FORMS = Integer(0, 5)
#: When the loop searches for a form: when structure remains after the library rounds, always
#: (still gated: on clean data it proposes nothing), or never.
FORM_MODES = ("auto", "always", "never")
ALPHA = Real(0.0, 0.5, closed="neither")


def discover(
    data: MeasuredData | str | os.PathLike,
    *,
    model: ModelAdapter | None = None,
    candidates: Sequence[str] | None = None,
    extra_candidates: Sequence[Candidate] = (),
    train_fraction: float = 0.6,
    max_effects: int = 3,
    alpha: float = 0.01,
    min_rel_reduction: float = 0.01,
    block_len: int | None = None,
    out_dir: str | os.PathLike | None = None,
    plots: bool = True,
    max_lag: int = 20,
    progress: bool | None = False,
    forms: str = "auto",
    max_forms: int = 1,
    form_search: FormSearch | None = None,
    drift: str = "auto",
    drift_fit: str = "joint",
) -> DiscoveryReport:
    """Run the residual → missing-effect loop and return the report (also written to ``out_dir``).

    Args:
        data: :class:`MeasuredData` or a dataset path (read with :func:`load_measured`).
        model: the declared model (default :class:`PhysicsModel`).
        candidates: ids of the model's candidates to try (default: all it offers).
        extra_candidates: user candidates (for :class:`PhysicsModel`: :class:`PhysicsCandidate`).
        train_fraction: share of each episode used for fitting, in (0.2, 0.9).
        max_effects: at most this many effects are added (0–10).
        alpha: family-wise significance level per round (Bonferroni over the candidates).
        min_rel_reduction: minimum relative held-out weighted-SSE reduction to accept.
        block_len: block length of the held-out test (default max(25, N_held // 32)).
        out_dir: where ``report.json`` and the plots go (None: nothing written).
        progress: a bar per round over the candidates fitted, on standard error (``None``:
            when it is a terminal; :mod:`fcc_common.progress`); the report is the same.
        forms: search for a form (:mod:`evaluation.discover.form_search`) after the library
            rounds: ``"auto"`` when structure remains, ``"always"``, or ``"never"``. Only for
            a model with a state simulator (:class:`PhysicsModel`).
        max_forms: at most this many forms are added (0–5).
        form_search: the search's settings (default :class:`FormSearch`: at most 3 terms).
        drift: estimate the unmeasured feed-coking drift first and feed it to the model
            (:mod:`evaluation.discover.drift`): ``"auto"`` on closed-loop data
            (``data.closed_loop``), ``"estimate"`` always, ``"off"`` never; the report's
            ``drift`` section and ``drift.png`` show the estimate.
        drift_fit: how the estimate is fed (:mod:`evaluation.discover.drift_joint`):
            ``"joint"`` with a correction line (level and trend) fitted with every candidate,
            so a level or trend an effect leaked into the estimate goes back to the effect;
            ``"fixed"`` as it is.

    Returns:
        A frozen :class:`~evaluation.discover.report.DiscoveryReport`. Until the previous
        release this function returned a plain dict; ``discover(...).to_json()`` gives exactly
        that dict (the content of ``report.json``).
    """
    t_start = time.perf_counter()
    train_fraction = check("train_fraction", train_fraction, TRAIN_FRACTION)
    max_effects = check("max_effects", max_effects, MAX_EFFECTS)
    alpha = check("alpha", alpha, ALPHA)
    forms = check("forms", forms, Options(FORM_MODES))
    max_forms = check("max_forms", max_forms, MAX_FORMS)
    drift = check_mode(drift)
    drift_fit = check_fit(drift_fit)
    search = form_search if form_search is not None else FormSearch()
    if not isinstance(data, MeasuredData):
        data = load_measured(data)
    model = model if model is not None else PhysicsModel()
    T = data.n_samples
    n_train = round(train_fraction * T)
    n_hold = T - n_train
    if n_train < 30 or n_hold < 30:
        raise ValueError(f"{T} samples split at {train_fraction} leave too few for train/held-out")
    model.prepare(data, n_train)
    pool = model.candidates()
    skipped = model.skipped_candidates()
    if candidates is not None:
        unknown = [c for c in candidates if c not in pool]
        if unknown:
            why = {c: skipped[c] for c in unknown if c in skipped}
            raise ValueError(
                f"unknown candidate id(s) {unknown}"
                + (f" (not offered: {why})" if why else "")
                + f". Available: {sorted(pool)}"
            )
        pool = {c: pool[c] for c in candidates}
    for c in extra_candidates:
        if not isinstance(c, Candidate):
            raise ValueError(f"extra candidate {c!r} has no id/params (see Candidate)")
        pool[c.id] = c
    block_len = int(block_len or max(25, n_hold // 32))
    est = apply_drift(drift, data, model, n_train)
    chans = model.output_channels
    Y = data.stack(chans)
    empty = np.zeros((1, 0))
    P0 = model.predict(data, [], empty, T)[0]
    E0 = Y - P0
    sigma = noise_levels(E0[:, :n_train])
    sigma = np.where(sigma > 0, sigma, 1.0)
    sqrt_w = 1.0 / sigma
    ctx = FitContext(model, data, Y, n_train, sqrt_w, block_len, alpha, min_rel_reduction)

    accepted: list[Accepted] = []
    joint = est is not None and est.used and drift_fit == "joint"
    if joint:  # the baseline every candidate is tested against: the line fitted alone
        for cid in [c for c, cand in pool.items() if changes_coking(cand)]:
            del pool[cid]
            skipped[cid] = "changes the coking factor over time: the fitted drift line's trend"
        accepted.append(fit_line(ctx, T * data.sample_time_s / 2.0))
        line_effs, line_th = stacked(accepted)
        E0 = Y - model.predict(data, line_effs, line_th[None], T)[0]
    excluded: set[str] = set()  # dropped by backward elimination: not offered again
    rounds: list[dict[str, Any]] = []
    for rnd in range(1, max_effects + 1):
        effs, th_acc = stacked(accepted)
        nuis = nuisance_mask(accepted)  # the drift line: free in every candidate's fit
        e0 = Y - model.predict(data, effs, th_acc[None], T)[0]
        rows = []
        desc = f"round {rnd}/{max_effects}"
        for cid, cand in progress_bar(pool.items(), desc=desc, unit="candidate", progress=progress):
            if cid in excluded or any(a.cand.id == cid for a in accepted):
                continue
            th0 = np.concatenate([th_acc, [p.typical for p in cand.params]])
            scan = np.r_[np.zeros(th_acc.size, bool), np.ones(len(cand.params), bool)]
            free = scan | np.r_[nuis, np.zeros(len(cand.params), bool)]
            fit = fit_effects(model, data, [*effs, cand], th0, free, Y, n_train, sqrt_w, scan=scan)
            e1 = Y - model.predict(data, [*effs, cand], fit.theta[None], T)[0]
            cmp = heldout_comparison(e0[:, n_train:], e1[:, n_train:], sqrt_w, block_len)
            k = len(cand.params)
            score = (cmp["sse0"] - cmp["sse1"]) - k * math.log(data.n_episodes * n_hold)
            rows.append({"id": cid, "cand": cand, "fit": fit, "score": score, **cmp, "k": k})
        if not rows:
            break
        thresh = alpha / len(rows)
        for r in rows:
            r["significant"] = bool(
                r["p_value"] < thresh and r["rel_reduction"] >= min_rel_reduction and r["score"] > 0
            )
        rows.sort(key=lambda r: -r["score"] if np.isfinite(r["score"]) else np.inf)
        sig = [r for r in rows if r["significant"]]
        table = [
            {
                "id": r["id"],
                "params": named(r["cand"], r["fit"].theta[-r["k"] :]),
                "score": finite_or_none(r["score"]),
                "rel_reduction": finite_or_none(r["rel_reduction"]),
                "p_value": finite_or_none(r["p_value"]),
                "significant": r["significant"],
            }
            for r in rows
        ]
        rounds.append(
            {
                "round": rnd,
                "p_threshold": thresh,
                "candidates": table,
                "accepted": sig[0]["id"] if sig else None,
            }
        )
        if not sig:
            break
        win = sig[0]
        k = win["k"]
        if nuis.any():  # the line as fitted with the winner
            assign(accepted, win["fit"].theta[:-k], win["fit"].stderr[:-k], nuisance_only=True)
        accepted.append(
            Accepted(
                win["cand"],
                win["fit"].theta[-k:],
                win["fit"].stderr[-k:],
                rnd,
                {x: win[x] for x in ("score", "rel_reduction", "p_value")},
            )
        )
        refit_all(ctx, accepted, rounds[-1], excluded)

    can_form = forms != "never" and callable(getattr(model, "signals", None))
    form_note = None
    if can_form and importlib.util.find_spec("pysindy") is None:
        if forms == "always":
            raise ValueError(
                "forms='always' needs PySINDy: pip install 'fcc-fault-diagnosis[forms]'"
            )
        can_form, form_note = False, "form search skipped: PySINDy is not installed ([forms])"
    for i in range(max_forms if can_form else 0):
        effs, th_acc = stacked(accepted)
        e_now = Y - model.predict(data, effs, th_acc[None], T)[0]
        s_now = structure_statistics(e_now[:, n_train:], sigma)
        bad = (s_now["ratio"] > RATIO_LIMIT) | (s_now["lf"] > LF_LIMIT)
        if forms == "auto" and not bad.any():
            break
        # library effects accepted while structure remains are provisional: the first form is
        # also searched on the declared model alone, and the better model (held-out, with a
        # ln N penalty per parameter) is kept
        alone = [a for a in accepted if a.nuisance]  # the declared model (with its drift line)
        bases = [list(accepted), alone] if i == 0 and findings(accepted) else [list(accepted)]
        pen = math.log(data.n_episodes * n_hold)
        # a form must beat the model as it stands (on the declared model alone too)
        crit_now = float(np.sum((e_now[:, n_train:] * sqrt_w) ** 2)) + th_acc.size * pen
        best: tuple[Any, ...] | None = None
        for base in bases:
            b_effs = [a.cand for a in base]
            b_th = np.concatenate([a.theta for a in base]) if base else np.zeros(0)
            table, win = form_round(
                model,
                data,
                b_effs,
                b_th,
                Y,
                n_train,
                sqrt_w,
                [c for c, b in zip(chans, bad, strict=True) if b] or list(chans),
                search=search,
                block_len=block_len,
                alpha=alpha,
                min_rel_reduction=min_rel_reduction,
                progress=progress,
            )
            rounds.append(
                {"round": len(rounds) + 1, "base": [e.id for e in b_effs], **_form_table(table)}
            )
            if win is None:
                continue
            form, fit = win
            e1 = Y - model.predict(data, [*b_effs, form], fit.theta[None], T)[0]
            crit = float(np.sum((e1[:, n_train:] * sqrt_w) ** 2)) + fit.theta.size * pen
            if crit < (crit_now if best is None else best[0]):
                best = (crit, base, form, fit, table, len(rounds))
        if best is None:
            break
        _, base, form, fit, table, rnd = best
        rounds[rnd - 1]["chosen"] = True
        replaced = [a.cand.id for a in accepted if a not in base]
        if replaced:
            rounds[rnd - 1]["replaced"] = replaced
            excluded.update(replaced)
        accepted[:] = base
        k = len(form.params)
        row = next(r for r in table["candidates"] if r["form"] is form)
        accepted.append(
            Accepted(
                form,
                fit.theta[-k:],
                fit.stderr[-k:],
                rnd,
                {x: row[x] for x in ("score", "rel_reduction", "p_value")},
            )
        )
        refit_all(ctx, accepted, rounds[-1], excluded)

    effs, th_acc = stacked(accepted)
    P1 = model.predict(data, effs, th_acc[None], T)[0]
    E1 = Y - P1
    s_before = structure_statistics(E0[:, n_train:], sigma)
    s_after = structure_statistics(E1[:, n_train:], sigma)
    bad = (s_after["ratio"] > RATIO_LIMIT) | (s_after["lf"] > LF_LIMIT)
    unexplained = bool(bad.any())
    others = model.other_signals(data)
    note = None
    if findings(accepted) and unexplained:
        note = (
            "structure remains that the accepted effects do not explain; they improved the fit "
            "significantly but are not claimed to be its cause"
        )
    elif unexplained:
        note = "structure remains that no candidate explains"
    if form_note is not None:
        note = form_note if note is None else f"{note}; {form_note}"
    elapsed_s = time.perf_counter() - t_start
    plot_files = None
    if out_dir is not None:
        Path(out_dir).mkdir(parents=True, exist_ok=True)
        if plots:
            plot_files = tuple(plot_residuals(Path(out_dir), data, E0, E1, n_train, chans, max_lag))
            if est is not None:
                plot_files += (plot_drift(Path(out_dir), est, data.sample_time_s),)
    report = DiscoveryReport(
        model=model.name,
        data=data.source,
        n_episodes=data.n_episodes,
        n_samples=T,
        n_train=n_train,
        channels=tuple(chans),
        effects=tuple(
            AcceptedEffect(
                id=a.cand.id,
                params=named(a.cand, a.theta),
                stderr=named(a.cand, a.stderr),
                ci95={
                    p.name: [finite_or_none(v - 1.96 * s), finite_or_none(v + 1.96 * s)]
                    for p, v, s in zip(a.cand.params, a.theta, a.stderr, strict=True)
                },
                round=a.round,
                heldout={k: finite_or_none(v) for k, v in a.stats.items()},
                explains_structure=not unexplained,
                equation=equation(a.cand, a.theta) if isinstance(a.cand, FormCandidate) else None,
                form=form_to_json(a.cand) if isinstance(a.cand, FormCandidate) else None,
            )
            for a in findings(accepted)
        ),
        rmse_before=per_channel(chans, np.sqrt(np.mean(E0[:, n_train:] ** 2, axis=(0, 1)))),
        rmse_after=per_channel(chans, np.sqrt(np.mean(E1[:, n_train:] ** 2, axis=(0, 1)))),
        rmse_train_before=per_channel(chans, np.sqrt(np.mean(E0[:, :n_train] ** 2, axis=(0, 1)))),
        rmse_train_after=per_channel(chans, np.sqrt(np.mean(E1[:, :n_train] ** 2, axis=(0, 1)))),
        noise_std_estimate=per_channel(chans, sigma),
        unexplained=unexplained,
        unexplained_channels=tuple(c for c, b in zip(chans, bad, strict=True) if b),
        structure_before={k: per_channel(chans, v) for k, v in s_before.items()},
        structure_after={k: per_channel(chans, v) for k, v in s_after.items()},
        structure_limits={"ratio": RATIO_LIMIT, "lf": LF_LIMIT, "lf_window": LF_WINDOW},
        tests_before=residual_diagnostics(data, E0, n_train, chans, others, max_lag),
        tests_after=residual_diagnostics(data, E1, n_train, chans, others, max_lag),
        rounds=tuple(rounds),
        skipped_candidates=skipped,
        settings={
            "train_fraction": float(train_fraction),
            "max_effects": max_effects,
            "alpha": alpha,
            "min_rel_reduction": min_rel_reduction,
            "block_len": block_len,
            "n_candidates": len(pool),
            "forms": forms,
            "max_forms": max_forms,
            "max_terms": search.max_terms,
            "drift": drift,
            "drift_fit": drift_fit,
        },
        drift=None if est is None else _drift_section(est, accepted, data),
        note=note,
        elapsed_s=elapsed_s,
        plots=plot_files,
    )
    if out_dir is not None:
        report.write(out_dir)
    return report


def _drift_section(
    est: DriftEstimate, accepted: list[Accepted], data: MeasuredData
) -> dict[str, Any]:
    """The report's ``drift``: the estimate's summary and, with the joint fit, its line."""
    out = est.summary(data.sample_time_s)
    line = next((a for a in accepted if a.nuisance), None)
    if line is not None:
        out["line"] = line_summary(line.theta, line.stderr, data.n_samples * data.sample_time_s / 2)
    return out


def _form_table(table: dict[str, Any]) -> dict[str, Any]:
    """A form round's table as JSON: each tested form's equation, scores and stability."""
    rows = []
    for r in table["candidates"]:
        form = r["form"]
        rows.append(
            {
                "id": form.id,
                "equation": equation(form, r["fit"].theta[-len(form.params) :])["text"],
                "n_terms": len(form.terms),
                "score": finite_or_none(r["score"]),
                "train_score": finite_or_none(r["train_score"]),
                "rel_reduction": finite_or_none(r["rel_reduction"]),
                "p_value": finite_or_none(r["p_value"]),
                "significant": r["significant"],
                **({"stability": r["stability"]} if "stability" in r else {}),
            }
        )
    return {**{k: v for k, v in table.items() if k != "candidates"}, "candidates": rows}


def heldout_rmse(
    data: MeasuredData, *, model: ModelAdapter | None = None, train_fraction: float = 0.6
) -> dict[str, float]:
    """The held-out RMSE per output channel of the declared ``model`` alone (default
    :class:`PhysicsModel`) on ``data``: on the same seed without an effect, the floor a found
    effect should bring the error down to (the report's ``rmse_before`` is this on its data)."""
    train_fraction = check("train_fraction", train_fraction, TRAIN_FRACTION)
    m = PhysicsModel() if model is None else model
    n_train = round(train_fraction * data.n_samples)
    m.prepare(data, n_train)
    pred = m.predict(data, [], np.zeros((1, 0)), data.n_samples)[0]
    err = data.stack(m.output_channels) - pred
    rmse = np.sqrt(np.mean(err[:, n_train:] ** 2, axis=(0, 1)))
    return dict(zip(m.output_channels, rmse.tolist(), strict=True))
