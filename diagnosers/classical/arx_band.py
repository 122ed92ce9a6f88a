"""The ``arx-band`` detector: a linear ARX model of one output, run in simulation, with a band.

The default is the paper's relation (14): ``T_rx`` from ``T_rg2`` and ``T_fp``.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy import signal as sps

from diagnosers.classical.channel_selection import ALPHA, channel_indices, check_channel_names
from diagnosers.contract import require_varying
from diagnosers.detection import Decision, Detection
from diagnosers.diagnoser import Diagnoser
from diagnosers.episode.record import Episode
from diagnosers.registry import register
from diagnosers.stages.band import band
from fcc_common.validation import Integer, check_params, invalid

__all__ = ["ARXBand", "fit_percent"]


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
        output: name of the modelled output channel; default ``"T_rx"``.
        inputs: names of the input channels, distinct; default ``("T_rg2", "T_fp")`` (with
            ``T_rx``, the paper's relation (14)).
        na: number of output lags (``0 <= na <= 50``; ``0`` gives an FIR model); default 2.
        nb: number of lags per input (``1 <= nb <= 200``); default 10. More lags fit slower
            input dynamics and lengthen the warm-up.
        nk: input delay in samples (``0 <= nk <= 100``); the default 0 lets the model use the
            current input samples, which are measured together with the output.
        alpha: significance level in (0, 1), default 0.01: the band is ``y_m ± t_α·σ``, so a
            smaller ``alpha`` widens it (fewer false alarms, later detection).

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
        check_channel_names("inputs", self.inputs, allow_none=False)
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
        self.output_idx_ = channel_indices([self.output], self.channels_, "output")
        self.input_idx_ = channel_indices(list(self.inputs), self.channels_, "inputs")
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
        # the band half-width t_α·σ, from the one formula of diagnosers.stages.band.band
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
