"""``lrgf-mem``: the paper's detector (LRGF nominal models + NNARX model-error models + bands)
with an alarm stage.

:class:`LRGFMEM` is the paper's method as a bank of relations
(:class:`~diagnosers.lrgf.bank_detector.BankDetector`) whose remaining errors go to
:class:`~diagnosers.stages.ewma_stage.EWMAStage`: the paper's band rule, or EWMA persistence combined
by Hotelling's T² with a calibrated limit. ``lrgf-mem-paper``, the paper's configuration, is a
preset of it (:mod:`diagnosers.lrgf.lrgf_presets`). :data:`PARAMETER_CONSTRAINTS` holds the
constraints of its hyperparameters, documented on the class.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, ClassVar

import numpy as np

from diagnosers.contract import require_varying
from diagnosers.detection import Detection
from diagnosers.episode.record import Episode
from diagnosers.lrgf.bank_detector import (
    BANK_CONSTRAINTS,
    BANK_DEFAULTS,
    MIN_CALIBRATION_SAMPLES,
    RUN_DEFAULTS,
    BankDetector,
    MemSelect,
    holdout_split,
)
from diagnosers.presets import keyword_init
from diagnosers.registry import register
from diagnosers.stages.alarm import two_sided_normal_quantile
from diagnosers.stages.band import BandScale, band_scale
from diagnosers.stages.ewma_stage import AlarmFilter, EWMAStage
from fcc_common.validation import Options, check_params

__all__ = ["LRGFMEM", "PARAMETER_CONSTRAINTS", "AlarmFilter"]


#: declarative hyperparameter constraints of :class:`LRGFMEM`, checked in ``fit`` (the alarm
#: stage's are :class:`~diagnosers.stages.ewma_stage.EWMAStage`'s own)
PARAMETER_CONSTRAINTS: dict[str, Any] = {
    **BANK_CONSTRAINTS,
    "band_definition": Options(BandScale),
    **EWMAStage.CONSTRAINTS,
}


@register("lrgf-mem")
class LRGFMEM(BankDetector):
    """The paper's LRGF + model-error-model detector with an alarm stage.

    Use it for the paper's method on a bank of relations; ``lrgf-glr`` (same bank, a
    cross-fitted limit and tests along fault directions) detects earlier on most tracks, and
    ``lrgf-mem-paper`` is the paper's configuration (one relation, the band rule).

    The bank (:class:`~diagnosers.lrgf.bank_detector.BankDetector`, whose hyperparameters it
    inherits) gives each relation's centre ``y_m + y_e``; the remaining error
    ``y − y_m − y_e``, divided by the band scale ``v``, goes to the alarm stage
    (:class:`~diagnosers.stages.ewma_stage.EWMAStage`, ``stage_``, which owns
    ``false_alarm_target``). ``lrgf-mem``'s defaults: a bank of three relations
    (:data:`~diagnosers.bank.relations.BANK_RELATIONS`) of 5 neurons each, ``v`` from held-out
    remaining error, error models kept only where they help, EWMA persistence (λ = 0.3)
    combined by T², limit ``"chi2-tail"`` at a target of 0.002 (chosen on validation seeds,
    lab/detector-lab.md).

    Training data: the healthy episodes passed to ``fit`` are divided into a training part
    (the first ``n − max(1, n // 3)`` episodes) for the networks and error models and a
    calibration part (the rest) for ``v`` and the limits; a single episode trains on its first
    70 % and calibrates on the rest (simulated over the whole episode).

    Args:
        band_definition: the band scale ``v``: ``"residual"`` (default), the RMS of
            ``y − y_m − y_e`` on the held-out healthy episodes (about zero, because the band
            is centred on ``y_m + y_e``), a band that covers 1 − α of healthy samples when the
            remaining error is roughly normal; ``"paper"``, the paper's literal text, the
            standard deviation of ``y_e`` on the training part (how much the error model
            moves, not how far the output strays, so its coverage is not 1 − α in general); or
            ``"paper-record"``, the same over the whole healthy record given to ``fit``
            (training and calibration parts, each episode from its first sample, start-up
            included) (:class:`diagnosers.stages.band.BandScale`).
        alarm_filter: the alarm logic (:class:`~diagnosers.stages.ewma_stage.AlarmFilter`):
            ``"none"``, the paper's rule, an alarm when a measured output leaves its band
            (``signal`` the output, ``lower``/``upper`` the band); ``"ewma"``, an EWMA of each
            relation's normalised remaining error, an alarm when one leaves ±h (``signal``
            the EWMAs, ``lower``/``upper`` ∓h), each h set for ``false_alarm_target / k`` of
            healthy samples (k relations); ``"ewma-t2"`` (default), the EWMA vector combined
            into Hotelling's T² with the calibration covariance, an alarm when T² exceeds h
            set for ``false_alarm_target`` (``signal`` T², ``upper`` h). The relations' healthy
            errors are correlated while a fault moves them in its own direction, which T²
            sees and per-relation limits do not.
        ewma_lambda: the EWMA's weight λ, in (0, 1]; default 0.3. Smaller averages longer:
            less white noise, later alarms (the remaining error that carries f3 is mostly
            low-frequency model error, which averaging does not remove).
        false_alarm_target: the declared share of healthy samples in alarm, in (0, 0.5);
            default 0.002. It sets the limits h (``alarm_filter`` ``"ewma"``/``"ewma-t2"``);
            with ``"none"`` it moves no alarm (``band_alpha`` does).
        threshold_margin: a factor on every limit, in [0.5, 10]; default 1.0.
        limit_method: how a limit is set from the calibration statistic
            (:func:`diagnosers.stages.alarm.calibrate_limit`): ``"empirical"``, its quantile at
            1 − target; ``"chi2-tail"`` (default), the reference distribution's quantile (χ²_k
            for T², the normal for one EWMA) scaled by the calibration's tail inflation at its
            0.99 quantile, because an empirical 0.998 quantile of a few autocorrelated
            episodes rests on one or two excursions.

    Bank hyperparameters (each described in full on
    :class:`~diagnosers.lrgf.bank_detector.BankDetector`; defaults ``lrgf-mem``'s):

    | hyperparameter | default | allowed values [unit] |
    |---|---|---|
    | ``relations`` | ``None``: three relations | ``[[output, [inputs...]], ...]`` in channel names |
    | ``n_hidden`` | 5 | neurons per network in [1, 64], a list (one per relation), or ``None`` (by output) |
    | ``order`` | 2 | IIR filter order of each neuron, [1, 8] |
    | ``n_linear`` | 0 | linear (no tanh) neurons per network, [0, smallest network] |
    | ``steady_window`` | 100 | silent start-up window, [1, 100000] samples |
    | ``mem_hidden`` | 5 | hidden neurons of each NNARX error model, [1, 256] |
    | ``mem_input_delays`` | 15 | error-model input delays, [1, 100] samples |
    | ``mem_output_delays`` | 15 | error-model output delays, [1, 100] samples |
    | ``mem_output_activation`` | ``"linear"`` | ``"linear"`` or ``"tanh"`` |
    | ``mem_max_epochs`` | 200 | error-model training epochs, [1, 100000] |
    | ``mem_select`` | ``"if_better"`` | ``"always"`` or ``"if_better"`` (keep where it lowers the error) |
    | ``method`` | ``"adam"`` | the networks' optimiser, ``"adam"`` or ``"spsa"`` |
    | ``lr`` | 0.03 | the networks' learning rate, (0, 1] |
    | ``max_epochs`` | 3000 | the networks' training epochs, [1, 100000] |
    | ``val_fraction`` | 0.25 | share of each training episode held out for early stopping, [0, 1) |
    | ``band_alpha`` | 0.01 | two-sided level α of the band ``y_m + y_e ± t_α·v``, (0, 0.5) |
    | ``seed`` | 0 | integer ≥ 0; relation ``j`` uses ``seed + 101 j`` |
    | ``progress`` | ``None`` | tqdm bar: ``True``, ``False``, ``None`` (when interactive); execution only |
    | ``n_jobs`` | ``None`` | training processes, an integer ≥ 1 or ``None`` (1); execution only |
    """

    DEFAULTS: ClassVar[dict[str, Any]] = {
        **BANK_DEFAULTS,
        "band_definition": "residual",
        **EWMAStage.DEFAULTS,  # the alarm stage's hyperparameters
        **RUN_DEFAULTS,
    }
    __init__ = keyword_init(DEFAULTS)
    STAGE = EWMAStage
    stage_: EWMAStage

    band_definition: str
    alarm_filter: str
    ewma_lambda: float
    false_alarm_target: float
    threshold_margin: float
    limit_method: str
    mem_select: str

    def _validate_params(self) -> None:
        check_params(self.get_params(), PARAMETER_CONSTRAINTS)
        self._check_sizes()

    # ---- fitting -------------------------------------------------------------------------------
    def _fit(self, episodes: list[Episode]) -> None:
        bank = self._new_bank()
        outputs = sorted(set(bank.out_idx.tolist()))  # a flat output: no band to calibrate
        require_varying(
            np.concatenate([e.y[:, outputs] for e in episodes]),
            [self.channels_[i] for i in outputs],
            self.name or type(self).__name__,
        )
        train, cal, cal_from = holdout_split(episodes)
        bank.set_models(self._train_banks([train])[0])
        # held-out healthy calibration
        bank.use_mem = np.ones(len(bank), dtype=bool)
        # the warm-up samples are not calibrated on: the detector is silent there
        cal_from = max(cal_from, self.steady_window)
        n_cal = sum(max(0, y.shape[0] - cal_from) for y in cal)
        if n_cal < MIN_CALIBRATION_SAMPLES:
            raise ValueError(
                f"{n_cal} calibration samples after the warm-up (steady_window="
                f"{self.steady_window}); at least {MIN_CALIBRATION_SAMPLES} are needed: pass "
                "longer or more episodes, or a smaller steady_window"
            )
        rem = [bank.remaining(y)[cal_from:] for y in cal]  # (T, k) each
        if self.mem_select == MemSelect.IF_BETTER:
            # An error model that does not reduce the held-out error only adds its own: drop it.
            bank.use_mem = np.zeros(len(bank), dtype=bool)
            rem_off = np.concatenate([bank.remaining(y)[cal_from:] for y in cal])
            rms_on = np.sqrt(np.mean(np.concatenate(rem) ** 2, axis=0))
            rms_off = np.sqrt(np.mean(rem_off**2, axis=0))
            bank.use_mem = rms_on < rms_off
            rem = [bank.remaining(y)[cal_from:] for y in cal]
        rem_all = np.concatenate(rem)
        self.v_residual_ = np.sqrt(np.mean(rem_all**2, axis=0))
        if self.band_definition == BandScale.PAPER_RECORD:
            # every error model's output, kept or not: the band is the paper's, whatever the
            # held-out selection decided for the centre
            self.v_record_ = band_scale(
                np.concatenate([bank.parts(e.y)[1] for e in episodes]),
                definition=BandScale.PAPER_RECORD,
            )
        self.stage_ = self._new_stage().fit([r / self.v_residual_ for r in rem])
        self._finish()

    def _finish(self) -> None:
        """Derived state shared by ``_fit`` and ``_set_state``."""
        if self.band_definition == BandScale.PAPER:
            self.v_ = self.bank_.v_paper
        elif self.band_definition == BandScale.PAPER_RECORD:
            self.v_ = self.v_record_
        else:
            self.v_ = self.v_residual_
        self.v_ = np.maximum(self.v_, 1e-9)
        half_band = two_sided_normal_quantile(self.band_alpha) * np.asarray(self.v_, np.float64)
        self.stage_.set_band(half_band)  # as band()
        self.signal_names_ = self.stage_.signal_names([o for o, _ in self._relations()])

    # ---- views ---------------------------------------------------------------------------------
    def band_view(self, episode: Episode) -> Detection | None:
        """The bands (:meth:`BankDetector.band_view`); ``None`` with ``alarm_filter="none"``,
        where :meth:`detect` reports them already."""
        if self.alarm_filter == AlarmFilter.NONE:
            self._check_episode(episode)
            return None
        return super().band_view(episode)

    # ---- persistence ---------------------------------------------------------------------------
    def _family_state(self) -> dict[str, np.ndarray]:
        if self.band_definition == BandScale.PAPER_RECORD:
            return {"v_record": self.v_record_}  # only this band has it: other states unchanged
        return {}

    def _set_family_state(self, state: Mapping[str, np.ndarray]) -> None:
        if self.band_definition == BandScale.PAPER_RECORD:
            try:
                self.v_record_ = state["v_record"]
            except KeyError as e:
                raise ValueError(f"saved state lacks array {e.args[0]!r}") from None
