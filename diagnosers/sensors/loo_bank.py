"""A generalised observer scheme for the FCC's sensors: one state estimator on every sensor,
and one per sensor that leaves that sensor out (Frank 1990; after Clark's dedicated observers).

Filter 0 reads all eight measured channels; filter ``c + 1`` reads every channel but channel
``c``. Leaving a channel out is done by giving it a measurement noise ``LEAVE_OUT_FACTOR``
times its own (so its Kalman gain is about ``1 / LEAVE_OUT_FACTOR²`` of the normal one, 10⁻⁶:
over a whole episode a 10 °C bias moves that filter's states by micro-degrees), which keeps the
compiled filter of :mod:`diagnosers.filters` unchanged: the same model, the same step gate, the
same square-root algebra.

The scheme's structure: a fault on sensor ``c`` enters every filter but filter ``c + 1``, so
filter ``c + 1``'s innovations stay white while the others' do not (isolation), and filter
``c + 1``'s *prediction* of sensor ``c`` from the other seven sensors and the model
(:attr:`BankOutput.dedicated`) is the analytically redundant reading of that sensor: the
faulty reading minus it is the fault's own shape (a step, a ramp, more noise).

Why leave one out rather than one filter per sensor (Clark's dedicated scheme): the FCC's
states are not observable from one thermocouple alone; from seven they are, so every filter
of the bank stays a good estimator and only the left-out sensor's redundancy is tested.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from diagnosers.filters import FCCStateEstimator, UKFConfig
from diagnosers.filters.ukf_kernels import sigma_weights, workspace
from diagnosers.filters.ukf_model import fcc_sample
from fcc_env.params import FCCParams
from fcc_env.physics import njit_kernel

__all__ = ["LEAVE_OUT_FACTOR", "BankOutput", "LeaveOneOutBank", "loo_bank_run"]

#: Measurement-noise multiplier of the channel a filter leaves out (its std): large enough that
#: the channel cannot move the filter, small enough that its innovation variance minus the
#: inflated noise keeps 10 significant digits in double precision.
LEAVE_OUT_FACTOR = 1000.0


@njit_kernel
def loo_bank_run(
    model, Ms, Ps, Y, q, w, R_abs, R_rel, gate_idx, gate_lin, gate, n_scratch, WHITE, DED, PM, PP
) -> None:
    """Every filter of the bank on the samples ``Y`` (T, n_obs), in order.

    ``Ms`` (H, n) and ``Ps`` (H, n, n) are the filters' priors (advanced in place); ``R_abs``,
    ``R_rel`` (H, 8) their measurement-noise stds (row 0 the true ones, row ``c + 1`` with
    channel ``c`` inflated by :data:`LEAVE_OUT_FACTOR`). Out: ``WHITE`` (T, H, 8) the whitened
    innovations; ``DED`` (T, 8) channel ``c``'s innovation in filter ``c + 1`` over its
    standard deviation with the channel's *own* noise (NaN on a skipped sample); ``PM`` (T, n),
    ``PP`` (T, n, n) filter 0's prior before each sample (where a bank of bias hypotheses
    starts, :mod:`diagnosers.sensors.glr_bank`).
    """
    H, n = Ms.shape
    ny = R_abs.shape[1]
    G = gate_idx.shape[0]
    ws = workspace(n, ny, n_scratch)
    innov, stdz = np.empty(ny), np.empty(ny)
    S = np.empty((ny, ny))
    post, post_sd = np.empty(n), np.empty(n)
    jumps = np.empty(G, dtype=np.bool_)
    k2 = LEAVE_OUT_FACTOR * LEAVE_OUT_FACTOR
    for k in range(Y.shape[0]):
        PM[k] = Ms[0]
        PP[k] = Ps[0]
        for h in range(H):
            fixed = (q, R_abs[h], R_rel[h], gate_idx, gate_lin, gate, w)
            out = (innov, stdz, WHITE[k, h], S, post, post_sd, jumps)
            status = fcc_sample(model, Ms[h], Ps[h], Y[k], fixed, ws, out)
            if h == 0:
                continue
            c = h - 1
            if status & 1:
                DED[k, c] = np.nan
                continue
            sd = R_abs[0, c] + R_rel[0, c] * abs(Y[k, c])
            var = S[c, c] - (k2 - 1.0) * sd * sd  # the prediction's variance plus own noise
            DED[k, c] = innov[c] / math.sqrt(max(var, sd * sd))


@dataclass(frozen=True)
class BankOutput:
    """What :meth:`LeaveOneOutBank.run` returns for ``T`` samples.

    ``white`` (T, 9, 8): each filter's whitened innovations (filter 0 all sensors, filter
    ``c + 1`` without sensor ``c``; the left-out channel's entry is about 1/1000 of the
    others'); ``dedicated`` (T, 8): sensor ``c``'s reading less filter ``c + 1``'s prediction,
    in standard deviations (standard normal while sensor ``c`` is right); ``prior_m`` (T, n),
    ``prior_p`` (T, n, n): filter 0's prior before each sample.
    """

    white: np.ndarray
    dedicated: np.ndarray
    prior_m: np.ndarray
    prior_p: np.ndarray


class LeaveOneOutBank:
    """The nine filters of the scheme on one model (``params``, never a scored plant's) and
    plant side (``config``); :meth:`start` gives fresh priors, :meth:`run` advances them."""

    def __init__(self, params: FCCParams, config: UKFConfig) -> None:
        est = FCCStateEstimator(params, config)
        self.estimator = est
        m = est.filter_model
        self.n_channels = int(m.r_abs.shape[0])
        H = self.n_channels + 1
        self.R_abs = np.tile(m.r_abs, (H, 1))
        self.R_rel = np.tile(m.r_rel, (H, 1))
        for c in range(self.n_channels):
            self.R_abs[c + 1, c] *= LEAVE_OUT_FACTOR
            self.R_rel[c + 1, c] *= LEAVE_OUT_FACTOR
        self.weights = sigma_weights(m.n, config.alpha, config.beta, config.kappa)
        self.gate = math.inf if config.step_gate is None else float(config.step_gate)

    @property
    def n_filters(self) -> int:
        return self.n_channels + 1

    def start(self) -> tuple[np.ndarray, np.ndarray]:
        """Fresh priors ``(Ms, Ps)`` of the nine filters (the estimator's initial prior)."""
        return self.estimator.initial_prior(self.n_filters)

    def run(self, Ms: np.ndarray, Ps: np.ndarray, Y: np.ndarray) -> BankOutput:
        """Advance the priors ``Ms``, ``Ps`` (in place) over the observations ``Y`` (T, n_obs)."""
        Y = np.ascontiguousarray(Y, dtype=np.float64)
        m = self.estimator.filter_model
        T = Y.shape[0]
        white = np.empty((T, self.n_filters, self.n_channels))
        ded = np.empty((T, self.n_channels))
        pm, pp = np.empty((T, m.n)), np.empty((T, m.n, m.n))
        loo_bank_run(
            m.model,
            Ms,
            Ps,
            Y,
            m.q,
            self.weights,
            self.R_abs,
            self.R_rel,
            m.gate_idx,
            m.gate_lin,
            self.gate,
            m.n_scratch,
            white,
            ded,
            pm,
            pp,
        )
        return BankOutput(white, ded, pm, pp)
