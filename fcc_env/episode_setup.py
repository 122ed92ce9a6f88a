"""One episode's set-up, shared by the env (chunk by chunk) and batch simulation (whole episodes).

Both paths build an episode from one seeded generator in the same order (program, noise and
random-fault streams spawned from it) and change the plant through the same
:class:`PlantSchedule`, so :func:`fcc_env.simulate_episodes` reproduces ``FCC-v0`` episodes with
the same seed and options sample for sample (zero actions).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from fcc_env import effects as fx
from fcc_env.actuator_faults import require_loops
from fcc_env.excitation import ProgramGenerator, episode_generators
from fcc_env.faults import ActuatorPath, SensorPath
from fcc_env.integrator import (
    aux_kernel,
    measure_kernel,
    noisy_kernel,
    rhs_batch_kernel,
    step_kernel,
)
from fcc_env.params import N_INPUTS, N_MEASUREMENTS, N_STATES, PARAM_INDEX, FCCParams
from fcc_env.physics import N_AUX, measure_batch_kernel
from fcc_env.plant import NOISE_STD_ABS, NOISE_STD_REL, PlantConfig
from fcc_env.regulatory import SetpointStream
from fcc_env.scenarios import EpisodeFault, FaultSpec

#: Samples of program, noise and multipliers an :class:`EpisodeStream` draws at a time.
CHUNK_SAMPLES = 512


class PlantSchedule:
    """What changes the plant over an episode: the fault and the undeclared plant effects.

    Parameter changes (the fault's and the library process effects') become per-sample
    multipliers of parameter slots ``pidx``; input effects, then the fault's
    ``transform_inputs`` hook, transform the operating program; ``measure`` effects, then the
    fault's ``measure`` hook (:mod:`fcc_env.faults`), transform the noise-free measurements;
    ``d_state`` effects need the generic (Python-level RK4) path. Every method is elementwise in
    the sample index, so the env (chunk by chunk) and batch simulation (whole episodes) compute
    the same numbers. A channel fault's transmitter (``sensor``, one per episode) comes last, in
    :meth:`sense`, which both paths call once per sample, in order; an actuator fault's device
    (``actuator``) transforms the inputs as commanded into those applied, in :meth:`actuate`.
    A concurrent fault's parts act each through its own hooks, one after the other.
    """

    def __init__(
        self,
        fault: EpisodeFault,
        effects: list[Any],
        params: FCCParams,
        sample_time_s: float,
        sensors: tuple[SensorPath, ...] = (),
        actuators: tuple[ActuatorPath, ...] = (),
    ):
        self.fault = fault
        self.params = params
        self.sample_time_s = sample_time_s
        self.param_effects = [e for e in effects if fx.has_hook(e, "param_multipliers")]
        self.input_effects = [e for e in effects if fx.has_hook(e, "transform_inputs")]
        self.measure_effects = [e for e in effects if fx.has_hook(e, "measure")]
        self.state_effects = [e for e in effects if fx.has_hook(e, "d_state")]
        parts = [(c, c.definition) for c in fault.components]
        self.fault_measures = [(c, d.measure) for c, d in parts if d.measure is not None]
        self.fault_inputs = [(c, d.transform_inputs) for c, d in parts if d.transform_inputs]
        self.sensors = tuple(sensors)
        self.actuators = tuple(actuators)
        names: list[str] = []
        for e in self.param_effects:
            names.extend(e.param_multipliers(np.zeros(1), params))
        self.pidx = np.concatenate(
            [fault.param_indices, np.array([PARAM_INDEX[n] for n in names], dtype=np.int64)]
        )

    @property
    def generic(self) -> bool:
        """True when a user effect adds to the state derivative (Python-level integration)."""
        return bool(self.state_effects)

    @property
    def measures(self) -> bool:
        """True when something acts on the measurements (an effect or the fault's hook), which
        the compiled kernels cannot call."""
        return bool(self.measure_effects) or self.python_fault

    @property
    def python_fault(self) -> bool:
        """True when the fault acts in Python per sample (a measure hook, a transmitter or an
        actuator device)."""
        return bool(self.fault_measures or self.sensors or self.actuators)

    def actuate(self, k: int, u: np.ndarray) -> np.ndarray:
        """Sample ``k``'s inputs ``(6,)`` as the process receives them from the inputs as
        commanded (the actuator devices, if any)."""
        for device in self.actuators:
            u = device.move(k, u)
        return u

    def multipliers(self, k: np.ndarray) -> np.ndarray:
        """Parameter multipliers over samples ``k``: shape (n, len(pidx))."""
        cols = [self.fault.multipliers(k)]
        t = np.asarray(k) * self.sample_time_s
        for e in self.param_effects:
            for v in e.param_multipliers(t, self.params).values():
                cols.append(np.asarray(v, dtype=np.float64).reshape(-1, 1))
        return np.concatenate(cols, axis=1)

    def inputs(self, k: np.ndarray, u: np.ndarray) -> np.ndarray:
        t = np.asarray(k) * self.sample_time_s
        for e in self.input_effects:
            u = e.transform_inputs(t, u)
        for part, hook in self.fault_inputs:
            u = np.asarray(hook(part, np.asarray(k), u), dtype=np.float64)
        return u

    def measure_effects_only(self, k: int, y: np.ndarray) -> np.ndarray:
        """``y`` after the plant effects' ``measure`` (``y``: one sample, any leading axes)."""
        t = k * self.sample_time_s
        for e in self.measure_effects:
            y = np.asarray(e.measure(t, y), dtype=np.float64)
        return y

    def measure_fault(self, k: int, y: np.ndarray) -> np.ndarray:
        """``y`` (one sample of this episode, ``(8,)``) after the fault's ``measure`` hook."""
        for part, hook in self.fault_measures:
            y = np.asarray(hook(part, k, y), dtype=np.float64)
        return y

    def measure(self, k: int, y: np.ndarray) -> np.ndarray:
        """The measurement of sample ``k`` after the effects, then the fault (the transmitter
        is last: a sensor fault sits at its output)."""
        return self.measure_fault(k, self.measure_effects_only(k, y))

    def sense(self, k: int, y: np.ndarray, z: np.ndarray) -> tuple[np.ndarray, np.ndarray, bool]:
        """Sample ``k`` as the transmitters deliver it: the noise-free measurement ``y``
        ``(8,)`` after :meth:`measure`, then the channel fault's transmitter on ``y`` and the
        noise draws ``z``; returns ``(y', z', dropped)``."""
        return self.sense_only(k, self.measure(k, y), z)

    def sense_only(
        self, k: int, y: np.ndarray, z: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, bool]:
        """:meth:`sense` on a measurement ``y`` that has been through :meth:`measure`."""
        dropped = False
        for sensor in self.sensors:
            y, z, lost = sensor.read(k, y, z)
            dropped = dropped or lost
        return y, z, dropped

    def d_state(self, t: float, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        total = np.zeros_like(x)
        for e in self.state_effects:
            total = total + np.asarray(e.d_state(t, x, u, self.params), dtype=np.float64)
        return total


class BatchSchedule:
    """The schedules of a batch's episodes as :func:`fcc_env.simulate_episodes` runs them.

    The plant effects are the same objects in every episode, so they act on the whole batch
    once per sample (the last episode's schedule holds them, as every one does); each
    episode's fault hook acts on its own row.
    """

    def __init__(self, schedules: list[PlantSchedule]) -> None:
        self.shared = schedules[-1]
        self.faulty_rows = [(b, s) for b, s in enumerate(schedules) if s.python_fault]

    @property
    def generic(self) -> bool:
        return self.shared.generic

    @property
    def measures(self) -> bool:
        return bool(self.shared.measure_effects or self.faulty_rows)

    @property
    def actuates(self) -> bool:
        """True when an episode's fault acts on its actuators (Python per sample)."""
        return any(s.actuators for _, s in self.faulty_rows)

    def actuate(self, k: int, u: np.ndarray) -> np.ndarray:
        """Sample ``k``'s applied inputs of every episode ``(B, 6)`` from the commanded ``u``."""
        u = np.array(u, dtype=np.float64, copy=True)
        for b, s in self.faulty_rows:
            u[b] = s.actuate(k, u[b])
        return u

    def d_state(self, t: float, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        return self.shared.d_state(t, x, u)

    def measure(self, k: int, y: np.ndarray) -> np.ndarray:
        """Sample ``k`` of every episode ``(B, 8)`` after the effects, then each fault."""
        y = self.shared.measure_effects_only(k, y)
        if self.faulty_rows:
            y = np.array(y, dtype=np.float64, copy=True)
            for b, s in self.faulty_rows:
                y[b] = s.measure_fault(k, y[b])
        return y

    def sense(
        self, k: int, y: np.ndarray, z: np.ndarray, lost: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Sample ``k`` of every episode as :meth:`PlantSchedule.sense` delivers it: ``y`` and
        ``z`` ``(B, 8)``; each episode's dropout flag written into ``lost`` ``(B,)``."""
        y = self.measure(k, y)
        z = np.array(z, dtype=np.float64, copy=True)
        for b, s in self.faulty_rows:
            if s.sensors:
                y[b], z[b], lost[b] = s.sense_only(k, y[b], z[b])
        return y, z


def apply_multipliers(p_base: np.ndarray, pidx: np.ndarray, mult: np.ndarray) -> np.ndarray:
    """Numpy twin of the kernels' parameter scaling: p_base (B, n_p), pidx (B, K), mult (B, K)."""
    p = p_base.copy()
    rows = np.arange(p.shape[0])
    for j in range(pidx.shape[1]):
        ok = pidx[:, j] >= 0
        p[rows[ok], pidx[ok, j]] = p[rows[ok], pidx[ok, j]] * mult[ok, j]
    return p


def generic_sample(
    x: np.ndarray,
    u: np.ndarray,
    p: np.ndarray,
    k: int,
    schedule: PlantSchedule | BatchSchedule,
    sample_time_s: float,
    substeps: int,
    advance: bool = True,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One sample of B episodes with ``d_state`` effects: RK4 in numpy over the compiled RHS.

    Returns (measurement, aux, next state) at sample k; x, u: (B, ·), p: (B, n_params).

    Why a numpy twin of the compiled RK4 (``integrator.step_kernel``): a user effect's ``d_state`` is
    arbitrary Python, which compiled code cannot call, so the stages are combined here around one
    compiled RHS call per stage (:func:`fcc_env.integrator.rhs_batch_kernel`). Everything else is
    shared: the RHS, the measurement map (:func:`fcc_env.physics.measure_batch_kernel`) and the
    stage arithmetic, written in the same order as the compiled loop so that both give the same
    numbers (``tests/fcc_env/test_effects.py`` checks env = batch on this path).
    """
    B = x.shape[0]
    h = sample_time_s / substeps
    t0 = k * sample_time_s

    def f(t: float, xx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        dx = np.empty((B, N_STATES))
        aux = np.empty((B, N_AUX))
        rhs_batch_kernel(np.ascontiguousarray(xx), u, p, dx, aux)
        return dx + schedule.d_state(t, xx, u), aux

    k1, aux = f(t0, x)
    y = np.empty((B, N_MEASUREMENTS))
    measure_batch_kernel(np.ascontiguousarray(x), u, aux, y)
    if not advance:
        return y, aux, x
    xn = x.copy()
    for j in range(substeps):
        t = t0 + j * h
        if j > 0:
            k1, _ = f(t, xn)
        k2, _ = f(t + 0.5 * h, xn + 0.5 * h * k1)
        k3, _ = f(t + 0.5 * h, xn + 0.5 * h * k2)
        k4, _ = f(t + h, xn + h * k3)
        xn = xn + h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
    return y, aux, xn


@dataclass
class EpisodeSetup:
    fault: EpisodeFault
    program: ProgramGenerator
    noise_rng: np.random.Generator
    schedule: PlantSchedule
    setpoints: SetpointStream | None = None  # closed loop: the set-point program

    def take_program(self, k: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """The next ``len(k)`` samples of the program: inputs (after input effects) and, in
        closed loop, set points (else None). In closed loop the feed coking factor drifts."""
        u = self.program.take(k.shape[0])
        sp = None
        if self.setpoints is not None:
            sp, u[:, 5] = self.setpoints.take(k.shape[0])
        return self.schedule.inputs(k, u), sp

    def draw_chunk(
        self, ks: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray, np.ndarray]:
        """The episode's next samples ``ks``: program inputs, set points (closed loop, else
        None), the noise's standard-normal draws ``(len(ks), 8)`` and the parameter multipliers,
        drawn in this one order (the single env and the vector env give the same numbers)."""
        u, sp = self.take_program(ks)
        z = self.noise_rng.standard_normal((ks.shape[0], N_MEASUREMENTS))
        return u, sp, z, self.schedule.multipliers(ks)


def setup_episode(
    rng: np.random.Generator,
    config: PlantConfig,
    fault: FaultSpec,
    horizon: int,
    plant_effects: list[Any] | None = None,
) -> EpisodeSetup:
    """Set up one episode from its seeded generator (the env's and batch simulation's order)."""
    gens = episode_generators(rng, closed_loop=config.closed_loop)
    resolved = fault.resolve(horizon, gens["fault"])
    effects = plant_effects or []
    fx.reset_all(effects)
    require_loops(resolved, config.regulatory)
    # the transmitters draw after resolve, so its draws stay as they were
    sensors = tuple(
        c.definition.sensor(c, gens["fault"], horizon, config.sample_time_s)
        for c in resolved.components
        if c.definition.sensor is not None
    )
    actuators = tuple(
        c.definition.actuator(c, horizon, config.sample_time_s)
        for c in resolved.components
        if c.definition.actuator is not None
    )
    schedule = PlantSchedule(
        resolved, effects, config.params, config.sample_time_s, sensors, actuators
    )
    setpoints = None
    if config.regulatory is not None:
        setpoints = SetpointStream(
            config.regulatory.program, config.initial_setpoints(), gens["setpoints"]
        )
    return EpisodeSetup(
        resolved,
        ProgramGenerator(config.excitation, gens["program"]),
        gens["noise"],
        schedule,
        setpoints,
    )


def add_noise(y_clean: np.ndarray, z: np.ndarray, noise_scale: float) -> np.ndarray:
    """float32 measurement = clean + noise_scale·std·z, for one sample (shape (8,))."""
    return noisy_kernel(
        np.asarray(y_clean, np.float64),
        np.asarray(z, np.float64),
        NOISE_STD_ABS,
        NOISE_STD_REL,
        float(noise_scale),
    )


class EpisodeStream:
    """One episode's plant sample by sample (the env's path; batch simulation runs whole arrays).

    Draws the operating program, the measurement noise and the parameter multipliers in chunks
    of :data:`CHUNK_SAMPLES` as the episode reaches them, and integrates or measures one sample
    with the same kernels (or the same numpy twin, with ``d_state`` effects) as the batch.
    """

    def __init__(self, setup: EpisodeSetup, config: PlantConfig, p_base: np.ndarray) -> None:
        self.fault = setup.fault
        self.schedule = setup.schedule
        self.config = config
        self._p_base = p_base
        self._pidx = setup.schedule.pidx
        self._setup = setup
        self._u_prog = np.empty((0, N_INPUTS))
        self._sp = np.empty((0, 2))
        self._z = np.empty((0, N_MEASUREMENTS))
        self._pm = np.empty((0, self._pidx.shape[0]))
        #: whether the last measured sample was a dropout (the value held)
        self.dropped = False

    def _ensure(self, k: int) -> None:
        while self._u_prog.shape[0] <= k:
            ks = np.arange(self._u_prog.shape[0], self._u_prog.shape[0] + CHUNK_SAMPLES)
            chunk, sp, z, pm = self._setup.draw_chunk(ks)
            self._u_prog = np.concatenate([self._u_prog, chunk])
            if sp is not None:
                self._sp = np.concatenate([self._sp, sp])
            self._z = np.concatenate([self._z, z])
            self._pm = np.concatenate([self._pm, pm])

    def program(self, k: int) -> np.ndarray:
        """The operating program's inputs at sample ``k`` (after input effects), shape (6,)."""
        self._ensure(k)
        return self._u_prog[k]

    def setpoints(self, k: int) -> np.ndarray:
        """The program's set points at sample ``k`` (closed loop), shape (2,)."""
        self._ensure(k)
        return self._sp[k]

    def noise(self, k: int) -> np.ndarray:
        """The standard-normal draws of the measurement noise at sample ``k``, shape (8,)."""
        self._ensure(k)
        return self._z[k]

    def multipliers(self, k: int) -> np.ndarray:
        """The parameter multipliers in force over sample ``k``."""
        self._ensure(k)
        return self._pm[k]

    def _params(self, k: int) -> np.ndarray:
        return apply_multipliers(self._p_base[None], self._pidx[None], self.multipliers(k)[None])

    def advance(self, x: np.ndarray, u: np.ndarray, k: int) -> np.ndarray:
        """The state after sample ``k`` from state ``x`` with input ``u`` held."""
        cfg = self.config
        if self.schedule.generic:
            _, _, xn = generic_sample(
                x[None],
                u[None],
                self._params(k),
                k,
                self.schedule,
                cfg.sample_time_s,
                cfg.rk4_substeps,
            )
            return xn[0]
        x_next = x.copy()
        step_kernel(
            x_next,
            u,
            self._p_base,
            self._pidx,
            self.multipliers(k),
            cfg.sample_time_s / cfg.rk4_substeps,
            cfg.rk4_substeps,
        )
        return x_next

    def measure(self, x: np.ndarray, u: np.ndarray, k: int) -> np.ndarray:
        """Noise-free measurement of sample ``k`` (state, held input, plant effects, the
        fault's transmitter: which may change the stream's noise draws of ``k``; call once per
        sample, in order)."""
        if self.schedule.generic:
            y, _, _ = generic_sample(
                x[None],
                u[None],
                self._params(k),
                k,
                self.schedule,
                self.config.sample_time_s,
                self.config.rk4_substeps,
                advance=False,
            )
            y = y[0]
        else:
            y = measure_kernel(x, u, self._p_base, self._pidx, self.multipliers(k))
        if not self.schedule.measures:
            return y
        y, self._z[k], self.dropped = self.schedule.sense(k, y, self.noise(k))
        return y

    def aux(self, x: np.ndarray, u: np.ndarray, k: int) -> np.ndarray:
        """The auxiliary variables (:data:`fcc_env.physics.AUX_NAMES`) at sample ``k``."""
        return aux_kernel(x, u, self._p_base, self._pidx, self.multipliers(k))
