"""``mmae``: isolation with probabilities, from a bank of state estimators (issue 42 item 5).

One :class:`~diagnosers.filters.FCCStateEstimator` per hypothesis (healthy, and each fault of
the labelled training episodes that the fault registry says scales plant parameters), run as
one compiled bank (:mod:`diagnosers.isolation.filter_bank`), and the multiple-model posterior
of their innovations: a probability per hypothesis and sample, in :attr:`Detection.posterior`.

**Tier: grey box.** The filters know the published model structure and use the spec's nominal
:class:`~fcc_env.FCCParams` (a prior), or the values given in ``params`` (e.g. fitted on
healthy training episodes); they read no parameter of the plant they watch. The fault filters
estimate the faulty parameter online, so no fault size is assumed, and nothing is learned from
fault data: the labelled training faults only name the classes.

**Decision** per sample: alarmed when the probability of a fault, ``1 − P(nominal)``, exceeds
``alarm_level``, or when no hypothesis explains the innovations: the smallest window NIS over
the hypotheses (each filter's normalised innovation squared summed over the last ``window``
samples, χ²(8 · window) while that filter's hypothesis is right) beyond its χ² limit at tail
``unknown_alpha`` for ``window`` samples in a row (a fault filter needs a while to find the
fault's size, and its innovations are large meanwhile: without the persistence a known
fault at the paper's size was "unknown" for its first 100-130 samples). An alarmed sample's diagnosis is ``"unknown"`` in the second case, else the
most probable fault.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
from scipy import stats

from diagnosers.contract import Tier
from diagnosers.detection import NO_DIAGNOSIS, UNKNOWN, Decision, Detection
from diagnosers.diagnoser import Diagnoser
from diagnosers.episode.record import Episode
from diagnosers.filters import UKFConfig
from diagnosers.filters.ukf_config import check_fcc_channels, model_params
from diagnosers.isolation.filter_bank import FilterBank, calibrate_walks, mmae_run
from diagnosers.presets import keyword_init
from diagnosers.registry import register
from fcc_common.validation import Integer, Real, check_params
from fcc_env.closed_loop import CLOSED_LOOP_CHANNELS
from fcc_env.faults import FAULTS
from fcc_env.params import FCCParams

__all__ = ["CALIBRATION_SAMPLES", "MMAE"]

#: samples of the healthy training episode the fault walks are calibrated on
CALIBRATION_SAMPLES = 1500


@register("mmae")
class MMAE(Diagnoser):
    """A bank of unscented Kalman filters, one per hypothesis, and their posterior (MMAE).

    Args:
        params: the model's parameters: ``None`` (default) the spec's nominal
            :class:`~fcc_env.FCCParams` (a grey-box prior), a dict of FCCParams fields to
            change from nominal (JSON, so the diagnoser saves), or an FCCParams (e.g. a fitted
            one; such an instance cannot be saved: pass ``dataclasses.asdict(p)``).
        noise_scale: the plant's measurement-noise multiplier the filters assume, in (0, 10];
            default 1.0 (the spec's noise; the ``noisy`` track's is 2).
        switch_prob: ε, the probability per sample that the plant switches hypothesis (the
            posterior's floor, about ε/H), in (0, 0.5); default 1e-5. Larger: a faster move to
            a fault, and a posterior that believes the healthy hypothesis less.
        tracking_rate: how fast a fault filter follows its fault's size, 1 / samples, in
            (0, 1]; default 0.01 (about 100 samples). Each fault's parameter walk is set from it
            in ``fit`` (:func:`~diagnosers.isolation.filter_bank.calibrate_walks`, on the first
            healthy training episode), so that every fault filter tracks as fast and pays as
            much for its freedom on healthy data. Larger: sooner, and a posterior that leans
            less on the healthy hypothesis.
        fault_leave_prob: the probability per sample that a fault hypothesis switches to each
            other hypothesis, nominal included, in [0, 0.5), or None for ``switch_prob / H``
            (every switch alike, a plain MMAE); default 1e-12. Why smaller than the switches
            out of nominal: an abrupt fault does not heal, and a few hundred samples after its
            onset the healthy filter's input walks (R_ar, T_fp) explain a small weir fault
            as well as the f2 filter does; with the plain term the posterior then forgot the
            evidence of the onset within some 600 samples (its odds were capped at about
            ``log(H / switch_prob)``) and f2 at 3 % went back to "not alarmed"
            (``lab/mmae-lab.md``). Larger: a posterior that follows a fault that ends.
        fault_initial_std: the fault parameters' prior std, relative, in (0, 1]; default 0.01.
        alarm_level: alarm when ``1 − P(nominal)`` exceeds it, in (0, 1); default 0.9.

    The defaults were chosen on validation seeds 5000-5009 of the ``small`` track
    (``lab/mmae-lab.md``).
        window: samples of the window NIS, in [10, 10000]; default 100.
        settle: samples after a ``reset`` during which the posterior holds its prior (the
            filters converge from the nominal steady state); at its end every fault filter
            restarts from the healthy filter's estimate
            (:meth:`~diagnosers.isolation.filter_bank.FilterBank.restart_faults`), in
            [0, 100000]; default 0 (no restart: a record that starts at the nominal steady
            state, as the tracks' do). For a plant run at other set points (the control study).
        unknown_alpha: tail of the window NIS's χ²(8 · window) limit, in (0, 0.5); default 1e-4.

    Attributes:
        classes_: the fault hypotheses (the labelled training faults the registry gives
            parameters for, registry order).
        hypotheses_: ``("nominal", *classes_)``, the columns of the posterior.
        walks_: each fault filter's parameter walk per sample, relative (from
            ``tracking_rate``).
    """

    isolates: ClassVar[bool] = True
    tier: ClassVar[Tier] = Tier.GREY_BOX
    #: its classes are the registry's faults, each modelled by its parameters: labels that are
    #: not registered faults (synthetic test data) mean nothing to it
    physical_classes: ClassVar[bool] = True
    CONSTRAINTS: ClassVar[dict[str, Any]] = {
        "noise_scale": Real(0, 10, closed="right"),
        "switch_prob": Real(0, 0.5, closed="neither"),
        "fault_leave_prob": (Real(0, 0.5, closed="left"), None),
        "tracking_rate": Real(0, 1, closed="right"),
        "fault_initial_std": Real(0, 1, closed="right"),
        "alarm_level": Real(0, 1, closed="neither"),
        "window": Integer(10, 10_000),
        "settle": Integer(0, 100_000),
        "unknown_alpha": Real(0, 0.5, closed="neither"),
    }
    DEFAULTS: ClassVar[dict[str, Any]] = {
        "params": None,
        "noise_scale": 1.0,
        "switch_prob": 1e-5,
        "fault_leave_prob": 1e-12,
        "tracking_rate": 0.01,
        "fault_initial_std": 0.01,
        "alarm_level": 0.9,
        "window": 100,
        "settle": 0,
        "unknown_alpha": 1e-4,
    }
    __init__ = keyword_init(DEFAULTS)

    params: FCCParams | dict[str, float] | None
    noise_scale: float
    switch_prob: float
    fault_leave_prob: float | None
    tracking_rate: float
    fault_initial_std: float
    alarm_level: float
    window: int
    settle: int
    unknown_alpha: float

    def _validate_params(self) -> None:
        check_params(
            {k: v for k, v in self.get_params().items() if k in self.CONSTRAINTS}, self.CONSTRAINTS
        )
        self.model_params()

    def leave_value(self) -> float:
        """The probability per sample that a fault switches to each other hypothesis
        (``fault_leave_prob``, or ``switch_prob / H`` like any other switch when it is None)."""
        if self.fault_leave_prob is not None:
            return float(self.fault_leave_prob)
        return self.switch_prob / len(self.hypotheses_)

    def model_params(self) -> FCCParams:
        """The :class:`~fcc_env.FCCParams` the filters use (``params`` resolved)."""
        return model_params(self.params)

    # ---- fitting -------------------------------------------------------------------------------
    def _fit(self, episodes: list[Episode]) -> None:
        labels = {ep.scenario for ep in episodes if ep.fault_onset is not None}
        self.classes_ = tuple(f for f in FAULTS if f in labels and FAULTS[f].parameters)
        if not self.classes_:
            raise ValueError(
                f"mmae needs labelled training faults that scale plant parameters (fcc_env.FAULTS "
                f"with parameters); the training faults are {sorted(labels)}"
            )
        healthy = max(
            (ep for ep in episodes if ep.fault_onset is None), key=lambda ep: ep.n_samples
        )
        self._check_channels()
        self.walks_ = calibrate_walks(
            self.model_params(),
            self._config(),
            self.classes_,
            healthy.y[:CALIBRATION_SAMPLES],
            rate=self.tracking_rate,
            initial_std_rel=self.fault_initial_std,
        )
        self._finish()

    def _check_channels(self) -> None:
        check_fcc_channels("mmae", self.channels_)

    def _config(self) -> UKFConfig:
        return UKFConfig(
            noise_scale=self.noise_scale,
            sample_time_s=self.sample_time_s_,
            closed_loop=self.channels_ == CLOSED_LOOP_CHANNELS,
        )

    def _finish(self) -> None:
        self._check_channels()
        self.bank_ = FilterBank.build(
            self.model_params(),
            self._config(),
            self.classes_,
            fault_walk_std_rel=self.walks_,
            fault_initial_std_rel=self.fault_initial_std,
        )
        self.hypotheses_ = self.bank_.hypotheses
        self.nis_limit_ = float(stats.chi2.isf(self.unknown_alpha, 8 * self.window))
        self.signal_names_ = ("P(fault)", f"persistent smallest NIS over {self.window} samples")

    # ---- detection -----------------------------------------------------------------------------
    def _reset(self) -> None:
        self._M, self._P = self.bank_.start()
        H = len(self.hypotheses_)
        eps = self.switch_prob
        self._p = np.full(H, eps / H)
        self._p[0] += 1.0 - eps  # the prior: healthy, but for the switching term
        self._ring = np.zeros((self.window, H))
        self._best = np.zeros(self.window)
        self._pos = 0
        self._seen = 0

    def _filter(self, Y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The bank on ``Y`` (T, channels) from its state, restarting the fault filters when
        ``settle`` samples have been seen (the same point whether streamed or in one call)."""
        cut = min(max(self.settle - self._seen, 0), Y.shape[0])
        if self.settle == 0 or self._seen >= self.settle:
            out = self.bank_.run(self._M, self._P, Y)
        else:
            first = self.bank_.run(self._M, self._P, Y[:cut])
            if self._seen + cut == self.settle:
                self.bank_.restart_faults(self._M, self._P)
            rest = self.bank_.run(self._M, self._P, Y[cut:])
            out = tuple(np.concatenate([a, b]) for a, b in zip(first, rest, strict=True))
        self._seen += Y.shape[0]
        return out[0], out[1]

    def _run(self, Y: np.ndarray) -> Detection:
        white, loglik = self._filter(Y)
        return self.decide(loglik, np.sum(white * white, axis=2), white[:, 0, :])

    def decide(self, loglik: np.ndarray, nis: np.ndarray, residual: np.ndarray) -> Detection:
        """The posterior and the decisions of the bank's next samples: ``loglik`` and ``nis``
        (T, H) each filter's innovation log-likelihood and NIS, ``residual`` (T, 8) the
        healthy filter's whitened innovations (what :meth:`detect` computes after the bank;
        lets a study score other decision settings on filter outputs it keeps)."""
        post, signal, upper, alarm, diagnosis = self._decide_arrays(loglik, nis)
        return Detection(
            alarm=alarm,
            signal=signal,
            lower=np.full(signal.shape, -np.inf),
            upper=upper,
            residual=residual,
            signal_names=self.signal_names_,
            diagnosis=diagnosis,
            class_scores=post[:, 1:],
            class_names=self.classes_,
            posterior=post,
            hypothesis_names=self.hypotheses_,
        )

    def _decide_arrays(self, loglik: np.ndarray, nis: np.ndarray) -> tuple[np.ndarray, ...]:
        """``(posterior, signal, upper, alarm, diagnosis)`` of the next samples."""
        T, H = loglik.shape
        post, win = np.empty((T, H)), np.empty(T)
        self._pos = mmae_run(
            loglik,
            nis,
            self._p,
            self._ring,
            self._best,
            self._pos,
            self.switch_prob,
            self.leave_value(),
            self.settle,
            post,
            win,
        )
        p_fault = 1.0 - post[:, 0]
        warm = np.isnan(win)
        signal = np.stack([p_fault, np.where(warm, 0.0, win)], axis=1)
        upper = np.tile([self.alarm_level, self.nis_limit_], (T, 1))
        upper[warm, 1] = np.inf
        unknown = signal[:, 1] > upper[:, 1]
        alarm = (p_fault > self.alarm_level) | unknown
        names = np.array(self.classes_)
        diagnosis = np.where(unknown, UNKNOWN, names[np.argmax(post[:, 1:], axis=1)])
        diagnosis = np.where(alarm, diagnosis, NO_DIAGNOSIS)
        return post, signal, upper, alarm, diagnosis

    def _update(self, y: np.ndarray) -> Decision:
        # one sample without a whole Detection around it: its checks cost as much as the
        # bank's Python side (bench.bank_speed); the same arrays as decide's
        white, loglik = self._filter(y[None, :])
        post, signal, upper, alarm, diagnosis = self._decide_arrays(
            loglik, np.sum(white * white, axis=2)
        )
        return Decision(
            alarm=bool(alarm[0]),
            signal=signal[0],
            lower=np.full(2, -np.inf),
            upper=upper[0],
            residual=white[0, 0, :],
            diagnosis=str(diagnosis[0]),
            class_scores=post[0, 1:],
            posterior=post[0],
        )

    def _detect(self, y: np.ndarray) -> Detection:
        return self._run(y)

    # ---- persistence ---------------------------------------------------------------------------
    def save(self, path: str | os.PathLike) -> Path:
        if isinstance(self.params, FCCParams):
            raise ValueError(
                "mmae with params=FCCParams(...) cannot be saved (its config is JSON): build it "
                "with params=dataclasses.asdict(p), which is the same model"
            )
        return super().save(path)

    def _get_state(self) -> dict[str, np.ndarray]:
        # the parameters too: a saved bank says what model it ran, and a load checks it
        return {
            "classes": np.array(self.classes_, dtype=str),
            "params": self.model_params().as_array(),
            "walks": np.array(self.walks_),
        }

    def _set_state(self, state: dict[str, np.ndarray]) -> None:
        classes = tuple(str(c) for c in state["classes"])
        unknown = [c for c in classes if c not in FAULTS or not FAULTS[c].parameters]
        if unknown:
            raise ValueError(f"saved classes {unknown} are not registered faults with parameters")
        if not np.array_equal(np.asarray(state["params"]), self.model_params().as_array()):
            raise ValueError("the saved parameters differ from those of the saved params")
        self.classes_ = classes
        self.walks_ = tuple(float(w) for w in np.asarray(state["walks"]).reshape(-1))
        if len(self.walks_) != len(classes) or not all(0 < w <= 0.1 for w in self.walks_):
            raise ValueError(f"walks {self.walks_} do not fit the classes {classes}")
        self._finish()
