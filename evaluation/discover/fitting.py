"""Simulation-error least squares of candidate-effect parameters, and their covariance.

:func:`fit_effects` fits the free parameters of a list of effects on the training part of the
record with :func:`scipy.optimize.least_squares` (bounded trust-region reflective, ``"trf"``).
The Jacobian is a forward finite difference whose ``1 + n_params`` perturbed parameter sets are
simulated as one batched ``predict`` call together with the trial point, so one optimiser
iteration costs one batched simulation. The start is the best point of a global first pass: the
parameters' grids (:attr:`ParamInfo.grid`, or :func:`range_grid` over the declared range when a
candidate gives none) plus the start value, all evaluated in one batched ``predict`` call.

**Parameter intervals** are σ²(JᵀJ)⁻¹ at the optimum (J the weighted simulation-error
Jacobian), inflated by (1+ρ̄)/(1−ρ̄), ρ̄ the mean lag-1 autocorrelation of the fitted residual (an
AR(1) effective-sample-size correction, :func:`ar1_inflation`). Residuals with slower structure
than AR(1) still make them optimistic.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence

import numpy as np
from scipy.optimize import least_squares

from evaluation.discover.base import Candidate, FitResult, ModelAdapter, ParamInfo
from evaluation.discover.data import MeasuredData

__all__ = ["ar1_inflation", "fit_effects", "range_grid", "weighted_residuals"]

#: Residual given to every sample of a parameter set whose simulation diverged: a huge cost that
#: makes the optimiser back off (the trust region shrinks) instead of failing on NaN.
DIVERGED_RESIDUAL = 1e6


#: Points of :func:`range_grid`, and the largest grid product evaluated jointly (above it, each
#: free parameter's grid is scanned alone with the others at their start values).
RANGE_GRID_POINTS = 9
MAX_GRID_ROWS = 256


def range_grid(p: ParamInfo, n: int = RANGE_GRID_POINTS) -> tuple[float, ...]:
    """A start grid over a parameter's declared range [low, high], plus its null value.

    Log-spaced when the range is positive and spans at least a factor 20 (time constants),
    linear otherwise.

    >>> range_grid(ParamInfo("tau_s", 60.0, 1.0, 1800.0, 1.0), 5)
    (1.0, 6.51, 42.4, 276.0, 1800.0)
    >>> range_grid(ParamInfo("bias", 4.0, -50.0, 50.0), 5)
    (-50.0, -25.0, 0.0, 25.0, 50.0)
    """
    lo, hi = float(p.low), float(p.high)
    if not (np.isfinite(lo) and np.isfinite(hi)) or hi <= lo:
        return ()
    if lo > 0 and hi / lo >= 20:
        pts = np.geomspace(lo, hi, n)
    else:
        pts = np.linspace(lo, hi, n)
    if lo <= p.null <= hi:
        pts = np.append(pts, p.null)
    return tuple(float(f"{v:.3g}") if lo < v < hi else float(v) for v in np.unique(pts))


def ar1_inflation(res: np.ndarray) -> float:
    """(1+ρ̄)/(1−ρ̄) from the mean lag-1 autocorrelation of residuals (E, n, channels)."""
    r = res - res.mean(axis=1, keepdims=True)
    num = np.sum(r[:, 1:] * r[:, :-1], axis=1)
    den = np.sum(r * r, axis=1)
    rho = float(np.mean(num / np.where(den > 0, den, 1.0)))
    rho = min(max(rho, 0.0), 0.98)
    return (1.0 + rho) / (1.0 - rho)


def weighted_residuals(
    model: ModelAdapter,
    data: MeasuredData,
    effects: Sequence[Candidate],
    thetas: np.ndarray,
    Y: np.ndarray,
    n: int,
    sqrt_w: np.ndarray,
) -> np.ndarray:
    """Weighted simulation errors (B, E·n·C) of the B parameter rows ``thetas`` on ``n`` samples."""
    P = model.predict(data, effects, thetas, n)
    R = (Y[None, :, :n] - P) * sqrt_w
    R = R.reshape(R.shape[0], -1)
    bad = ~np.isfinite(R).all(axis=1)
    R[bad] = DIVERGED_RESIDUAL
    return R


def fit_effects(
    model: ModelAdapter,
    data: MeasuredData,
    effects: Sequence[Candidate],
    theta0: np.ndarray,
    free: np.ndarray,
    Y: np.ndarray,
    n_train: int,
    sqrt_w: np.ndarray,
    *,
    grid: bool = True,
    max_iter: int = 25,
    scan: np.ndarray | None = None,
) -> FitResult:
    """Simulation-error least squares of the ``free`` parameters on the first ``n_train`` samples.

    Bounded trust-region reflective least squares (:func:`scipy.optimize.least_squares`,
    ``method="trf"``, ``x_scale="jac"``) with at most ``max_iter`` trial points after the start;
    each residual evaluation simulates the trial point and its forward finite-difference
    perturbations as one batched ``predict`` call, and the Jacobian handed to the optimiser is
    taken from that same call. With ``grid`` the start is the best point of the parameters'
    grids (one batched call); ``scan`` (a mask like ``free``) limits the grid to those free
    parameters, the other free ones start where they stand (a nuisance parameter fitted with
    every candidate: its grid would multiply each candidate's). A model with its own ``fit``
    method (a closed-form fit) is delegated to.
    """
    custom = getattr(model, "fit", None)
    if callable(custom):
        return custom(data, effects, theta0, free, n_train, sqrt_w)
    infos = [p for e in effects for p in e.params]
    lo = np.array([p.low for p in infos])
    hi = np.array([p.high for p in infos])
    fidx = np.flatnonzero(free)
    theta = np.clip(np.asarray(theta0, float).copy(), lo, hi)
    n_evals = 0

    def residuals(rows: np.ndarray) -> np.ndarray:
        nonlocal n_evals
        n_evals += rows.shape[0]
        return weighted_residuals(model, data, effects, rows, Y, n_train, sqrt_w)

    gidx = fidx if scan is None else np.flatnonzero(np.asarray(free, bool) & np.asarray(scan, bool))
    if grid and gidx.size:
        axes = [
            sorted(
                {
                    theta[i],
                    *(v for v in infos[i].grid or range_grid(infos[i]) if lo[i] <= v <= hi[i]),
                }
            )
            for i in gidx
        ]
        if math.prod(len(a) for a in axes) <= MAX_GRID_ROWS:
            rows = np.tile(theta, (math.prod(len(a) for a in axes), 1))
            rows[:, gidx] = np.array(list(itertools.product(*axes)), float)
        else:  # one parameter at a time, the others at their start values
            blocks = []
            for j, a in zip(gidx, axes, strict=True):
                b = np.tile(theta, (len(a), 1))
                b[:, j] = a
                blocks.append(b)
            rows = np.concatenate(blocks)
        if rows.shape[0] > 1:
            cost = np.sum(residuals(rows) ** 2, axis=1)
            theta = rows[int(np.argmin(cost))]
    cov = np.zeros((theta.size, theta.size))
    if not fidx.size:
        r = residuals(theta[None])[0]
        return FitResult(theta, cov, n_evals, float(r @ r), True)
    steps = np.array([1e-3 * max(abs(infos[i].typical), 1e-6) for i in fidx])
    last: dict[str, np.ndarray] = {}  # the latest batched evaluation: x, r, J (m, p)

    def evaluate(x: np.ndarray) -> None:
        th = theta.copy()
        th[fidx] = x
        rows = np.tile(th, (1 + fidx.size, 1))
        h = np.where(x + steps <= hi[fidx], steps, -steps)  # one-sided, away from the bound
        rows[1 + np.arange(fidx.size), fidx] += h
        R = residuals(rows)
        last.update(x=x.copy(), r=R[0], J=((R[1:] - R[0]) / h[:, None]).T)

    def fun(x: np.ndarray) -> np.ndarray:
        evaluate(x)
        return last["r"]

    def jac(x: np.ndarray) -> np.ndarray:
        if "x" not in last or not np.array_equal(x, last["x"]):
            evaluate(x)  # least_squares asks for J at the point it last evaluated: not reached
        return last["J"]

    sol = least_squares(
        fun,
        theta[fidx],
        jac=jac,
        bounds=(lo[fidx], hi[fidx]),
        method="trf",
        x_scale="jac",
        ftol=1e-7,
        xtol=1e-9,
        max_nfev=max_iter + 1,
    )
    theta = theta.copy()
    theta[fidx] = sol.x
    r, J = np.asarray(sol.fun), np.asarray(sol.jac).T  # J: (p, m)
    cost = float(r @ r)
    m, p = r.size, fidx.size
    s2 = cost / max(1, m - p)
    shape_res = r.reshape(data.n_episodes, n_train, -1)
    cov[np.ix_(fidx, fidx)] = s2 * np.linalg.pinv(J @ J.T) * ar1_inflation(shape_res)
    return FitResult(theta, cov, n_evals, cost, bool(sol.status > 0))
