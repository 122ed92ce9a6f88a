"""Classical baselines: fixed limits, PCA (T² + SPE) and an ARX output-error band.

All three learn from healthy episodes only and decide with a confidence level ``1 - alpha``
(``alpha = 0.01`` as in the paper). They give the neural detectors a yardstick:

* ``limits``   - :class:`LimitChecker`: per-channel ``mean ± t_α·std`` limits.
* ``pca``      - :class:`PCADetector`: Hotelling T² and SPE (Q) on standardised measurements.
* ``arx-band`` - :class:`ARXBand`: a linear ARX model of ``T_rx`` from ``T_rg2`` and ``T_fp``
  (the paper's relation (14)) run in simulation, with a band ``y_m ± t_α·σ``.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy import signal as sps
from scipy import stats

from diagnosers.alarm import two_sided_normal_quantile
from diagnosers.base import Decision, Detection, Diagnoser, Episode, require_varying
from diagnosers.mem import band
from diagnosers.registry import register
from fcc_env.validation import Integer, Real, check, check_params, invalid

__all__ = [
    "ARXBand",
    "LimitChecker",
    "PCADetector",
    "fit_percent",
    "hotelling_t2_limit",
    "spe_limit",
    "two_sided_quantile",
]


# ---- shared helpers ----------------------------------------------------------------------------
#: ``t_α``: standard normal quantile with ``alpha`` split over both tails, ``Φ⁻¹(1 - α/2)``
#: (the one implementation is :func:`diagnosers.alarm.two_sided_normal_quantile`).
two_sided_quantile = two_sided_normal_quantile

#: significance level of every baseline
ALPHA = Real(0, 1, closed="neither")


def fit_percent(y: np.ndarray, y_hat: np.ndarray) -> float:
    """Normalised fit ``100·(1 - ‖y - ŷ‖ / ‖y - mean(y)‖)`` in percent (MATLAB ``compare`` style).

    100 is a perfect model, 0 is no better than the mean, negative is worse than the mean.
    """
    y = np.asarray(y, dtype=np.float64).ravel()
    y_hat = np.asarray(y_hat, dtype=np.float64).ravel()
    if y.shape != y_hat.shape:
        raise ValueError(f"y and y_hat must have the same length, got {y.shape} and {y_hat.shape}")
    spread = np.linalg.norm(y - y.mean())
    if spread == 0.0:
        raise ValueError("y is constant, so fit_percent is undefined (division by zero spread)")
    return float(100.0 * (1.0 - np.linalg.norm(y - y_hat) / spread))


def _check_names(name: str, value: object, *, allow_none: bool) -> None:
    if value is None and allow_none:
        return
    if (
        isinstance(value, str)
        or not isinstance(value, Sequence)
        or len(value) == 0
        or not all(isinstance(v, str) for v in value)
        or len(set(value)) != len(value)
    ):
        allowed = "None or " if allow_none else ""
        raise invalid(name, value, f"{allowed}a non-empty list of distinct channel names")


def _channel_indices(
    names: Sequence[str] | None, channels: tuple[str, ...], param: str
) -> np.ndarray:
    """Column indices of ``names`` in ``channels`` (all columns when ``names`` is None)."""
    if names is None:
        return np.arange(len(channels))
    unknown = [n for n in names if n not in channels]
    if unknown:
        raise ValueError(f"{param}: unknown channel(s) {unknown}. Available: {list(channels)}")
    return np.array([channels.index(n) for n in names], dtype=np.int64)


def _stack(episodes: list[Episode]) -> np.ndarray:
    return np.concatenate([ep.y for ep in episodes], axis=0)


# ---- limits ------------------------------------------------------------------------------------
@register("limits")
class LimitChecker(Diagnoser):
    """Per-channel fixed limits ``mean ± t_α·std`` learned from healthy data.

    ``t_α`` is the two-sided standard normal quantile, so for a Gaussian channel each limit pair
    holds the healthy signal with probability ``1 - alpha``. An alarm is raised when any monitored
    channel leaves its limits (with ``c`` channels the healthy false-alarm rate is therefore up
    to ``1 - (1 - alpha)^c``).

    Args:
        alpha: significance level in (0, 1).
        channels: names of the monitored channels, or ``None`` for all.

    Decision arrays (one entry per monitored channel, named by ``signal_names_``):
        signal = measurement [physical units], lower/upper = limits, residual = ``y - mean_``.

    Attributes:
        mean_, std_: per-channel healthy mean and standard deviation (ddof=1).
        lower_, upper_: limits.
    """

    def __init__(self, *, alpha: float = 0.01, channels: Sequence[str] | None = None) -> None:
        self.alpha = alpha
        self.channels = channels

    def _validate_params(self) -> None:
        check("alpha", self.alpha, ALPHA)
        _check_names("channels", self.channels, allow_none=True)

    def _fit(self, episodes: list[Episode]) -> None:
        self.channel_idx_ = _channel_indices(self.channels, self.channels_, "channels")
        y = _stack(episodes)[:, self.channel_idx_]
        if y.shape[0] < 2:
            raise ValueError(f"limits needs at least 2 training samples, got {y.shape[0]}")
        require_varying(y, [self.channels_[i] for i in self.channel_idx_], "limits", every=False)
        self.mean_ = y.mean(axis=0)
        self.std_ = y.std(axis=0, ddof=1)
        self._finish()

    def _finish(self) -> None:
        self.lower_, self.upper_ = band(self.mean_, 0.0, self.std_, self.alpha)
        self.signal_names_ = tuple(self.channels_[i] for i in self.channel_idx_)

    def _get_state(self) -> dict[str, np.ndarray]:
        return {"channel_idx": self.channel_idx_, "mean": self.mean_, "std": self.std_}

    def _set_state(self, state: dict[str, np.ndarray]) -> None:
        self.channel_idx_ = np.asarray(state["channel_idx"], dtype=np.int64)
        self.mean_ = np.asarray(state["mean"], dtype=np.float64)
        self.std_ = np.asarray(state["std"], dtype=np.float64)
        self._finish()

    def _reset(self) -> None:
        pass  # memoryless

    def _update(self, y: np.ndarray) -> Decision:
        s = y[self.channel_idx_]
        alarm = bool(np.any((s < self.lower_) | (s > self.upper_)))
        return Decision(alarm, s, self.lower_.copy(), self.upper_.copy(), s - self.mean_)

    def _detect(self, y: np.ndarray) -> Detection:
        s = y[:, self.channel_idx_]
        n = s.shape[0]
        return Detection(
            alarm=np.any((s < self.lower_) | (s > self.upper_), axis=1),
            signal=s,
            lower=np.broadcast_to(self.lower_, (n, s.shape[1])).copy(),
            upper=np.broadcast_to(self.upper_, (n, s.shape[1])).copy(),
            residual=s - self.mean_,
            signal_names=self.signal_names_,
        )


# ---- PCA ---------------------------------------------------------------------------------------
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
    constant in training keeps scale 1, so any change of it shows up in SPE). The number of
    principal components is ``n_components`` if given, else the smallest ``k`` whose cumulative
    explained variance reaches ``variance_explained``; it is capped at ``m - 1`` (``m`` monitored
    channels) so that a residual subspace, and hence SPE, exists. Alarm when T² > ``T2_lim`` or
    SPE > ``Q_lim``, both at level ``alpha``.

    Args:
        alpha: significance level in (0, 1) for both limits.
        variance_explained: target cumulative explained variance in (0, 1], used when
            ``n_components`` is None.
        n_components: number of retained components (``1 <= k <= m - 1``), or None.
        channels: monitored channel names (at least 2), or None for all.

    Decision arrays, names ``("T2", "SPE")`` (dimensionless, standardised units squared):
        signal = residual = ``[T², SPE]``, lower = ``[-inf, -inf]``, upper = ``[T2_lim, Q_lim]``.
        There is no measured-minus-predicted output here, so ``residual`` repeats the statistics.

    Attributes:
        mean_, scale_: standardisation; components_ ``(m, k)`` loadings; eigenvalues_ ``(m,)``
        covariance eigenvalues (descending); n_components_; n_samples_; t2_limit_; q_limit_.
    """

    def __init__(
        self,
        *,
        alpha: float = 0.01,
        variance_explained: float = 0.95,
        n_components: int | None = None,
        channels: Sequence[str] | None = None,
    ) -> None:
        self.alpha = alpha
        self.variance_explained = variance_explained
        self.n_components = n_components
        self.channels = channels

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
        _check_names("channels", self.channels, allow_none=True)

    def _fit(self, episodes: list[Episode]) -> None:
        idx = _channel_indices(self.channels, self.channels_, "channels")
        m = idx.size
        if m < 2:
            raise ValueError(f"pca needs at least 2 monitored channels, got {m}")
        x = _stack(episodes)[:, idx]
        n = x.shape[0]
        if n <= m:
            raise ValueError(f"pca needs more training samples than channels ({m}), got {n}")
        require_varying(x, [self.channels_[i] for i in idx], "pca", every=False)
        mean = x.mean(axis=0)
        scale = x.std(axis=0, ddof=1)
        scale = np.where(scale > 0.0, scale, 1.0)
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
        self._finish()

    def _finish(self) -> None:
        k = self.n_components_
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
        }

    def _set_state(self, state: dict[str, np.ndarray]) -> None:
        self.channel_idx_ = np.asarray(state["channel_idx"], dtype=np.int64)
        self.mean_ = np.asarray(state["mean"], dtype=np.float64)
        self.scale_ = np.asarray(state["scale"], dtype=np.float64)
        self.components_ = np.asarray(state["components"], dtype=np.float64)
        self.eigenvalues_ = np.asarray(state["eigenvalues"], dtype=np.float64)
        self.n_components_ = int(self.components_.shape[1])
        self.n_samples_ = int(state["n_samples"])
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


# ---- ARX output-error band ---------------------------------------------------------------------
@register("arx-band")
class ARXBand(Diagnoser):
    """Linear ARX model of one output, run in simulation, with a fixed-width band around it.

    Model (one step, least squares on the healthy training episodes, with a constant ``c``)::

        y(t) = Σ_{i=1..na} a_i y(t-i) + Σ_k Σ_{j=0..nb-1} b_{k,j} u_k(t-nk-j) + c

    For detection the model runs in *simulation* (output-error) mode: its own past outputs
    ``y_m`` replace the measured ``y`` on the right-hand side, so a fault on ``y`` is not absorbed
    into the prediction. Band: ``y_m ± t_α·σ``, ``σ`` the root mean square of the free-run residual
    ``y - y_m`` on the training episodes (the band is centred on ``y_m``, so the spread is taken
    about zero, not about the residual's mean). Alarm when ``y`` leaves the band.

    Warm-up: the first ``n_warmup_ = max(na, nk + nb - 1)`` samples of each episode lack a full
    regressor; there ``y_m`` is set to the measured output (so the residual is 0 and no alarm is
    possible) and the simulation starts from those values.

    Args:
        output: name of the modelled output channel.
        inputs: names of the input channels.
        na: number of output lags (``0 <= na <= 50``; ``0`` gives an FIR model).
        nb: number of lags per input (``1 <= nb <= 200``).
        nk: input delay in samples (``0 <= nk <= 100``); the default 0 lets the model use the
            current input samples, which are measured together with the output.
        alpha: significance level in (0, 1).

    Decision arrays (one entry, named ``output``, °C for ``T_rx``):
        signal = measured output, lower/upper = band, residual = ``y - y_m``.

    Attributes:
        a_ ``(na,)``, b_ ``(n_inputs, nb)``, c_: model coefficients (physical units).
        sigma_: band half-width before scaling by ``t_α``.
        train_fit_percent_: :func:`fit_percent` of the free run on the training data.
    """

    def __init__(
        self,
        *,
        output: str = "T_rx",
        inputs: Sequence[str] = ("T_rg2", "T_fp"),
        na: int = 2,
        nb: int = 10,
        nk: int = 0,
        alpha: float = 0.01,
    ) -> None:
        self.output = output
        self.inputs = inputs
        self.na = na
        self.nb = nb
        self.nk = nk
        self.alpha = alpha

    def _validate_params(self) -> None:
        if not isinstance(self.output, str):
            raise invalid("output", self.output, "a channel name (str)")
        _check_names("inputs", self.inputs, allow_none=False)
        if self.output in self.inputs:
            raise ValueError(
                f"output={self.output!r} must not also be one of inputs={self.inputs!r}"
            )
        check_params(
            self.get_params(),
            {"na": Integer(0, 50), "nb": Integer(1, 200), "nk": Integer(0, 100), "alpha": ALPHA},
        )

    # -- model ---------------------------------------------------------------------------------
    @property
    def n_warmup_(self) -> int:
        """Samples at the start of an episode during which ``y_m`` follows the measurement."""
        return max(int(self.na), int(self.nk) + int(self.nb) - 1)

    def _regressors(self, y: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """One-step regression matrix ``(T - n0, na + n_in·nb)`` and target for one episode."""
        n0, na, nb, nk = self.n_warmup_, int(self.na), int(self.nb), int(self.nk)
        t = np.arange(n0, y.shape[0])
        cols = [y[t - i] for i in range(1, na + 1)]
        for k in range(u.shape[1]):
            cols += [u[t - nk - j, k] for j in range(nb)]
        return np.column_stack(cols) if cols else np.empty((t.size, 0)), y[t]

    def _fit(self, episodes: list[Episode]) -> None:
        self.output_idx_ = _channel_indices([self.output], self.channels_, "output")
        self.input_idx_ = _channel_indices(list(self.inputs), self.channels_, "inputs")
        require_varying(
            np.concatenate([ep.y[:, self.output_idx_] for ep in episodes]),
            [self.output],
            "arx-band",
        )
        n0 = self.n_warmup_
        n_par = int(self.na) + self.input_idx_.size * int(self.nb) + 1
        parts = [self._regressors(*self._split(ep.y)) for ep in episodes if ep.n_samples > n0]
        n_rows = sum(p[1].size for p in parts)
        if n_rows < 2 * n_par:
            raise ValueError(
                f"arx-band needs at least {2 * n_par} regression rows for {n_par} parameters, "
                f"got {n_rows}; give longer healthy episodes or smaller na/nb"
            )
        phi = np.concatenate([p[0] for p in parts])
        target = np.concatenate([p[1] for p in parts])
        # Centre the data before least squares: temperatures of ~500 °C next to a constant column
        # make the raw problem badly conditioned. The constant is mapped back afterwards.
        phi_mean, t_mean = phi.mean(axis=0), target.mean()
        theta, *_ = np.linalg.lstsq(phi - phi_mean, target - t_mean, rcond=None)
        na = int(self.na)
        self.a_ = theta[:na].copy()
        self.b_ = theta[na:].reshape(self.input_idx_.size, int(self.nb))
        self.c_ = float(t_mean - phi_mean @ theta)
        poles = np.roots(np.r_[1.0, -self.a_]) if na else np.empty(0)
        if poles.size and np.max(np.abs(poles)) >= 1.0:
            raise ValueError(
                f"the fitted ARX model is unstable (pole magnitude {np.max(np.abs(poles)):.4f} "
                f">= 1), so it cannot run in simulation; try a smaller na or more varied data"
            )
        resid, y_all = [], []
        for ep in episodes:
            y, u = self._split(ep.y)
            y_m = self._simulate(u, y[: min(n0, y.size)], y.size)
            resid.append((y - y_m)[n0:])
            y_all.append((y, y_m))
        r = np.concatenate(resid)
        self.sigma_ = float(np.sqrt(np.mean(r**2)))
        y_cat = np.concatenate([p[0][n0:] for p in y_all])
        y_m_cat = np.concatenate([p[1][n0:] for p in y_all])
        self.train_fit_percent_ = fit_percent(y_cat, y_m_cat) if np.ptp(y_cat) > 0 else float("nan")
        self._finish()

    def _finish(self) -> None:
        self.signal_names_ = (self.channels_[int(self.output_idx_[0])],)
        # the band half-width t_α·σ, from mem.band's one formula
        _, upper = band(0.0, 0.0, self.sigma_, self.alpha)
        self.half_width_ = float(upper)

    def _split(self, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return y[:, self.output_idx_[0]], y[:, self.input_idx_]

    def _simulate(self, u: np.ndarray, y_init: np.ndarray, n: int) -> np.ndarray:
        """Free run over ``n`` samples; ``y_init`` supplies the warm-up outputs."""
        n0 = min(self.n_warmup_, n)
        y_m = np.empty(n)
        y_m[:n0] = y_init[:n0]
        if n <= n0:
            return y_m
        # Exogenous part v(t) = Σ b u(t-nk-j) + c, vectorised as FIR filters of each input.
        v = np.full(n, self.c_)
        for k in range(u.shape[1]):
            fir = sps.lfilter(self.b_[k], [1.0], u[:, k])
            v[int(self.nk) :] += fir[: n - int(self.nk)]
        na = int(self.na)
        if na == 0:
            y_m[n0:] = v[n0:]
            return y_m
        # AR recursion y_m(t) = Σ a_i y_m(t-i) + v(t) as an IIR filter started from the warm-up.
        den = np.r_[1.0, -self.a_]
        # n0 >= na here, so the last na warm-up outputs (newest first) set the filter state.
        zi = sps.lfiltic([1.0], den, y=y_m[n0 - 1 :: -1][:na])
        y_m[n0:], _ = sps.lfilter([1.0], den, v[n0:], zi=zi)
        return y_m

    def simulate(self, u: np.ndarray, y0: float | np.ndarray) -> np.ndarray:
        """Free-run (simulation) output of the fitted model.

        Args:
            u: inputs, shape ``(T, n_inputs)`` in the order of ``inputs``, physical units.
            y0: warm-up outputs, a scalar (held constant) or an array of at least ``n_warmup_``
                measured outputs (only the first ``n_warmup_`` are used).

        Returns:
            ``y_m``, shape ``(T,)``; its first ``n_warmup_`` entries are the warm-up values.
        """
        self._check_fitted()
        u = np.asarray(u, dtype=np.float64)
        if u.ndim != 2 or u.shape[1] != self.input_idx_.size:
            raise ValueError(
                f"u must have shape (T, {self.input_idx_.size}) for inputs {list(self.inputs)}, "
                f"got {u.shape}"
            )
        n0 = min(self.n_warmup_, u.shape[0])
        y0 = np.asarray(y0, dtype=np.float64)
        y_init = np.full(n0, float(y0)) if y0.ndim == 0 else y0.ravel()
        if y_init.size < n0:
            raise ValueError(f"y0 needs at least {n0} warm-up outputs, got {y_init.size}")
        return self._simulate(u, y_init, u.shape[0])

    # -- state ---------------------------------------------------------------------------------
    def _get_state(self) -> dict[str, np.ndarray]:
        return {
            "output_idx": self.output_idx_,
            "input_idx": self.input_idx_,
            "a": self.a_,
            "b": self.b_,
            "c": np.array(self.c_),
            "sigma": np.array(self.sigma_),
            "train_fit_percent": np.array(self.train_fit_percent_),
        }

    def _set_state(self, state: dict[str, np.ndarray]) -> None:
        self.output_idx_ = np.asarray(state["output_idx"], dtype=np.int64)
        self.input_idx_ = np.asarray(state["input_idx"], dtype=np.int64)
        self.a_ = np.asarray(state["a"], dtype=np.float64)
        self.b_ = np.asarray(state["b"], dtype=np.float64).reshape(self.input_idx_.size, -1)
        self.c_ = float(state["c"])
        self.sigma_ = float(state["sigma"])
        self.train_fit_percent_ = float(state["train_fit_percent"])
        self._finish()

    # -- streaming -----------------------------------------------------------------------------
    def _reset(self) -> None:
        self._t = 0
        self._y_hist = np.zeros(int(self.na))  # past y_m, newest first
        # past inputs, newest first: row j holds u(t-j) once the current sample is pushed
        self._u_hist = np.zeros((int(self.nk) + int(self.nb), self.input_idx_.size))

    def _update(self, y: np.ndarray) -> Decision:
        y_now, u_now = y[self.output_idx_[0]], y[self.input_idx_]
        self._u_hist = np.roll(self._u_hist, 1, axis=0)
        self._u_hist[0] = u_now
        if self._t < self.n_warmup_:
            y_m = float(y_now)
        else:
            lagged = self._u_hist[int(self.nk) :].T  # (n_in, nb), column j = u(t-nk-j)
            y_m = float(self.a_ @ self._y_hist + np.sum(self.b_ * lagged) + self.c_)
        if self._y_hist.size:
            self._y_hist = np.roll(self._y_hist, 1)
            self._y_hist[0] = y_m
        self._t += 1
        lo, hi = y_m - self.half_width_, y_m + self.half_width_
        return Decision(
            alarm=bool(y_now < lo or y_now > hi),
            signal=np.array([y_now]),
            lower=np.array([lo]),
            upper=np.array([hi]),
            residual=np.array([y_now - y_m]),
        )

    def _detect(self, y: np.ndarray) -> Detection:
        y_out, u = self._split(y)
        y_m = self._simulate(u, y_out, y_out.size)
        lo, hi = y_m - self.half_width_, y_m + self.half_width_
        return Detection(
            alarm=(y_out < lo) | (y_out > hi),
            signal=y_out[:, None].copy(),
            lower=lo[:, None],
            upper=hi[:, None],
            residual=(y_out - y_m)[:, None],
            signal_names=self.signal_names_,
        )
