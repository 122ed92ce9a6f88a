"""What a closed-loop plant shows, and its batch path when plant effects need Python per sample.

In closed loop (:class:`fcc_env.regulatory.RegulatoryLayer`) the observation adds what a control
system records beside the Table 1 measurements: the slide-valve command u_F (the controller's
output, exact) and the two set points (exact, known). R_ar stays a measurement (the air flow
meter, 0.5 % noise) although the regenerator loop now sets it.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from fcc_common.validation import invalid
from fcc_env.episode_setup import (
    BatchSchedule,
    apply_multipliers,
    generic_sample,
)
from fcc_env.integrator import aux_kernel, measure_kernel, noisy_kernel, step_kernel
from fcc_env.params import (
    INPUT_NAMES,
    MEASUREMENT_NAMES,
    MEASUREMENTS,
    N_MEASUREMENTS,
    N_STATES,
    NOMINAL_INPUTS,
)
from fcc_env.physics import N_AUX
from fcc_env.plant import NOISE_STD_ABS, NOISE_STD_REL, PlantConfig
from fcc_env.regulatory import (
    SETPOINT_NAMES,
    RegulatoryLayer,
    apply_controller_outputs,
    check_setpoints,
    controller_update,
    initial_controller_state,
)

__all__ = [
    "CHANNEL_UNITS",
    "CLOSED_LOOP_CHANNELS",
    "CLOSED_LOOP_ROLES",
    "CLOSED_LOOP_UNITS",
    "assemble_observation",
    "observation_channels",
    "visibility_threshold",
]

#: Observation channels of the closed-loop plant, in order: Table 1, the valve command, the
#: set points.
CLOSED_LOOP_CHANNELS: tuple[str, ...] = (*MEASUREMENT_NAMES, "u_F", *SETPOINT_NAMES)
#: Units of :data:`CLOSED_LOOP_CHANNELS` beyond Table 1.
CLOSED_LOOP_UNITS: dict[str, str] = {"u_F": "kg/s", "T_rx_sp": "°C", "T_rg1_sp": "°C"}
#: Units of every closed-loop channel.
CHANNEL_UNITS: dict[str, str] = {**{m.name: m.unit for m in MEASUREMENTS}, **CLOSED_LOOP_UNITS}
#: u_F is the controller's exact output (no noise): it counts as visible beyond 3 × 0.5 % of
#: nominal, the air flow meter's relative resolution, so valve and air are judged alike.
U_F_RELATIVE_RESOLUTION = 0.005


def visibility_threshold(channel: str) -> float:
    """3 × the channel's noise std (R_ar: relative to nominal 148.4 t/h; u_F: see
    :data:`U_F_RELATIVE_RESOLUTION`), in the channel's unit: beyond it, a difference shows
    in a single sample."""
    if channel == "u_F":
        return 3.0 * U_F_RELATIVE_RESOLUTION * float(NOMINAL_INPUTS[0])
    for m in MEASUREMENTS:
        if m.name == channel:
            scale = float(NOMINAL_INPUTS[INPUT_NAMES.index(m.name)]) if m.noise_relative else 1.0
            return 3.0 * m.noise_std * scale
    raise invalid("channel", channel, f"one of {list(CHANNEL_UNITS)} but the set points")


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
    out = np.empty((*table1.shape[:-1], len(CLOSED_LOOP_CHANNELS)), dtype=table1.dtype)
    out[..., :N_MEASUREMENTS] = table1
    out[..., N_MEASUREMENTS] = u_F
    out[..., N_MEASUREMENTS + 1 :] = setpoints
    return out


class ControlSystem:
    """One closed-loop episode's control system, sample by sample (the env's path).

    Holds the controller state, the supervisory move (the last action, °C on each set point)
    and the set points. ``program`` gives the operating program's set points of a sample
    (:meth:`fcc_env.episode_setup.EpisodeStream.setpoints`).
    """

    def __init__(self, layer: RegulatoryLayer, sample_time_s: float, program: Any) -> None:
        self.gains = layer.gains(sample_time_s)
        self.program = program
        self.c = initial_controller_state(NOMINAL_INPUTS)
        self.move = np.zeros(2)
        self.saturated = False
        self.clipped = False
        self.shown, _ = check_setpoints(program(0))
        self._shown_at = 0

    def inputs(self, u_program: np.ndarray) -> np.ndarray:
        """The applied inputs: the program's, the closed loops' outputs in place."""
        u = u_program.copy()
        apply_controller_outputs(u, self.c, self.gains)
        return u

    def supervise(self, k: int, move: np.ndarray, table1: np.ndarray) -> None:
        """Sample ``k``: the set points (program + ``move``, clipped to their ranges) and the
        controllers' update from the observation's Table 1 part ``table1`` (float32)."""
        self.move = move
        setpoints, self.clipped = check_setpoints(self.program(k) + move)
        self.saturated = controller_update(self.c, setpoints, table1, self.gains)

    def info(self) -> dict[str, Any]:
        """The env's closed-loop info keys."""
        return {
            "controller_saturated": self.saturated,
            "setpoint_clipped": self.clipped,
            "setpoints": self.shown.copy(),
        }

    def observe(self, k: int, table1: np.ndarray, u_F: float) -> np.ndarray:
        """The observation of sample ``k``: Table 1, the valve command and the set points in
        force (the program's plus the last move) in ``table1``'s dtype."""
        if k != self._shown_at:
            self.shown, _ = check_setpoints(self.program(k) + self.move)
            self._shown_at = k
        out = np.empty(len(CLOSED_LOOP_CHANNELS), dtype=table1.dtype)
        out[:N_MEASUREMENTS] = table1
        out[N_MEASUREMENTS] = u_F
        out[N_MEASUREMENTS + 1 :] = self.shown
        return out


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
    schedule: BatchSchedule,
    config: PlantConfig,
    lost: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Closed-loop episodes with measurement or ``d_state`` effects (or a fault's measure hook,
    transmitter or actuator device), sample by sample.

    The controllers must read each sample's observation after the effects, which the compiled
    batch kernel cannot call; this loop calls the env's own kernels per episode (or the numpy
    RK4 of :func:`fcc_env.episode_setup.generic_sample` with ``d_state`` effects, as the env
    does), so batch = env bit for bit here too. ``U`` is written in place (applied inputs:
    after an actuator fault's device; the observation's ``u_F`` is the controller's command).

    Returns (Y, OBS, X, AUX, SAT) as :func:`fcc_env.simulate_episodes` returns them (Y and
    OBS with the closed-loop channels); each sample's dropout flags are written into ``lost``
    ``(B, T)``.
    """
    B, T = U.shape[:2]
    command = np.empty((B, T))  # the valve command the control system records
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
        command[:, k] = U[:, k, 0]
        if schedule.actuates:  # the actuators deliver what the process receives
            U[:, k] = schedule.actuate(k, U[:, k])
        u = np.ascontiguousarray(U[:, k])
        if schedule.generic:
            p = apply_multipliers(p_base, pidx, PM[:, k])
            y, aux, x_next = generic_sample(
                x,
                u,
                p,
                k,
                schedule,
                config.sample_time_s,
                config.rk4_substeps,
                advance=k + 1 < T,
            )
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
        if schedule.measures:  # the transmitters, before the controllers read them
            Y[:, k], Z[:, k] = schedule.sense(k, Y[:, k], Z[:, k], lost[:, k])
        for b in range(B):
            # the serial kernel: the parallel batch one costs a thread-pool start per sample
            OBS[b, k] = noisy_kernel(
                Y[b, k], Z[b, k], NOISE_STD_ABS, NOISE_STD_REL, config.noise_scale
            )
        for b in range(B):
            saturated = controller_update(C[b], SP[b, k], OBS[b, k], gains)
            if k + 1 < T:  # the flag of the output in force over the next sample
                SAT[b, k + 1] = saturated
        x = x_next
    return (
        assemble_observation(Y, command, SP),
        assemble_observation(OBS, command, SP),
        X,
        A,
        SAT,
    )
