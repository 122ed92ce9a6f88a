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
else in ``lrgf-mem``. ``lrgf-glr``'s stage is :class:`diagnosers.stages.directional_stage.
DirectionalStage`.
"""

from __future__ import annotations

from collections.abc import Sequence
from enum import StrEnum

import numpy as np

from diagnosers.detection import Decision
from diagnosers.stages.alarm import EWMA, HotellingT2, calibrate_limit

__all__ = ["AlarmFilter", "EWMAStage"]


class AlarmFilter(StrEnum):
    """Alarm logic after the band (see the module docstring)."""

    NONE = "none"
    EWMA = "ewma"
    EWMA_T2 = "ewma-t2"


class EWMAStage:
    """The band rule or EWMA persistence with calibrated limits (module docstring).

    Args:
        alarm_filter: ``"none"``, ``"ewma"`` or ``"ewma-t2"`` (:class:`AlarmFilter`).
        ewma_lambda: the EWMA's weight.
        false_alarm_target: the declared share of healthy samples in alarm.
        limit_method: ``"empirical"`` or ``"chi2-tail"`` (:func:`diagnosers.stages.alarm.calibrate_limit`).
        threshold_margin: the limits' factor.

    Attributes (after :meth:`fit` or :meth:`set_state`): ``h_`` the limits (one per relation
    for ``"ewma"``, one for ``"ewma-t2"``), ``s_inv_`` the T² precision.
    """

    def __init__(
        self,
        *,
        alarm_filter: str,
        ewma_lambda: float,
        false_alarm_target: float,
        limit_method: str,
        threshold_margin: float,
    ) -> None:
        self.alarm_filter = alarm_filter
        self.ewma_lambda = ewma_lambda
        self.false_alarm_target = false_alarm_target
        self.limit_method = limit_method
        self.threshold_margin = threshold_margin

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

    def set_band(self, half_band: np.ndarray) -> None:
        """The band's half-width per relation (``t_α · v``) for the paper's rule; call after
        :meth:`fit` or :meth:`set_state`."""
        self._half_band = half_band
        if self.alarm_filter == AlarmFilter.EWMA_T2:
            n = 1
        else:
            n = len(half_band)
        self._warm_lower, self._warm_upper = np.full(n, -np.inf), np.full(n, np.inf)

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

    def filter_step(self, e: np.ndarray) -> np.ndarray:
        """The EWMA of one sample's normalised error (streaming :meth:`filter`)."""
        return self._ewma.update(e)

    def filter(self, e: np.ndarray) -> np.ndarray:
        """The EWMA of a whole record of normalised errors, from a fresh start."""
        return EWMA(self.ewma_lambda).filter(e)

    def decide(self, y_out: np.ndarray, centre: np.ndarray, z: np.ndarray, warm: bool) -> Decision:
        """The decision of one sample: its outputs, band centres and EWMA; none while ``warm``.

        Called for every sample by streaming and batch detection alike: the limits come
        precomputed, and the arrays the decisions share are never written to.
        """
        resid = y_out - centre
        if self.alarm_filter == AlarmFilter.EWMA:
            signal, lower, upper = z, self._limit_lower, self.h_
        elif self.alarm_filter == AlarmFilter.EWMA_T2:
            signal = np.array([self.t2_.score(z)])
            lower, upper = self._limit_lower, self.h_
        else:
            signal = y_out
            lower, upper = centre - self._half_band, centre + self._half_band  # as band()
        if warm:  # no limit while the models settle (alarm stays "outside the limits")
            lower, upper = self._warm_lower, self._warm_upper
        alarm = bool(((signal < lower) | (signal > upper)).any())
        return Decision(alarm, signal, lower, upper, resid)

    # ---- persistence ---------------------------------------------------------------------------
    def get_state(self) -> dict[str, np.ndarray]:
        return {"h": self.h_, "s_inv": self.s_inv_}

    def set_state(self, state: dict[str, np.ndarray]) -> None:
        try:
            self.h_ = state["h"]
            self.s_inv_ = state["s_inv"]
        except KeyError as e:
            raise ValueError(f"saved state lacks array {e.args[0]!r}") from None
        self._finish()
