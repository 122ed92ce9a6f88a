"""A native Gymnasium vector env of the FCC plant: N episodes stepped in one compiled loop.

``SyncVectorEnv`` over ``FCCEnv`` pays Python per env and step (some 10,000 env-steps/s);
:class:`FCCVectorEnv` keeps every episode's state in arrays and steps them all in one numba
``prange`` loop over the env's own kernels (``step_kernel``, ``aux_kernel``, ``noisy_kernel``,
``controller_update``, ``envelope_code``), so the physics stays the one definition. Python only
sets episodes up (:func:`fcc_env.episode_setup.setup_episode`, per env, as ``FCCEnv.reset``)
and draws each episode's program, noise and parameter multipliers every
:data:`~fcc_env.episode_setup.CHUNK_SAMPLES` samples, in ``EpisodeStream``'s order, so a
vector env seeded as ``SyncVectorEnv`` seeds its sub-envs gives their numbers bit for bit
(``tests/fcc_env/test_vector_env.py``). Through Gymnasium:
``gym.make_vec("FCC-v0", 1024, vectorization_mode="vector_entry_point", ...)``.

Threads (``threads=``): :mod:`fcc_env.vector_threads` (the policy, the threading layers).

>>> envs = FCCVectorEnv(4, scenario="f1", fault_time=50)
>>> obs, info = envs.reset(seed=0)
>>> obs.shape, info["fault_time"].tolist()
((4, 8), [50, 50, 50, 50])
"""

from __future__ import annotations

import warnings
from typing import Any, NamedTuple

import numba
import numpy as np
from gymnasium.error import ResetNeeded
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from fcc_common.validation import Integer, check, invalid
from fcc_env import effects as fx
from fcc_env.env import (
    ACTION_SCALE,
    ACTUATOR_BOUNDS,
    CLOSED_LOOP_ENV_ID,
    SETPOINT_ACTION_SCALE,
    FCCEnv,
    actuate,
    closed_loop_keyword,
    episode_request,
)
from fcc_env.episode_setup import CHUNK_SAMPLES, EpisodeSetup, setup_episode
from fcc_env.integrator import aux_kernel, noisy_kernel, step_kernel
from fcc_env.params import N_INPUTS, N_MEASUREMENTS, N_STATES, NOMINAL_INPUTS
from fcc_env.physics import AUX_NAMES, N_AUX, measurements_into
from fcc_env.plant import (
    AFTERBURN_WARNING_C,
    NOISE_STD_ABS,
    NOISE_STD_REL,
    TERMINATION_REASONS,
    envelope_code,
)
from fcc_env.regulatory import (
    CONTROLLER_STATE_SIZE,
    SETPOINT_NAMES,
    SETPOINT_RANGES,
    apply_controller_outputs,
    clip_rows,
    controller_update,
    initial_controller_state,
)
from fcc_env.scenarios import DEFAULT_N_SAMPLES
from fcc_env.sensor_faults import compiled_transmitter
from fcc_env.sensor_kernel import sensor_read
from fcc_env.vector_threads import check_threads, vector_threads

__all__ = [
    "VECTOR_ENTRY_POINT",
    "FCCClosedLoopVectorEnv",
    "FCCVectorEnv",
]

VECTOR_ENTRY_POINT = "fcc_env.vector_env:FCCVectorEnv"
#: Samples of program/noise/multipliers held per env: two chunks, sample k at row k % RING, so
#: the chunk of k + 1 can be drawn while sample k is still needed.
RING = 2 * CHUNK_SAMPLES
#: ``info["termination_reason"]`` by code: the envelope's codes, then the env's own.
REASONS = np.array([*TERMINATION_REASONS, "measurement_out_of_range"], dtype=object)
_OUT_OF_RANGE = len(TERMINATION_REASONS)
_NUMERICAL_FAILURE = 1
#: Info keys some episodes' ``FCCEnv`` infos lack: batched only where one env has them.
_OPTIONAL_KEYS = ("fault_time", "fault_labels", "fault_times", "fault_channel", "sensor_dropout")
# Per-env kernel modes.
_SKIP, _STEP, _START = 0, 1, 2
#: Actuator limits as [low, high] rows over (u_F, R_ar): the numbers of ``actuator_inputs``.
_SP_LIMITS = np.array([[SETPOINT_RANGES[n].low, SETPOINT_RANGES[n].high] for n in SETPOINT_NAMES]).T


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _setpoints(program: np.ndarray, move: np.ndarray, limits: np.ndarray, out: np.ndarray) -> bool:
    """``check_setpoints(program + move)`` into ``out``; True when a set point was clipped."""
    for j in range(2):
        out[j] = program[j] + move[j]
    return clip_rows(out.reshape(1, 2), limits[0], limits[1])


class Episodes(NamedTuple):
    """Every env's episode state, one row per env (what ``FCCEnv`` holds in attributes)."""

    x: np.ndarray  # (n, 11) plant state
    u: np.ndarray  # (n, 6) inputs applied over the current sample
    c: np.ndarray  # (n, 4) controller state (closed loop)
    move: np.ndarray  # (n, 2) the last action in physical units
    obs: np.ndarray  # (n, d) float32 observation
    y_clean: np.ndarray  # (n, d) noise-free observation
    aux: np.ndarray  # (n, N_AUX) auxiliary variables
    shown: np.ndarray  # (n, 2) set points in force (closed loop)
    k: np.ndarray  # (n,) int64 sample index
    reason: np.ndarray  # (n,) int8 index into REASONS
    saturated: np.ndarray  # (n,) bool: action or actuator limit hit this step
    controller_saturated: np.ndarray  # (n,) bool
    setpoint_clipped: np.ndarray  # (n,) bool
    # the faulty transmitter (fcc_env.sensor_kernel): kind code (0 none), channel, size, onset,
    # ramp (0 abrupt); its last delivered (y, z), valid where sensor_has_held
    sensor_kind: np.ndarray  # (n,) int8
    sensor_ch: np.ndarray  # (n,) int64
    sensor_size: np.ndarray  # (n,) float64, the fault's magnitude (its unit)
    sensor_onset: np.ndarray  # (n,) int64 sample
    sensor_ramp: np.ndarray  # (n,) int64 samples
    sensor_held: np.ndarray  # (n, 2) float64
    sensor_has_held: np.ndarray  # (n,) bool


class Streams(NamedTuple):
    """Every env's drawn program, noise and multipliers: sample k at row k % RING."""

    program: np.ndarray  # (n, RING, 6) operating program (after input effects)
    setpoints: np.ndarray  # (n, RING, 2) set-point program (closed loop)
    z: np.ndarray  # (n, RING, 8) standard-normal noise draws
    mult: np.ndarray  # (n, RING, K) parameter multipliers (1 in unused slots)
    pidx: np.ndarray  # (n, K) int64 parameter slots (-1 unused)


class Plant(NamedTuple):
    """What every env shares."""

    p_base: np.ndarray
    h: float  # RK4 step (s)
    substeps: int
    noise_scale: float
    gains: np.ndarray  # RegulatoryLayer.gains; empty = open loop
    u_limits: np.ndarray  # (2, 2) actuator [low, high] rows of u_F, R_ar
    sp_limits: np.ndarray  # (2, 2) set-point [low, high] rows
    low: np.ndarray  # (d,) float32 observation bounds
    high: np.ndarray
    scale: np.ndarray  # (2,) physical size of a unit action
    hours_per_sample: float  # a drifting transmitter's clock


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _observe(b: int, k: int, e: Episodes, s: Streams, pl: Plant) -> bool:
    """Sample ``k`` of env ``b`` once its state is set: applied inputs, clean and noisy
    observation, aux (``FCCEnv._inputs``/``_measure``/``_make_obs``/``_get_info``); True when
    the observation lies in the space."""
    j = k % s.program.shape[1]
    u = s.program[b, j].copy()
    if pl.gains.shape[0] > 0:
        apply_controller_outputs(u, e.c[b], pl.gains)
        _setpoints(s.setpoints[b, j], e.move[b], pl.sp_limits, e.shown[b])
    elif actuate(u, e.move[b], pl.u_limits):
        e.saturated[b] = True
    e.u[b] = u
    # one RHS evaluation gives the info's aux and T_rx for the measurement (as simulate_kernel)
    aux = aux_kernel(e.x[b], u, pl.p_base, s.pidx[b], s.mult[b, j])
    e.aux[b] = aux
    y = e.y_clean[b, :N_MEASUREMENTS]
    measurements_into(e.x[b], u, aux[0], y)
    if e.sensor_kind[b] != 0:  # the transmitter sits before the noise and the controllers
        e.sensor_has_held[b] = sensor_read(
            e.sensor_kind[b],
            k,
            y,
            s.z[b, j],
            e.sensor_ch[b],
            e.sensor_size[b],
            e.sensor_onset[b],
            e.sensor_ramp[b],
            pl.hours_per_sample,
            e.sensor_held[b],
            e.sensor_has_held[b],
        )
    e.obs[b, :N_MEASUREMENTS] = noisy_kernel(
        y, s.z[b, j], NOISE_STD_ABS, NOISE_STD_REL, pl.noise_scale
    )
    if pl.gains.shape[0] > 0:
        e.y_clean[b, N_MEASUREMENTS] = u[0]
        e.y_clean[b, N_MEASUREMENTS + 1 :] = e.shown[b]
        e.obs[b, N_MEASUREMENTS] = np.float32(u[0])
        e.obs[b, N_MEASUREMENTS + 1 :] = e.shown[b].astype(np.float32)
    inside = True
    for i in range(e.obs.shape[1]):
        inside = inside and pl.low[i] <= e.obs[b, i] <= pl.high[i]
    return inside


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _step_env(b: int, mode: int, a: np.ndarray, e: Episodes, s: Streams, pl: Plant) -> None:
    """Env ``b``: ``FCCEnv.step`` with action ``a`` (float64) when ``mode`` is ``_STEP``, the
    reset observation (state already set) when it is ``_START``."""
    if mode == _START:
        _observe(b, 0, e, s, pl)
        return
    if mode != _STEP:
        return
    closed = pl.gains.shape[0] > 0
    ring = s.program.shape[1]
    k = e.k[b]
    j = k % ring
    c0 = min(max(a[0], -1.0), 1.0)
    c1 = min(max(a[1], -1.0), 1.0)
    e.saturated[b] = c0 != a[0] or c1 != a[1]
    e.move[b, 0] = c0 * pl.scale[0]
    e.move[b, 1] = c1 * pl.scale[1]
    if closed:  # the controllers' outputs of sample k hold over it
        u = e.u[b].copy()
    else:  # the new move applies from this sample on
        u = s.program[b, j].copy()
        if actuate(u, e.move[b], pl.u_limits):
            e.saturated[b] = True
    x = e.x[b].copy()
    step_kernel(x, u, pl.p_base, s.pidx[b], s.mult[b, j], pl.h, pl.substeps)
    if closed:
        sp = np.empty(2)
        e.setpoint_clipped[b] = _setpoints(s.setpoints[b, j], e.move[b], pl.sp_limits, sp)
        e.controller_saturated[b] = controller_update(e.c[b], sp, e.obs[b], pl.gains)
    code = envelope_code(x)
    e.k[b] = k + 1
    if code == _NUMERICAL_FAILURE:
        # the env keeps its last finite sample; its info reads sample k + 1's multipliers and
        # set points
        j1 = (k + 1) % ring
        e.aux[b] = aux_kernel(e.x[b], e.u[b], pl.p_base, s.pidx[b], s.mult[b, j1])
        if closed:
            _setpoints(s.setpoints[b, j1], e.move[b], pl.sp_limits, e.shown[b])
            e.y_clean[b, N_MEASUREMENTS + 1 :] = e.shown[b]
        e.reason[b] = code
        return
    e.x[b] = x
    inside = _observe(b, k + 1, e, s, pl)
    if code == 0 and not inside:
        code = _OUT_OF_RANGE
        for i in range(e.obs.shape[1]):
            e.obs[b, i] = min(max(e.obs[b, i], pl.low[i]), pl.high[i])
    e.reason[b] = code


@numba.njit(cache=True, nogil=True, parallel=True, error_model="numpy")
def _batch_step(mode: np.ndarray, actions: np.ndarray, e: Episodes, s: Streams, pl: Plant) -> None:
    """:func:`_step_env` of every env, in parallel (the body lives there: inlined in the
    ``prange`` loop, numba's parfor pass lost an episode's termination code)."""
    for b in numba.prange(mode.shape[0]):
        _step_env(b, mode[b], actions[b], e, s, pl)


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _serial_step(mode: np.ndarray, actions: np.ndarray, e: Episodes, s: Streams, pl: Plant) -> None:
    """:func:`_batch_step` on the calling thread alone: no parallel region, so no barrier and
    no pool threads left spinning after it (one env's numbers do not depend on the loop)."""
    for b in range(mode.shape[0]):
        _step_env(b, mode[b], actions[b], e, s, pl)


class FCCVectorEnv(VectorEnv):
    """``num_envs`` FCC episodes (``FCC-v0`` or, with ``regulatory``, ``FCC-closedloop-v0``)
    stepped together; Gymnasium 1.x vector semantics (NEXT_STEP autoreset, dict-of-array infos
    with ``_key`` masks, the ``TimeLimit`` of ``max_episode_steps`` inside).

    Keywords are ``FCCEnv``'s (validated by it, with its messages) plus ``max_episode_steps``
    (``None``: no truncation) and ``threads`` (numba threads of a step, 1 to
    ``NUMBA_NUM_THREADS``; ``None``: :func:`vector_threads` picks them at each step;
    :mod:`fcc_env.vector_threads` says why and how the threads wait). A sensor fault's transmitter (bias, drift, stuck,
    noise) runs in the compiled loop (:mod:`fcc_env.sensor_kernel`), before the noise and the
    controllers. Plant effects that act through ``measure`` or ``d_state``, a fault's measure
    hook, an actuator fault and a sensor dropout need Python per sample and are refused: run
    them with ``vectorization_mode="sync"``.
    """

    metadata = {"autoreset_mode": AutoresetMode.NEXT_STEP, "render_modes": []}  # noqa: RUF012

    def __init__(
        self,
        num_envs: int = 1,
        *,
        max_episode_steps: int | None = DEFAULT_N_SAMPLES - 1,
        render_mode: str | None = None,
        threads: int | None = None,
        **env_kwargs: Any,
    ) -> None:
        self.num_envs = check("num_envs", num_envs, Integer(1))
        #: numba threads of a step (``None``: :func:`vector_threads` picks them at each step)
        self.threads = check_threads(threads)
        self.max_episode_steps = check("max_episode_steps", max_episode_steps, Integer(1), None)
        if render_mode is not None:
            raise invalid("render_mode", render_mode, "None", "render through SyncVectorEnv")
        self._template = FCCEnv(**env_kwargs)  # the single env validates every keyword
        self._effects_request = env_kwargs.get("plant_effects", ())
        self.config = self._template.config
        self.closed_loop = self.config.closed_loop
        self.single_observation_space = self._template.observation_space
        self.single_action_space = self._template.action_space
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        n, d = self.num_envs, self.single_observation_space.shape[0]
        self._e = Episodes(
            np.zeros((n, N_STATES)),
            np.zeros((n, N_INPUTS)),
            np.zeros((n, CONTROLLER_STATE_SIZE)),
            np.zeros((n, 2)),
            np.zeros((n, d), np.float32),
            np.zeros((n, d)),
            np.zeros((n, N_AUX)),
            np.zeros((n, 2)),
            np.zeros(n, np.int64),
            np.zeros(n, np.int8),
            np.zeros(n, np.bool_),
            np.zeros(n, np.bool_),
            np.zeros(n, np.bool_),
            np.zeros(n, np.int8),
            np.zeros(n, np.int64),
            np.zeros(n),
            np.zeros(n, np.int64),
            np.zeros(n, np.int64),
            np.zeros((n, 2)),
            np.zeros(n, np.bool_),
        )
        self._s = self._streams(n, 1)
        cfg = self.config
        gains = cfg.regulatory.gains(cfg.sample_time_s) if self.closed_loop else np.empty(0)
        self._plant = Plant(
            cfg.params.as_array(),
            cfg.sample_time_s / cfg.rk4_substeps,
            cfg.rk4_substeps,
            float(cfg.noise_scale),
            gains,
            ACTUATOR_BOUNDS,
            _SP_LIMITS,
            self.single_observation_space.low,
            self.single_observation_space.high,
            SETPOINT_ACTION_SCALE if self.closed_loop else ACTION_SCALE,
            cfg.sample_time_s / 3600.0,
        )
        self._x0 = cfg.initial_state()
        self._rngs: list[np.random.Generator | None] = [None] * n
        self._setups: list[EpisodeSetup | None] = [None] * n
        self._drawn = np.zeros(n, np.int64)
        self._elapsed = np.zeros(n, np.int64)
        self._autoreset = np.zeros(n, np.bool_)
        self._faulty = np.zeros(n, np.bool_)
        self._onset = np.zeros(n, np.int64)
        self._magnitude = np.zeros(n)
        self._scenario = np.full(n, None, dtype=object)
        # a concurrent episode's labels and onsets (FCCEnv's info keys), else None
        self._labels = np.full(n, None, dtype=object)
        self._times = np.full(n, None, dtype=object)
        # a channel fault's channel, and whether an episode has a transmitter fault (FCCEnv's
        # info keys fault_channel and sensor_dropout)
        self._channel = np.full(n, None, dtype=object)
        self._sensed = np.zeros(n, np.bool_)

    @staticmethod
    def _streams(n: int, n_mult: int) -> Streams:
        return Streams(
            np.zeros((n, RING, N_INPUTS)),
            np.zeros((n, RING, 2)),
            np.zeros((n, RING, N_MEASUREMENTS)),
            np.ones((n, RING, n_mult)),
            np.full((n, n_mult), -1, np.int64),
        )

    # ---- Gymnasium API -------------------------------------------------------------------------
    def reset(
        self, *, seed: int | list[int | None] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Start episodes: all, or those of ``options["reset_mask"]`` (as ``SyncVectorEnv``).

        ``seed``: ``None`` (continue each env's generator), an int ``s`` (env i gets ``s + i``)
        or a list of ``num_envs`` ints or ``None``; other ``options`` are ``FCCEnv.reset``'s.
        """
        n = self.num_envs
        seeds = [seed + i for i in range(n)] if isinstance(seed, int) else seed
        seeds = [None] * n if seeds is None else list(seeds)
        if len(seeds) != n:
            raise invalid("seed", seed, f"None, an int or a list of num_envs={n} seeds")
        seeds = [check("seed", s, Integer(0), None) for s in seeds]
        options = None if options is None else dict(options)
        mask = np.ones(n, np.bool_)
        if options is not None and "reset_mask" in options:
            mask = options.pop("reset_mask")
            if not (isinstance(mask, np.ndarray) and mask.dtype == np.bool_ and mask.any()):
                raise invalid("reset_mask", mask, f"a bool array of shape ({n},), not all False")
            if mask.shape != (n,):
                raise invalid("reset_mask", mask, f"shape ({n},)", f"shape {mask.shape}")
        if isinstance(seed, int):
            super().reset(seed=seed)
        for b in np.flatnonzero(mask):
            self._start_episode(int(b), seeds[b], options)
        self._warn_onset(mask)
        self._run(np.where(mask, _START, _SKIP).astype(np.int8), np.zeros((n, 2)))
        self._autoreset[mask] = False
        return self._e.obs.copy(), self._infos(mask)

    def step(
        self, actions: Any
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        if not self._drawn.all():
            raise ResetNeeded("call reset() before step(): some envs have no episode")
        a = self._check_actions(actions)
        restart = self._autoreset.copy()
        for b in np.flatnonzero(restart):
            self._start_episode(int(b), None, None)
        self._warn_onset(restart)
        stepping = ~restart
        # sample k + 1 must be buffered before the kernel reads it
        for b in np.flatnonzero(stepping & (self._e.k + 1 >= self._drawn * CHUNK_SAMPLES)):
            self._draw_chunk(int(b))
        self._run(np.where(restart, _START, _STEP).astype(np.int8), a)
        terminated = stepping & (self._e.reason != 0)
        self._elapsed[stepping] += 1
        truncated = np.zeros(self.num_envs, np.bool_)
        if self.max_episode_steps is not None:
            truncated = stepping & (self._elapsed >= self.max_episode_steps)
        self._autoreset = terminated | truncated
        return self._e.obs.copy(), np.zeros(self.num_envs), terminated, truncated, self._infos(None)

    def close_extras(self, **kwargs: Any) -> None:
        self._template.close()

    # ---- episodes ------------------------------------------------------------------------------
    def _episode_options(
        self, b: int, seed: int | None, options: dict[str, Any] | None
    ) -> dict[str, Any] | None:
        """Env ``b``'s reset options (a subclass draws its fault here: the control env's
        catalogue), called once per episode before its set-up; ``seed`` as :meth:`reset` got it
        for the env (``None`` on an autoreset)."""
        return options

    def _start_episode(self, b: int, seed: int | None, options: dict[str, Any] | None) -> None:
        """``FCCEnv.reset`` up to the first sample: the generator, the set-up, chunk 0."""
        options = self._episode_options(b, seed, options)
        effects = fx.resolve(self._effects_request)
        spec, effects = episode_request(options, self._template.fault_spec, effects)
        if seed is not None or self._rngs[b] is None:
            self._rngs[b] = seeding.np_random(seed)[0]
        setup = setup_episode(self._rngs[b], self.config, spec, self._template.horizon, effects)
        python_only = setup.schedule.measure_effects + setup.schedule.state_effects
        if python_only:
            raise invalid(
                "plant_effects",
                python_only,
                "effects acting through parameters or inputs",
                "measure/d_state effects need Python per sample: use vectorization_mode='sync'",
            )
        if setup.schedule.fault_measures or setup.schedule.actuators:
            raise invalid(
                "scenario",
                setup.fault.scenario,
                "a fault acting through parameters, inputs or a sensor fault's transmitter "
                "(bias, drift, stuck, noise)",
                "a fault's measure hook or actuator device needs Python per sample: "
                "use vectorization_mode='sync'",
            )
        sensor = compiled_transmitter(setup.schedule.sensors, setup.fault.scenario)
        self._setups[b] = setup
        fault = setup.fault
        self._channel[b] = fault.channel
        self._sensed[b] = any(c.channel is not None for c in fault.components)
        self._faulty[b] = not fault.nominal
        self._onset[b], self._magnitude[b] = fault.onset, fault.magnitude
        self._scenario[b] = fault.scenario
        self._labels[b] = fault.labels if fault.parts else None
        self._times[b] = tuple(p.onset for p in fault.parts) if fault.parts else None
        n_mult = setup.schedule.pidx.shape[0]
        if n_mult > self._s.pidx.shape[1]:  # more multiplied parameters than any episode yet
            grown = self._streams(self.num_envs, n_mult)
            for old, new in zip(self._s, grown, strict=True):
                new[..., : old.shape[-1]] = old
            self._s = grown
        self._s.pidx[b] = -1
        self._s.pidx[b, :n_mult] = setup.schedule.pidx
        self._drawn[b] = 0
        self._draw_chunk(b)
        e = self._e
        e.x[b], e.move[b], e.k[b], e.reason[b] = self._x0, 0.0, 0, 0
        e.c[b] = initial_controller_state(NOMINAL_INPUTS)
        e.saturated[b] = e.controller_saturated[b] = e.setpoint_clipped[b] = False
        kind, ch, size, onset, ramp = sensor
        e.sensor_kind[b], e.sensor_ch[b], e.sensor_size[b] = kind, ch, size
        e.sensor_onset[b], e.sensor_ramp[b] = onset, ramp
        e.sensor_held[b], e.sensor_has_held[b] = 0.0, False
        self._elapsed[b] = 0

    def _draw_chunk(self, b: int) -> None:
        """The next chunk of env ``b`` (:meth:`EpisodeSetup.draw_chunk`, as ``EpisodeStream``)."""
        setup = self._setups[b]
        ks = np.arange(self._drawn[b] * CHUNK_SAMPLES, (self._drawn[b] + 1) * CHUNK_SAMPLES)
        u, sp, z, pm = setup.draw_chunk(ks)
        rows = slice(ks[0] % RING, ks[0] % RING + CHUNK_SAMPLES)
        s = self._s
        s.program[b, rows], s.z[b, rows] = u, z
        if sp is not None:
            s.setpoints[b, rows] = sp
        s.mult[b, rows] = 1.0
        s.mult[b, rows, : pm.shape[1]] = pm
        self._drawn[b] += 1

    def _run(self, mode: np.ndarray, actions: np.ndarray) -> None:
        threads = vector_threads(self.num_envs, self.threads)
        if threads == 1:
            _serial_step(mode, actions, self._e, self._s, self._plant)
            return
        before = numba.get_num_threads()
        numba.set_num_threads(threads)
        try:
            _batch_step(mode, actions, self._e, self._s, self._plant)
        finally:
            numba.set_num_threads(before)

    def _check_actions(self, actions: Any) -> np.ndarray:
        raw = np.asarray(actions)
        shape = (self.num_envs, 2)
        if raw.dtype.kind not in "biuf" or raw.shape != shape:
            # the array's kind and shape, not its repr: a batch of 1024 rows names nothing
            raise invalid(
                "actions",
                f"<{raw.dtype} array of shape {raw.shape}>",
                f"real numbers of shape {shape}, one row [Δu_F, ΔR_ar] (closed loop: set-point "
                "moves) per env, in [-1, 1]",
            )
        a = raw.astype(np.float64)
        if not np.isfinite(a).all():
            bad = np.argwhere(~np.isfinite(a))[0]
            raise invalid(f"actions[{bad[0]}]", a[bad[0]].tolist(), "finite values in [-1, 1]")
        return a

    def _warn_onset(self, mask: np.ndarray) -> None:
        """``OnsetHorizonCheck`` for the vector env: the limit ends episodes before the onset."""
        limit = self.max_episode_steps
        late = mask & self._faulty & (self._onset > (limit if limit is not None else np.inf))
        if late.any():
            b = int(np.flatnonzero(late)[0])
            warnings.warn(
                f"env {b}'s episode ends at sample {limit} (max_episode_steps={limit}) before its "
                f"{self._scenario[b]} fault onset at sample {self._onset[b]}: it will show no "
                f"fault. Pass max_episode_steps >= {self._onset[b]}, or fault_time <= {limit}",
                UserWarning,
                stacklevel=3,
            )

    def _infos(self, mask: np.ndarray | None) -> dict[str, Any]:
        """``FCCEnv``'s info keys batched as ``SyncVectorEnv._add_info`` batches them."""
        e, onset = self._e, self._onset
        values: dict[str, np.ndarray] = {
            "t": e.k.copy(),
            "time_s": e.k * self.config.sample_time_s,
            "scenario": self._scenario.copy(),
            "fault_active": self._faulty & (onset >= 0) & (onset <= e.k),
            "fault_time": np.where(self._faulty, onset, 0),
            "fault_magnitude": self._magnitude.copy(),
            "fault_labels": self._labels.copy(),
            "fault_times": self._times.copy(),
            "fault_channel": self._channel.copy(),
            # a native transmitter never drops a sample (a dropout is refused)
            "sensor_dropout": np.zeros(self.num_envs, np.bool_),
            "y_clean": e.y_clean.copy(),
            "state": e.x.copy(),
            "inputs": e.u.copy(),
            "action_saturated": e.saturated.copy(),
            "afterburn_warning": e.x[:, 9] - e.x[:, 4] > AFTERBURN_WARNING_C,
            "termination_reason": REASONS[e.reason],
        }
        if self.closed_loop:
            values["controller_saturated"] = e.controller_saturated.copy()
            values["setpoint_clipped"] = e.setpoint_clipped.copy()
            values["setpoints"] = e.shown.copy()
        for i, name in enumerate(AUX_NAMES):
            values[name] = e.aux[:, i].copy()
        infos: dict[str, Any] = {}
        full = mask is None or bool(mask.all())
        for key, value in values.items():
            reported = np.ones(self.num_envs, np.bool_) if full else mask.copy()
            if key == "fault_time":  # a healthy episode's info has none (FCCEnv._get_info)
                reported &= self._faulty
            elif key in ("fault_labels", "fault_times"):  # a concurrent episode's only
                reported &= self._labels != None  # noqa: E711 (elementwise on an object array)
            elif key == "fault_channel":  # a channel fault's only
                reported &= self._channel != None  # noqa: E711
            elif key == "sensor_dropout":  # an episode with a faulty transmitter's only
                reported &= self._sensed
            if key in _OPTIONAL_KEYS and not reported.any():
                continue
            # envs without the key or left alone: zeros or None, as sync leaves them
            value[~reported] = None if value.dtype == object else 0
            infos[key] = value
            infos[f"_{key}"] = reported
        return infos


class FCCClosedLoopVectorEnv(FCCVectorEnv):
    """``FCC-closedloop-v0``'s native vector env: :class:`FCCVectorEnv` with ``regulatory``
    checked as :class:`~fcc_env.env.FCCClosedLoopEnv` checks it (default ``True``; ``False`` or
    ``None`` refused by name)."""

    def __init__(self, num_envs: int = 1, *, regulatory: Any = True, **kwargs: Any) -> None:
        regulatory = closed_loop_keyword(regulatory, CLOSED_LOOP_ENV_ID)
        super().__init__(num_envs, regulatory=regulatory, **kwargs)
