"""``lrgf-glr``'s alarm stage as one object: filters, statistics, limits and the alarm rule.

:class:`DirectionalStage` takes a detector's *normalised* remaining errors ``e`` (``(T, k)``
records, healthy for :meth:`~DirectionalStage.fit`) and turns them into alarms:

1. **filter**: an EWMA ``z`` of weight ``ewma_lambda``, beside it one EWMA per slow scale
   (``slow_ewma_lambda``), after removing an optional :class:`diagnosers.stages.baseline.HeldBaseline`;
2. **statistics**: an omnibus Hotelling T² of ``z``, and per fault direction a one-sided score
   (``statistic="directional"``: a matched-filter projection of every EWMA scale; ``"glr"``/
   ``"cusum"``: a windowed GLR or a CUSUM on the projections of ``e``; ``"t2"``: the T² alone);
3. **limits**: the false-alarm target is split by a union bound, ``omnibus_share`` to the T²
   and the rest equally over the directional tests (the slow scales share ``slow_share`` of
   it), each limit calibrated on the healthy statistic (T² ``limit_method``, the directional
   scores :func:`diagnosers.stages.alarm.normal_tail_limit`, GLR and CUSUM the empirical quantile);
4. **rule**: alarm when any statistic is over its limit for ``on_delay`` samples in a row.

``false_alarm_target`` lives here and nowhere else: a detector or a reference row that uses
this stage passes its target to it. The stage knows nothing of models, so the perfect-model
reference row of :mod:`evaluation.tracks.oracle` runs exactly the detector's stage.
"""

from __future__ import annotations

from collections.abc import Sequence
from enum import StrEnum

import numpy as np
from scipy.linalg import block_diag

from diagnosers.detection import Decision
from diagnosers.stages.alarm import (
    CUSUM,
    EWMA,
    DirectionalGLR,
    DirectionalProjection,
    HotellingT2,
    calibrate_limit,
    normal_tail_limit,
)
from diagnosers.stages.baseline import HeldBaseline

__all__ = ["DirectionalStage", "Statistic"]


class Statistic(StrEnum):
    """The directional tests of :class:`DirectionalStage` (see the module docstring)."""

    T2 = "t2"
    DIRECTIONAL = "directional"
    GLR = "glr"
    CUSUM = "cusum"


class DirectionalStage:
    """Filters, statistics, limits and alarm rule on normalised errors (module docstring).

    Args:
        false_alarm_target: the declared share of healthy samples in alarm, split over the
            statistics by a union bound.
        statistic: ``"directional"``, ``"glr"``, ``"cusum"`` or ``"t2"`` (:class:`Statistic`).
        ewma_lambda: the fast EWMA's weight.
        slow_ewma_lambda: the slow scales' weights (``statistic="directional"`` only; 0: none).
        slow_share: the slow scales' share of the directional target.
        omnibus_share: the T²'s share of the target when there are fault directions.
        glr_window, cusum_drift: the GLR's onset window and the CUSUM's drift.
        limit_method, threshold_margin: the T² limit's method and every limit's factor.
        on_delay: samples in a row over a limit before an alarm.
        baseline: a held baseline removed before the EWMAs, or None.

    Attributes (after :meth:`fit` or :meth:`set_state`): ``s_inv_`` the fast EWMA's T²
    precision, ``h_`` the T² limit ``(1,)``, ``dir_weights_`` the projections, ``h_dir_`` the
    directional limits, ``upper_`` every limit in signal order.
    """

    #: the settings a detector passes through under the same names (its hyperparameters)
    PARAMETERS = (
        "false_alarm_target",
        "statistic",
        "ewma_lambda",
        "slow_ewma_lambda",
        "slow_share",
        "omnibus_share",
        "glr_window",
        "cusum_drift",
        "limit_method",
        "threshold_margin",
        "on_delay",
    )

    def __init__(
        self,
        *,
        false_alarm_target: float,
        statistic: str = "directional",
        ewma_lambda: float = 0.3,
        slow_ewma_lambda: float | Sequence[float] = 0.02,
        slow_share: float = 0.5,
        omnibus_share: float = 0.2,
        glr_window: int = 200,
        cusum_drift: float = 0.5,
        limit_method: str = "chi2-tail",
        threshold_margin: float = 1.0,
        on_delay: int = 1,
        baseline: HeldBaseline | None = None,
    ) -> None:
        self.false_alarm_target = false_alarm_target
        self.statistic = statistic
        self.ewma_lambda = ewma_lambda
        self.slow_ewma_lambda = slow_ewma_lambda
        self.slow_share = slow_share
        self.omnibus_share = omnibus_share
        self.glr_window = glr_window
        self.cusum_drift = cusum_drift
        self.limit_method = limit_method
        self.threshold_margin = threshold_margin
        self.on_delay = on_delay
        self.baseline = baseline

    # ---- calibration ---------------------------------------------------------------------------
    def fit(
        self,
        norm: list[np.ndarray],
        directions: np.ndarray,
        features: list[np.ndarray | None] | None = None,
    ) -> DirectionalStage:
        """Covariances and limits from healthy normalised error records ``norm`` (past their
        warm-up) and the unit fault ``directions`` ``(m, k)``; ``features``: each record's
        regressors for a regression baseline.

        Without a baseline the statistics are fixed filters of the error: one fit. With one,
        what the baseline absorbs depends on when it holds, which depends on the limits: fit on
        an always-adapting baseline, then once more on the baseline held by those limits.
        """
        self.directions_ = np.asarray(directions)
        phis = [None] * len(norm) if features is None else features
        pairs = list(zip(norm, phis, strict=True))
        if self.baseline is None:
            self._fit_limits(norm)
            return self
        self._fit_limits([self.baseline.track(e, p) for e, p in pairs])
        self._fit_limits([self.track_held(e, p) for e, p in pairs])
        return self

    def track_held(self, e: np.ndarray, phi: np.ndarray | None) -> np.ndarray:
        """The baseline-removed error of a record past its warm-up, with the baseline held by
        the current limits (the stage's own recursion, from a fresh start)."""
        self.reset()
        out = np.empty_like(e)
        for k in range(e.shape[0]):
            out[k] = self.step(e[k], warm=False, phi=None if phi is None else phi[k])[0]
        return out

    def _fit_limits(self, norm: list[np.ndarray]) -> None:
        """Covariances and limits on healthy (baseline-removed) normalised errors ``norm``."""
        k, m = self.directions_.shape[1], len(self.directions_)
        z = np.concatenate([EWMA(self.ewma_lambda).filter(e) for e in norm])
        t2 = HotellingT2(centered=False).fit(z)
        self.s_inv_ = t2.precision_
        det = Statistic(self.statistic)
        share = 1.0 if m == 0 or det is Statistic.T2 else self.omnibus_share
        self.h_ = calibrate_limit(
            np.asarray(t2.score(z))[:, None],
            self.false_alarm_target * share,
            method=self.limit_method,
            dof=k,
            margin=self.threshold_margin,
        )
        self.dir_weights_ = np.zeros((0, k))
        self.h_dir_ = np.zeros(0)
        if m and det is not Statistic.T2:
            t_dir = self.false_alarm_target * (1.0 - share) / m
            if det is Statistic.DIRECTIONAL:
                zz = self._scales(z, norm)
                # one block of projections per EWMA scale, each with its own healthy covariance
                blocks = [
                    DirectionalProjection().fit(self.directions_, np.cov(zz[:, i : i + k].T))
                    for i in range(0, zz.shape[1], k)
                ]
                self.dir_weights_ = block_diag(*[b.weights_ for b in blocks])
                n_slow = len(blocks) - 1
                # the fast scale keeps 1 - slow_share, the slow scales split slow_share equally
                shares = (
                    [1.0 - self.slow_share] + [self.slow_share / n_slow] * n_slow
                    if n_slow
                    else [1.0]
                )
                scores = zz @ self.dir_weights_.T  # m columns per scale
                self.h_dir_ = self.threshold_margin * np.concatenate(
                    [
                        normal_tail_limit(scores[:, i * m : (i + 1) * m], t_dir * sh)
                        for i, sh in enumerate(shares)
                    ]
                )
            else:
                proj = DirectionalProjection().fit(self.directions_, np.cov(np.concatenate(norm).T))
                self.dir_weights_ = proj.weights_
                seq = np.concatenate([self._sequential().filter(proj.score(e)) for e in norm])
                self.h_dir_ = self.threshold_margin * np.full(
                    m, np.quantile(seq.max(axis=1), 1.0 - t_dir * m)
                )
        self._finish()

    def slow_lambdas(self) -> tuple[float, ...]:
        """The weights of the slower EWMA scales (``slow_ewma_lambda``; none for 0)."""
        lam = self.slow_ewma_lambda
        if isinstance(lam, int | float | np.integer | np.floating):
            return (float(lam),) if lam > 0 else ()
        return tuple(float(x) for x in lam)

    def _scales(self, z: np.ndarray, norm: list[np.ndarray]) -> np.ndarray:
        """The EWMAs the directional tests project: ``z`` (weight ``ewma_lambda``), beside it
        one EWMA of every record of ``norm`` per slow scale (``slow_ewma_lambda``)."""
        slow = [np.concatenate([EWMA(lam).filter(e) for e in norm]) for lam in self.slow_lambdas()]
        return np.column_stack([z, *slow]) if slow else z

    def _sequential(self) -> DirectionalGLR | CUSUM:
        if self.statistic == Statistic.GLR:
            return DirectionalGLR(self.glr_window)
        return CUSUM(self.cusum_drift)

    def _finish(self) -> None:
        """The derived state shared by :meth:`fit` and :meth:`set_state`."""
        self.t2_ = HotellingT2(centered=False)
        self.t2_.set_state({"mean": np.zeros(len(self.s_inv_)), "precision": self.s_inv_})
        self._proj = DirectionalProjection()
        self._proj.set_state({"weights": self.dir_weights_})
        self.upper_ = np.concatenate([self.h_, self.h_dir_])
        self._lower = np.full(len(self.upper_), -np.inf)
        self._no_limit = np.full(len(self.upper_), np.inf)
        self._hold_limits = None if self.baseline is None else self.baseline.hold * self.upper_

    @property
    def n_slow_scales(self) -> int:
        """How many slow scales the fitted directional tests carry (one limit a direction each)."""
        m = len(self.directions_)
        return len(self.h_dir_) // m - 1 if m and len(self.h_dir_) else 0

    def signal_names(self, faults: Sequence[str]) -> tuple[str, ...]:
        """The names of the signals: the T², then each directional test of ``faults``."""
        m = len(self.directions_) if len(self.h_dir_) else 0
        names = [f"{self.statistic}[{f}]" for f in faults[:m]]
        n_slow = self.n_slow_scales
        for j in range(n_slow):
            tag = "slow" if n_slow == 1 else f"slow{j + 1}"
            names += [f"{self.statistic}-{tag}[{f}]" for f in faults[:m]]
        return ("T2[ewma]", *names)

    # ---- running -------------------------------------------------------------------------------
    def reset(self) -> None:
        """Fresh streaming state: EWMAs, sequential test, on-delay count and baseline."""
        self._ewma = EWMA(self.ewma_lambda)
        self._ewma_slow = [EWMA(lam) for lam in self.slow_lambdas()[: self.n_slow_scales]]
        self._seq = self._sequential() if len(self.h_dir_) else None
        self._over_run = 0  # samples in a row with a statistic over its limit
        if self.baseline is not None:
            self.baseline.reset()

    def step(
        self, e: np.ndarray, *, warm: bool, phi: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """One sample of the stage: (baseline-removed error, signal). The one place the
        recursion is written; streaming and batch with a baseline both call it. ``phi``: the
        sample's regressors with a regression baseline."""
        base = self.baseline
        et = e if base is None else e - base.value(phi)
        z = self._ewma.update(et)
        signal = np.empty(len(self.upper_))
        signal[0] = z @ self.s_inv_ @ z
        if self._seq is None:
            pass
        elif self.statistic == Statistic.DIRECTIONAL:
            if self._ewma_slow:
                z = np.concatenate([z, *(ew.update(et) for ew in self._ewma_slow)])
            signal[1:] = self.dir_weights_ @ z
        else:
            signal[1:] = self._seq.update(self.dir_weights_ @ et)
        if base is not None and not warm:
            inside = bool((signal <= self._hold_limits).all())
            base.adapt(e, inside_hold=inside, phi=phi)
        return et, signal

    def signals(self, e: np.ndarray, warm_up: int, phi: np.ndarray | None = None) -> np.ndarray:
        """The signals ``(T, n)`` of a whole record ``e`` (zero in its first ``warm_up``
        samples), from a fresh :meth:`reset`; equal to :meth:`step` on every row."""
        if self.baseline is not None:  # the baseline's hold makes the stage a recursion
            rows = [None] * len(e) if phi is None else list(phi)
            return np.array(
                [self.step(e[k], warm=k < warm_up, phi=rows[k])[1] for k in range(len(e))]
            )
        z = EWMA(self.ewma_lambda).filter(e)
        if self.n_slow_scales > 0:
            z = self._scales(z, [e])
        seq = None
        if len(self.h_dir_) and self.statistic != Statistic.DIRECTIONAL:
            seq = self._sequential().filter(self._proj.score(e))
        return self._scores(z, seq)

    def _scores(self, z: np.ndarray, seq: np.ndarray | None) -> np.ndarray:
        """T² of the fast EWMA (the first k columns of ``z``) and the directional scores of all
        of ``z`` (or the sequential statistics ``seq``), row by row."""
        t2 = np.atleast_1d(self.t2_.score(z[..., : len(self.s_inv_)]))
        if not len(self.h_dir_):
            return t2[..., None]
        if self.statistic == Statistic.DIRECTIONAL:
            d = self._proj.score(z)
        else:
            assert seq is not None
            d = seq
        return np.column_stack([t2, d])

    def decision(self, residual: np.ndarray, signal: np.ndarray, warm: bool) -> Decision:
        """The alarm of one sample's ``signal`` (none while ``warm``), with the on-delay."""
        upper = self._no_limit if warm else self.upper_
        self._over_run = self._over_run + 1 if (signal > upper).any() else 0
        return Decision(self._over_run >= self.on_delay, signal, self._lower, upper, residual)

    # ---- persistence ---------------------------------------------------------------------------
    def get_state(self) -> dict[str, np.ndarray]:
        return {
            "s_inv": self.s_inv_,
            "h": self.h_,
            "directions": self.directions_,
            "dir_weights": self.dir_weights_,
            "h_dir": self.h_dir_,
        }

    def set_state(self, state: dict[str, np.ndarray]) -> None:
        try:
            self.s_inv_ = state["s_inv"]
            self.h_ = state["h"]
            self.directions_ = state["directions"]
            self.dir_weights_ = state["dir_weights"]
            self.h_dir_ = state["h_dir"]
        except KeyError as e:
            raise ValueError(f"saved state lacks array {e.args[0]!r}") from None
        self._finish()
