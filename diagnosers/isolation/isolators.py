"""The two registered isolators, ``lrgf-iso`` and ``lrgf-lda``: classifiers of the
alarm-relative residual features of :class:`diagnosers.isolation.isolating_detector.IsolatingDetector` (see
:mod:`diagnosers.isolation.isolating_detector` for the features, the decision and the inner detector).

* ``lrgf-iso`` (structured residuals, nearest direction): per age bin and fault, a few prototype
  directions (:func:`spherical_kmeans` of the training samples' unit features); the score of a
  fault is the best cosine with its prototypes; "unknown" below the ``unknown_quantile``
  quantile of its own training cosines, and never an angle tighter than ``min_angle_deg``.
* ``lrgf-lda`` (data-driven baseline): linear discriminant analysis per age bin; "unknown"
  beyond the ``1 − unknown_quantile`` quantile of the class's training Mahalanobis distances.
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np
from scipy import stats

from diagnosers.isolation.isolating_detector import AGE_EDGES, MIN_CLASS_SAMPLES, IsolatingDetector
from diagnosers.presets import keyword_init
from diagnosers.registry import register
from fcc_common.validation import Integer, Real

__all__ = ["LRGFISO", "LRGFLDA", "spherical_kmeans"]


def spherical_kmeans(u: np.ndarray, k: int, *, seed: int = 0, n_iter: int = 50) -> np.ndarray:
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


@register("lrgf-iso")
class LRGFISO(IsolatingDetector):
    """A detector + nearest signature direction of the bank's residuals (structured residuals).

    Per age bin and fault, a few prototype directions (:func:`spherical_kmeans` of the
    training samples' unit features, :mod:`diagnosers.isolation.isolating_detector`); the score of a fault is the
    best cosine with its prototypes (the GLR of a known direction with unknown size under white
    noise ranks hypotheses the same way). "unknown" when the best fault's cosine is below its
    threshold. The hyperparameters were chosen on validation seeds of the paper track
    (``python -m evaluation.isolation.study --seeds validation``).

    Args:
        detector_name: the registry name of the inner LRGF detector, whose alarms are the
            isolator's alarms sample for sample (a
            :class:`~diagnosers.lrgf.bank_detector.BankDetector`: ``"lrgf-mem"`` (default),
            ``"lrgf-mem-paper"``, ``"lrgf-glr"`` or ``"lrgf-glr-adaptive"``).
        detector: that detector's hyperparameters as a dict, or ``None`` (default): its
            defaults. It is trained on the healthy training episodes exactly as alone.
        n_prototypes: prototype directions per fault and age bin, in [1, 10]; default 2. More
            follow a signature that turns within a bin, each from fewer samples.
        unknown_quantile: a fault's cosine threshold is this quantile of its own training
            cosines, in (0, 0.5); default 0.02. Larger: more samples called "unknown".
        min_angle_deg: the threshold is never an angle tighter than this [degrees], in
            [0, 90]; default 20.0.
        alarm_gap: quiet samples [samples] after which the next alarmed sample begins a new
            alarm (its features restart from the value just before it, its age from 0), in
            [1, 100000]; default 100.
        score_lambda: weight of the EWMA that smooths the per-sample scores and acceptance
            flags over one alarm, in (0, 1]; default 0.1. Smaller: a steadier label that
            settles later.
        seed: the seed of the prototypes' k-means, an integer ≥ 0; default 0.
    """

    CONSTRAINTS: ClassVar[dict[str, Any]] = {
        **IsolatingDetector.CONSTRAINTS,
        "n_prototypes": Integer(1, MIN_CLASS_SAMPLES),
        "min_angle_deg": Real(0, 90),
    }

    DEFAULTS: ClassVar[dict[str, Any]] = {
        "detector_name": "lrgf-mem",
        "detector": None,
        "n_prototypes": 2,
        "unknown_quantile": 0.02,
        "min_angle_deg": 20.0,
        "alarm_gap": 100,
        "score_lambda": 0.1,
        "seed": 0,
    }
    __init__ = keyword_init(DEFAULTS)

    @staticmethod
    def _unit(F: np.ndarray) -> np.ndarray:
        norm = np.sqrt(np.sum(F * F, axis=1, keepdims=True))
        return F / np.maximum(norm, 1e-12)

    def _fit_classes(self, binned: dict[int, dict[str, np.ndarray]]) -> None:
        B, C, P, d = len(AGE_EDGES), len(self.classes_), self.n_prototypes, self._n_features_in()
        self.prototypes_ = np.zeros((B, C, P, d))
        self.threshold_ = np.zeros((B, C))
        for b in range(B):
            for j, c in enumerate(self.classes_):
                u = self._unit(binned[b][c])
                p = spherical_kmeans(u, P, seed=self.seed + 97 * b + j)
                self.prototypes_[b, j] = p[np.arange(P) % len(p)]  # repeat when fewer found
            floor = float(np.cos(np.radians(self.min_angle_deg)))
            for j, c in enumerate(self.classes_):
                own = self._scores(binned[b][c], b)[0][:, j]
                self.threshold_[b, j] = min(float(np.quantile(own, self.unknown_quantile)), floor)

    def _scores(self, D: np.ndarray, b: int) -> tuple[np.ndarray, np.ndarray]:
        u = self._unit(D)
        protos = self.prototypes_[b]  # (C, P, d)
        cos = np.sum(u[:, None, None, :] * protos[None], axis=3)  # (n, C, P)
        scores = np.max(cos, axis=2)
        return scores, scores >= self.threshold_[b][None, :]

    def _class_state(self) -> dict[str, np.ndarray]:
        return {"prototypes": self.prototypes_, "threshold": self.threshold_}

    def _set_class_state(self, state: dict[str, np.ndarray]) -> None:
        self.prototypes_ = np.asarray(state["prototypes"], dtype=np.float64)
        self.threshold_ = np.asarray(state["threshold"], dtype=np.float64)


@register("lrgf-lda")
class LRGFLDA(IsolatingDetector):
    """A detector + linear discriminant analysis of exponential residual windows (baseline).

    Per age bin, linear discriminant analysis of the alarm-relative features
    (:mod:`diagnosers.isolation.isolating_detector`), fitted by scikit-learn's
    :class:`~sklearn.discriminant_analysis.LinearDiscriminantAnalysis`; only the fitted arrays
    (class means, pooled precision, priors, thresholds) are stored and prediction is computed
    from them, so loading never unpickles. The data-driven baseline of the isolators.

    Args:
        detector_name: the registry name of the inner LRGF detector, whose alarms are the
            isolator's alarms sample for sample (a
            :class:`~diagnosers.lrgf.bank_detector.BankDetector`: ``"lrgf-mem"`` (default),
            ``"lrgf-mem-paper"``, ``"lrgf-glr"`` or ``"lrgf-glr-adaptive"``).
        detector: that detector's hyperparameters as a dict, or ``None`` (default): its
            defaults. It is trained on the healthy training episodes exactly as alone.
        unknown_quantile: "unknown" when the Mahalanobis distance (pooled covariance) to the
            chosen class's mean exceeds the ``1 − unknown_quantile`` quantile of that class's
            training distances (never less than the χ² quantile of the Gaussian model), in
            (0, 0.5); default 0.01. Larger: more samples called "unknown".
        alarm_gap: quiet samples [samples] after which the next alarmed sample begins a new
            alarm (its features restart from the value just before it, its age from 0), in
            [1, 100000]; default 100.
        score_lambda: weight of the EWMA that smooths the per-sample scores and acceptance
            flags over one alarm, in (0, 1]; default 0.03. Smaller: a steadier label that
            settles later.
        seed: an integer ≥ 0, default 0; the discriminant analysis is deterministic and does
            not read it (the isolators share the hyperparameter).
    """

    DEFAULTS: ClassVar[dict[str, Any]] = {
        "detector_name": "lrgf-mem",
        "detector": None,
        "unknown_quantile": 0.01,
        "alarm_gap": 100,
        "score_lambda": 0.03,
        "seed": 0,
    }
    __init__ = keyword_init(DEFAULTS)

    def _fit_classes(self, binned: dict[int, dict[str, np.ndarray]]) -> None:
        # scikit-learn fits; only its arrays are kept (see the class docstring)
        from sklearn.discriminant_analysis import LinearDiscriminantAnalysis

        B, C, d = len(AGE_EDGES), len(self.classes_), self._n_features_in()
        self.means_ = np.zeros((B, C, d))
        self.precision_ = np.tile(np.eye(d), (B, 1, 1))
        self.log_priors_ = np.zeros((B, C))
        self.threshold_ = np.zeros((B, C))
        if not C:
            return
        for b in range(B):
            X = np.concatenate([binned[b][c] for c in self.classes_])
            y = np.concatenate([np.full(len(binned[b][c]), j) for j, c in enumerate(self.classes_)])
            if C >= 2:
                lda = LinearDiscriminantAnalysis(solver="lsqr", store_covariance=True).fit(X, y)
                self.means_[b], cov = lda.means_, lda.covariance_
                self.log_priors_[b] = np.log(lda.priors_)
            else:  # one class: nothing to discriminate, the unknown region only
                self.means_[b], cov = X.mean(axis=0, keepdims=True), np.cov(X, rowvar=False)
            cov = cov + 1e-6 * np.trace(cov) / d * np.eye(d)
            self.precision_[b] = np.linalg.inv(cov)
            d2 = self._mahalanobis(X, b)
            # never tighter than the Gaussian model's own quantile (χ² with d degrees of freedom)
            floor = float(stats.chi2.ppf(1.0 - self.unknown_quantile, d))
            self.threshold_[b] = [
                max(float(np.quantile(d2[y == j, j], 1.0 - self.unknown_quantile)), floor)
                for j in range(C)
            ]

    def _mahalanobis(self, F: np.ndarray, b: int) -> np.ndarray:
        diff = F[:, None, :] - self.means_[b][None, :, :]  # (n, C, d)
        # elementwise products and sums, no BLAS: each row's result is the same in a batch of
        # one (streaming) and of n (batch), to the bit
        m = np.sum(diff[:, :, :, None] * self.precision_[b][None, None, :, :], axis=2)
        return np.sum(m * diff, axis=2)

    def _scores(self, D: np.ndarray, b: int) -> tuple[np.ndarray, np.ndarray]:
        # LDA's discriminant with a pooled covariance: -d²/2 + log prior (same argmax as sklearn)
        d2 = self._mahalanobis(D, b)
        return -0.5 * d2 + self.log_priors_[b][None, :], d2 <= self.threshold_[b][None, :]

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
