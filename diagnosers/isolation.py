"""Isolating diagnosers: ``lrgf-mem``'s detection, plus which fault it is.

Both diagnosers here *compose* an inner :class:`diagnosers.lrgf_mem.LRGFMEM` (``detector_``),
trained on the healthy training episodes exactly as ``lrgf-mem`` is: their alarms are that
detector's alarms, sample for sample, so isolation cannot cost detection. While alarmed, they
compare the bank's residuals with what they learned from labelled training faults
(``Episode.fault_onset`` and ``Episode.scenario``, training seeds only):

* ``lrgf-iso`` (structured residuals, nearest direction): the bank's normalised remaining
  errors ``e = (y − y_m − y_e) / v`` of its three relations (T_rx, T_rg1, T_rg2) are averaged by
  an EWMA of weight ``iso_lambda`` (``q``), and ``q``'s *direction* is compared with each fault's
  signature directions, a few prototype unit vectors per fault (spherical k-means over the
  alarmed post-onset samples of its training episodes; a fault's signature turns as its effect
  propagates, so one direction is not enough). The score of class ``c`` is the best cosine
  ``max_p q̂·μ_cp`` (the GLR of a known direction with unknown size under white noise ranks the
  same way: ``‖q‖² cos²``). The diagnosis is the best class, or ``"unknown"`` when its cosine is
  below that class's threshold: the ``unknown_quantile`` quantile of its own training samples'
  cosines (a share ``unknown_quantile`` of training-fault samples fall into "unknown").
* ``lrgf-lda`` (data-driven baseline): linear discriminant analysis (scikit-learn's
  :class:`~sklearn.discriminant_analysis.LinearDiscriminantAnalysis` fits it) on exponential
  windows of the residuals: EWMAs of ``e`` at the weights ``LDA_LAMBDAS``, a 3 × 4 feature vector.
  "unknown" when the Mahalanobis distance (pooled covariance) to the chosen class's mean exceeds
  the ``1 − unknown_quantile`` quantile of that class's training distances. Only the fitted arrays
  (class means, pooled covariance, priors) are stored; prediction is computed from them, so
  loading never unpickles anything.

Thresholds are set on the training faults only (training seeds 1000+); the hyperparameters were
chosen on validation seeds (5000+). Before the alarm the diagnosis is ``""``.
"""

from __future__ import annotations

from abc import abstractmethod
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from diagnosers.alarm import EWMA
from diagnosers.base import NO_DIAGNOSIS, UNKNOWN, Decision, Detection, Diagnoser, Episode
from diagnosers.lrgf_mem import LRGFMEM
from diagnosers.registry import register
from fcc_env.validation import Integer, Real, check_params, invalid

__all__ = ["LDA_LAMBDAS", "LRGFISO", "LRGFLDA", "spherical_kmeans"]

#: EWMA weights of the exponential windows of ``lrgf-lda``'s features
LDA_LAMBDAS: tuple[float, ...] = (0.3, 0.1, 0.03, 0.01)
#: fewest alarmed post-onset training samples a fault class needs
MIN_CLASS_SAMPLES = 10


def spherical_kmeans(
    u: np.ndarray, k: int, *, seed: int = 0, n_iter: int = 50
) -> np.ndarray:
    """``k`` unit prototype vectors of the unit vectors ``u`` (n, d) (cosine k-means).

    Deterministic in ``seed``; starts from k-means++-style picks by angle.
    """
    rng = np.random.default_rng(seed)
    n = u.shape[0]
    k = min(k, n)
    centres = [u[int(rng.integers(n))]]
    for _ in range(1, k):
        d = 1.0 - np.max(u @ np.array(centres).T, axis=1)
        p = np.maximum(d, 0.0)
        centres.append(u[int(rng.choice(n, p=p / p.sum()))] if p.sum() > 0 else u[0])
    c = np.array(centres)
    for _ in range(n_iter):
        lab = np.argmax(u @ c.T, axis=1)
        new = np.array([u[lab == j].sum(axis=0) if np.any(lab == j) else c[j] for j in range(k)])
        new /= np.maximum(np.linalg.norm(new, axis=1, keepdims=True), 1e-12)
        if np.allclose(new, c):
            break
        c = new
    return c


class _IsolatingLRGF(Diagnoser):
    """Shared implementation: inner ``lrgf-mem`` detector, features, unknown region, persistence."""

    isolates: ClassVar[bool] = True
    #: hyperparameter constraints checked in ``fit`` (besides ``detector``)
    CONSTRAINTS: ClassVar[dict[str, Any]] = {
        "unknown_quantile": Real(0, 0.5, closed="neither"),
        "seed": Integer(0),
    }

    @classmethod
    def fast_params(cls) -> dict[str, Any]:
        return {"detector": LRGFMEM.fast_params()}

    def _validate_params(self) -> None:
        check_params(
            {k: v for k, v in self.get_params().items() if k in self.CONSTRAINTS}, self.CONSTRAINTS
        )
        if self.detector is not None and not isinstance(self.detector, dict):
            raise invalid("detector", self.detector, "a dict of lrgf-mem hyperparameters or None")
        LRGFMEM(**(self.detector or {}))._validate_params()

    # ---- features ------------------------------------------------------------------------------
    @abstractmethod
    def _lambdas(self) -> tuple[float, ...]:
        """EWMA weights of the feature filters (one block of 3 relations each)."""

    def _normalised(self, residual: np.ndarray, k0: int) -> np.ndarray:
        """Normalised remaining error; zero during the detector's warm-up (as its EWMA sees it)."""
        e = residual / self.detector_.v_residual_
        if k0 < self.detector_.steady_window:
            e = np.array(e, copy=True)
            e[: self.detector_.steady_window - k0] = 0.0
        return e

    def _batch_features(self, residual: np.ndarray) -> np.ndarray:
        e = self._normalised(residual, 0)
        return np.concatenate([EWMA(lam).filter(e) for lam in self._lambdas()], axis=1)

    # ---- fitting -------------------------------------------------------------------------------
    def _fit(self, episodes: list[Episode]) -> None:
        healthy = [e for e in episodes if e.fault_onset is None]
        self.detector_ = LRGFMEM(**(self.detector or {})).fit(healthy)
        self.fit_isolation([e for e in episodes if e.fault_onset is not None])

    def fit_isolation(self, faulty: list[Episode]) -> None:
        """Learn the fault classes from labelled faulty episodes (``detector_`` already fitted).

        Public so that a trained ``lrgf-mem`` can be reused: set ``detector_``, call this.
        """
        X: dict[str, list[np.ndarray]] = {}
        for ep in faulty:
            det = self.detector_.detect(ep)
            F = self._batch_features(det.residual)
            mask = det.alarm.copy()
            mask[: ep.fault_onset] = False
            X.setdefault(ep.scenario, []).append(F[mask])
        self.classes_ = tuple(sorted(X))
        data = {c: np.concatenate(X[c]) for c in self.classes_}
        # the classes' names become diagnoses; an empty set of classes calls every alarm unknown
        for c, x in data.items():
            if x.shape[0] < MIN_CLASS_SAMPLES:
                raise ValueError(
                    f"fault class {c!r} has {x.shape[0]} alarmed post-onset training samples; at "
                    f"least {MIN_CLASS_SAMPLES} are needed (larger or more training faults)"
                )
        self._fit_classes(data)
        self._finish_iso()
        self.channels_ = self.detector_.channels_

    @abstractmethod
    def _fit_classes(self, data: dict[str, np.ndarray]) -> None:
        """Fit the classifier and its unknown thresholds on per-class features."""

    @abstractmethod
    def _scores(self, F: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(class scores (T, C), accepted (T, C) bool)`` of features ``F`` (T, d), row-wise
        (each row's result must not depend on the other rows: streaming equals batch)."""

    def _finish_iso(self) -> None:
        self.signal_names_ = self.detector_.signal_names_

    def _diagnose(self, F: np.ndarray, alarm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per sample: the best accepted class, "unknown", or "" while not alarmed."""
        names = np.array([*self.classes_, UNKNOWN])
        width = max(len(n) for n in names)
        if not self.classes_:  # trained on no fault: every alarm is unknown
            diag = np.where(alarm, UNKNOWN, NO_DIAGNOSIS).astype(f"<U{width}")
            return diag, np.zeros((len(F), 0))
        scores, accepted = self._scores(F)
        best = np.argmax(scores, axis=1)
        ok = accepted[np.arange(len(F)), best]
        diag = np.where(ok, names[best], UNKNOWN)
        return np.where(alarm, diag, NO_DIAGNOSIS).astype(f"<U{width}"), scores

    # ---- detection -----------------------------------------------------------------------------
    def _reset(self) -> None:
        self.detector_.reset()
        self._filters = [EWMA(lam) for lam in self._lambdas()]
        self._k = 0

    def _update(self, y: np.ndarray) -> Decision:
        d = self.detector_._update(y)
        e = self._normalised(d.residual[None, :], self._k)[0]
        self._k += 1
        F = np.concatenate([f.update(e) for f in self._filters])[None, :]
        diag, scores = self._diagnose(F, np.array([d.alarm]))
        return Decision(
            d.alarm, d.signal, d.lower, d.upper, d.residual, str(diag[0]), scores[0]
        )

    def _detect(self, y: np.ndarray) -> Detection:
        det = self.detector_._detect(y)
        F = self._batch_features(det.residual)
        diag, scores = self._diagnose(F, det.alarm)
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
        if not isinstance(inner, LRGFMEM):
            raise ValueError(f"{directory / 'detector'} holds a {inner.name!r}, not an lrgf-mem")
        if inner.channels_ != self.channels_:
            raise ValueError(
                f"{directory / 'detector'} was trained on channels {inner.channels_}, the "
                f"isolator on {self.channels_}; the directory is inconsistent"
            )
        self.detector_ = inner
        self._finish_iso()


@register("lrgf-iso")
class LRGFISO(_IsolatingLRGF):
    """``lrgf-mem`` + nearest signature direction of the bank's residuals (module docstring)."""

    CONSTRAINTS: ClassVar[dict[str, Any]] = {
        **_IsolatingLRGF.CONSTRAINTS,
        "iso_lambda": Real(0, 1, closed="right"),
        "n_prototypes": Integer(1, 50),
    }

    def __init__(
        self,
        *,
        detector: dict[str, Any] | None = None,
        iso_lambda: float = 0.05,
        n_prototypes: int = 4,
        unknown_quantile: float = 0.02,
        seed: int = 0,
    ) -> None:
        self.detector = detector
        self.iso_lambda = iso_lambda
        self.n_prototypes = n_prototypes
        self.unknown_quantile = unknown_quantile
        self.seed = seed

    def _lambdas(self) -> tuple[float, ...]:
        return (float(self.iso_lambda),)

    def _n_features_in(self) -> int:
        return len(self.detector_.out_idx_) * len(self._lambdas())

    @staticmethod
    def _unit(F: np.ndarray) -> np.ndarray:
        norm = np.sqrt(np.sum(F * F, axis=1, keepdims=True))
        return F / np.maximum(norm, 1e-12)

    def _fit_classes(self, data: dict[str, np.ndarray]) -> None:
        protos, owner = [np.zeros((0, self._n_features_in()))], []
        for j, c in enumerate(self.classes_):
            p = spherical_kmeans(self._unit(data[c]), self.n_prototypes, seed=self.seed + j)
            protos.append(p)
            owner += [j] * len(p)
        self.prototypes_ = np.concatenate(protos)
        self.owner_ = np.array(owner, dtype=np.int64)
        self.threshold_ = np.zeros(len(self.classes_))
        self.threshold_ = np.array(
            [
                float(np.quantile(self._scores(data[c])[0][:, j], self.unknown_quantile))
                for j, c in enumerate(self.classes_)
            ]
        )

    def _scores(self, F: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        u = self._unit(F)
        cos = np.sum(u[:, None, :] * self.prototypes_[None, :, :], axis=2)  # (T, P)
        C = len(self.classes_)
        scores = np.full((len(F), C), -1.0)
        for j in range(C):
            scores[:, j] = np.max(cos[:, self.owner_ == j], axis=1)
        return scores, scores >= self.threshold_[None, :]

    def _class_state(self) -> dict[str, np.ndarray]:
        return {
            "prototypes": self.prototypes_,
            "owner": self.owner_,
            "threshold": self.threshold_,
        }

    def _set_class_state(self, state: dict[str, np.ndarray]) -> None:
        self.prototypes_ = np.asarray(state["prototypes"], dtype=np.float64)
        self.owner_ = np.asarray(state["owner"], dtype=np.int64)
        self.threshold_ = np.asarray(state["threshold"], dtype=np.float64)


@register("lrgf-lda")
class LRGFLDA(_IsolatingLRGF):
    """``lrgf-mem`` + linear discriminant analysis of exponential residual windows (baseline)."""

    def __init__(
        self,
        *,
        detector: dict[str, Any] | None = None,
        unknown_quantile: float = 0.01,
        seed: int = 0,
    ) -> None:
        self.detector = detector
        self.unknown_quantile = unknown_quantile
        self.seed = seed

    def _lambdas(self) -> tuple[float, ...]:
        return LDA_LAMBDAS

    def _fit_classes(self, data: dict[str, np.ndarray]) -> None:
        # scikit-learn fits; only its arrays are kept (see the module docstring)
        from sklearn.discriminant_analysis import LinearDiscriminantAnalysis

        d = len(self.detector_.out_idx_) * len(self._lambdas())
        if not self.classes_:
            self.means_, self.precision_ = np.zeros((0, d)), np.eye(d)
            self.log_priors_, self.threshold_ = np.zeros(0), np.zeros(0)
            return
        X = np.concatenate([data[c] for c in self.classes_])
        y = np.concatenate([np.full(len(data[c]), j) for j, c in enumerate(self.classes_)])
        self.means_ = np.array([data[c].mean(axis=0) for c in self.classes_])
        if len(self.classes_) >= 2:
            lda = LinearDiscriminantAnalysis(solver="lsqr", store_covariance=True).fit(X, y)
            self.means_, cov = lda.means_, lda.covariance_
            self.log_priors_ = np.log(lda.priors_)
        else:  # one class: nothing to discriminate, the unknown region only
            cov = np.cov(X, rowvar=False)
            self.log_priors_ = np.zeros(1)
        cov = cov + 1e-9 * np.trace(cov) / len(cov) * np.eye(len(cov))
        self.precision_ = np.linalg.inv(cov)
        self.threshold_ = np.zeros(len(self.classes_))
        d2 = self._mahalanobis(X)
        self.threshold_ = np.array(
            [
                float(np.quantile(d2[y == j, j], 1.0 - self.unknown_quantile))
                for j in range(len(self.classes_))
            ]
        )

    def _mahalanobis(self, F: np.ndarray) -> np.ndarray:
        diff = F[:, None, :] - self.means_[None, :, :]  # (T, C, d)
        # elementwise products and sums, no BLAS: each row's result is the same in a batch of
        # one (streaming) and of T (batch), to the bit
        m = np.sum(diff[:, :, :, None] * self.precision_[None, None, :, :], axis=2)
        return np.sum(m * diff, axis=2)

    def _scores(self, F: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        # LDA's discriminant with a pooled covariance: -d²/2 + log prior (same argmax as sklearn)
        d2 = self._mahalanobis(F)
        return -0.5 * d2 + self.log_priors_[None, :], d2 <= self.threshold_[None, :]

    def _class_state(self) -> dict[str, np.ndarray]:
        return {
            "means": self.means_,
            "precision": self.precision_,
            "log_priors": self.log_priors_,
            "threshold": self.threshold_,
        }

    def _set_class_state(self, state: dict[str, np.ndarray]) -> None:
        self.means_ = np.asarray(state["means"], dtype=np.float64)
        self.precision_ = np.asarray(state["precision"], dtype=np.float64)
        self.log_priors_ = np.asarray(state["log_priors"], dtype=np.float64)
        self.threshold_ = np.asarray(state["threshold"], dtype=np.float64)
