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
this stage passes its target to it. It is an :class:`~diagnosers.stages.alarm_stage.AlarmStage`
whose ``DEFAULTS`` are ``lrgf-glr``'s. The stage knows nothing of models, so the perfect-model
reference rows of :mod:`evaluation.tracks.oracle` run exactly the detector's stage (the
physical-limit row with ``statistic="t2"`` and a centred T², ``centered=True``).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from enum import StrEnum
from typing import Any, ClassVar

import numpy as np
from scipy.linalg import block_diag

from diagnosers.detection import Decision, Detection
from diagnosers.presets import keyword_init
from diagnosers.stages.alarm import (
    CUSUM,
    EWMA,
    DirectionalGLR,
    DirectionalProjection,
    HotellingT2,
    OnDelay,
    calibrate_limit,
    normal_tail_limit,
)
from diagnosers.stages.alarm_stage import stage_constraints
from diagnosers.stages.baseline import HeldBaseline
from fcc_common.validation import Integer, Options, Real, RealSequence

__all__ = ["DirectionalStage", "Statistic", "projection_limits", "sequential_limits"]


class Statistic(StrEnum):
    """The directional tests of :class:`DirectionalStage` (see the module docstring)."""

    T2 = "t2"
    DIRECTIONAL = "directional"
    GLR = "glr"
    CUSUM = "cusum"


class DirectionalStage:
    """Filters, statistics, limits and alarm rule on normalised errors (module docstring).

    The hyperparameters default to :attr:`DEFAULTS` (``lrgf-glr``'s).

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
        centered: the T² about the calibration mean of the fast EWMA (``mean_``) instead of
            zero (default False: a detector's healthy normalised error is zero-mean by
            construction).
        baseline: a held baseline removed before the EWMAs, or None.

    Attributes (after :meth:`fit` or :meth:`set_state`): ``s_inv_`` the fast EWMA's T²
    precision, ``mean_`` its centre, ``h_`` the T² limit ``(1,)``, ``dir_weights_`` the
    projections, ``h_dir_`` the directional limits, ``upper_`` every limit in signal order.
    """

    DEFAULTS: ClassVar[Mapping[str, Any]] = {
        "false_alarm_target": 0.025,
        "statistic": "directional",
        "ewma_lambda": 0.3,
        "slow_ewma_lambda": 0.02,
        "slow_share": 0.5,
        "omnibus_share": 0.2,
        "glr_window": 200,
        "cusum_drift": 0.5,
        "limit_method": "chi2-tail",
        "threshold_margin": 1.0,
        "on_delay": 1,
    }
    CONSTRAINTS: ClassVar[Mapping[str, Any]] = stage_constraints(
        DEFAULTS,
        {
            "statistic": Options(Statistic),
            "slow_ewma_lambda": (Real(0, 1, closed="left"), RealSequence(0, 1, closed="neither")),
            "slow_share": Real(0, 1, closed="neither"),
            "omnibus_share": Real(0, 1, closed="right"),
            "glr_window": Integer(1, 5000),
            "cusum_drift": Real(0),
            "on_delay": Integer(1, 1000),
        },
    )
    # the stage's own parts beside its hyperparameters: how T² is centred, the baseline
    __init__ = keyword_init({**DEFAULTS, "centered": False, "baseline": None})
    baseline: HeldBaseline | None

    # ---- calibration ---------------------------------------------------------------------------
    def fit(
        self,
        norm: Sequence[np.ndarray],
        directions: np.ndarray | None = None,
        features: list[np.ndarray | None] | None = None,
    ) -> DirectionalStage:
        """Covariances and limits from healthy normalised error records ``norm`` (past their
        warm-up) and the unit fault ``directions`` ``(m, k)`` (None: none, the T² alone);
        ``features``: each record's regressors for a regression baseline.

        Without a baseline the statistics are fixed filters of the error: one fit. With one,
        what the baseline absorbs depends on when it holds, which depends on the limits: fit on
        an always-adapting baseline, then once more on the baseline held by those limits.
        """
        if directions is None:  # no fault direction: the T² alone
            directions = np.zeros((0, norm[0].shape[1]))
        self.directions_ = np.asarray(directions)
        phis = [None] * len(norm) if features is None else features
        pairs = list(zip(norm, phis, strict=True))
        if self.baseline is None:
            self._fit_limits(list(norm))
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
            out[k] = self._advance(e[k], warm=False, phi=None if phi is None else phi[k])[0]
        return out

    def _fit_limits(self, norm: list[np.ndarray]) -> None:
        """Covariances and limits on healthy (baseline-removed) normalised errors ``norm``."""
        k, m = self.directions_.shape[1], len(self.directions_)
        z = np.concatenate([EWMA(self.ewma_lambda).filter(e) for e in norm])
        t2 = HotellingT2(centered=self.centered).fit(z)
        self.s_inv_, self.mean_ = t2.precision_, t2.mean_
        det = Statistic(self.statistic)
        share = 1.0 if m == 0 or det is Statistic.T2 else self.omnibus_share
        self.h_ = calibrate_limit(
            np.asarray(t2.score(z))[:, None],
            self.false_alarm_target * share,
            method=self.limit_method,
            dof=k,
            margin=self.threshold_margin,
        )
        self.dir_weights_, self.h_dir_ = np.zeros((0, k)), np.zeros(0)
        if m and det is not Statistic.T2:
            t_dir = self.false_alarm_target * (1.0 - share) / m
            margin = self.threshold_margin
            if det is Statistic.DIRECTIONAL:
                zz = self._scales(z, norm)
                self.dir_weights_, self.h_dir_ = projection_limits(
                    zz, self.directions_, t_dir, self.slow_share, margin
                )
            else:
                self.dir_weights_, self.h_dir_ = sequential_limits(
                    norm, self.directions_, self._sequential(), t_dir, margin
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
        self.t2_ = HotellingT2(centered=self.centered)
        self.t2_.set_state({"mean": self.mean_, "precision": self.s_inv_})
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
        self._delay = OnDelay(self.on_delay)  # samples in a row over a limit
        if self.baseline is not None:
            self.baseline.reset()

    def step(
        self,
        e: np.ndarray,
        *,
        warm: bool,
        residual: np.ndarray,
        output: np.ndarray | None = None,
        centre: np.ndarray | None = None,
        phi: np.ndarray | None = None,
    ) -> Decision:
        """The decision of one sample (:class:`~diagnosers.stages.alarm_stage.AlarmStage`):
        its normalised error ``e``; ``phi``: its regressors with a regression baseline."""
        return self._decide(residual, self._advance(e, warm=warm, phi=phi)[1], warm)

    def detect(
        self,
        e: np.ndarray,
        *,
        warm_up: int,
        residual: np.ndarray,
        names: Sequence[str],
        output: np.ndarray | None = None,
        centre: np.ndarray | None = None,
        phi: np.ndarray | None = None,
    ) -> Detection:
        """The decisions of a whole record (:class:`~diagnosers.stages.alarm_stage.
        AlarmStage`): its :meth:`signals`, then the alarm rule on every row."""
        self.reset()
        signal = self.signals(e, warm_up, phi)
        upper = np.tile(self.upper_, (len(signal), 1))
        upper[:warm_up] = self._no_limit
        alarm = OnDelay(self.on_delay).filter((signal > upper).any(axis=1))
        lower = np.full(upper.shape, -np.inf)
        return Detection(alarm, signal, lower, upper, residual, tuple(names))

    def _advance(
        self, e: np.ndarray, *, warm: bool, phi: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """One sample of the stage: (baseline-removed error, signal). The one place the
        recursion is written; streaming and batch with a baseline both call it. ``phi``: the
        sample's regressors with a regression baseline."""
        if warm:  # the statistics start after the warm-up: they see zeros there
            e = np.zeros(np.shape(e))
        base = self.baseline
        et = e if base is None else e - base.value(phi)
        z = self._ewma.update(et)
        signal = np.empty(len(self.upper_))
        signal[0] = self.t2_.score(z)
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
        """The signals ``(T, n)`` of a whole record ``e`` (read as zero in its first
        ``warm_up`` samples), from a fresh :meth:`reset`; equal to :meth:`step`'s on every
        row (up to rounding: the batch T² is vectorised)."""
        e = np.array(e, dtype=np.float64)
        e[:warm_up] = 0.0
        if self.baseline is not None:  # the baseline's hold makes the stage a recursion
            rows = [None] * len(e) if phi is None else list(phi)
            return np.array(
                [self._advance(e[k], warm=k < warm_up, phi=rows[k])[1] for k in range(len(e))]
            )
        z = EWMA(self.ewma_lambda).filter(e)
        if self.n_slow_scales > 0:
            z = self._scales(z, [e])
        # T² of the fast EWMA (the first k columns of z), then the directional statistics
        t2 = np.atleast_1d(self.t2_.score(z[..., : len(self.s_inv_)]))
        if not len(self.h_dir_):
            return t2[..., None]
        if self.statistic == Statistic.DIRECTIONAL:
            return np.column_stack([t2, self._proj.score(z)])
        return np.column_stack([t2, self._sequential().filter(self._proj.score(e))])

    def _decide(self, residual: np.ndarray, signal: np.ndarray, warm: bool) -> Decision:
        """The alarm of one sample's ``signal`` (none while ``warm``), with the on-delay."""
        upper = self._no_limit if warm else self.upper_
        alarm = self._delay.update(bool((signal > upper).any()))
        return Decision(alarm, signal, self._lower, upper, residual)

    # ---- persistence ---------------------------------------------------------------------------
    def get_state(self) -> dict[str, np.ndarray]:
        state = {
            "s_inv": self.s_inv_,
            "h": self.h_,
            "directions": self.directions_,
            "dir_weights": self.dir_weights_,
            "h_dir": self.h_dir_,
        }
        if self.centered:  # only a centred T² has a centre: a detector's state is unchanged
            state["mean"] = self.mean_
        return state

    def set_state(self, state: Mapping[str, np.ndarray]) -> None:
        try:
            self.s_inv_ = state["s_inv"]
            self.mean_ = state["mean"] if self.centered else np.zeros(len(self.s_inv_))
            self.h_ = state["h"]
            self.directions_ = state["directions"]
            self.dir_weights_ = state["dir_weights"]
            self.h_dir_ = state["h_dir"]
        except KeyError as e:
            raise ValueError(f"saved state lacks array {e.args[0]!r}") from None
        self._finish()


# ---- the directional tests' limits -------------------------------------------------------------
def projection_limits(
    zz: np.ndarray, directions: np.ndarray, target: float, slow_share: float, margin: float
) -> tuple[np.ndarray, np.ndarray]:
    """Weights and limits of the ``"directional"`` tests: the matched filters of the unit fault
    ``directions`` ``(m, k)`` on each EWMA scale of the healthy ``zz`` ``(T, k · scales)`` (fast
    first), block-diagonal ``(m · scales, k · scales)``, and one normal-tail limit per score,
    each direction getting ``target`` (the fast scale ``1 − slow_share`` of it)."""
    m, k = directions.shape
    # one block of projections per EWMA scale, each with its own healthy covariance
    blocks = [
        DirectionalProjection().fit(directions, np.cov(zz[:, i : i + k].T))
        for i in range(0, zz.shape[1], k)
    ]
    weights = block_diag(*[b.weights_ for b in blocks])
    n_slow = len(blocks) - 1
    # the fast scale keeps 1 - slow_share, the slow scales split slow_share equally
    shares = [1.0 - slow_share] + [slow_share / n_slow] * n_slow if n_slow else [1.0]
    scores = zz @ weights.T  # m columns per scale
    limits = margin * np.concatenate(
        [
            normal_tail_limit(scores[:, i * m : (i + 1) * m], target * sh)
            for i, sh in enumerate(shares)
        ]
    )
    return weights, limits


def sequential_limits(
    norm: list[np.ndarray],
    directions: np.ndarray,
    sequential: DirectionalGLR | CUSUM,
    target: float,
    margin: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Weights and limits of the ``"glr"``/``"cusum"`` tests: the matched filters of the unit
    fault ``directions`` ``(m, k)`` on the healthy records ``norm``, and one limit shared by the
    directions, the empirical quantile of the largest ``sequential`` statistic of a sample at
    ``1 − m · target``."""
    m = len(directions)
    proj = DirectionalProjection().fit(directions, np.cov(np.concatenate(norm).T))
    seq = np.concatenate([sequential.filter(proj.score(e)) for e in norm])
    return proj.weights_, margin * np.full(m, np.quantile(seq.max(axis=1), 1.0 - target * m))
