"""The compiled integrator: RK4 stepping of the model's right-hand side with parameters scaled
per sample (faults, effects), and the measurement noise, for one episode (the env) and for a
batch (numba ``prange`` over episodes).

The model itself (:func:`fcc_env.physics.rhs_core`, the measurement map) lives in
:mod:`fcc_env.physics`; this module only advances it in time, so every path integrates the same
right-hand side with the same stage arithmetic.
"""

from __future__ import annotations

import numba
import numpy as np

from fcc_env.params import N_MEASUREMENTS, N_STATES, FCCParams
from fcc_env.physics import (
    N_AUX,
    as_param_array,
    measure_core,
    measurements_into,
    njit_kernel,
    rhs_core,
)
from fcc_env.regulatory import (
    CONTROLLER_STATE_SIZE,
    apply_controller_outputs,
    controller_update,
)

#: Parameter slots of "no fault" (entries < 0 are unused).
NO_FAULT = np.array([-1, -1], dtype=np.int64)


def open_loop_controller_args(B: int, T: int) -> tuple[np.ndarray, ...]:
    """The controller arguments of :func:`simulate_kernel` for open-loop episodes (unused)."""
    return (
        np.zeros((B, CONTROLLER_STATE_SIZE)),
        np.zeros((B, 1, 2)),
        np.empty(0),
        np.zeros((B, 1), dtype=np.bool_),
    )


@njit_kernel
def _rk4_inplace(
    x: np.ndarray, u: np.ndarray, p: np.ndarray, h: float, n: int, work: np.ndarray, k1_ready: bool
):
    """Advance x by n RK4 steps of h seconds (inputs and parameters held).

    With ``k1_ready`` the caller has already evaluated the RHS at (x, u, p) into ``work[0]``.
    """
    k1, k2, k3, k4, xt, aux = work[0], work[1], work[2], work[3], work[4], work[5]
    for step in range(n):
        if not (k1_ready and step == 0):
            rhs_core(x, u, p, k1, aux)
        for i in range(N_STATES):
            xt[i] = x[i] + 0.5 * h * k1[i]
        rhs_core(xt, u, p, k2, aux)
        for i in range(N_STATES):
            xt[i] = x[i] + 0.5 * h * k2[i]
        rhs_core(xt, u, p, k3, aux)
        for i in range(N_STATES):
            xt[i] = x[i] + h * k3[i]
        rhs_core(xt, u, p, k4, aux)
        for i in range(N_STATES):
            x[i] = x[i] + h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])


@njit_kernel
def _apply_mult(p_base: np.ndarray, p_out: np.ndarray, pidx: np.ndarray, mult: np.ndarray):
    """p_out = p_base with p_out[pidx[j]] *= mult[j] (entries < 0 are unused slots)."""
    for j in range(p_base.shape[0]):
        p_out[j] = p_base[j]
    for j in range(pidx.shape[0]):
        if pidx[j] >= 0:
            p_out[pidx[j]] = p_out[pidx[j]] * mult[j]


@njit_kernel
def _noisy(y: float, z: float, std_abs: float, std_rel: float, scale: float) -> np.float32:
    return np.float32(y + (scale * (std_abs + std_rel * abs(y))) * z)


@njit_kernel
def noisy_kernel(
    y: np.ndarray, z: np.ndarray, std_abs: np.ndarray, std_rel: np.ndarray, scale: float
) -> np.ndarray:
    """Noisy float32 measurement of one sample (the env's path; the batch kernel inlines it)."""
    out = np.empty(y.shape[0], dtype=np.float32)
    for i in range(y.shape[0]):
        out[i] = _noisy(y[i], z[i], std_abs[i], std_rel[i], scale)
    return out


@njit_kernel
def step_kernel(
    x: np.ndarray,
    u: np.ndarray,
    p_base: np.ndarray,
    pidx: np.ndarray,
    mult: np.ndarray,
    h: float,
    substeps: int,
) -> None:
    """One sample of one episode, in place on ``x`` (the env's step)."""
    p = np.empty_like(p_base)
    _apply_mult(p_base, p, pidx, mult)
    work = np.empty((6, N_STATES))
    _rk4_inplace(x, u, p, h, substeps, work, False)


@njit_kernel
def measure_kernel(
    x: np.ndarray, u: np.ndarray, p_base: np.ndarray, pidx: np.ndarray, mult: np.ndarray
) -> np.ndarray:
    p = np.empty_like(p_base)
    _apply_mult(p_base, p, pidx, mult)
    y = np.empty(N_MEASUREMENTS)
    measure_core(x, u, p, y)
    return y


@njit_kernel
def aux_kernel(
    x: np.ndarray, u: np.ndarray, p_base: np.ndarray, pidx: np.ndarray, mult: np.ndarray
) -> np.ndarray:
    p = np.empty_like(p_base)
    _apply_mult(p_base, p, pidx, mult)
    dx = np.empty(N_STATES)
    aux = np.empty(N_AUX)
    rhs_core(x, u, p, dx, aux)
    return aux


@numba.njit(cache=True, nogil=True, parallel=True, error_model="numpy")
def rhs_batch_kernel(X: np.ndarray, U: np.ndarray, P: np.ndarray, DX: np.ndarray, AUX: np.ndarray):
    """RHS of B episodes at once: X (B, 11), U (B, 6), P (B, n_params) -> DX, AUX."""
    for b in numba.prange(X.shape[0]):
        rhs_core(X[b], U[b], P[b], DX[b], AUX[b])


@numba.njit(cache=True, nogil=True, parallel=True, error_model="numpy")
def simulate_kernel(
    x0: np.ndarray,  # (B, N_STATES)
    U: np.ndarray,  # (B, T, N_INPUTS) inputs held over each sample
    p_base: np.ndarray,  # (B, N_PARAMS)
    pidx: np.ndarray,  # (B, K) int, parameter indices scaled per sample (-1 = unused)
    PM: np.ndarray,  # (B, T, K) multipliers of those parameters over each sample
    h: float,
    substeps: int,
    Z: np.ndarray,  # (B, T, N_MEASUREMENTS) standard-normal noise draws
    noise_abs: np.ndarray,  # (N_MEASUREMENTS,) absolute noise std
    noise_rel: np.ndarray,  # (N_MEASUREMENTS,) noise std relative to the value
    noise_scale: float,
    Y: np.ndarray,  # (B, T, N_MEASUREMENTS [+ 3 closed loop]) out: noise-free observations
    OBS: np.ndarray,  # (B, T, N_MEASUREMENTS [+ 3]) float32 out: noisy observations
    Xs: np.ndarray,  # (B, T, N_STATES) out: states
    AUX: np.ndarray,  # (B, T, N_AUX) out
    add_noise: bool,
    C: np.ndarray,  # (B, CONTROLLER_STATE_SIZE) controller states, updated in place
    SP: np.ndarray,  # (B, T, 2) set points (closed loop)
    gains: np.ndarray,  # controller gains (RegulatoryLayer.gains); empty = open loop
    SAT: np.ndarray,  # (B, T) bool out, zeros in: the output over sample k was clamped
) -> None:
    """Simulate B episodes of T samples; same arithmetic as :func:`step_kernel` per episode.

    With ``add_noise=False`` OBS is left untouched (the caller transforms Y first). In closed
    loop (``gains`` not empty, which needs ``add_noise``) the controllers' outputs replace
    U[b, k, 0:2] (written back: U holds the applied inputs), Y and OBS carry the valve command
    and the set points after Table 1 (:data:`fcc_env.closed_loop.CLOSED_LOOP_CHANNELS`), and
    each sample's noisy observation updates the controllers for the next sample
    (:func:`fcc_env.regulatory.controller_update`).
    """
    B, T = U.shape[0], U.shape[1]
    closed = gains.shape[0] > 0
    for b in numba.prange(B):
        x = x0[b].copy()
        p = np.empty_like(p_base[b])
        work = np.empty((6, N_STATES))
        aux = work[5]
        c = C[b]
        for k in range(T):
            u = U[b, k]
            if closed:  # a closed loop's output replaces the program's input
                apply_controller_outputs(u, c, gains)
            _apply_mult(p_base[b], p, pidx[b], PM[b, k])
            # One RHS evaluation gives the first RK4 stage, the info quantities and T_rx (the
            # same riser solve the measurement would repeat).
            rhs_core(x, u, p, work[0], aux)
            measurements_into(x, u, aux[0], Y[b, k])
            if add_noise:
                for i in range(N_MEASUREMENTS):
                    OBS[b, k, i] = _noisy(
                        Y[b, k, i], Z[b, k, i], noise_abs[i], noise_rel[i], noise_scale
                    )
            for i in range(N_STATES):
                Xs[b, k, i] = x[i]
            for i in range(N_AUX):
                AUX[b, k, i] = aux[i]
            if closed:
                # what the control system records, then the controllers' update: its clamp is
                # the flag of the output in force over the next sample (the env's info)
                Y[b, k, N_MEASUREMENTS] = u[0]
                Y[b, k, N_MEASUREMENTS + 1] = SP[b, k, 0]
                Y[b, k, N_MEASUREMENTS + 2] = SP[b, k, 1]
                for i in range(N_MEASUREMENTS, N_MEASUREMENTS + 3):
                    OBS[b, k, i] = np.float32(Y[b, k, i])
                saturated = controller_update(c, SP[b, k], OBS[b, k], gains)
                if k + 1 < T:
                    SAT[b, k + 1] = saturated
            if k + 1 < T:
                _rk4_inplace(x, u, p, h, substeps, work, True)


@numba.njit(cache=True, nogil=True, parallel=True, error_model="numpy")
def noisy_batch_kernel(Y, Z, noise_abs, noise_rel, noise_scale, OBS):
    """OBS = noisy float32 Y, element for element as :func:`noisy_kernel`."""
    for b in numba.prange(Y.shape[0]):
        for k in range(Y.shape[1]):
            for i in range(Y.shape[2]):
                OBS[b, k, i] = _noisy(
                    Y[b, k, i], Z[b, k, i], noise_abs[i], noise_rel[i], noise_scale
                )


def integrate_step(x: np.ndarray, u: np.ndarray, dt_s: float, p: FCCParams, substeps: int = 1):
    """Pure RK4 step: the state after ``dt_s`` seconds with inputs and parameters held."""
    x_next = np.array(x, dtype=np.float64)
    step_kernel(
        x_next, np.asarray(u, float), as_param_array(p), NO_FAULT, 1.0, dt_s / substeps, substeps
    )
    return x_next
