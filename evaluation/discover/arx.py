"""Input-output adapters whose candidates are missing measured inputs, and the linear ARX model.

:class:`MissingInputAdapter` is the shared part (declared inputs per output, candidate channels
and delays); :class:`ARXModel` is a linear ARX model per output channel fitted on the training
part; the LRGF adapter (:mod:`evaluation.discover.lrgf_model`) builds on the same base.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from scipy import signal

from evaluation.discover.base import Candidate, FitResult, ParamInfo
from evaluation.discover.data import MeasuredData
from evaluation.discover.fitting import ar1_inflation
from fcc_common.validation import Integer, check

__all__ = ["ARXModel", "MissingInput", "MissingInputAdapter", "missing_input_candidates"]

#: Allowed ARX orders (``na`` and ``nb``).
ARX_ORDER_RANGE = Integer(1, 10)


@dataclass(frozen=True)
class MissingInput:
    """Candidate: measured channel ``source`` at ``delay`` samples missing from ``target``'s model.

    One parameter, the coefficient ``gain`` of source(k − delay) in the target's ARX equation.
    """

    source: str
    target: str
    delay: int
    id: str = ""
    params: tuple[ParamInfo, ...] = (ParamInfo("gain", 1.0, -1e6, 1e6, 0.0, "-", ()),)

    def __post_init__(self) -> None:
        if not self.id:
            object.__setattr__(self, "id", f"input:{self.source}->{self.target}@{self.delay}")


def missing_input_candidates(
    data: MeasuredData,
    inputs: Mapping[str, Sequence[str]],
    pool: Sequence[str],
    delays: Sequence[int],
) -> dict[str, MissingInput]:
    """Every channel of ``pool`` at every delay, for every output, that the model does not have."""
    cands: dict[str, MissingInput] = {}
    for tgt, declared in inputs.items():
        for src in pool:
            if src == tgt or src in declared or (src.startswith("cmd_") and src[4:] in declared):
                continue
            if np.ptp(data.channels[src]) == 0:
                continue  # a constant channel cannot be a missing input
            for d in delays:
                c = MissingInput(src, tgt, d)
                cands[c.id] = c
    return cands


class MissingInputAdapter:
    """Shared part of the input-output adapters whose candidates are missing measured inputs.

    Subclasses set ``name``, call ``super().__init__`` with the declared inputs
    ({output: inputs}) and the candidate channels and delays, and call
    :meth:`_prepare_missing_inputs` in ``prepare``.
    """

    name: str

    def __init__(
        self,
        inputs: Mapping[str, Sequence[str]],
        candidate_channels: Sequence[str] | None,
        candidate_delays: Sequence[int],
    ):
        if not inputs:
            raise ValueError(
                f"{type(self).__name__} needs at least one output channel with its inputs"
            )
        self.inputs = {str(k): tuple(v) for k, v in inputs.items()}
        self.output_channels = tuple(self.inputs)
        self.candidate_channels = None if candidate_channels is None else tuple(candidate_channels)
        self.candidate_delays = tuple(int(d) for d in candidate_delays)
        self._n_train = 0
        self._cands: dict[str, MissingInput] = {}

    def _prepare_missing_inputs(self, data: MeasuredData, n_train: int) -> None:
        need = set(self.output_channels) | {u for v in self.inputs.values() for u in v}
        data.require(sorted(need), self.name)
        self._n_train = int(n_train)
        pool = self.candidate_channels or tuple(data.channels)
        data.require(list(pool), self.name)
        self._cands = missing_input_candidates(data, self.inputs, pool, self.candidate_delays)

    def candidates(self) -> dict[str, Candidate]:
        return dict(self._cands)

    def skipped_candidates(self) -> dict[str, str]:
        return {}

    def other_signals(self, data: MeasuredData) -> list[str]:
        return sorted({u for v in self.inputs.values() for u in v})


class ARXModel(MissingInputAdapter):
    """A linear ARX model per output channel, fitted on the training part, simulated in output error.

    target(k) = Σ_{i=1..na} a_i target(k−i) + Σ_u Σ_{i=0..nb−1} b_{u,i} u(k−delay_u−i) + c

    with the inputs ``inputs[target]``. Candidates are :class:`MissingInput`: every channel of
    ``candidate_channels`` (default: all measured channels other than the target and its declared
    inputs) at delays ``candidate_delays``. Fitting (``fit``) is the closed-form least-squares
    (equation-error) estimate of the whole channel model with the extra regressors; the
    parameter covariance is σ²(XᵀX)⁻¹ with the same AR(1) inflation as the generic fit. For
    ``predict`` with given extra coefficients the declared coefficients are re-estimated given
    them (profiled), so the scored model is consistent with the fit.
    """

    name = "arx"

    def __init__(
        self,
        inputs: Mapping[str, Sequence[str]],
        *,
        na: int = 2,
        nb: int = 3,
        candidate_channels: Sequence[str] | None = None,
        candidate_delays: Sequence[int] = (0, 1, 2, 3),
    ):
        super().__init__(inputs, candidate_channels, candidate_delays)
        self.na = check("na", na, ARX_ORDER_RANGE)
        self.nb = check("nb", nb, ARX_ORDER_RANGE)

    def prepare(self, data: MeasuredData, n_train: int) -> None:
        self._prepare_missing_inputs(data, n_train)

    # -- regression ------------------------------------------------------------------------------
    @staticmethod
    def _shift(x: np.ndarray, d: int) -> np.ndarray:
        """x(k − d) along the last axis, the first value repeated for k < d."""
        if d == 0:
            return x
        return np.concatenate([np.repeat(x[..., :1], d, axis=-1), x[..., :-d]], axis=-1)

    def _regressors(
        self, data: MeasuredData, target: str, extra: Sequence[MissingInput], n: int
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(y (E, n), declared regressors (E, n, q), extra regressors (E, n, r))."""
        y = np.asarray(data.channels[target][:, :n], np.float64)
        cols = [self._shift(y, i) for i in range(1, self.na + 1)]
        for u in self.inputs[target]:
            x = np.asarray(data.channels[u][:, :n], np.float64)
            cols += [self._shift(x, i) for i in range(self.nb)]
        cols.append(np.ones_like(y))
        ext = [
            self._shift(np.asarray(data.channels[m.source][:, :n], float), m.delay) for m in extra
        ]
        X = np.stack(cols, axis=-1)
        Z = np.stack(ext, axis=-1) if ext else np.zeros((*y.shape, 0))
        return y, X, Z

    def _skip(self) -> int:
        return self.na + self.nb + max(self.candidate_delays, default=0)

    def _simulate_channel(
        self,
        data: MeasuredData,
        target: str,
        coef: np.ndarray,
        extra: Sequence[MissingInput],
        gains: np.ndarray,
        n: int,
    ) -> np.ndarray:
        """Output-error simulation of one channel: (E, n)."""
        a = coef[: self.na]
        A = np.concatenate([[1.0], -a])
        y = np.asarray(data.channels[target][:, :n], np.float64)
        out = np.zeros_like(y)
        k = self.na
        terms: list[tuple[np.ndarray, np.ndarray]] = []
        for u in self.inputs[target]:
            terms.append((coef[k : k + self.nb], np.asarray(data.channels[u][:, :n], float)))
            k += self.nb
        c = coef[k]
        for m, g in zip(extra, gains, strict=True):
            b = np.zeros(m.delay + 1)
            b[m.delay] = g
            terms.append((b, np.asarray(data.channels[m.source][:, :n], float)))
        terms.append((np.array([c]), np.ones_like(y)))
        for b, x in terms:
            zi = signal.lfilter_zi(b, A) if len(A) > 1 or len(b) > 1 else None
            if zi is None:
                out += signal.lfilter(b, A, x, axis=-1)
            else:
                out += signal.lfilter(b, A, x, axis=-1, zi=zi[None, :] * x[:, :1])[0]
        return out

    def _lsq(self, X: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        s = self._skip()
        Xf = X[:, s : self._n_train].reshape(-1, X.shape[-1])
        yf = y[:, s : self._n_train].ravel()
        coef, *_ = np.linalg.lstsq(Xf, yf, rcond=None)
        return coef, yf - Xf @ coef

    def predict(
        self, data: MeasuredData, effects: Sequence[Candidate], thetas: np.ndarray, n_samples: int
    ) -> np.ndarray:
        thetas = np.atleast_2d(np.asarray(thetas, np.float64))
        n = int(n_samples)
        out = np.empty((thetas.shape[0], data.n_episodes, n, len(self.output_channels)))
        for b in range(thetas.shape[0]):
            for j, tgt in enumerate(self.output_channels):
                idx = [i for i, e in enumerate(effects) if getattr(e, "target", None) == tgt]
                extra = [effects[i] for i in idx]
                gains = np.array([thetas[b, i] for i in idx])
                y, X, Z = self._regressors(data, tgt, extra, data.n_samples)
                coef, _ = self._lsq(X, y - Z @ gains if gains.size else y)
                out[b, :, :, j] = self._simulate_channel(data, tgt, coef, extra, gains, n)
        return out

    def fit(
        self,
        data: MeasuredData,
        effects: Sequence[Candidate],
        theta0: np.ndarray,
        free: np.ndarray,
        n_train: int,
        sqrt_w: np.ndarray,
    ) -> FitResult:
        """Closed-form joint least squares of each affected channel with its extra inputs."""
        theta = np.asarray(theta0, float).copy()
        cov = np.zeros((theta.size, theta.size))
        for tgt in self.output_channels:
            idx = [i for i, e in enumerate(effects) if getattr(e, "target", None) == tgt]
            if not idx or not any(free[i] for i in idx):
                continue
            y, X, Z = self._regressors(data, tgt, [effects[i] for i in idx], data.n_samples)
            XZ = np.concatenate([X, Z], axis=-1)
            coef, res = self._lsq(XZ, y)
            q = X.shape[-1]
            s = self._skip()
            Xf = XZ[:, s : self._n_train].reshape(-1, XZ.shape[-1])
            dof = max(1, Xf.shape[0] - Xf.shape[1])
            s2 = float(res @ res) / dof
            C = s2 * np.linalg.pinv(Xf.T @ Xf) * ar1_inflation(res[None, :, None])
            for jj, i in enumerate(idx):
                theta[i] = coef[q + jj]
                for kk, i2 in enumerate(idx):
                    cov[i, i2] = C[q + jj, q + kk]
        return FitResult(theta, cov, n_evals=1, cost=float("nan"), converged=True)
