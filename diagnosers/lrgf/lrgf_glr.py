"""``lrgf-glr``: the ``lrgf-mem`` bank with a cross-fitted limit and tests along fault directions.

:class:`LRGFGLR` keeps ``lrgf-mem``'s models (a bank of LRGF relations, error models kept where
they help, the band scale from held-out remaining error) and changes two things:

* **where the limits are calibrated**: cross-fitted, on the out-of-fold remaining errors of
  every healthy episode, instead of on the last third of them, so a limit rests on every
  episode and the detector's models see every episode too;
* **how the remaining error is evaluated**: a fault moves the normalised remaining errors of
  the relations in its own direction (f2 and f4 pull T_rx down and T_rg2 up; f3 cools the
  regenerator), learned in ``fit`` from the labelled training faults passed with the healthy
  episodes (:attr:`LRGFGLR.learns_from_faults`); the alarm stage
  (:class:`diagnosers.stages.directional_stage.DirectionalStage`) tests along each direction on a
  fast and a slow EWMA scale, beside an omnibus Hotelling T² for faults outside them.

Optional parts, built from hyperparameters: a held baseline (:mod:`diagnosers.stages.baseline`, the
``lrgf-glr-adaptive`` preset of :mod:`diagnosers.lrgf.lrgf_presets`) and a novelty scale
(:mod:`diagnosers.lrgf.novelty`). Every hyperparameter is documented on :class:`LRGFGLR` and
:class:`~diagnosers.lrgf.bank_detector.BankDetector`; defaults :data:`GLR_DEFAULTS`, constraints
:data:`GLR_CONSTRAINTS`.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, ClassVar

import numpy as np

from diagnosers.bank.parallel import TrainedBank
from diagnosers.bank.relation_bank import RelationBank
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
from diagnosers.lrgf.fault_directions import (
    DEFAULT_FAULT_SEEDS,
    FaultDirections,
    Pairs,
    paired_difference,
)
from diagnosers.lrgf.novelty import (
    NoveltyScale,
    PredictionRange,
    exogenous_relations,
    novelty_scale,
)
from diagnosers.presets import keyword_init
from diagnosers.registry import register
from diagnosers.stages.baseline import HeldBaseline
from diagnosers.stages.directional_stage import DirectionalStage
from fcc_common.validation import Integer, Options, Real, RealSequence, check_params

__all__ = ["GLR_CONSTRAINTS", "GLR_DEFAULTS", "LRGFGLR", "Calibration", "cross_fit_models"]

from enum import StrEnum


class Calibration(StrEnum):
    """Where the limits are calibrated (``LRGFGLR``'s ``calibration``)."""

    CROSS_FIT = "cross-fit"
    HOLDOUT = "holdout"


#: declarative constraints of :class:`LRGFGLR`'s own hyperparameters, checked in ``fit`` (the
#: alarm stage's are :class:`~diagnosers.stages.directional_stage.DirectionalStage`'s own)
GLR_CONSTRAINTS: dict[str, Any] = {
    **DirectionalStage.CONSTRAINTS,
    "calibration": Options(Calibration),
    "n_folds": Integer(2, 20),
    "refit_epochs": (Integer(1, 100_000), None),
    "direction_window": Integer(1, 2000),
    "baseline_lambda": Real(0, 1, closed="left"),
    "baseline_hold": Real(0, 1, closed="right"),
    "baseline_settle": Integer(0, 100_000),
    "baseline_filters": (RealSequence(1, 1e6), None),
    "baseline_ridge": Real(0, closed="neither"),
    "novelty_gain": Real(0),
}


#: :class:`LRGFGLR`'s hyperparameters and their defaults, in signature order
GLR_DEFAULTS: dict[str, Any] = {
    **BANK_DEFAULTS,
    "n_hidden": None,
    **DirectionalStage.DEFAULTS,  # the alarm stage's hyperparameters
    # where the limits are calibrated
    "calibration": "cross-fit",
    "n_folds": 3,
    "refit_epochs": None,
    # the optional parts
    "fault_scenarios": None,
    "fault_seeds": list(DEFAULT_FAULT_SEEDS),
    "direction_window": 300,
    "baseline_lambda": 0.0,
    "baseline_hold": 0.5,
    "baseline_settle": 200,
    "baseline_filters": None,
    "baseline_ridge": 1.0,
    "novelty_gain": 5.0,
    **RUN_DEFAULTS,
    "progress": False,
}


def cross_fit_models(
    det: LRGFGLR, ys: list[np.ndarray]
) -> tuple[list[tuple[np.ndarray, np.ndarray]], list[np.ndarray], TrainedBank]:
    """``det``'s out-of-fold ``(y_out − y_m, y_e)`` of every record of ``ys`` and their novelty
    against the fold bank's own training range, and the bank trained on all.

    With ``refit_epochs=None`` the ``n_folds`` banks without a fold and the bank on all
    records are trained from scratch in one call, so that ``n_jobs`` processes share all of
    their (relation, training set) jobs. Otherwise the fold banks train first, and the bank
    on all records starts from the first fold's networks for ``refit_epochs`` epochs (at
    most ``max_epochs``): it only has to take in one more fold, and the out-of-fold
    residuals stay out of fold (the warm start flows from a fold bank into the final bank,
    never back).
    """
    folds = np.array_split(np.arange(len(ys)), det.n_folds)
    sets = [[ys[i] for i in range(len(ys)) if i not in set(f.tolist())] for f in folds]
    if det.refit_epochs is None:
        *fold_banks, final = det._train_banks([*sets, ys])
    else:
        fold_banks = det._train_banks(sets)
        final = det._train_banks(
            [ys], init=[fold_banks[0]], max_epochs=min(det.refit_epochs, det.max_epochs)
        )[0]
    cal_parts, distances = [], []
    for fold, train, trained in zip(folds, sets, fold_banks, strict=True):
        bank = RelationBank(det._relations(), det.channels_)
        bank.set_models(trained)
        cal_parts += [bank.parts(ys[i]) for i in fold]
        distances += det.novelty_.distances(bank, train, [ys[i] for i in fold])
    return cal_parts, distances, final


@register("lrgf-glr")
class LRGFGLR(BankDetector):
    """A bank of LRGF relations, a cross-fitted limit and tests along learned fault directions.

    For the earliest detection on a plant like the training plants (it leads most tracks);
    ``lrgf-glr-adaptive`` is its preset for a plant that may differ from them. The bank's
    hyperparameters, ranges and units on :class:`~diagnosers.lrgf.bank_detector.BankDetector`
    (``n_hidden=None``, ``progress=False`` here), are ``relations``, ``order``, ``n_linear``,
    ``steady_window``, ``mem_hidden``, ``mem_input_delays``, ``mem_output_delays``,
    ``mem_output_activation``, ``mem_max_epochs``, ``mem_select``, ``method``, ``lr``,
    ``max_epochs``, ``val_fraction``, ``band_alpha``, ``seed``, ``n_jobs``. The alarm stage
    (:class:`~diagnosers.stages.directional_stage.DirectionalStage`, ``stage_``) owns
    ``false_alarm_target``; the optional parts are the fault directions
    (:class:`~diagnosers.lrgf.fault_directions.FaultDirections`), the held baseline
    (:class:`~diagnosers.stages.baseline.HeldBaseline`) and the novelty scale
    (:class:`~diagnosers.lrgf.novelty.NoveltyScale`). ``signal`` is ``[T², score_f1, ...]``,
    ``upper`` their limits; an alarm when any is over its limit after the silent warm-up.

    Args:
        false_alarm_target: declared share of healthy samples in alarm, in (0, 0.5); default
            0.025. Split over the statistics by a union bound (realised rate ≤ target).
        statistic: the directional test: ``"directional"`` (default; the EWMA vector ``z``
            projected on each direction d, score ``dᵀS⁻¹z / sqrt(dᵀS⁻¹d)``, a 1-dof test),
            ``"glr"`` or ``"cusum"`` (on the projections of the normalised error), ``"t2"``
            (the omnibus T² alone, ``lrgf-mem``'s stage).
        ewma_lambda: weight of the fast EWMA ``z``, in (0, 1]; default 0.3.
        slow_ewma_lambda: weight of a slow EWMA scale beside ``z`` (``"directional"`` only),
            in which a small or slow fault builds up; in [0, 1) (0: none) or a list of
            weights, one scale each; default 0.02.
        slow_share: the slow scales' share of the directional target, in (0, 1); default 0.5.
        omnibus_share: the omnibus T²'s share of the target (it keeps faults outside the
            learned directions detectable), in (0, 1]; default 0.2. The directions share the rest.
        glr_window: the GLR's onset search window [samples], in [1, 5000]; default 200.
        cusum_drift: the CUSUM's drift [normalised error], ≥ 0; default 0.5.
        limit_method: the T² limit, ``"chi2-tail"`` (default) or ``"empirical"`` (as
            ``lrgf-mem``); directional scores use a normal tail, GLR and CUSUM the empirical one.
        threshold_margin: factor on every limit, in [0.5, 10]; default 1.0.
        on_delay: samples in a row over a limit before an alarm (ISA-18.2's on-delay), in
            [1, 1000]; default 1. Removes shorter exceedances; delays each alarm by it − 1.
        calibration: ``"cross-fit"`` (default): the healthy episodes in ``n_folds`` folds, a
            bank trained without each, every limit, scale and error-model choice taken from
            the out-of-fold errors, the detector's models then trained on all; ``"holdout"``:
            ``lrgf-mem``'s split (also used with fewer episodes than folds).
        n_folds: cross-fit folds, in [2, 20]; default 3. Each trains one more bank.
        refit_epochs: ``None`` (default): the final bank trains from scratch; an integer in
            [1, 100000]: it starts from the first fold's networks for that many epochs
            (faster, more false alarms on validation seeds).
        fault_scenarios: the labelled faults passed to ``fit`` that give directions (each
            paired with the healthy episode of its seed, :mod:`diagnosers.lrgf.fault_directions`;
            none passed: the omnibus T² alone); default ``None``: every one passed.
        fault_seeds: the seeds whose faulty episodes give them; ``None``: every seed passed;
            default 1000-1002 (the tracks' first three training seeds).
        direction_window: samples after the onset averaged, in [1, 2000]; default 300.
        baseline_lambda: gain of a held baseline of each relation's normalised error,
            subtracted before the EWMAs: it learns a unit's own offset from the model and
            loses small, slow faults under the hold level; in [0, 1), default 0 (off).
        baseline_hold: the baseline learns after settling only while every statistic is
            below ``baseline_hold`` × its limit, in (0, 1]; default 0.5.
        baseline_settle: samples after the warm-up it always learns, in [0, 100000]; default 200.
        baseline_filters: ``None`` (default): a running mean; time constants [samples, ≥ 1]:
            a ridge regression on low-pass filters of each relation's inputs and output, which
            learns another plant's gains too. Needs ``baseline_lambda > 0``.
        baseline_ridge: the regression's ridge ρ > 0; default 1.0.
        novelty_gain: where T_rg1's prediction (exogenous inputs only) leaves its training
            range by ``d`` standard deviations, every normalised error is divided by
            ``1 + novelty_gain·d`` (the networks extrapolate there); ≥ 0, default 5, 0 off.
    """

    DEFAULTS: ClassVar[dict[str, Any]] = GLR_DEFAULTS
    __init__ = keyword_init(DEFAULTS)
    STAGE = DirectionalStage
    stage_: DirectionalStage
    learns_from_faults: ClassVar[bool] = True

    false_alarm_target: float
    statistic: str
    calibration: str
    n_folds: int
    refit_epochs: int | None
    fault_scenarios: list[str] | None
    fault_seeds: list[int] | None
    direction_window: int
    baseline_lambda: float
    baseline_filters: list[float] | None
    novelty_gain: float
    mem_select: str

    @classmethod
    def fast_params(cls) -> dict[str, Any]:
        return {**super().fast_params(), "n_folds": 2, "fault_seeds": [1000]}

    def _validate_params(self) -> None:
        params = self.get_params()
        check_params({k: params[k] for k in BANK_CONSTRAINTS}, BANK_CONSTRAINTS)
        check_params({k: params[k] for k in GLR_CONSTRAINTS}, GLR_CONSTRAINTS)
        self._check_sizes()  # checks the relations and n_linear too
        if self.baseline_filters is not None and self.baseline_lambda == 0:
            raise ValueError(
                f"baseline_filters={self.baseline_filters} needs a baseline: baseline_lambda "
                "must be in (0, 1), got 0"
            )
        self._fault_directions().check()

    # ---- the parts -----------------------------------------------------------------------------
    def _fault_directions(self) -> FaultDirections:
        return FaultDirections(self.fault_scenarios, self.fault_seeds, self.direction_window)

    def _new_stage(self) -> DirectionalStage:
        """The alarm stage of the hyperparameters, with its held baseline if any."""
        baseline = None
        if self.baseline_lambda > 0:
            baseline = HeldBaseline(
                lam=self.baseline_lambda,
                hold=self.baseline_hold,
                settle=self.baseline_settle,
                filters=self.baseline_filters,
                ridge=self.baseline_ridge,
            )
            baseline.bind(self.bank_.in_idx, self.bank_.out_idx, self.bank_.lrgf)
        return super()._new_stage(baseline=baseline)

    def _new_novelty(self) -> NoveltyScale:
        relations = exogenous_relations(self._relations())
        return NoveltyScale(self.novelty_gain, relations, self.steady_window)

    # ---- fitting -------------------------------------------------------------------------------
    def _fit(self, episodes: list[Episode]) -> None:
        pairs = self._fault_directions().pairs(episodes)  # checked before anything trains
        episodes = [e for e in episodes if e.fault_onset is None]
        bank = self._new_bank()
        self.novelty_ = self._new_novelty()
        w = self.steady_window
        ys = [e.y for e in episodes]
        if self.calibration == Calibration.CROSS_FIT and len(ys) >= self.n_folds:
            cal_parts, distances, final = cross_fit_models(self, ys)
            bank.set_models(final)
            train, cal = ys, ys  # every record is out of fold once, in order
        else:  # lrgf-mem's split (also when there are fewer episodes than folds)
            train, cal, cal_from = holdout_split(episodes)
            bank.set_models(self._train_banks([train])[0])
            w = max(w, cal_from)
            cal_parts = [bank.parts(y) for y in cal]
            distances = self.novelty_.distances(bank, train, cal)
        self.novelty_.fit(bank, train)
        self._calibrate(cal_parts, w, distances, cal, pairs)

    def _calibrate(
        self,
        cal_parts: list[tuple[np.ndarray, np.ndarray]],
        w: int,
        distances: list[np.ndarray],
        cal_ys: list[np.ndarray],
        pairs: Pairs,
    ) -> None:
        """Error-model choice, scale, fault directions and the stage's limits from healthy
        calibration records ``cal_parts`` (``(y_out − y_m, y_e)`` each; the first ``w`` samples
        skipped) with, per record, its distance outside the training predictions
        ``distances`` (``(T,)``) and its measurements ``cal_ys``; the directions from the
        training faults ``pairs`` (:meth:`FaultDirections.pairs`)."""
        bank = self.bank_
        n_cal = sum(max(0, r.shape[0] - w) for r, _ in cal_parts)
        if n_cal < MIN_CALIBRATION_SAMPLES:
            raise ValueError(
                f"{n_cal} calibration samples after the warm-up (steady_window="
                f"{self.steady_window}); at least {MIN_CALIBRATION_SAMPLES} are needed"
            )
        on = np.concatenate([(r - e)[w:] for r, e in cal_parts])
        off = np.concatenate([r[w:] for r, _ in cal_parts])
        if self.mem_select == MemSelect.IF_BETTER:
            bank.use_mem = np.sqrt(np.mean(on**2, axis=0)) < np.sqrt(np.mean(off**2, axis=0))
        else:
            bank.use_mem = np.ones(len(bank), dtype=bool)
        rem = [
            ((r - e * bank.use_mem) / novelty_scale(d, self.novelty_gain)[:, None])[w:]
            for (r, e), d in zip(cal_parts, distances, strict=True)
        ]
        self.v_residual_ = np.maximum(np.sqrt(np.mean(np.concatenate(rem) ** 2, axis=0)), 1e-9)
        norm = [r / self.v_residual_ for r in rem]
        directions, self.direction_faults_ = self._fault_directions().learn(
            pairs, len(bank), paired_difference(self.normalised)
        )
        self.stage_ = self._new_stage()
        features: list[np.ndarray | None] = [None] * len(cal_parts)
        baseline = self.stage_.baseline
        if baseline is not None and baseline.regression:
            # the regressors of every calibration record past w (its own out-of-fold outputs)
            baseline.reset()
            features = []
            for (r, _), y in zip(cal_parts, cal_ys, strict=True):
                phi = baseline.features(y, y[:, bank.out_idx] - r)
                assert phi is not None
                features.append(phi[w:])
        self.stage_.fit(norm, directions, features)
        self._finish()

    def normalised(self, y: np.ndarray) -> np.ndarray:
        """The normalised remaining error ``(T, k)`` of a record ``y`` with the fitted bank,
        scale and novelty (what the alarm stage reads)."""
        r, e = self.bank_.parts(y)
        scale = self.novelty_.scale(self.bank_, y)
        return (r - e * self.bank_.use_mem) / self.v_residual_ / scale[:, None]

    def _finish(self) -> None:
        """Derived state shared by ``_fit`` and ``_set_state``."""
        self.v_ = np.maximum(self.v_residual_, 1e-9)
        self.directions_ = self.stage_.directions_
        # a model saved before the names were assumes its hyperparameters' faults, in order
        self.direction_faults_ = self.direction_faults_[: len(self.directions_)]
        if len(self.direction_faults_) != len(self.directions_):
            raise ValueError(
                f"direction_faults names {len(self.direction_faults_)} faults for "
                f"{len(self.directions_)} fault directions"
            )
        self.signal_names_ = self.stage_.signal_names(self.direction_faults_)

    # ---- what the alarm stage reads and what is saved beside it ----------------------------------
    def _normalise(self, resid: np.ndarray, y: np.ndarray) -> np.ndarray:
        return resid / self.v_residual_ / self.novelty_.scale(self.bank_, y)[:, None]

    def _normalise_step(self, resid: np.ndarray, y_m: np.ndarray) -> np.ndarray:
        e = resid / self.v_residual_
        if self.novelty_.active:
            e /= self.novelty_.scale_step(y_m)
        return e

    def _features(self, y: np.ndarray, y_m: np.ndarray) -> np.ndarray | None:
        baseline = self.stage_.baseline
        return None if baseline is None else baseline.features(y, y_m)

    def _features_step(self, y: np.ndarray, y_m: np.ndarray) -> np.ndarray | None:
        baseline = self.stage_.baseline  # its filters run while warm too
        return None if baseline is None else baseline.features_step(y, y_m)

    def _family_state(self) -> dict[str, np.ndarray]:
        rng = self.novelty_.range_
        return {
            "prediction_range": (np.zeros((3, 0)) if rng is None else rng.to_array()),
            # the names depend on the faults passed to fit: saved with the directions
            "direction_faults": np.array(self.direction_faults_, dtype=str),
        }

    def _set_family_state(self, state: Mapping[str, np.ndarray]) -> None:
        try:
            rng = np.asarray(state["prediction_range"])
        except KeyError as e:
            raise ValueError(f"saved state lacks array {e.args[0]!r}") from None
        self.novelty_ = self._new_novelty()
        if rng.size and rng.shape[-1] != len(self.novelty_.relations):
            raise ValueError(
                f"prediction_range has {rng.shape[-1]} columns; allowed: one per relation "
                f"with exogenous inputs ({len(self.novelty_.relations)})"
            )
        self.novelty_.range_ = PredictionRange.from_array(rng) if rng.size else None
        names = state.get("direction_faults")
        # a model saved before the names were: it learned the faults its hyperparameters name
        faults = self._fault_directions().saved_faults() if names is None else names.tolist()
        self.direction_faults_ = tuple(str(f) for f in faults)

    def _models_loaded(self) -> None:
        if self.stage_.baseline is not None:  # the baseline reads the loaded networks' scalers
            self.stage_.baseline.bind(self.bank_.in_idx, self.bank_.out_idx, self.bank_.lrgf)
