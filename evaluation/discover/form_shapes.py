"""Fitting a selected form's shape parameters (a tanh's centre and scale, a lag's time constant).

The sparse selection of :mod:`evaluation.discover.form_search` works on a fixed dictionary:
every nonlinear factor has its centre at the signal's training mean, its scale at the signal's
standard deviation, and a lag has one of a few time constants. A real effect rarely sits there
(a thermocouple saturating at 10 °C around 716 °C, not 9.4 °C around 717 °C), and the form can
then only come near it. Once the terms are selected, :func:`refine_shapes` fits those shape
parameters together with the coefficients by simulation error — the same weighted training
residual as :func:`~evaluation.discover.fitting.fit_effects`, bounded trust-region least squares
(:func:`scipy.optimize.least_squares`), deterministic — and the structure (which terms, which
equation) stays the one selected.

Shape parameters (:func:`shape_parameters`), per factor of the form:

* ``tanh``: centre and scale; ``sq``, ``cube``, ``pos``, ``abs``: centre; ``exp``: scale (its
  centre only rescales the coefficient);
* a linear factor of a product: centre (where the product's zero lines lie);
* a lagged factor: the time constant.

They move within bounds (centre within :data:`CENTER_SPAN` start scales of its start, scale and
time constant within a factor :data:`LOG_SPAN` of theirs). One optimiser iteration is one batched
``predict`` call: the trial form, one copy per perturbed coefficient and one form per perturbed
shape (each copy a separate form, its coefficients zero in the other rows) are simulated together.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.optimize import least_squares

from evaluation.discover.base import Candidate, FitResult
from evaluation.discover.data import MeasuredData
from evaluation.discover.fitting import ar1_inflation, weighted_residuals
from evaluation.discover.terms import FormCandidate, Term, equation, shape_slots

__all__ = ["CENTER_SPAN", "LOG_SPAN", "Shape", "refine_shapes", "shape_parameters", "with_shapes"]

#: A centre moves at most this many of its factor's start scales from its start.
CENTER_SPAN = 5.0
#: A scale or a time constant moves at most this factor from its start (either way).
LOG_SPAN = 10.0
#: Finite-difference step of a shape parameter, in its optimiser unit (start scales or ln).
SHAPE_STEP = 1e-4


@dataclass(frozen=True)
class Shape:
    """One shape parameter: factor ``factor`` of term ``term``, ``kind`` "center", "scale" or
    "lag_s". The optimiser moves ``u``: center = start + ref·u, scale/lag = start·exp(u)."""

    term: int
    factor: int
    kind: str
    start: float
    ref: float

    @property
    def bounds(self) -> tuple[float, float]:
        span = CENTER_SPAN if self.kind == "center" else math.log(LOG_SPAN)
        return -span, span

    def value(self, u: float) -> float:
        if self.kind == "center":
            return self.start + self.ref * u
        return self.start * math.exp(u)


def shape_parameters(form: FormCandidate) -> tuple[Shape, ...]:
    """The shape parameters of ``form``'s factors (:func:`~evaluation.discover.terms.shape_slots`),
    each starting at its factor's value."""
    out = []
    for i, j, kind in shape_slots(form):
        f = form.terms[i].factors[j]
        start = float(getattr(f, kind))
        out.append(Shape(i, j, kind, start, f.scale if kind == "center" else start))
    return tuple(out)


def with_shapes(
    form: FormCandidate, shapes: Sequence[Shape], u: np.ndarray, form_id: str | None = None
) -> FormCandidate:
    """``form`` with its shape parameters at ``u``. ``form_id`` None: an id naming every exact
    shape value (model caches key on ids, and the readable id rounds the values)."""
    facs = [list(t.factors) for t in form.terms]
    for s, v in zip(shapes, u, strict=True):
        facs[s.term][s.factor] = dataclasses.replace(facs[s.term][s.factor], **{s.kind: s.value(v)})
    terms = tuple(Term(tuple(f)) for f in facs)
    if form_id is None:
        exact = ";".join(f"{f.center!r},{f.scale!r},{f.lag_s!r}" for t in terms for f in t.factors)
        form_id = f"{FormCandidate(form.target, terms, form.params).id}|{exact}"
    return FormCandidate(form.target, terms, form.params, form_id)


def refine_shapes(
    model: Any,
    data: MeasuredData,
    effects: Sequence[Candidate],
    theta: np.ndarray,
    form: FormCandidate,
    coefs: np.ndarray,
    Y: np.ndarray,
    n_train: int,
    sqrt_w: np.ndarray,
    *,
    max_iter: int = 20,
) -> tuple[FormCandidate, FitResult, dict[str, Any]] | None:
    """Fit ``form``'s shape parameters and coefficients (``coefs`` the start) on the training
    part, with ``effects`` held at ``theta``. Returns (the form at the fitted shapes, its fit:
    ``theta`` + coefficients with their covariance, a summary: shape values, their standard
    errors, training costs), or None when the form has no shape parameter."""
    shapes = shape_parameters(form)
    if not shapes:
        return None
    k, m = len(form.terms), len(shapes)
    typ = np.maximum(np.abs(np.asarray(coefs, float)), 1e-12)
    c_steps = 1e-3 * typ
    lo = np.r_[np.full(k, -np.inf), [s.bounds[0] for s in shapes]]
    hi = np.r_[np.full(k, np.inf), [s.bounds[1] for s in shapes]]
    n_evals = 0
    last: dict[str, np.ndarray] = {}

    def evaluate(x: np.ndarray) -> None:
        nonlocal n_evals
        c, u = x[:k], x[k:]
        h_u = np.where(u + SHAPE_STEP <= hi[k:], SHAPE_STEP, -SHAPE_STEP)
        forms = [with_shapes(form, shapes, u)]
        for j in range(m):
            uj = u.copy()
            uj[j] += h_u[j]
            forms.append(with_shapes(form, shapes, uj))
        rows = np.zeros((1 + k + m, theta.size + k * (1 + m)))
        rows[:, : theta.size] = theta
        rows[: 1 + k, theta.size : theta.size + k] = c
        rows[1 + np.arange(k), theta.size + np.arange(k)] += c_steps
        for j in range(m):
            a = theta.size + k * (1 + j)
            rows[1 + k + j, a : a + k] = c
        R = weighted_residuals(model, data, [*effects, *forms], rows, Y, n_train, sqrt_w)
        n_evals += rows.shape[0]
        h = np.r_[c_steps, h_u]
        last.update(x=x.copy(), r=R[0], J=((R[1:] - R[0]) / h[:, None]).T)

    def fun(x: np.ndarray) -> np.ndarray:
        evaluate(x)
        return last["r"]

    def jac(x: np.ndarray) -> np.ndarray:
        if "x" not in last or not np.array_equal(x, last["x"]):
            evaluate(x)
        return last["J"]

    x0 = np.r_[np.asarray(coefs, float), np.zeros(m)]
    r0 = fun(x0)
    cost0 = float(r0 @ r0)
    x_scale = np.r_[typ, np.ones(m)]
    sol = least_squares(
        fun,
        x0,
        jac=jac,
        bounds=(lo, hi),
        method="trf",
        x_scale=x_scale,
        ftol=1e-7,
        xtol=1e-9,
        max_nfev=max_iter + 1,
    )
    x = sol.x if 2 * sol.cost <= cost0 else x0
    r, J = (np.asarray(sol.fun), np.asarray(sol.jac)) if x is sol.x else (r0, last["J"])
    cost = float(r @ r)
    p = k + m
    s2 = cost / max(1, r.size - p)
    infl = ar1_inflation(r.reshape(data.n_episodes, n_train, -1))
    cov_all = s2 * np.linalg.pinv(J.T @ J) * infl
    fitted = with_shapes(form, shapes, x[k:], form_id="")
    cov = np.zeros((theta.size + k, theta.size + k))
    cov[theta.size :, theta.size :] = cov_all[:k, :k]
    fit = FitResult(np.r_[theta, x[:k]], cov, n_evals, cost, bool(sol.status > 0))
    se_u = np.sqrt(np.clip(np.diag(cov_all)[k:], 0.0, None))
    summary = {
        "n_shapes": m,
        "cost_before": cost0,
        "cost_after": cost,
        "shapes": [
            {**row, "stderr": float(sd * (s.ref if s.kind == "center" else row["value"]))}
            for row, s, sd in zip(equation(fitted, x[:k])["shapes"], shapes, se_u, strict=True)
        ],
    }
    return fitted, fit, summary
