"""The ``pca`` detector: Hotelling's T² and the squared prediction error (SPE, Q) of a PCA model."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, ClassVar

import numpy as np
from scipy import stats

from diagnosers.classical.channel_selection import (
    ALPHA,
    channel_indices,
    check_channel_names,
    stack_episodes,
)
from diagnosers.contract import require_varying
from diagnosers.detection import Decision, Detection
from diagnosers.diagnoser import Diagnoser
from diagnosers.episode.record import Episode
from diagnosers.presets import keyword_init, preset
from diagnosers.registry import register
from fcc_common.validation import Integer, Real, check_params, invalid

__all__ = ["LIMITS", "PCADetector", "PCAEmpirical", "hotelling_t2_limit", "spe_limit"]

#: How :class:`PCADetector` sets its control limits.
LIMITS: tuple[str, ...] = ("analytic", "empirical")


def hotelling_t2_limit(n_components: int, n_samples: int, alpha: float) -> float:
    """Upper control limit of Hotelling's T² for a *new* observation (Tracy, Young & Mason 1992).

    ``T²_lim = k (n-1)(n+1) / (n (n-k)) · F_{1-α}(k, n-k)``, ``k`` retained components, ``n``
    training samples.
    """
    k, n = n_components, n_samples
    return float(k * (n - 1) * (n + 1) / (n * (n - k)) * stats.f.ppf(1.0 - alpha, k, n - k))


def spe_limit(residual_eigenvalues: np.ndarray, alpha: float) -> float:
    """Jackson–Mudholkar (1979) limit of the squared prediction error Q.

    ``θ_i = Σ_{j>k} λ_j^i``, ``h0 = 1 - 2θ1θ3/(3θ2²)``,
    ``Q_lim = θ1 [c_α √(2θ2h0²)/θ1 + 1 + θ2h0(h0-1)/θ1²]^{1/h0}``, ``c_α = Φ^{-1}(1-α)``.
    The normal-power approximation behind it fails when ``h0`` is near zero or negative (very
    uneven residual eigenvalues: one large, many small; by Monte Carlo it then gives a fraction
    of the true quantile), so for ``h0 <= 0.05`` or a non-positive bracket Box's (1954)
    ``g·χ²_h`` approximation, ``g = θ2/θ1``, ``h = θ1²/θ2``, is used instead.
    """
    lam = np.asarray(residual_eigenvalues, dtype=np.float64)
    t1, t2, t3 = (float(np.sum(lam**i)) for i in (1, 2, 3))
    if t1 <= 0.0:
        return 0.0
    h0 = 1.0 - 2.0 * t1 * t3 / (3.0 * t2**2)
    c = float(stats.norm.ppf(1.0 - alpha))
    bracket = c * np.sqrt(2.0 * t2 * h0**2) / t1 + 1.0 + t2 * h0 * (h0 - 1.0) / t1**2
    if h0 > 0.05 and bracket > 0.0:
        q = t1 * bracket ** (1.0 / h0)
        if np.isfinite(q):
            return float(q)
    g, h = t2 / t1, t1**2 / t2
    return float(g * stats.chi2.ppf(1.0 - alpha, h))


@register("pca")
class PCADetector(Diagnoser):
    """PCA monitoring with Hotelling's T² and the squared prediction error (SPE, Q).

    Measurements are standardised with the healthy mean and standard deviation (a channel that is
    constant in training keeps scale 1, so any change of it shows up in SPE; "constant" includes a
    spread at the round-off level of its values, ``std <= 1e-9·|mean|``, as in recorded data whose
    noise-free pressure channels differ only in their last bits). The number of
    principal components is ``n_components`` if given, else the smallest ``k`` whose cumulative
    explained variance reaches ``variance_explained``; it is capped at ``m - 1`` (``m`` monitored
    channels) so that a residual subspace, and hence SPE, exists. Alarm when T² > ``T2_lim`` or
    SPE > ``Q_lim``, both at level ``alpha``.

    The limits are either the distributions' (``limits="analytic"``: Tracy–Young–Mason's F limit
    of T² for a new observation, Jackson–Mudholkar's of SPE, which assume independent normal
    samples) or the empirical ``1 - alpha`` quantiles of both statistics on the training samples
    (``limits="empirical"``), the common practice of data-driven monitoring studies (e.g. the
    source notebooks of the Santander et al. FCCU data set). Empirical limits hold the
    training data's false-alarm rate whatever the distribution, but on autocorrelated data they
    rest on fewer independent samples than there are rows. ``pca-empirical`` is ``pca`` with
    ``limits="empirical"``.

    Args:
        alpha: significance level in (0, 1) for both limits; default 0.01. Smaller: higher
            limits, fewer false alarms.
        variance_explained: target cumulative explained variance in (0, 1], used when
            ``n_components`` is None; default 0.95. More components leave less to SPE.
        n_components: number of retained components (``1 <= k <= m - 1``), or None
            (default: chosen by ``variance_explained``).
        channels: monitored channel names (at least 2), or None (default) for all.
        limits: ``"analytic"`` (default) or ``"empirical"``, see above.

    Decision arrays, names ``("T2", "SPE")`` (dimensionless, standardised units squared):
        signal = residual = ``[T², SPE]``, lower = ``[-inf, -inf]``, upper = ``[T2_lim, Q_lim]``.
        There is no measured-minus-predicted output here, so ``residual`` repeats the statistics.

    Attributes:
        mean_, scale_: standardisation; components_ ``(m, k)`` loadings; eigenvalues_ ``(m,)``
        covariance eigenvalues (descending); n_components_; n_samples_; t2_limit_; q_limit_.
    """

    DEFAULTS: ClassVar[dict[str, Any]] = {
        "alpha": 0.01,
        "variance_explained": 0.95,
        "n_components": None,
        "channels": None,
        "limits": "analytic",
    }
    __init__ = keyword_init(DEFAULTS)
    alpha: float
    variance_explained: float
    n_components: int | None
    channels: Sequence[str] | None
    limits: str

    def _validate_params(self) -> None:
        check_params(
            self.get_params(),
            {
                "alpha": ALPHA,
                "variance_explained": Real(0, 1, closed="right"),
                # The upper bound depends on the data (m - 1); it is checked again in _fit.
                "n_components": (Integer(1, 10_000), None),
            },
        )
        check_channel_names("channels", self.channels, allow_none=True)
        if self.limits not in LIMITS:
            raise invalid("limits", self.limits, f"one of {LIMITS}")

    def _fit(self, episodes: list[Episode]) -> None:
        idx = channel_indices(self.channels, self.channels_, "channels")
        m = idx.size
        if m < 2:
            raise ValueError(f"pca needs at least 2 monitored channels, got {m}")
        stacked = stack_episodes(episodes)
        x = stacked[:, idx]
        n = x.shape[0]
        if n <= m:
            raise ValueError(f"pca needs more training samples than channels ({m}), got {n}")
        require_varying(x, [self.channels_[i] for i in idx], "pca", every=False)
        mean = x.mean(axis=0)
        scale = x.std(axis=0, ddof=1)
        scale = np.where(scale > 1e-9 * np.abs(mean), scale, 1.0)
        z = (x - mean) / scale
        # SVD of the data matrix is more accurate than eigh of the covariance.
        _, s, vt = np.linalg.svd(z, full_matrices=False)
        eig = s**2 / (n - 1)
        if self.n_components is None:
            ratio = np.cumsum(eig) / eig.sum()
            k = int(np.searchsorted(ratio, float(self.variance_explained) - 1e-12) + 1)
            k = min(k, m - 1)
        else:
            k = int(self.n_components)
            if k > m - 1:
                raise invalid(
                    "n_components",
                    k,
                    Integer(1, m - 1).describe(),
                    f"{m} monitored channels; one dimension at least is needed for SPE",
                )
        # Fix the sign of each loading vector so that repeated fits give identical state.
        comps = vt[:k].T
        signs = np.sign(comps[np.argmax(np.abs(comps), axis=0), np.arange(k)])
        self.channel_idx_ = idx
        self.mean_ = mean
        self.scale_ = scale
        self.components_ = comps * signs
        self.eigenvalues_ = eig
        self.n_components_ = k
        self.n_samples_ = n
        self.empirical_limits_ = np.quantile(
            self.statistics(stacked), 1.0 - float(self.alpha), axis=0
        )
        self._finish()

    def _finish(self) -> None:
        k = self.n_components_
        if self.limits == "empirical":
            self.t2_limit_, self.q_limit_ = (float(v) for v in self.empirical_limits_)
        else:
            self.t2_limit_ = hotelling_t2_limit(k, self.n_samples_, self.alpha)
            self.q_limit_ = spe_limit(self.eigenvalues_[k:], self.alpha)
        self.signal_names_ = ("T2", "SPE")
        self._lower = np.array([-np.inf, -np.inf])
        self._upper = np.array([self.t2_limit_, self.q_limit_])

    def _get_state(self) -> dict[str, np.ndarray]:
        return {
            "channel_idx": self.channel_idx_,
            "mean": self.mean_,
            "scale": self.scale_,
            "components": self.components_,
            "eigenvalues": self.eigenvalues_,
            "n_samples": np.array(self.n_samples_, dtype=np.int64),
        } | ({} if self.empirical_limits_ is None else {"empirical_limits": self.empirical_limits_})

    def _set_state(self, state: dict[str, np.ndarray]) -> None:
        self.channel_idx_ = np.asarray(state["channel_idx"], dtype=np.int64)
        self.mean_ = np.asarray(state["mean"], dtype=np.float64)
        self.scale_ = np.asarray(state["scale"], dtype=np.float64)
        self.components_ = np.asarray(state["components"], dtype=np.float64)
        self.eigenvalues_ = np.asarray(state["eigenvalues"], dtype=np.float64)
        self.n_components_ = int(self.components_.shape[1])
        self.n_samples_ = int(state["n_samples"])
        # Models saved before the empirical limits existed have none; only that mode needs them.
        saved = state.get("empirical_limits")
        if saved is None and self.limits == "empirical":
            raise ValueError(
                "this saved pca model has no empirical limits (saved before limits='empirical' "
                "existed); refit it"
            )
        self.empirical_limits_ = None if saved is None else np.asarray(saved, dtype=np.float64)
        self._finish()

    def statistics(self, y: np.ndarray) -> np.ndarray:
        """``[T², SPE]`` for measurements ``y`` of shape ``(T, n_channels)``; returns ``(T, 2)``."""
        z = (np.atleast_2d(y)[:, self.channel_idx_] - self.mean_) / self.scale_
        scores = z @ self.components_
        t2 = np.sum(scores**2 / self.eigenvalues_[: self.n_components_], axis=1)
        resid = z - scores @ self.components_.T
        spe = np.sum(resid**2, axis=1)
        return np.column_stack([t2, spe])

    def _reset(self) -> None:
        pass  # memoryless

    def _update(self, y: np.ndarray) -> Decision:
        st = self.statistics(y)[0]
        alarm = bool(np.any(st > self._upper))
        return Decision(alarm, st, self._lower.copy(), self._upper.copy(), st.copy())

    def _detect(self, y: np.ndarray) -> Detection:
        st = self.statistics(y)
        n = st.shape[0]
        return Detection(
            alarm=np.any(st > self._upper, axis=1),
            signal=st,
            lower=np.broadcast_to(self._lower, (n, 2)).copy(),
            upper=np.broadcast_to(self._upper, (n, 2)).copy(),
            residual=st.copy(),
            signal_names=self.signal_names_,
        )


PCAEmpirical = preset(
    "pca-empirical",
    PCADetector,
    {"limits": "empirical"},
    """``pca`` with empirical limits: the ``1 - alpha`` quantiles (99 %) of T² and SPE on the
    training samples, the recipe of most data-driven monitoring studies and of the source
    notebooks of the Santander et al. (2022) FCCU data set (standardised channels, components
    to 95 % of the variance, alarm when either statistic is over its 99th percentile), so that
    recipe is a row beside ``pca``'s distribution limits.""",
    module=__name__,
)
