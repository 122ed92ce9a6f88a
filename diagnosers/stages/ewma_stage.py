"""``lrgf-mem``'s alarm stage as one object: the paper's band rule, or EWMA persistence.

:class:`EWMAStage` turns a bank's remaining errors into alarms in one of three ways
(``alarm_filter``):

* ``"none"``: the paper's rule, an alarm when a measured output leaves its band
  ``centre ± half_band`` (``signal`` is the output, ``lower``/``upper`` the band);
* ``"ewma"``: an EWMA (weight ``ewma_lambda``) of each relation's normalised remaining error,
  an alarm when one leaves ±h, each h set for ``false_alarm_target / k`` of healthy samples;
* ``"ewma-t2"``: the EWMA vector combined into Hotelling's T² (zero mean, the calibration
  covariance), an alarm when T² exceeds h set for ``false_alarm_target``.

The limits come from healthy calibration records (:func:`diagnosers.stages.alarm.calibrate_limit`,
``limit_method`` times ``threshold_margin``). ``false_alarm_target`` lives here and nowhere
else in ``lrgf-mem``. It is an :class:`~diagnosers.stages.alarm_stage.AlarmStage`, whose
``DEFAULTS`` are ``lrgf-mem``'s; ``lrgf-glr``'s stage is
:class:`diagnosers.stages.directional_stage.DirectionalStage`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from enum import StrEnum
from typing import Any, ClassVar

import numpy as np

from diagnosers.detection import Decision, Detection
from diagnosers.presets import keyword_init
from diagnosers.stages.alarm import EWMA, HotellingT2, calibrate_limit
from diagnosers.stages.alarm_stage import stage_constraints
from fcc_common.validation import Options

__all__ = ["AlarmFilter", "EWMAStage"]


class AlarmFilter(StrEnum):
    """Alarm logic after the band (see the module docstring)."""

    NONE = "none"
    EWMA = "ewma"
    EWMA_T2 = "ewma-t2"


class EWMAStage:
    """The band rule or EWMA persistence with calibrated limits (module docstring).

    The hyperparameters default to :attr:`DEFAULTS` (``lrgf-mem``'s).

    Args:
        alarm_filter: ``"none"``, ``"ewma"`` or ``"ewma-t2"`` (:class:`AlarmFilter`).
        ewma_lambda: the EWMA's weight.
        false_alarm_target: the declared share of healthy samples in alarm.
        threshold_margin: the limits' factor.
        limit_method: ``"empirical"`` or ``"chi2-tail"``
            (:func:`diagnosers.stages.alarm.calibrate_limit`).

    Attributes (after :meth:`fit` or :meth:`set_state`): ``h_`` the limits (one per relation
    for ``"ewma"``, one for ``"ewma-t2"``), ``s_inv_`` the T² precision.
    """

    DEFAULTS: ClassVar[Mapping[str, Any]] = {
        "alarm_filter": "ewma-t2",
        "ewma_lambda": 0.3,
        "false_alarm_target": 0.002,
        "threshold_margin": 1.0,
        "limit_method": "chi2-tail",
    }
    CONSTRAINTS: ClassVar[Mapping[str, Any]] = stage_constraints(
        DEFAULTS, {"alarm_filter": Options(AlarmFilter)}
    )
    __init__ = keyword_init(DEFAULTS)

    def fit(self, norm: Sequence[np.ndarray]) -> EWMAStage:
        """The limits from healthy normalised remaining errors ``norm`` (``(T, k)`` records past
        their warm-up). :meth:`set_band` gives the band of the paper's rule."""
        ewma = EWMA(self.ewma_lambda)
        stats = np.concatenate([ewma.filter(e) for e in norm])
        k = stats.shape[1]
        if AlarmFilter(self.alarm_filter) is AlarmFilter.EWMA_T2:
            # The EWMA of a healthy normalised error is zero-mean by construction: T² about 0.
            t2 = HotellingT2(centered=False).fit(stats)
            self.s_inv_ = t2.precision_
            self.h_ = np.array([self.limit(t2.score(stats)[:, None], k)[0]])
        else:
            self.s_inv_ = np.eye(k)
            self.h_ = self.limit(np.abs(stats), 0)
        self._finish()
        return self

    def limit(self, stat: np.ndarray, dof: int) -> np.ndarray:
        """Alarm limit per column of the healthy calibration statistic ``stat`` (T, c).

        ``dof = 0``: columns are |EWMA| of one relation each, with the target split over them
        (``false_alarm_target / c`` each); ``dof = k``: one column of Hotelling's T² over k
        relations. The method and its reasons: :func:`diagnosers.stages.alarm.calibrate_limit`.
        """
        target = self.false_alarm_target / (stat.shape[1] if dof == 0 else 1)
        return calibrate_limit(
            stat, target, method=self.limit_method, dof=dof, margin=self.threshold_margin
        )

    def _finish(self) -> None:
        self.t2_ = HotellingT2(centered=False)
        self.t2_.set_state({"mean": np.zeros(len(self.s_inv_)), "precision": self.s_inv_})
        ewma = self.alarm_filter == AlarmFilter.EWMA
        self._limit_lower = -self.h_ if ewma else np.array([-np.inf])
        n = 1 if self.alarm_filter == AlarmFilter.EWMA_T2 else len(self.s_inv_)
        self._warm_lower, self._warm_upper = np.full(n, -np.inf), np.full(n, np.inf)

    def set_band(self, half_band: np.ndarray) -> None:
        """The band's half-width per relation (``t_α · v``) for the paper's rule
        (``alarm_filter="none"``); call after :meth:`fit` or :meth:`set_state`."""
        self._half_band = half_band

    def signal_names(self, outputs: Sequence[str]) -> tuple[str, ...]:
        """The names of the signals, given the relations' outputs."""
        if self.alarm_filter == AlarmFilter.EWMA:
            return tuple(f"ewma[{o}]" for o in outputs)
        if self.alarm_filter == AlarmFilter.EWMA_T2:
            return ("T2[ewma]",)
        return tuple(outputs)

    # ---- running -------------------------------------------------------------------------------
    def reset(self) -> None:
        """Fresh streaming state (the EWMA)."""
        self._ewma = EWMA(self.ewma_lambda)

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
        its normalised error ``e``; ``output`` and ``centre`` for the band rule."""
        # the EWMA starts after the warm-up: it sees zeros there, as in detect()
        z = self._ewma.update(np.zeros(np.shape(e)) if warm else e)
        return self._decide(z, residual, output, centre, warm)

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
        AlarmStage`): the EWMA of the record at once, then :meth:`step`'s rule on every row."""
        self.reset()
        e = np.array(e, dtype=np.float64)
        e[:warm_up] = 0.0
        z = EWMA(self.ewma_lambda).filter(e)
        n = e.shape[0]
        if self.alarm_filter == AlarmFilter.NONE:
            assert output is not None and centre is not None, "the band rule needs them"
            signal, lower, upper = output, centre - self._half_band, centre + self._half_band
        else:
            if self.alarm_filter == AlarmFilter.EWMA:
                signal = z
            else:  # T² row by row, as step() computes it: batch and stream agree to the bit
                signal = np.array([self.t2_.score(row) for row in z], np.float64).reshape(n, 1)
            lower, upper = np.tile(self._limit_lower, (n, 1)), np.tile(self.h_, (n, 1))
        lower[:warm_up], upper[:warm_up] = self._warm_lower, self._warm_upper
        alarm = ((signal < lower) | (signal > upper)).any(axis=1)
        return Detection(alarm, signal, lower, upper, residual, tuple(names))

    def _decide(
        self,
        z: np.ndarray,
        residual: np.ndarray,
        output: np.ndarray | None,
        centre: np.ndarray | None,
        warm: bool,
    ) -> Decision:
        """The decision of one streamed sample from its EWMA ``z``; none while ``warm``
        (:meth:`detect` applies the same rule to every row at once).

        The limits come precomputed, and the arrays the decisions share are never written to.
        """
        if self.alarm_filter == AlarmFilter.EWMA:
            signal, lower, upper = z, self._limit_lower, self.h_
        elif self.alarm_filter == AlarmFilter.EWMA_T2:
            signal = np.array([self.t2_.score(z)])
            lower, upper = self._limit_lower, self.h_
        else:
            assert output is not None and centre is not None, "the band rule needs them"
            signal = output
            lower, upper = centre - self._half_band, centre + self._half_band  # as band()
        if warm:  # no limit while the models settle (alarm stays "outside the limits")
            lower, upper = self._warm_lower, self._warm_upper
        alarm = bool(((signal < lower) | (signal > upper)).any())
        return Decision(alarm, signal, lower, upper, residual)

    # ---- persistence ---------------------------------------------------------------------------
    def get_state(self) -> dict[str, np.ndarray]:
        return {"h": self.h_, "s_inv": self.s_inv_}

    def set_state(self, state: Mapping[str, np.ndarray]) -> None:
        try:
            self.h_ = state["h"]
            self.s_inv_ = state["s_inv"]
        except KeyError as e:
            raise ValueError(f"saved state lacks array {e.args[0]!r}") from None
        self._finish()
