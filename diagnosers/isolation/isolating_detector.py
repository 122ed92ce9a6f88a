"""Isolating diagnosers: any LRGF detector's detection, plus which fault it is.

Both diagnosers here *compose* an inner detector (``detector_``): the registered LRGF detector
named ``detector_name`` (default ``lrgf-mem``; ``lrgf-glr`` and its presets too) with the
hyperparameters ``detector``, trained on the training episodes exactly as that detector is (the
healthy ones, and the labelled faults too if it learns from them): their alarms are its alarms,
sample for sample, so isolation cannot cost detection. The isolator reads the detection only
through its public parts: the residual of each relation and the detector's
``residual_scale_`` and ``steady_window``. While alarmed, they
compare the bank's residuals with what they learned from labelled training faults
(``Episode.fault_onset`` and ``Episode.scenario``, training seeds only).

**Features** (shared). The bank's normalised remaining errors ``e = (y − y_m − y_e) / v`` of its
three relations (T_rx, T_rg1, T_rg2) are averaged by EWMAs of the weights
:data:`FEATURE_LAMBDAS` (exponential windows of about 3 to 100 samples): a 12-vector ``q`` that
holds the *time course* of the signature as well as its direction (f1, f2 and f4 point nearly
the same way, see :mod:`evaluation.isolation.isolability`; they differ in how the relations
respond over time). The feature of an alarmed sample is ``q − q_0``, ``q_0`` the value just
before the alarm began (an alarm begins after ``alarm_gap`` quiet samples): the healthy model
error of the slow averages cancels. Signatures turn as a fault propagates, so each *age* of the
alarm (samples since it began, bins :data:`AGE_EDGES`) has its own classifier.

The classifiers are the registered isolators of :mod:`diagnosers.isolation.isolators`: ``lrgf-iso``
(nearest signature direction) and ``lrgf-lda`` (linear discriminant analysis).

**Decision.** Per-sample scores and acceptance flags are smoothed over the samples of one alarm
by an EWMA of weight ``score_lambda`` (sequential evidence: one odd sample does not flip the
label); the diagnosis is the best smoothed class, or "unknown" when its smoothed acceptance is
below one half. Before the alarm, and between alarms, the diagnosis is ``""``.

Thresholds are set on the training faults only (training seeds 1000+); the hyperparameters
(``score_lambda``, ``min_angle_deg``, ``unknown_quantile``) were chosen on validation seeds
(5000+) of the paper track (``python -m evaluation.isolation.study --seeds validation``).
"""

from __future__ import annotations

from abc import abstractmethod
from pathlib import Path
from typing import Any, ClassVar, Self

import numpy as np

from diagnosers.detection import NO_DIAGNOSIS, UNKNOWN, Decision, Detection
from diagnosers.diagnoser import Diagnoser
from diagnosers.episode.record import Episode
from diagnosers.lrgf.bank_detector import BankDetector
from diagnosers.registry import diagnoser_class, make
from diagnosers.stages.alarm import EWMA
from fcc_common.validation import Integer, Real, check_params, invalid

__all__ = [
    "AGE_EDGES",
    "FEATURE_LAMBDAS",
    "MIN_CLASS_SAMPLES",
    "IsolatingDetector",
    "bank_detector_class",
]

#: EWMA weights of the exponential windows of the residuals (features of both isolators)
FEATURE_LAMBDAS: tuple[float, ...] = (0.3, 0.1, 0.03, 0.01)
#: edges [samples since the alarm began] of the age bins; each bin has its own classifier
AGE_EDGES: tuple[int, ...] = (0, 10, 30, 100, 300, 1000)
#: fewest alarmed post-onset training samples a fault class needs
MIN_CLASS_SAMPLES = 10


def bank_detector_class(name: str) -> type[BankDetector]:
    """The registered LRGF detector class ``name``; ``ValueError`` naming it otherwise."""
    try:
        cls = diagnoser_class(name)
    except ValueError:
        cls = None
    if cls is None or not issubclass(cls, BankDetector):
        raise invalid(
            "detector_name",
            name,
            "the registry name of an LRGF detector (lrgf-mem, lrgf-mem-paper, lrgf-glr, "
            "lrgf-glr-adaptive)",
        )
    return cls


class IsolatingDetector(Diagnoser):
    """An isolator around any LRGF detector: alarm-relative features, per-age classifiers.

    Hyperparameters shared by the isolators: ``detector_name`` (a registered
    :class:`~diagnosers.lrgf.bank_detector.BankDetector`, default ``"lrgf-mem"``), ``detector`` (its
    hyperparameters; None: its defaults), ``unknown_quantile``, ``alarm_gap``, ``score_lambda``
    and ``seed``, documented on each isolator (:mod:`diagnosers.isolation.isolators`).
    """

    isolates: ClassVar[bool] = True
    #: hyperparameter constraints checked in ``fit`` (besides ``detector``)
    CONSTRAINTS: ClassVar[dict[str, Any]] = {
        "unknown_quantile": Real(0, 0.5, closed="neither"),
        "alarm_gap": Integer(1, 100_000),
        "score_lambda": Real(0, 1, closed="right"),
        "seed": Integer(0),
    }

    detector_name: str
    detector: dict[str, Any] | None
    alarm_gap: int
    score_lambda: float
    detector_: BankDetector

    @classmethod
    def fast_params(cls) -> dict[str, Any]:
        return {"detector": diagnoser_class("lrgf-mem").fast_params()}

    def result_params(self) -> dict[str, Any]:
        # the inner detector's execution parameters (n_jobs, progress) do not change the fit
        # either; without them an empty dict is the default detector, as in _fit
        params = super().result_params()
        if isinstance(self.detector, dict):
            skip = bank_detector_class(self.detector_name).execution_params
            inner = {k: v for k, v in self.detector.items() if k not in skip}
            params["detector"] = inner or None
        return params

    def _validate_params(self) -> None:
        check_params(
            {k: v for k, v in self.get_params().items() if k in self.CONSTRAINTS}, self.CONSTRAINTS
        )
        if self.detector is not None and not isinstance(self.detector, dict):
            raise invalid(
                "detector", self.detector, f"a dict of {self.detector_name} hyperparameters or None"
            )
        bank_detector_class(self.detector_name)
        make(self.detector_name, **(self.detector or {})).validate_params()

    # ---- features ------------------------------------------------------------------------------
    def _n_features_in(self) -> int:
        return len(self.detector_.residual_scale_) * len(FEATURE_LAMBDAS)

    def _normalised(self, residual: np.ndarray, k0: int) -> np.ndarray:
        """Normalised remaining error; zero during the detector's warm-up (as its EWMA sees it)."""
        e = residual / self.detector_.residual_scale_
        if k0 < self.detector_.steady_window:
            e = np.array(e, copy=True)
            e[: self.detector_.steady_window - k0] = 0.0
        return e

    def _start_feature_state(self) -> None:
        self._q_prev = np.zeros(self._n_features_in())
        self._base = np.zeros(self._n_features_in())
        self._start = -1
        self._last = -1
        self._smooth: np.ndarray | None = None
        self._smooth_ok: np.ndarray | None = None

    def _step_features(self, k: int, q: np.ndarray, alarm: bool) -> tuple[np.ndarray, int, bool]:
        """``(q − q before the alarm began, age bin, a new alarm began)`` of sample ``k``; bin −1
        when not alarmed. An alarm begins after ``alarm_gap`` quiet samples.

        One place for the recursion, used by streaming and batch alike.
        """
        out, b, new = np.zeros_like(q), -1, False
        if alarm:
            if self._start < 0 or k - self._last > self.alarm_gap:
                self._start, self._base, new = k, self._q_prev, True
            self._last = k
            out = q - self._base
            b = int(np.searchsorted(AGE_EDGES, k - self._start, side="right")) - 1
        self._q_prev = q
        return out, b, new

    def _batch_features(
        self, residual: np.ndarray, alarm: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Features, age bins and new-alarm flags of a whole record (from a fresh start)."""
        e = self._normalised(residual, 0)
        Q = np.concatenate([EWMA(lam).filter(e) for lam in FEATURE_LAMBDAS], axis=1)
        D, bins, new = np.zeros_like(Q), np.full(len(Q), -1), np.zeros(len(Q), dtype=bool)
        self._start_feature_state()
        for k in range(len(Q)):
            D[k], bins[k], new[k] = self._step_features(k, Q[k], bool(alarm[k]))
        return D, bins, new

    def diagnose_detection(self, det: Detection) -> Detection:
        """The isolator's detection from its inner detector's detection of the same record
        (what :meth:`detect` computes; lets a study reuse one detector run for several
        isolators)."""
        D, bins, new = self._batch_features(det.residual, det.alarm)
        diag, scores = self._diagnose(D, bins, new)
        self._start_feature_state()
        return Detection(
            alarm=det.alarm,
            signal=det.signal,
            lower=det.lower,
            upper=det.upper,
            residual=det.residual,
            signal_names=det.signal_names,
            diagnosis=diag,
            class_scores=scores,
            class_names=self.classes_,
        )

    # ---- fitting -------------------------------------------------------------------------------
    def _fit(self, episodes: list[Episode]) -> None:
        healthy = [e for e in episodes if e.fault_onset is None]
        faulty = [e for e in episodes if e.fault_onset is not None]
        detector = make(self.detector_name, **(self.detector or {}))
        assert isinstance(detector, BankDetector)  # checked by _validate_params
        # a detector that learns from faults (lrgf-glr's directions) gets them as it would alone
        self.detector_ = detector.fit(episodes if detector.learns_from_faults else healthy)
        self.fit_isolation(faulty)

    def fit_on_detector(
        self,
        detector: BankDetector,
        faulty: list[Episode],
        detections: list[Detection] | None = None,
    ) -> Self:
        """Fit the isolation on an already fitted ``detector`` and return ``self``.

        What :meth:`fit` does after training its own detector: lets a study or a benchmark
        train one bank and isolate with it in several isolators. ``detections``: the
        detector's detections of ``faulty``, if already computed (else they are computed).
        """
        self.validate_params()
        if not isinstance(detector, bank_detector_class(self.detector_name)):
            raise ValueError(
                f"detector must be a fitted {self.detector_name!r}, got {type(detector).__name__}"
            )
        detector.check_is_fitted()
        if detections is not None and len(detections) != len(faulty):
            raise ValueError(
                f"detections must match faulty: got {len(detections)} and {len(faulty)} episodes"
            )
        self._fitted_ = False
        self.detector_ = detector
        self.sample_time_s_ = detector.sample_time_s_
        self.fit_isolation(faulty, detections)
        self._fitted_ = True
        self.reset()
        return self

    def fit_isolation(
        self, faulty: list[Episode], detections: list[Detection] | None = None
    ) -> None:
        """Learn the fault classes from labelled faulty episodes (``detector_`` already fitted;
        :meth:`fit_on_detector` is the public way in)."""
        per: dict[str, list[tuple[np.ndarray, np.ndarray]]] = {}
        for i, ep in enumerate(faulty):
            det = self.detector_.detect(ep) if detections is None else detections[i]
            D, bins, _ = self._batch_features(det.residual, det.alarm)
            keep = bins >= 0
            keep[: ep.fault_onset] = False
            per.setdefault(ep.scenario, []).append((D[keep], bins[keep]))
        self.classes_ = tuple(sorted(per))
        data = {
            c: (np.concatenate([d for d, _ in per[c]]), np.concatenate([b for _, b in per[c]]))
            for c in self.classes_
        }
        for c, (x, _) in data.items():
            if x.shape[0] < MIN_CLASS_SAMPLES:
                raise ValueError(
                    f"fault class {c!r} has {x.shape[0]} alarmed post-onset training samples; at "
                    f"least {MIN_CLASS_SAMPLES} are needed (larger or more training faults)"
                )
        # per age bin and class: that bin's samples, or all of the class's when too few
        binned = {
            b: {
                c: x[bins == b] if np.count_nonzero(bins == b) >= MIN_CLASS_SAMPLES else x
                for c, (x, bins) in data.items()
            }
            for b in range(len(AGE_EDGES))
        }
        self._fit_classes(binned)
        self.channels_ = self.detector_.channels_
        self._finish_iso()

    @abstractmethod
    def _fit_classes(self, binned: dict[int, dict[str, np.ndarray]]) -> None:
        """Fit the classifier of every age bin and its unknown thresholds."""

    @abstractmethod
    def _scores(self, D: np.ndarray, b: int) -> tuple[np.ndarray, np.ndarray]:
        """``(class scores (n, C), accepted (n, C) bool)`` of features ``D`` (n, d) in age bin
        ``b``, row by row (no row's result depends on another's: streaming equals batch)."""

    def _finish_iso(self) -> None:
        self.signal_names_ = self.detector_.signal_names_

    def _diagnose(
        self, D: np.ndarray, bins: np.ndarray, new: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Per sample: the best accepted class, "unknown", or "" while not alarmed (bin −1).

        The class scores and acceptance flags are smoothed over the alarmed samples of one alarm
        (an EWMA of weight ``score_lambda``, restarted where ``new`` marks a new alarm): the
        evidence of several samples decides, and one odd sample does not flip the label.
        """
        names = np.array([*self.classes_, UNKNOWN])
        diag = np.full(len(D), NO_DIAGNOSIS, dtype=f"<U{max(len(n) for n in names)}")
        C = len(self.classes_)
        scores = np.full((len(D), C), np.nan)
        accepted = np.zeros((len(D), C))
        for b in np.unique(bins[bins >= 0]):
            rows = bins == b
            if C:
                s, acc = self._scores(D[rows], int(b))
                scores[rows], accepted[rows] = s, acc
        lam = self.score_lambda
        for k in np.flatnonzero(bins >= 0):
            if not C:  # trained on no fault: every alarm is unknown
                diag[k] = UNKNOWN
                continue
            if new[k] or self._smooth is None or self._smooth_ok is None:
                self._smooth, self._smooth_ok = scores[k].copy(), accepted[k].copy()
            else:
                self._smooth = lam * scores[k] + (1.0 - lam) * self._smooth
                self._smooth_ok = lam * accepted[k] + (1.0 - lam) * self._smooth_ok
            best = int(np.argmax(self._smooth))
            diag[k] = names[best] if self._smooth_ok[best] >= 0.5 else UNKNOWN
            scores[k] = self._smooth
        return diag, scores

    # ---- detection -----------------------------------------------------------------------------
    def _reset(self) -> None:
        self.detector_.reset()
        self._filters = [EWMA(lam) for lam in FEATURE_LAMBDAS]
        self._start_feature_state()
        self._k = 0

    def _update(self, y: np.ndarray) -> Decision:
        d = self.detector_.update(y)
        e = self._normalised(d.residual[None, :], self._k)[0]
        q = np.concatenate([f.update(e) for f in self._filters])
        D, b, new = self._step_features(self._k, q, d.alarm)
        self._k += 1
        diag, scores = self._diagnose(D[None, :], np.array([b]), np.array([new]))
        return Decision(d.alarm, d.signal, d.lower, d.upper, d.residual, str(diag[0]), scores[0])

    def _detect(self, y: np.ndarray) -> Detection:
        episode = Episode(y, channels=self.channels_, sample_time_s=self.sample_time_s_)
        return self.diagnose_detection(self.detector_.detect(episode))

    def band_view(self, episode: Episode) -> Detection | None:
        self._check_episode(episode)
        return self.detector_.band_view(episode)

    # ---- persistence ---------------------------------------------------------------------------
    def _get_state(self) -> dict[str, np.ndarray]:
        return {"classes": np.array(self.classes_, dtype=str), **self._class_state()}

    def _set_state(self, state: dict[str, np.ndarray]) -> None:
        self.classes_ = tuple(str(c) for c in state["classes"])
        self._set_class_state(state)

    @abstractmethod
    def _class_state(self) -> dict[str, np.ndarray]: ...

    @abstractmethod
    def _set_class_state(self, state: dict[str, np.ndarray]) -> None: ...

    def _save_extra(self, directory: Path) -> None:
        self.detector_.save(directory / "detector")

    def _load_extra(self, directory: Path) -> None:
        inner = Diagnoser.load(directory / "detector")
        if not isinstance(inner, BankDetector) or inner.name != self.detector_name:
            raise ValueError(
                f"{directory / 'detector'} holds a {inner.name!r}, not the isolator's detector "
                f"{self.detector_name!r}"
            )
        if inner.channels_ != self.channels_:
            raise ValueError(
                f"{directory / 'detector'} was trained on channels {inner.channels_}, the "
                f"isolator on {self.channels_}; the directory is inconsistent"
            )
        self.detector_ = inner
        n_bins = len(AGE_EDGES)
        for key, arr in self._class_state().items():
            if arr.ndim < 1 or arr.shape[0] != n_bins:
                raise ValueError(
                    f"{directory / 'state.npz'}: array {key!r} has shape {arr.shape}; its first "
                    f"axis must hold the {n_bins} age bins"
                )
        self._finish_iso()
