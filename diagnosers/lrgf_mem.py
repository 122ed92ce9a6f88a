"""The paper's detector: LRGF nominal models + neural model-error models (NNARX) + bands.

For each monitored relation ``output = s(inputs)`` a locally recurrent globally feed-forward
network (:class:`diagnosers.lrgf.LRGF`) models the healthy process in simulation mode (it never
sees the measured output), and an NNARX model-error model (:class:`diagnosers.mem.NNARXErrorModel`,
also in simulation mode, driven by the same inputs) models what the nominal model misses. The
uncertainty band is (paper eqs 10–11)

    y_m + y_e ± t_α · v,   t_α two-sided standard normal quantile for 1 − α (2.576 at α = 0.01)

with α the hyperparameter ``band_alpha``: it sets the band the paper's rule (``alarm_filter=
"none"``) alarms on and the band :meth:`~diagnosers.bank_detector.BankDetector.band_view` draws;
with an alarm stage (``"ewma"``, ``"ewma-t2"``) it moves no alarm, ``false_alarm_target`` does.

Two definitions of ``v``:

* ``"paper"`` — the paper's literal text: the standard deviation of y_e on the training data.
  It measures how much the error model moves, not how far the output strays from the centre, so
  its coverage is not 1 − α in general.
* ``"residual"`` — the spread of what remains, RMS of y − y_m − y_e on held-out healthy episodes
  (RMS about zero, because the band is centred on y_m + y_e): a band that covers 1 − α of healthy
  samples when the remaining error is roughly normal.

Alarm logic (``alarm_filter``):

* ``"none"`` — the paper's rule: alarm when a measured output leaves its band. ``signal`` is the
  measured output, ``lower``/``upper`` the band.
* ``"ewma"`` — persistence: an exponentially weighted moving average (weight ``ewma_lambda``) of
  each relation's normalised remaining error (y − y_m − y_e)/v; alarm when one leaves ±h, with h
  set on held-out healthy episodes for a share ``false_alarm_target / n_relations`` of healthy
  samples beyond h per relation (see ``limit_method`` below). ``signal`` is that statistic,
  ``lower``/``upper`` are ∓h.
* ``"ewma-t2"`` — the EWMA vector of all relations combined into Hotelling's T² with the
  covariance of the EWMAs on the calibration episodes; alarm when T² exceeds h (set for a share
  ``false_alarm_target`` of healthy samples, see ``limit_method``). The healthy
  model errors of different relations are correlated (they share inputs and hidden states) while
  a fault moves the relations in its own direction (f2 and f4: s1 down and s2 up), which T² sees
  and per-relation limits do not. ``signal`` is T², ``upper`` is h.

Alarm limit (``limit_method``, times ``threshold_margin``): ``"empirical"`` takes the calibration
quantile at 1 − target; ``"chi2-tail"`` takes the reference distribution's quantile (χ²_k for T²,
the normal for one EWMA) scaled by the calibration's tail inflation measured at its 0.99 quantile,
because the empirical 0.998 quantile of a few autocorrelated calibration episodes rests on one or
two excursions (see :meth:`diagnosers.ewma_stage.EWMAStage.limit`).

Start-up (``steady_window`` W): the networks start at steady state for the mean of the first W
inputs (:class:`diagnosers.lrgf.InitialState`), and during those W samples the detector is silent
(no alarm; the EWMA starts at sample W; calibration skips them): there the model output is the
steady level still being estimated, not a prediction. W = 100 matches FCC-v0, whose inputs stay at
nominal for the first 100 samples. With W = 1 (the first sample alone) the noise of one air-flow
sample left a start-up error of 1.6 °C RMS on T_rg1 over the first 200 samples of every episode,
which set the alarm limits and the false alarms of earlier versions.

Two registered presets of :class:`LRGFMEM` (:func:`diagnosers.presets.preset`):

* ``lrgf-mem-paper`` — the paper's configuration (Sec. 5): relation T_rx = s1(T_rg2, T_fp), 3
  hidden neurons with 2nd-order filters, NNARX 5 tanh hidden neurons with 15 input and 15 output
  delays, α = 0.01, ``v = "paper"``, no persistence. The start-up convention (W = 100, silent
  warm-up) is ours, shared with ``lrgf-mem``; the paper does not say how its filters start.
* ``lrgf-mem`` — our best: a bank of three relations (the paper's (14)–(16) with the inputs the
  model's physics needs, see :data:`BANK_RELATIONS`) of 5 neurons each (2nd-order filters, 3000
  Adam epochs at learning rate 0.03), ``v = "residual"``, error models kept only where they
  help, EWMA (λ = 0.3) persistence combined by T², limit ``"chi2-tail"`` at a false-alarm target
  of 0.002 with margin 1.0. Hyperparameters (network size, epochs, the relations, λ, the target,
  margin and limit method, the alarm combination, the learning rate, W) were chosen on healthy
  validation episodes (seeds 5000–5039) and on faults with seeds 5000–5019 and magnitudes 0.7×
  the paper's, which the benchmark's test sweep (seeds 0–N, training seeds 1000+) never uses.
  The rule: the fastest f3 detection with a false detection rate ≤ 0.01 on the 40 healthy
  validation seeds and r_td ≥ 0.9 on the other faults, preferring the smaller target where the
  gain was a few samples. On validation: r_fd 0.0028; f1 1.000/0, f2 0.997/6, f3 0.952/66,
  f4 0.994/11 (r_td / mean t_dt in samples). Why λ = 0.3 and not a long average: the remaining
  error of the T_rg1 relation, which alone carries f3, is low-frequency model error (0.33 °C
  after an EWMA of 0.05, against 0.05 °C for its white noise), so long averaging removes little
  error and only delays the alarm.

``n_hidden`` is one network size for every relation, or a list with one size per relation
(e.g. ``[5, 10, 5]`` for :data:`~diagnosers.relations.BANK_RELATIONS`): the slow, high-gain
regenerator relation T_rg1 gains from a larger network more than the others do, and a
per-relation size keeps the others' training time. One size and that size repeated give the
same networks. ``None`` takes the sizes by output (10 neurons for a relation whose output is
T_rg1, 5 for the others, :data:`diagnosers.bank_detector.HIDDEN_BY_OUTPUT`), so it follows a
user's own ``relations``.

``mem_select="if_better"`` (``lrgf-mem``) keeps a relation's error model only when it lowers the
RMS of the remaining error on the calibration episodes: an NNARX that does not generalise adds its
own error to the band centre (seen on this plant for several relations).

``val_fraction`` (default 0.25): the share at the end of every training episode that each LRGF
network holds out to choose its epoch (early stopping, :func:`diagnosers.training.fit_lrgf`).
``0`` trains on every sample for ``max_epochs`` and keeps the parameters of the lowest training
loss, at the same cost per epoch (the network runs over the whole episode either way).
``lrgf-mem``, ``lrgf-mem-paper`` and ``lrgf-glr`` keep 0.25, the setting they were validated
with; ``lrgf-glr-adaptive`` uses 0 (:data:`diagnosers.lrgf_presets.LRGFGLRAdaptive` says why).

Training data split: the healthy episodes passed to ``fit`` are divided into a training part (the
first ``n − max(1, n // 3)`` episodes) for the nominal and error models, and a calibration part
(the rest) for ``v`` and h. With a single episode, the nominal and error models are trained on its
first 70 % and calibrated on the remaining 30 % (simulated over the whole episode).

``progress`` (default ``None``): a tqdm bar over the training epochs when run interactively
(standard error is a terminal, in the main process; :func:`diagnosers.base.auto_progress`),
``True``/``False`` to force it. It does not change the fit.

``n_jobs`` (default ``None``, meaning 1, as in scikit-learn): worker processes that train the
relations (and ``lrgf-glr``'s cross-fit folds) at once, :mod:`diagnosers.parallel`. Each relation
trains with its own seed and one thread, so the models are the same bits for every ``n_jobs``.
The default is 1 because the leaderboard's sweep already trains the diagnosers in parallel
worker processes, one core each: a pool inside each would oversubscribe the cores. Where a bank
trains alone it pays: the sweep gives the banks it trains the cores between them
(:func:`evaluation.sweep.training_jobs`: all of them to a bank that trains alone), and
``python -m diagnosers.benchmark --bank`` uses 2. Like ``progress`` it is an execution parameter
(:attr:`diagnosers.base.Diagnoser.execution_params`): the result store's model hash leaves both
out, so changing them reuses a stored model.
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np

from diagnosers.alarm import (
    LimitMethod,
    two_sided_normal_quantile,
)
from diagnosers.band import BandScale
from diagnosers.bank_detector import (
    BANK_CONSTRAINTS,
    BANK_DEFAULTS,
    MIN_CALIBRATION_SAMPLES,
    RUN_DEFAULTS,
    BankDetector,
    MemSelect,
    holdout_split,
)
from diagnosers.contract import require_varying
from diagnosers.detection import Decision, Detection
from diagnosers.episode import Episode
from diagnosers.ewma_stage import AlarmFilter, EWMAStage
from diagnosers.presets import keyword_init
from diagnosers.registry import register
from fcc_common.validation import Options, Real, check_params

__all__ = ["LRGFMEM", "PARAMETER_CONSTRAINTS", "AlarmFilter"]


#: declarative hyperparameter constraints of :class:`LRGFMEM`, checked in ``fit``
PARAMETER_CONSTRAINTS: dict[str, Any] = {
    **BANK_CONSTRAINTS,
    "band_definition": Options(BandScale),
    "alarm_filter": Options(AlarmFilter),
    "ewma_lambda": Real(0, 1, closed="right"),
    "false_alarm_target": Real(0, 0.5, closed="neither"),
    "threshold_margin": Real(0.5, 10),
    "limit_method": Options(LimitMethod),
}


@register("lrgf-mem")
class LRGFMEM(BankDetector):
    """Our LRGF + model-error-model detector: a bank of relations, band scale from held-out
    remaining error, EWMA persistence combined by Hotelling's T² (see the module docstring).

    Hyperparameters: the bank's (:mod:`diagnosers.bank_detector`) and the alarm stage's
    ``band_definition``, ``alarm_filter``, ``ewma_lambda``, ``false_alarm_target``,
    ``threshold_margin`` and ``limit_method`` (module docstring).
    """

    DEFAULTS: ClassVar[dict[str, Any]] = {
        **BANK_DEFAULTS,
        "band_definition": "residual",
        "alarm_filter": "ewma-t2",
        "ewma_lambda": 0.3,
        "false_alarm_target": 0.002,
        "threshold_margin": 1.0,
        "limit_method": "chi2-tail",
        **RUN_DEFAULTS,
    }
    __init__ = keyword_init(DEFAULTS)

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
        self.stage_ = self._new_stage().fit([r / self.v_residual_ for r in rem])
        self._finish()

    def _new_stage(self) -> EWMAStage:
        return EWMAStage(
            alarm_filter=self.alarm_filter,
            ewma_lambda=self.ewma_lambda,
            false_alarm_target=self.false_alarm_target,
            limit_method=self.limit_method,
            threshold_margin=self.threshold_margin,
        )

    def _finish(self) -> None:
        """Derived state shared by ``_fit`` and ``_set_state``."""
        self.v_ = (
            self.bank_.v_paper if self.band_definition == BandScale.PAPER else self.v_residual_
        )
        self.v_ = np.maximum(self.v_, 1e-9)
        half_band = two_sided_normal_quantile(self.band_alpha) * np.asarray(self.v_, np.float64)
        self.stage_.set_band(half_band)  # as band()
        self.signal_names_ = self.stage_.signal_names([o for o, _ in self._relations()])

    # ---- detection -----------------------------------------------------------------------------
    def _reset(self) -> None:
        self.bank_.reset()
        self.stage_.reset()
        self._k = 0

    def _update(self, y: np.ndarray) -> Decision:
        _, centre = self.bank_.step(y)
        y_out = y[self.bank_.out_idx]
        warm = self._k < self.steady_window
        self._k += 1
        # the EWMA starts after the warm-up: it sees zeros there, as in _detect
        e = np.zeros(len(centre)) if warm else (y_out - centre) / self.v_residual_
        return self.stage_.decide(y_out, centre, self.stage_.filter_step(e), warm)

    def _detect(self, y: np.ndarray) -> Detection:
        centre = self.bank_.centre(y)
        y_out = y[:, self.bank_.out_idx]
        w = self.steady_window
        e = (y_out - centre) / self.v_residual_
        e[:w] = 0.0  # the EWMA starts after the warm-up
        z = self.stage_.filter(e)
        return Detection.from_decisions(
            [self.stage_.decide(y_out[k], centre[k], z[k], k < w) for k in range(y.shape[0])],
            self.signal_names_,
        )

    def band_view(self, episode: Episode) -> Detection | None:
        """The bands (:meth:`BankDetector.band_view`); ``None`` with ``alarm_filter="none"``,
        where :meth:`detect` reports them already."""
        if self.alarm_filter == AlarmFilter.NONE:
            self._check_episode(episode)
            return None
        return super().band_view(episode)

    # ---- persistence ---------------------------------------------------------------------------
    def _get_state(self) -> dict[str, np.ndarray]:
        return {**self.bank_.get_state(), **self.stage_.get_state(), "v_residual": self.v_residual_}

    def _set_state(self, state: dict[str, np.ndarray]) -> None:
        self._set_bank_state(state)
        try:
            self.v_residual_ = state["v_residual"]
        except KeyError as e:
            raise ValueError(f"saved state lacks array {e.args[0]!r}") from None
        self.stage_ = self._new_stage()
        self.stage_.set_state(state)
        self._finish()
