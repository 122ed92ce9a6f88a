"""What a closed-loop plant shows, and its batch path when plant effects need Python per sample.

In closed loop (:class:`fcc_env.regulatory.RegulatoryLayer`) the observation adds what a control
system records beside the Table 1 measurements: the slide-valve command u_F (the controller's
output, exact) and the two set points (exact, known). R_ar stays a measurement (the air flow
meter, 0.5 % noise) although the regenerator loop now sets it.
"""

from __future__ import annotations

import numpy as np

from fcc_env.episode_setup import PlantSchedule, apply_multipliers, generic_sample
from fcc_env.integrator import aux_kernel, measure_kernel, noisy_batch_kernel, step_kernel
from fcc_env.params import MEASUREMENT_NAMES, N_MEASUREMENTS, N_STATES
from fcc_env.physics import N_AUX
from fcc_env.plant import NOISE_STD_ABS, NOISE_STD_REL, PlantConfig
from fcc_env.regulatory import SETPOINT_NAMES, apply_controller_outputs, controller_update

__all__ = [
    "CLOSED_LOOP_CHANNELS",
    "CLOSED_LOOP_ROLES",
    "CLOSED_LOOP_UNITS",
    "assemble_observation",
    "observation_channels",
]

#: Observation channels of the closed-loop plant, in order: Table 1, the valve command, the
#: set points.
CLOSED_LOOP_CHANNELS: tuple[str, ...] = (*MEASUREMENT_NAMES, "u_F", *SETPOINT_NAMES)
#: Units of :data:`CLOSED_LOOP_CHANNELS` beyond Table 1.
CLOSED_LOOP_UNITS: dict[str, str] = {"u_F": "kg/s", "T_rx_sp": "°C", "T_rg1_sp": "°C"}
#: What each closed-loop channel is to a control system (the dataset sidecar's roles).
CLOSED_LOOP_ROLES: dict[str, tuple[str, ...]] = {
    "measured": MEASUREMENT_NAMES,
    "manipulated": ("u_F", "R_ar"),  # R_ar: measured, and the air loop's output
    "setpoint": SETPOINT_NAMES,
}


def observation_channels(config: PlantConfig) -> tuple[str, ...]:
    """The observation channels of a plant: Table 1, plus u_F and set points in closed loop."""
    return CLOSED_LOOP_CHANNELS if config.closed_loop else MEASUREMENT_NAMES


def assemble_observation(table1: np.ndarray, u_F: np.ndarray, setpoints: np.ndarray) -> np.ndarray:
    """The closed-loop observation: Table 1 values (..., 8), the command (...) and the set
    points (..., 2), joined along the last axis in :data:`CLOSED_LOOP_CHANNELS` order, in the
    dtype of ``table1``."""
    dtype = table1.dtype
    return np.concatenate(
        [table1, np.asarray(u_F, dtype)[..., None], np.asarray(setpoints, dtype)], axis=-1
    )


def simulate_closed_per_sample(
    x0: np.ndarray,
    U: np.ndarray,
    SP: np.ndarray,
    C: np.ndarray,
    gains: np.ndarray,
    p_base: np.ndarray,
    pidx: np.ndarray,
    PM: np.ndarray,
    Z: np.ndarray,
    schedule: PlantSchedule,
    config: PlantConfig,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Closed-loop episodes with measurement or ``d_state`` effects, sample by sample.

    The controllers must read each sample's observation after the effects, which the compiled
    batch kernel cannot call; this loop calls the env's own kernels per episode (or the numpy
    RK4 of :func:`fcc_env.episode_setup.generic_sample` with ``d_state`` effects, as the env
    does), so batch = env bit for bit here too. ``U`` is written in place (applied inputs).

    Returns (Y, OBS, X, AUX, SAT) with the shapes of :func:`fcc_env.simulate_episodes`' arrays.
    """
    B, T = U.shape[:2]
    Y = np.empty((B, T, N_MEASUREMENTS))
    OBS = np.empty((B, T, N_MEASUREMENTS), dtype=np.float32)
    X = np.empty((B, T, N_STATES))
    A = np.empty((B, T, N_AUX))
    SAT = np.zeros((B, T), dtype=np.bool_)
    h = config.sample_time_s / config.rk4_substeps
    x = x0.copy()
    for k in range(T):
        for b in range(B):
            apply_controller_outputs(U[b, k], C[b], gains)
        u = np.ascontiguousarray(U[:, k])
        if schedule.generic:
            p = apply_multipliers(p_base, pidx, PM[:, k])
            y, aux, x_next = generic_sample(
                x, u, p, k, schedule, config.sample_time_s, config.rk4_substeps,
                advance=k + 1 < T,
            )  # fmt: skip
        else:
            y = np.stack(
                [measure_kernel(x[b], u[b], p_base[b], pidx[b], PM[b, k]) for b in range(B)]
            )
            aux = np.stack([aux_kernel(x[b], u[b], p_base[b], pidx[b], PM[b, k]) for b in range(B)])
            x_next = x.copy()
            if k + 1 < T:
                for b in range(B):
                    step_kernel(
                        x_next[b], u[b], p_base[b], pidx[b], PM[b, k], h, config.rk4_substeps
                    )
        Y[:, k], A[:, k], X[:, k] = y, aux, x
        Y[:, k] = schedule.measure(k, Y[:, k]) if schedule.measure_effects else Y[:, k]
        noisy_batch_kernel(
            Y[:, k : k + 1], Z[:, k : k + 1], NOISE_STD_ABS, NOISE_STD_REL, config.noise_scale,
            OBS[:, k : k + 1],
        )  # fmt: skip
        for b in range(B):
            SAT[b, k] = controller_update(C[b], SP[b, k], OBS[b, k], gains)
        x = x_next
    return Y, OBS, X, A, SAT
