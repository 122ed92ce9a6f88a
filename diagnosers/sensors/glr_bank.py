"""A GLR bank of bias hypotheses: which sensor reads a constant offset, from an alarm's first
samples (issue 43, sensor isolation).

At an alarm's start, one filter per sensor ``c`` starts from the all-sensor filter's prior
with channel ``c``'s readings lowered by a trial offset ``b1``. A Kalman filter's gains do not
depend on the data, so its innovation is affine in a constant offset on a reading: with
``Δ_c = white_c − white_0`` (``white_0`` the all-sensor filter's whitened innovation, which
the leave-out bank already has), the log-likelihood of "channel c reads b too high since the
start" is ``ℓ_0 − ½ Σ |white_0 + (b / b1) Δ_c|² + ½ Σ |white_0|²``, its maximum over b

    ``g_c = ½ (Σ white_0·Δ_c)² / Σ |Δ_c|²``  (nats),  at  ``b̂_c = −b1 Σ white_0·Δ_c / Σ |Δ_c|²``

the generalised likelihood ratio of a step on channel c through the model's own dynamics
(Willsky and Jones 1976), the closed loop's answer included (the filter reads the controller's
moves as inputs). The sensor named is the one of the largest ``g_c``.

Why, beside the leave-out bank: a leave-out filter throws its channel's reading away, a bias
that may change every sample; the hypothesis "a constant offset on c" keeps that reading's
own dynamics, which is what tells a T_fp bias from a T_rx one within tens of samples
(``evaluation.tracks.sensor_bound`` measures 9-39 nats in 30 samples on the exact model; the
leave-out filters' slow consistency needs hundreds, ``lab/sensor-validation.md``). The UKF
is close to linear in an offset where its step gate does not fire; the trial offset ``b1``
sits inside the track's sizes so that the channel of the true hypothesis is corrected toward
its true value rather than away from it.
"""

from __future__ import annotations

import math

import numpy as np

from diagnosers.filters.ukf_kernels import sigma_weights, workspace
from diagnosers.filters.ukf_model import fcc_sample
from fcc_env.physics import njit_kernel

__all__ = ["RAMP_SAMPLES", "GLRBank", "glr_bank_run"]

#: The trial ramp grows by the trial offset ``b1`` over this many samples (5 °C over 1000
#: samples: inside the ``sensor`` track's drifts of 0.5-2 °C per hour at 10 s a sample).
RAMP_SAMPLES = 1000.0


@njit_kernel
def glr_bank_run(
    model,
    Ms,
    Ps,
    Y,
    WHITE0,
    q,
    w,
    r_abs,
    r_rel,
    gate_idx,
    gate_lin,
    gate,
    n_scratch,
    b1,
    r1,
    age,
    acc,
    GAIN,
    RAMP,
    SIZE,
) -> None:
    """The hypothesis filters over ``Y`` (T, n_obs): filter ``c`` (priors ``Ms[c]``, ``Ps[c]``,
    advanced in place) reads channel ``c`` lowered by ``b1``, filter ``C + c`` lowered by
    ``r1`` times the samples since the start (``age[0]``, in place); ``WHITE0`` (T, ny) the
    all-sensor filter's whitened innovations of the same samples; ``acc`` (C, 5) the sums
    ``Σ w0·Δs, Σ Δs², Σ w0·Δr, Σ Δr², Σ Δs·Δr`` since the start (in place). Out, after each
    sample: ``GAIN`` (T, C) the step's GLR (nats), ``RAMP`` (T, C) what a ramp beside the step
    adds to it (nats), ``SIZE`` (T, C) the step's ``b̂_c``."""
    C2, n = Ms.shape
    C = C2 // 2
    ny = r_abs.shape[0]
    G = gate_idx.shape[0]
    ws = workspace(n, ny, n_scratch)
    innov, stdz, white = np.empty(ny), np.empty(ny), np.empty(ny)
    S = np.empty((ny, ny))
    post, post_sd = np.empty(n), np.empty(n)
    jumps = np.empty(G, dtype=np.bool_)
    y = np.empty(Y.shape[1])
    ds = np.empty((C, ny))
    fixed = (q, r_abs, r_rel, gate_idx, gate_lin, gate, w)
    out = (innov, stdz, white, S, post, post_sd, jumps)
    for k in range(Y.shape[0]):
        age[0] += 1.0
        for h in range(C2):
            c = h % C
            y[:] = Y[k]
            y[c] -= b1 if h < C else r1 * age[0]
            fcc_sample(model, Ms[h], Ps[h], y, fixed, ws, out)
            for j in range(ny):
                w0, wc = WHITE0[k, j], white[j]
                d = wc - w0 if math.isfinite(w0) and math.isfinite(wc) else 0.0
                w0 = w0 if math.isfinite(w0) else 0.0
                if h < C:
                    ds[c, j] = d
                    acc[c, 0] += w0 * d
                    acc[c, 1] += d * d
                else:
                    acc[c, 2] += w0 * d
                    acc[c, 3] += d * d
                    acc[c, 4] += ds[c, j] * d
        for c in range(C):
            ws_, ss, wr, rr, sr = acc[c, 0], max(acc[c, 1], 1e-12), acc[c, 2], acc[c, 3], acc[c, 4]
            GAIN[k, c] = 0.5 * ws_ * ws_ / ss
            SIZE[k, c] = -b1 * ws_ / ss
            det = ss * rr - sr * sr
            joint = 0.5 * (rr * ws_ * ws_ - 2.0 * sr * ws_ * wr + ss * wr * wr) / det
            RAMP[k, c] = max(joint - GAIN[k, c], 0.0) if det > 1e-12 * ss * rr else 0.0


class GLRBank:
    """The hypothesis filters on one state estimator's compiled model (``estimator``: the
    leave-out bank's, so the same parameters and plant side); ``b1`` the trial offset."""

    def __init__(self, estimator, b1: float, r1: float | None = None) -> None:
        self.estimator = estimator
        self.b1 = float(b1)
        self.r1 = self.b1 / RAMP_SAMPLES if r1 is None else float(r1)
        m = estimator.filter_model
        self.n_channels = int(m.r_abs.shape[0])
        cfg = estimator.config
        self.weights = sigma_weights(m.n, cfg.alpha, cfg.beta, cfg.kappa)
        self.gate = math.inf if cfg.step_gate is None else float(cfg.step_gate)

    def start(self, m0: np.ndarray, p0: np.ndarray) -> dict[str, np.ndarray]:
        """A fresh bank from the all-sensor filter's prior ``m0`` (n,), ``p0`` (n, n)."""
        C = self.n_channels
        return {
            "M": np.repeat(m0[None], 2 * C, axis=0),
            "P": np.repeat(p0[None], 2 * C, axis=0),
            "age": np.zeros(1),
            "acc": np.zeros((C, 5)),
        }

    def run(
        self, state: dict[str, np.ndarray], Y: np.ndarray, white0: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Advance ``state`` over ``Y`` (T, n_obs); ``(gain, ramp, size)`` (T, C) after each
        sample (:func:`glr_bank_run`)."""
        m = self.estimator.filter_model
        T, C = Y.shape[0], self.n_channels
        gain, ramp, size = np.empty((T, C)), np.empty((T, C)), np.empty((T, C))
        glr_bank_run(
            m.model,
            state["M"],
            state["P"],
            np.ascontiguousarray(Y, dtype=np.float64),
            np.ascontiguousarray(white0, dtype=np.float64),
            m.q,
            self.weights,
            m.r_abs,
            m.r_rel,
            m.gate_idx,
            m.gate_lin,
            self.gate,
            m.n_scratch,
            self.b1,
            self.r1,
            state["age"],
            state["acc"],
            gain,
            ramp,
            size,
        )
        return gain, ramp, size
