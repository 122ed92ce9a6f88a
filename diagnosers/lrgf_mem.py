"""The paper's detector: LRGF nominal models + neural model-error models (NNARX) + bands.

For each monitored relation ``output = s(inputs)`` a locally recurrent globally feed-forward
network (:class:`diagnosers.lrgf.LRGF`) models the healthy process in simulation mode (it never
sees the measured output), and an NNARX model-error model (:class:`diagnosers.mem.NNARXErrorModel`,
also in simulation mode, driven by the same inputs) models what the nominal model misses. The
uncertainty band is (paper eqs 10–11)

    y_m + y_e ± t_α · v,   t_α two-sided standard normal quantile for 1 − α (2.576 at α = 0.01)

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
two excursions (see :meth:`_LRGFMEMBase._limit`).

Start-up (``steady_window`` W): the networks start at steady state for the mean of the first W
inputs (:class:`diagnosers.lrgf.InitialState`), and during those W samples the detector is silent
(no alarm; the EWMA starts at sample W; calibration skips them): there the model output is the
steady level still being estimated, not a prediction. W = 100 matches FCC-v0, whose inputs stay at
nominal for the first 100 samples. With W = 1 (the first sample alone) the noise of one air-flow
sample left a start-up error of 1.6 °C RMS on T_rg1 over the first 200 samples of every episode,
which set the alarm limits and the false alarms of earlier versions.

Two registered configurations:

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
(e.g. ``[5, 10, 5]`` for :data:`BANK_RELATIONS`): the slow, high-gain regenerator relation T_rg1
gains from a larger network more than the others do, and a per-relation size keeps the others'
training time. One size and that size repeated give the same networks. ``None`` takes the
diagnoser's sizes by output (``lrgf-glr``: 10 neurons for a relation whose output is T_rg1, 5
for the others), so it follows a user's own ``relations``.

``mem_select="if_better"`` (``lrgf-mem``) keeps a relation's error model only when it lowers the
RMS of the remaining error on the calibration episodes: an NNARX that does not generalise adds its
own error to the band centre (seen on this plant for several relations).

``val_fraction`` (default 0.25): the share at the end of every training episode that each LRGF
network holds out to choose its epoch (early stopping, :func:`diagnosers.training.fit_lrgf`).
``0`` trains on every sample for ``max_epochs`` and keeps the parameters of the lowest training
loss, at the same cost per epoch (the network runs over the whole episode either way).
``lrgf-mem``, ``lrgf-mem-paper`` and ``lrgf-glr`` keep 0.25, the setting they were validated
with; ``lrgf-glr-adaptive`` uses 0 (:mod:`diagnosers.lrgf_glr_adaptive` says why).

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

from enum import StrEnum
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from diagnosers.alarm import (
    EWMA,
    TAIL_FIT_QUANTILE,
    HotellingT2,
    LimitMethod,
    calibrate_limit,
)
from diagnosers.base import Decision, Detection, Diagnoser, Episode, require_varying
from diagnosers.lrgf_stepper import BankStepper
from diagnosers.mem import BandScale, MEMBankStepper, OutputActivation, band, t_alpha
from diagnosers.modules import load_bank, save_bank
from diagnosers.parallel import BankSettings, TrainedBank, train_banks
from diagnosers.registry import register
from diagnosers.relations import (
    BANK_RELATIONS,
    DILUTE_RELATIONS,
    PAPER_RELATIONS,
    parse_relations,
)
from diagnosers.training import Method
from fcc_env.validation import (
    Boolean,
    Integer,
    IntegerSequence,
    Options,
    Real,
    check,
    check_params,
    invalid,
)

__all__ = [
    "BANK_RELATIONS",
    "DILUTE_RELATIONS",
    "LRGFMEM",
    "MIN_CALIBRATION_SAMPLES",
    "PAPER_RELATIONS",
    "TAIL_FIT_QUANTILE",
    "AlarmFilter",
    "LRGFMEMPaper",
    "MemSelect",
]


class AlarmFilter(StrEnum):
    """Alarm logic after the band (see the module docstring)."""

    NONE = "none"
    EWMA = "ewma"
    EWMA_T2 = "ewma-t2"


class MemSelect(StrEnum):
    """Which relations keep their error model: all, or those where it lowers the held-out error."""

    ALWAYS = "always"
    IF_BETTER = "if_better"


ALARM_FILTERS = tuple(f.value for f in AlarmFilter)
LIMIT_METHODS = tuple(m.value for m in LimitMethod)
#: fewest healthy calibration samples (after the warm-up) that ``fit`` accepts
MIN_CALIBRATION_SAMPLES = 50

#: declarative hyperparameter constraints of :class:`_LRGFMEMBase`, checked in ``fit``
PARAMETER_CONSTRAINTS: dict[str, Any] = {
    "n_hidden": (Integer(1, 64), IntegerSequence(1, 64, unique=False), None),
    "order": Integer(1, 8),
    "n_linear": Integer(0, 64),
    "steady_window": Integer(1, 100_000),
    "mem_hidden": Integer(1, 256),
    "mem_input_delays": Integer(1, 100),
    "mem_output_delays": Integer(1, 100),
    "mem_output_activation": Options(OutputActivation),
    "alpha": Real(0, 0.5, closed="neither"),
    "band_definition": Options(BandScale),
    "alarm_filter": Options(AlarmFilter),
    "ewma_lambda": Real(0, 1, closed="right"),
    "false_alarm_target": Real(0, 0.5, closed="neither"),
    "threshold_margin": Real(0.5, 10),
    "limit_method": Options(LimitMethod),
    "method": Options(Method),
    "lr": Real(0, 1, closed="right"),
    "max_epochs": Integer(1, 100_000),
    "val_fraction": Real(0, 1, closed="left"),
    "mem_max_epochs": Integer(1, 100_000),
    "mem_select": Options(MemSelect),
    "seed": Integer(0),
    "progress": (Boolean(), None),
    "n_jobs": (Integer(1), None),
}


class _LRGFMEMBase(Diagnoser):
    """Shared implementation; the registered subclasses only change defaults."""

    #: relations used when ``relations`` is None
    DEFAULT_RELATIONS: list[list[Any]] = PAPER_RELATIONS
    #: network sizes when ``n_hidden`` is None: by the relation's output, else the default
    HIDDEN_BY_OUTPUT: ClassVar[dict[str, int]] = {}
    DEFAULT_HIDDEN: ClassVar[int] = 5
    execution_params = ("progress", "n_jobs")

    def __init__(
        self,
        *,
        relations: list[list[Any]] | None = None,
        n_hidden: int | list[int] | None = 3,
        order: int = 2,
        n_linear: int = 0,
        steady_window: int = 100,
        mem_hidden: int = 5,
        mem_input_delays: int = 15,
        mem_output_delays: int = 15,
        mem_output_activation: str = "tanh",
        alpha: float = 0.01,
        band_definition: str = "paper",
        alarm_filter: str = "none",
        ewma_lambda: float = 0.05,
        false_alarm_target: float = 0.005,
        threshold_margin: float = 1.2,
        limit_method: str = "empirical",
        method: str = "adam",
        lr: float = 0.01,
        max_epochs: int = 3000,
        val_fraction: float = 0.25,
        mem_max_epochs: int = 200,
        mem_select: str = "always",
        seed: int = 0,
        progress: bool | None = None,
        n_jobs: int | None = None,
    ) -> None:
        self.relations = relations
        self.n_hidden = n_hidden
        self.order = order
        self.n_linear = n_linear
        self.steady_window = steady_window
        self.mem_hidden = mem_hidden
        self.mem_input_delays = mem_input_delays
        self.mem_output_delays = mem_output_delays
        self.mem_output_activation = mem_output_activation
        self.alpha = alpha
        self.band_definition = band_definition
        self.alarm_filter = alarm_filter
        self.ewma_lambda = ewma_lambda
        self.false_alarm_target = false_alarm_target
        self.threshold_margin = threshold_margin
        self.limit_method = limit_method
        self.method = method
        self.lr = lr
        self.max_epochs = max_epochs
        self.val_fraction = val_fraction
        self.mem_max_epochs = mem_max_epochs
        self.mem_select = mem_select
        self.seed = seed
        self.progress = progress
        self.n_jobs = n_jobs

    @classmethod
    def fast_params(cls) -> dict[str, Any]:
        """Small, fast settings for smoke runs, quick sweeps and tests."""
        return {
            "max_epochs": 30,
            "mem_max_epochs": 5,
            "mem_input_delays": 3,
            "mem_output_delays": 3,
        }

    # ---- validation ----------------------------------------------------------------------------
    def _relations(self) -> list[tuple[str, tuple[str, ...]]]:
        rel = type(self).DEFAULT_RELATIONS if self.relations is None else self.relations
        return parse_relations(rel)

    def _hidden_sizes(self) -> tuple[int, ...]:
        """Neurons of each relation's network: ``n_hidden`` for every relation, one per relation
        when it is a sequence (a slow, high-gain relation such as T_rg1 can take a larger network
        than the others without making them slower to train), or, when it is None, the class's
        size for the relation's output (:attr:`HIDDEN_BY_OUTPUT`, else :attr:`DEFAULT_HIDDEN`)."""
        relations = self._relations()
        k = len(relations)
        sizes = check("n_hidden", self.n_hidden, *PARAMETER_CONSTRAINTS["n_hidden"])
        if sizes is None:
            return tuple(
                self.HIDDEN_BY_OUTPUT.get(out, self.DEFAULT_HIDDEN) for out, _ in relations
            )
        if isinstance(sizes, int):
            return (sizes,) * k
        if len(sizes) != k:
            raise invalid(
                "n_hidden",
                self.n_hidden,
                f"an integer in [1, 64] or {k} of them, one per relation",
                f"there are {k} relations",
            )
        return sizes

    def _validate_params(self) -> None:
        check_params(self.get_params(), PARAMETER_CONSTRAINTS)
        self._check_sizes()

    def _check_sizes(self) -> None:
        """The networks' sizes (and the relations) and ``n_linear`` against the smallest."""
        sizes = self._hidden_sizes()
        if self.n_linear > min(sizes):
            raise invalid(
                "n_linear",
                self.n_linear,
                f"an integer from 0 to the smallest network's size ({min(sizes)})",
                f"the networks have {list(sizes)} neurons",
            )

    # ---- fitting -------------------------------------------------------------------------------
    def _split(self, episodes: list[Episode]) -> tuple[list[np.ndarray], list[np.ndarray], int]:
        """(training records, calibration records, first calibration sample of each record)."""
        n = len(episodes)
        if n == 1:
            y = episodes[0].y
            cut = int(0.7 * y.shape[0])
            return [y[:cut]], [y], cut
        n_cal = max(1, n // 3)
        return [e.y for e in episodes[: n - n_cal]], [e.y for e in episodes[n - n_cal :]], 0

    def _fit(self, episodes: list[Episode]) -> None:
        self._bank = None  # steppers are rebuilt from the new networks at the next reset
        relations = self._relations()
        idx = {c: i for i, c in enumerate(self.channels_)}
        for out, ins in relations:
            for c in (out, *ins):
                if c not in idx:
                    raise ValueError(
                        f"relation channel {c!r} is not in the episodes' channels {list(idx)}"
                    )
        outputs = sorted({idx[o] for o, _ in relations})  # a flat output: no band to calibrate
        require_varying(
            np.concatenate([e.y[:, outputs] for e in episodes]),
            [self.channels_[i] for i in outputs],
            self.name or type(self).__name__,
        )
        train, cal, cal_from = self._split(episodes)
        self.in_idx_ = [np.array([idx[c] for c in ins]) for _, ins in relations]
        self.out_idx_ = np.array([idx[o] for o, _ in relations])
        self.lrgf_, self.mem_, v_paper, fits = self._train_models(train)
        self.v_paper_ = np.array(v_paper)
        self.train_fit_loss_ = np.array([f.best_val_loss for f in fits])
        # held-out healthy calibration
        self.use_mem_ = np.ones(len(relations), dtype=bool)
        # the warm-up samples are not calibrated on: the detector is silent there
        cal_from = max(cal_from, self.steady_window)
        n_cal = sum(max(0, y.shape[0] - cal_from) for y in cal)
        if n_cal < MIN_CALIBRATION_SAMPLES:
            raise ValueError(
                f"{n_cal} calibration samples after the warm-up (steady_window="
                f"{self.steady_window}); at least {MIN_CALIBRATION_SAMPLES} are needed: pass longer "
                "or more episodes, or a smaller steady_window"
            )
        rem = [self._remaining(y)[cal_from:] for y in cal]  # (T, k) each
        if self.mem_select == MemSelect.IF_BETTER:
            # An error model that does not reduce the held-out error only adds its own: drop it.
            self.use_mem_[:] = False
            rem_off = np.concatenate([self._remaining(y)[cal_from:] for y in cal])
            rms_on = np.sqrt(np.mean(np.concatenate(rem) ** 2, axis=0))
            rms_off = np.sqrt(np.mean(rem_off**2, axis=0))
            self.use_mem_ = rms_on < rms_off
            rem = [self._remaining(y)[cal_from:] for y in cal]
        rem_all = np.concatenate(rem)
        self.v_residual_ = np.sqrt(np.mean(rem_all**2, axis=0))
        ewma = EWMA(self.ewma_lambda)
        stats = np.concatenate([ewma.filter(r / self.v_residual_) for r in rem])
        if AlarmFilter(self.alarm_filter) is AlarmFilter.EWMA_T2:
            # The EWMA of a healthy normalised error is zero-mean by construction: T² about 0.
            t2 = HotellingT2(centered=False).fit(stats)
            self.s_inv_ = t2.precision_
            self.h_ = np.array([self._limit(t2.score(stats)[:, None], len(relations))[0]])
        else:
            self.s_inv_ = np.eye(len(relations))
            self.h_ = self._limit(np.abs(stats), 0)
        self._finish()

    def _train_models(self, train: list[np.ndarray]) -> TrainedBank:
        """Train every relation's nominal and error model on the records ``train``.

        Returns a :class:`diagnosers.parallel.TrainedBank`: (LRGF networks, error models, std of
        each y_e on ``train`` (the paper's v), each network's
        :class:`diagnosers.training.FitResult`). Needs ``in_idx_``/``out_idx_``.
        """
        return self._train_banks([train])[0]

    def _train_banks(
        self,
        sets: list[list[np.ndarray]],
        init: list[TrainedBank | None] | None = None,
        max_epochs: int | None = None,
    ) -> list[TrainedBank]:
        """:meth:`_train_models` on each training set of ``sets``, all relations and sets sharing
        the ``n_jobs`` processes (:func:`diagnosers.parallel.train_banks`); ``init`` warm-starts
        the networks of a set from a trained bank, ``max_epochs`` replaces the hyperparameter."""
        params = self.get_params()
        if max_epochs is not None:
            params["max_epochs"] = max_epochs
        settings = [
            BankSettings.from_params({**params, "n_hidden": h}) for h in self._hidden_sizes()
        ]
        n_jobs = 1 if self.n_jobs is None else self.n_jobs
        return train_banks(
            settings, sets, self.in_idx_, self.out_idx_, self.seed, n_jobs, init=init
        )

    def _finish(self) -> None:
        """Derived state shared by ``_fit`` and ``_set_state``."""
        self.v_ = self.v_paper_ if self.band_definition == BandScale.PAPER else self.v_residual_
        self.v_ = np.maximum(self.v_, 1e-9)
        self.t_alpha_ = t_alpha(self.alpha)
        self.t2_ = HotellingT2(centered=False)
        self.t2_.set_state({"mean": np.zeros(len(self.s_inv_)), "precision": self.s_inv_})
        self.signal_names_ = self._signal_names()
        # the per-sample constants of _decide
        self._half_band = self.t_alpha_ * np.asarray(self.v_, dtype=np.float64)  # as band()
        ewma = self.alarm_filter == AlarmFilter.EWMA
        self._limit_lower = -self.h_ if ewma else np.array([-np.inf])
        k = len(self.signal_names_)
        self._warm_lower, self._warm_upper = np.full(k, -np.inf), np.full(k, np.inf)

    def _limit(self, stat: np.ndarray, dof: int) -> np.ndarray:
        """Alarm limit per column of the healthy calibration statistic ``stat`` (T, c).

        ``dof = 0``: columns are |EWMA| of one relation each, with the target split over them
        (``false_alarm_target / c`` each); ``dof = k``: one column of Hotelling's T² over k
        relations. The method and its reasons: :func:`diagnosers.alarm.calibrate_limit`.
        """
        target = self.false_alarm_target / (stat.shape[1] if dof == 0 else 1)
        return calibrate_limit(
            stat, target, method=self.limit_method, dof=dof, margin=self.threshold_margin
        )

    def _signal_names(self) -> tuple[str, ...]:
        rel = self._relations()
        if self.alarm_filter == AlarmFilter.EWMA:
            return tuple(f"ewma[{o}]" for o, _ in rel)
        if self.alarm_filter == AlarmFilter.EWMA_T2:
            return ("T2[ewma]",)
        return tuple(o for o, _ in rel)

    def _centre(self, y: np.ndarray) -> np.ndarray:
        """y_m + y_e for every relation over a whole record: (T, k)."""
        return self._outputs_and_centre(y)[1]

    def _outputs_and_centre(self, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The networks' outputs y_m and y_m + y_e for every relation over a record: (T, k).
        The one place a record's centre is computed: a subclass with another model overrides
        this (``_centre`` reads it)."""
        ym, cols = [], []
        for j in range(len(self.lrgf_)):
            u = y[:, self.in_idx_[j]]
            y_m = self.lrgf_[j].predict(u)[:, 0]
            ym.append(y_m)
            cols.append(y_m + self.mem_[j].predict(u)[:, 0] if self.use_mem_[j] else y_m)
        return np.column_stack(ym), np.column_stack(cols)

    def _remaining(self, y: np.ndarray) -> np.ndarray:
        return y[:, self.out_idx_] - self._centre(y)

    # ---- detection -----------------------------------------------------------------------------
    def _reset(self) -> None:
        if getattr(self, "_bank", None) is None:
            self._bank = BankStepper(self.lrgf_, self.in_idx_, len(self.channels_))
            self._mem_used = None
        used = np.flatnonzero(self.use_mem_)
        if self._mem_used is None or not np.array_equal(used, self._mem_used):
            # only the error models in use are stepped, all of them in one stacked pass
            self._mem_used = used
            self._mem_bank = MEMBankStepper(
                [self.mem_[j] for j in used], [self.in_idx_[j] for j in used]
            )
        self._bank.reset()
        self._mem_bank.reset()
        self._ewma = EWMA(self.ewma_lambda)
        self._k = 0

    def _step_centre(self, y: np.ndarray) -> np.ndarray:
        """y_m + y_e of every relation for one measurement ``y``: :meth:`_centre`, streaming."""
        self._step_y_m = self._bank.step(y)  # the networks' outputs alone (lrgf-glr's novelty)
        if not len(self._mem_used):
            return self._step_y_m
        centre = self._step_y_m.copy()
        centre[self._mem_used] += self._mem_bank.step(y)
        return centre

    def _decide(self, y_out: np.ndarray, centre: np.ndarray, z: np.ndarray, warm: bool) -> Decision:
        # called for every sample by _update and _detect alike: the limits come precomputed
        # from _finish, and the arrays the decisions share are never written to
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

    def _update(self, y: np.ndarray) -> Decision:
        centre = self._step_centre(y)
        y_out = y[self.out_idx_]
        warm = self._k < self.steady_window
        self._k += 1
        # the EWMA starts after the warm-up: it sees zeros there, as in _detect
        e = np.zeros(len(centre)) if warm else (y_out - centre) / self.v_residual_
        return self._decide(y_out, centre, self._ewma.update(e), warm)

    def _detect(self, y: np.ndarray) -> Detection:
        centre = self._centre(y)
        y_out = y[:, self.out_idx_]
        w = self.steady_window
        e = (y_out - centre) / self.v_residual_
        e[:w] = 0.0  # the EWMA starts after the warm-up
        z = EWMA(self.ewma_lambda).filter(e)
        return Detection.from_decisions(
            [self._decide(y_out[k], centre[k], z[k], k < w) for k in range(y.shape[0])],
            self.signal_names_,
        )

    def band_view(self, episode: Episode) -> Detection | None:
        """Each relation's measured output with its band y_m + y_e ± t_α·v (eqs 10–11).

        With ``alarm_filter="none"`` that is what :meth:`detect` reports already (``None``).
        Otherwise the same models seen the paper's way: ``alarm`` marks samples where an output
        leaves its band (after the warm-up); the detector's own alarms come from :meth:`detect`.
        """
        self._check_episode(episode)
        if self.alarm_filter == AlarmFilter.NONE:
            return None
        y_out = episode.y[:, self.out_idx_]
        centre = self._centre(episode.y)
        lower, upper = band(centre, 0.0, self.v_, self.alpha)
        lower[: self.steady_window], upper[: self.steady_window] = -np.inf, np.inf  # warm-up
        alarm = np.any((y_out < lower) | (y_out > upper), axis=1)
        names = tuple(f"{o} [°C]" for o, _ in self._relations())
        return Detection(alarm, y_out, lower, upper, y_out - centre, names)

    # ---- persistence ---------------------------------------------------------------------------
    def _get_state(self) -> dict[str, np.ndarray]:
        return {
            "out_idx": self.out_idx_,
            "in_idx": np.concatenate(self.in_idx_),
            "in_len": np.array([len(i) for i in self.in_idx_]),
            "v_paper": self.v_paper_,
            "v_residual": self.v_residual_,
            "h": self.h_,
            "use_mem": self.use_mem_.astype(np.int8),
            "s_inv": self.s_inv_,
            "train_fit_loss": self.train_fit_loss_,
        }

    def _set_state(self, state: dict[str, np.ndarray]) -> None:
        try:
            self.out_idx_ = state["out_idx"].astype(int)
            splits = np.cumsum(state["in_len"])[:-1]
            self.in_idx_ = [a.astype(int) for a in np.split(state["in_idx"], splits)]
            self.v_paper_ = state["v_paper"]
            self.v_residual_ = state["v_residual"]
            self.h_ = state["h"]
            self.use_mem_ = state["use_mem"].astype(bool)
            self.s_inv_ = state["s_inv"]
            self.train_fit_loss_ = state["train_fit_loss"]
        except KeyError as e:
            raise ValueError(f"saved state lacks array {e.args[0]!r}") from None
        relations = self._relations()
        if [len(i) for i in self.in_idx_] != [len(ins) for _, ins in relations]:
            raise ValueError(
                f"the state holds relations with {[len(i) for i in self.in_idx_]} inputs, the "
                f"settings of {self.name!r} {[len(ins) for _, ins in relations]}"
            )
        self._finish()

    def _save_extra(self, directory: Path) -> None:
        save_bank(
            directory, [{"lrgf": n, "mem": m} for n, m in zip(self.lrgf_, self.mem_, strict=True)]
        )

    def _load_extra(self, directory: Path) -> None:
        bank = load_bank(directory)
        try:
            self.lrgf_ = [parts["lrgf"] for parts in bank]
            self.mem_ = [parts["mem"] for parts in bank]
        except KeyError as e:
            raise ValueError(
                f"{directory / 'models.json'} lacks the {e.args[0]!r} part of a relation"
            ) from None
        # a model saved before ``n_linear`` existed has tanh neurons only, whatever the class's
        # default is now: the hyperparameter follows the networks that were loaded
        self.n_linear = min((int(net.n_linear) for net in self.lrgf_), default=0)
        self._bank = None


@register("lrgf-mem-paper")
class LRGFMEMPaper(_LRGFMEMBase):
    """The paper's detector, its configuration and definitions (see the module docstring)."""


@register("lrgf-mem")
class LRGFMEM(_LRGFMEMBase):
    """Our best LRGF + model-error-model detector: a bank of relations with persistence."""

    DEFAULT_RELATIONS = BANK_RELATIONS

    def __init__(
        self,
        *,
        relations: list[list[Any]] | None = None,
        n_hidden: int | list[int] = 5,
        order: int = 2,
        n_linear: int = 0,
        steady_window: int = 100,
        mem_hidden: int = 5,
        mem_input_delays: int = 15,
        mem_output_delays: int = 15,
        mem_output_activation: str = "linear",
        alpha: float = 0.01,
        band_definition: str = "residual",
        alarm_filter: str = "ewma-t2",
        ewma_lambda: float = 0.3,
        false_alarm_target: float = 0.002,
        threshold_margin: float = 1.0,
        limit_method: str = "chi2-tail",
        method: str = "adam",
        lr: float = 0.03,
        max_epochs: int = 3000,
        val_fraction: float = 0.25,
        mem_max_epochs: int = 200,
        mem_select: str = "if_better",
        seed: int = 0,
        progress: bool | None = None,
        n_jobs: int | None = None,
    ) -> None:
        super().__init__(
            relations=relations,
            n_hidden=n_hidden,
            order=order,
            n_linear=n_linear,
            steady_window=steady_window,
            mem_hidden=mem_hidden,
            mem_input_delays=mem_input_delays,
            mem_output_delays=mem_output_delays,
            mem_output_activation=mem_output_activation,
            alpha=alpha,
            band_definition=band_definition,
            alarm_filter=alarm_filter,
            ewma_lambda=ewma_lambda,
            false_alarm_target=false_alarm_target,
            threshold_margin=threshold_margin,
            limit_method=limit_method,
            method=method,
            lr=lr,
            max_epochs=max_epochs,
            val_fraction=val_fraction,
            mem_max_epochs=mem_max_epochs,
            mem_select=mem_select,
            seed=seed,
            progress=progress,
            n_jobs=n_jobs,
        )
