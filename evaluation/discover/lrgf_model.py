"""The modelling loop on the LRGF nominal model: which measured input does the network miss?

:class:`LRGFModel` is a :class:`evaluation.discover.ModelAdapter`. ``prepare`` trains one LRGF
network (simulation error, :func:`diagnosers.networks.training.fit_lrgf`) per output channel on the
training part of the record, from its declared inputs. Candidates are
:class:`evaluation.discover.MissingInput`: another measured channel, delayed by ``d`` samples,
missing from an output's model. A candidate enters as an additive path on the network's output,

    y(k) = LRGF(declared inputs)(k) + Σ gain · (x(k − d) − mean_train(x)),

the first-order (linear) expansion of the missing input's influence around the training
operating point, fitted in closed form (least squares of the network's training residual on the
centred, delayed channels) and scored by the loop on held-out data like every other candidate.
Retraining the network with the accepted input is the natural next step for a user; the loop
itself keeps the trained network fixed so that every candidate is compared on the same footing.

Usage::

    from evaluation.discover import discover
    from evaluation.discover.lrgf_model import LRGFModel
    report = discover(data, model=LRGFModel({"T_rx": ["T_fp"]}))
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from diagnosers.networks.lrgf_net import LRGF
from diagnosers.networks.training import fit_lrgf
from evaluation.discover.arx import MissingInput, MissingInputAdapter
from evaluation.discover.base import Candidate, FitResult
from evaluation.discover.data import MeasuredData
from evaluation.discover.fitting import ar1_inflation
from fcc_common.validation import Integer, check

__all__ = ["LRGFModel"]

#: Allowed training epochs of each output's network.
MAX_EPOCHS = Integer(1, 100_000)


class LRGFModel(MissingInputAdapter):
    """Per-output LRGF networks as the declared model; candidates are missing measured inputs."""

    name = "lrgf"

    def __init__(
        self,
        inputs: Mapping[str, Sequence[str]],
        *,
        n_hidden: int = 3,
        order: int = 2,
        max_epochs: int = 1000,
        lr: float = 0.03,
        seed: int = 0,
        candidate_channels: Sequence[str] | None = None,
        candidate_delays: Sequence[int] = (0, 1, 2, 3),
    ):
        super().__init__(inputs, candidate_channels, candidate_delays)
        self.max_epochs = check("max_epochs", max_epochs, MAX_EPOCHS)
        self.n_hidden, self.order = int(n_hidden), int(order)
        self.lr, self.seed = float(lr), int(seed)
        self.networks_: dict[str, LRGF] = {}
        self._y_m: dict[str, np.ndarray] = {}

    def prepare(self, data: MeasuredData, n_train: int) -> None:
        self._prepare_missing_inputs(data, n_train)
        for j, (tgt, declared) in enumerate(self.inputs.items()):
            u = data.stack(declared)  # (E, T, n)
            y = np.asarray(data.channels[tgt], np.float64)[..., None]
            net = LRGF(len(declared), self.n_hidden, self.order, 1, initial_state="steady")
            net = net.double()
            fit_lrgf(
                net,
                list(u[:, :n_train]),
                list(y[:, :n_train]),
                max_epochs=self.max_epochs,
                lr=self.lr,
                patience=self.max_epochs,
                seed=self.seed + j,
            )
            net.eval()
            self.networks_[tgt] = net
            self._y_m[tgt] = net.predict(u)[..., 0]  # (E, T)

    def _extra(self, data: MeasuredData, m: MissingInput, n: int) -> np.ndarray:
        """Centred, delayed source channel (E, n); the first value repeats for k < delay."""
        x = np.asarray(data.channels[m.source], np.float64)
        if m.delay:
            x = np.concatenate([np.repeat(x[:, :1], m.delay, axis=1), x[:, : -m.delay]], axis=1)
        return x[:, :n] - x[:, : self._n_train].mean()

    def predict(
        self, data: MeasuredData, effects: Sequence[Candidate], thetas: np.ndarray, n_samples: int
    ) -> np.ndarray:
        thetas = np.atleast_2d(np.asarray(thetas, np.float64))
        n = int(n_samples)
        out = np.empty((thetas.shape[0], data.n_episodes, n, len(self.output_channels)))
        for j, tgt in enumerate(self.output_channels):
            base = self._y_m[tgt][:, :n]
            idx = [i for i, e in enumerate(effects) if getattr(e, "target", None) == tgt]
            extra = [self._extra(data, effects[i], n) for i in idx]  # type: ignore[arg-type]
            for b in range(thetas.shape[0]):
                out[b, :, :, j] = base + sum(
                    (thetas[b, i] * x for i, x in zip(idx, extra, strict=True)),
                    start=np.zeros_like(base),
                )
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
        """Closed-form least squares of each output's network residual on its extra inputs."""
        theta = np.asarray(theta0, float).copy()
        cov = np.zeros((theta.size, theta.size))
        skip = max(self.candidate_delays, default=0)
        for tgt in self.output_channels:
            idx = [i for i, e in enumerate(effects) if getattr(e, "target", None) == tgt]
            if not idx or not any(free[i] for i in idx):
                continue
            n = data.n_samples
            r = np.asarray(data.channels[tgt], np.float64) - self._y_m[tgt]
            Z = np.stack([self._extra(data, effects[i], n) for i in idx], axis=-1)  # type: ignore[arg-type]
            Zf = Z[:, skip:n_train].reshape(-1, len(idx))
            rf = r[:, skip:n_train].ravel()
            coef, *_ = np.linalg.lstsq(Zf, rf, rcond=None)
            res = rf - Zf @ coef
            s2 = float(res @ res) / max(1, rf.size - len(idx))
            C = s2 * np.linalg.pinv(Zf.T @ Zf) * ar1_inflation(res[None, :, None])
            for jj, i in enumerate(idx):
                theta[i] = coef[jj]
                for kk, i2 in enumerate(idx):
                    cov[i, i2] = C[jj, kk]
        return FitResult(theta, cov, n_evals=1, cost=float("nan"), converged=True)
