"""Batch simulation: many seeded episodes at once (:func:`simulate_episodes`, identical to
``FCC-v0`` with zero actions), and the declared model run on a given input record
(:func:`simulate_inputs`)."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence, Sized
from dataclasses import dataclass
from typing import Any

import numpy as np
from gymnasium.utils import seeding

from fcc_common.validation import Integer, IntegerSequence, Real, check, invalid
from fcc_env import effects as fx
from fcc_env.closed_loop import (
    observation_channels,
    simulate_closed_per_sample,
)
from fcc_env.episode_setup import (
    BatchSchedule,
    PlantSchedule,
    apply_multipliers,
    generic_sample,
    setup_episode,
)
from fcc_env.integrator import noisy_batch_kernel, open_loop_controller_args, simulate_kernel
from fcc_env.params import (
    MEASUREMENT_NAMES,
    N_INPUTS,
    N_MEASUREMENTS,
    N_STATES,
    NOMINAL_INPUTS,
    PARAM_INDEX,
    FCCParams,
)
from fcc_env.physics import AUX_NAMES, N_AUX, steady_state
from fcc_env.plant import (
    NOISE_STD_ABS,
    NOISE_STD_REL,
    RK4_SUBSTEPS_RANGE,
    SAMPLE_TIME_RANGE,
    TERMINATION_REASONS,
    PlantConfig,
    envelope_codes,
)
from fcc_env.regulatory import check_setpoints, initial_controller_state
from fcc_env.scenarios import (
    DEFAULT_N_SAMPLES,
    EpisodeFault,
    FaultSpec,
)
from fcc_env.uncertainty import PlantUncertainty

#: Allowed episode length (samples, counting the reset observation): the env's ``horizon``.
N_SAMPLES_RANGE = Integer(2, why="an episode has an initial and at least one later sample")

#: Allowed episode seeds: at least one, non-negative (Gymnasium's seeding), repeats allowed.
SEEDS_RANGE = IntegerSequence(0, unique=False, why="one episode per seed")

#: Default ceiling on the bytes of the arrays of one :class:`BatchResult` (4 GiB): a request that
#: would need more is refused before simulating, rather than killed by the OS part-way through.
#: Raise it with ``memory_budget_bytes=`` (``python -m fcc_env.generate --memory-budget-gib``).
DEFAULT_MEMORY_BUDGET_BYTES: int = 4 * 2**30

#: Bytes per (episode, sample) of a :class:`BatchResult`: float32 observations, float64 y_clean,
#: inputs, states and aux, bool fault_active and sensor_dropout.
_BYTES_PER_SAMPLE = 8 * 4 + (8 + 6 + 11 + len(AUX_NAMES)) * 8 + 2


def batch_nbytes(n_episodes: int, n_samples: int) -> int:
    """Bytes of the arrays of a :class:`BatchResult` of ``n_episodes`` x ``n_samples``."""
    return int(n_episodes) * int(n_samples) * _BYTES_PER_SAMPLE


#: Peak resident memory of a process per byte of :func:`batch_nbytes`: the budget counts the
#: arrays only, and building them (and writing them out) takes more. Measured with
#: ``/usr/bin/time -v python -m fcc_env.generate --seeds 0-699``: 0.90 GiB of arrays, 2.3 GiB
#: maximum RSS (0.16 GiB of it the imports).
PEAK_RSS_FACTOR = 2.6


def _gib(n: float) -> str:
    return f"{n / 2**30:.3g} GiB"


def check_memory(
    n_episodes: int, n_samples: int, budget_bytes: float = DEFAULT_MEMORY_BUDGET_BYTES
) -> int:
    """Refuse a batch whose arrays would exceed ``budget_bytes``; returns the estimate.

    The message names the request, the estimate, the process's likely peak
    (:data:`PEAK_RSS_FACTOR` times the arrays) and the budget.
    """
    budget = check("memory_budget_bytes", budget_bytes, Real(0, closed="neither"))
    need = batch_nbytes(n_episodes, n_samples)
    if need > budget:
        raise ValueError(
            f"{n_episodes} episodes x {n_samples} samples need about {_gib(need)} of arrays "
            f"(the process peaks near {_gib(need * PEAK_RSS_FACTOR)}, {PEAK_RSS_FACTOR}x), "
            f"more than the memory budget of {_gib(budget)} of arrays: ask for fewer seeds or samples, "
            "split the request, or raise memory_budget_bytes (CLI: --memory-budget-gib)"
        )
    return need


#: :class:`PlantConfig`'s field defaults (what ``None`` means for :func:`simulate_inputs`).
_PLANT_DEFAULTS = {f.name: f.default for f in dataclasses.fields(PlantConfig)}


@dataclass(frozen=True)
class BatchResult:
    """Arrays of a batch of episodes; leading axes ``(n_episodes, n_samples)``.

    ``observations`` are exactly what ``FCC-v0`` (or, on a closed-loop plant,
    ``FCC-closedloop-v0``) returns (float32), channels :attr:`channels`; ``y_clean`` has the
    same channels noise-free; the other arrays are float64.
    """

    observations: np.ndarray  # (B, T, 8) float32, noisy Table 1 measurements
    y_clean: np.ndarray  # (B, T, 8) noise-free measurements
    fault_active: np.ndarray  # (B, T) bool
    inputs: np.ndarray  # (B, T, 6) inputs applied over each sample (INPUT_NAMES)
    states: np.ndarray  # (B, T, 11)
    aux: np.ndarray  # (B, T, len(AUX_NAMES))
    seeds: tuple[int, ...]
    scenarios: tuple[str, ...]
    fault_onsets: tuple[int | None, ...]
    fault_magnitudes: tuple[float, ...]
    terminated_at: np.ndarray  # (B,) first sample outside the envelope, -1 if none; later
    # samples are kept for inspection but are not meaningful (the env would have ended there)
    termination_reasons: tuple[str | None, ...]
    sample_time_s: float
    aux_names: tuple[str, ...] = AUX_NAMES
    #: Observation channels: Table 1, or in closed loop Table 1 + u_F + set points.
    channels: tuple[str, ...] = MEASUREMENT_NAMES
    setpoints: np.ndarray | None = None  # (B, T, 2) closed loop: set points in force, °C
    #: (B, T) bool, closed loop: the controller output in force over sample k was clamped at an
    #: actuator limit (the env's ``info["controller_saturated"]`` of sample k)
    controller_saturated: np.ndarray | None = None
    #: (B, T) bool: the sample was a sensor dropout, its channel holding the last good value
    #: (the env's ``info["sensor_dropout"]``; :mod:`fcc_env.sensor_faults`)
    sensor_dropout: np.ndarray | None = None
    #: each episode's faulty channel (a channel fault's, :mod:`fcc_env.sensor_faults`), else None
    fault_channels: tuple[str | None, ...] = ()
    #: each episode's faults by name (:attr:`fcc_env.scenarios.EpisodeFault.labels`): () when
    #: healthy, a concurrent episode's two in onset order (the labels an isolator must name)
    fault_labels: tuple[tuple[str, ...], ...] = ()


def _episode_faults(fault: FaultSpec | Sequence[FaultSpec] | None, n: int) -> list[FaultSpec]:
    """The fault of each of ``n`` episodes: ``fault`` (one spec for all, or one per episode)."""
    if fault is None or isinstance(fault, FaultSpec):
        return [FaultSpec() if fault is None else fault] * n
    if isinstance(fault, str) or not isinstance(fault, Sequence):
        raise invalid("fault", fault, "a FaultSpec, one FaultSpec per seed, or None")
    specs = list(fault)
    bad = [f for f in specs if not isinstance(f, FaultSpec)]
    if bad:
        raise invalid("fault", bad[0], "a FaultSpec (one per seed)")
    if len(specs) != n:
        raise ValueError(f"got {len(specs)} faults for {n} seeds; allowed: one, or one per seed")
    return specs


def simulate_episodes(
    seeds: Sequence[int],
    n_samples: int = DEFAULT_N_SAMPLES,
    *,
    fault: FaultSpec | Sequence[FaultSpec] | None = None,
    plant: PlantConfig | None = None,
    plant_effects: Any = (),
    plant_uncertainty: PlantUncertainty | None = None,
    memory_budget_bytes: float = DEFAULT_MEMORY_BUDGET_BYTES,
) -> BatchResult:
    """Simulate many seeded episodes at once, identical to ``FCC-v0`` with zero actions.

    Args:
        seeds: one episode per seed.
        n_samples: samples per episode (:data:`N_SAMPLES_RANGE`), the env's ``horizon``.
        fault: the fault asked for, a :class:`fcc_env.FaultSpec` or one per seed (default:
            nominal). ``FaultSpec(scenario="f1", onset=150)`` is what ``gym.make``'s keywords
            ``scenario=``, ``fault_time=`` build (:func:`fcc_env.scenarios.fault_from_request`).
        plant: the plant, a :class:`fcc_env.PlantConfig` (default: the paper's), passed whole;
            ``PlantConfig.build(noise_scale=2.0, regulatory=True)`` is what the env's keywords
            build. A plant with a :class:`fcc_env.RegulatoryLayer` runs closed loop, as
            ``FCC-closedloop-v0``.
        plant_effects: as for the env (:mod:`fcc_env.effects`); one effect object serves the
            whole batch, with a leading episode axis on its arrays.
        plant_uncertainty: each episode's plant drawn by seed
            (:meth:`fcc_env.uncertainty.PlantUncertainty.draw`: parameters within stated ranges
            and benign slow disturbances), independent of the scenario, so a healthy and a faulty
            episode of one seed share their plant; nothing of the draw is in the observations.
        memory_budget_bytes: refuse (``ValueError``, before simulating) a request whose result
            arrays would need more bytes (:data:`DEFAULT_MEMORY_BUDGET_BYTES`, 4 GiB).

    Episodes run in parallel threads of the compiled kernel (numba ``prange``); with a user
    effect that has ``d_state`` the integration runs in numpy over the episode axis instead
    (slower, same numbers as the env).

    >>> from fcc_env import FaultSpec
    >>> b = simulate_episodes([0, 1], 300, fault=FaultSpec(scenario="f1", onset=150))
    >>> b.observations.shape, b.scenarios, b.fault_onsets
    ((2, 300, 8), ('f1', 'f1'), (150, 150))
    """
    n_samples = check("n_samples", n_samples, N_SAMPLES_RANGE)
    if isinstance(seeds, Sized) and not isinstance(seeds, str | bytes):
        check_memory(len(seeds), n_samples, memory_budget_bytes)  # before copying the seeds
    seeds = list(check("seeds", seeds, SEEDS_RANGE))
    check_memory(len(seeds), n_samples, memory_budget_bytes)
    specs = _episode_faults(fault, len(seeds))
    if plant is not None and not isinstance(plant, PlantConfig):
        raise invalid("plant", plant, "a PlantConfig or None (the paper's plant)")
    config = PlantConfig() if plant is None else plant
    effects = fx.resolve(plant_effects)
    B, T = len(seeds), int(n_samples)
    configs = [config] * B
    drawn: list[list[Any]] = [[] for _ in seeds]
    if plant_uncertainty is not None:
        draws = [plant_uncertainty.draw(s, base=config.params) for s in seeds]
        configs = [config.replace(params=d.params) for d in draws]
        drawn = [list(d.effects) for d in draws]
    k = np.arange(T)
    U = np.empty((B, T, N_INPUTS))
    SP = np.empty((B, T, 2)) if config.closed_loop else None
    Z = np.empty((B, T, N_MEASUREMENTS))
    faults: list[EpisodeFault] = []
    schedules: list[PlantSchedule] = []
    for b, (seed, spec) in enumerate(zip(seeds, specs, strict=True)):
        rng, _ = seeding.np_random(seed)
        setup = setup_episode(rng, configs[b], spec, T, [*effects, *drawn[b]])
        U[b], sp = setup.take_program(k)
        if SP is not None:
            SP[b], _ = check_setpoints(sp)
        Z[b] = setup.noise_rng.standard_normal((T, N_MEASUREMENTS))
        faults.append(setup.fault)
        schedules.append(setup.schedule)
    fx.reset_all(effects)  # measurement effects start afresh for the batch as a whole
    pidx, PM = _slots(schedules, k)
    schedule = BatchSchedule(schedules)
    if plant_uncertainty is None:
        x0 = np.tile(config.initial_state(), (B, 1))
        p_base = np.tile(config.params.as_array(), (B, 1))
    else:  # each episode starts at its own plant's steady state
        x0 = np.stack([c.initial_state() for c in configs])
        p_base = np.stack([c.params.as_array() for c in configs])
    n_channels = len(observation_channels(config))
    Y = np.empty((B, T, n_channels))
    obs = np.empty((B, T, n_channels), dtype=np.float32)
    X = np.empty((B, T, N_STATES))
    A = np.empty((B, T, N_AUX))
    SAT = None
    LOST = np.zeros((B, T), dtype=np.bool_)  # a channel fault's dropouts (fcc_env.sensor_faults)

    def run_kernel(noise: np.ndarray, add_noise: bool, *controller: np.ndarray) -> None:
        """The compiled batch kernel on this batch with the standard-normal draws ``noise``; ``controller``: the loops' state, set
        points, gains and saturation flags (placeholders in open loop)."""
        dt_s = config.sample_time_s / config.rk4_substeps
        simulate_kernel(
            x0,
            U,
            p_base,
            pidx,
            PM,
            dt_s,
            config.rk4_substeps,
            noise,
            NOISE_STD_ABS,
            NOISE_STD_REL,
            config.noise_scale,
            Y,
            obs,
            X,
            A,
            add_noise,
            *controller,
        )

    if config.regulatory is None and schedule.actuates:
        # open loop: the inputs as commanded do not depend on the plant, so the devices act
        # on the whole program before the compiled kernel runs it
        for kk in range(T):
            U[:, kk] = schedule.actuate(kk, U[:, kk])
    if config.regulatory is not None:
        assert SP is not None
        C = np.tile(initial_controller_state(NOMINAL_INPUTS), (B, 1))
        gains = config.regulatory.gains(config.sample_time_s)
        if schedule.generic or schedule.measures or schedule.actuates:
            Y, obs, X, A, SAT = simulate_closed_per_sample(
                x0, U, SP, C, gains, p_base, pidx, PM, Z, schedule, config, LOST
            )
        else:
            SAT = np.zeros((B, T), dtype=np.bool_)
            run_kernel(Z, True, C, SP, gains, SAT)
    elif schedule.generic:
        x = x0
        for kk in range(T):
            p = apply_multipliers(p_base, pidx, PM[:, kk])
            y, aux, x_next = generic_sample(
                x,
                np.ascontiguousarray(U[:, kk]),
                p,
                kk,
                schedule,
                config.sample_time_s,
                config.rk4_substeps,
                advance=kk + 1 < T,
            )
            Y[:, kk], A[:, kk], X[:, kk] = y, aux, x
            x = x_next
    else:
        run_kernel(Z, not schedule.measures, *open_loop_controller_args(B, T))
    if config.regulatory is None and (schedule.generic or schedule.measures):
        for kk in range(T):
            Y[:, kk], Z[:, kk] = schedule.sense(kk, Y[:, kk], Z[:, kk], LOST[:, kk])
        noisy_batch_kernel(Y, Z, NOISE_STD_ABS, NOISE_STD_REL, config.noise_scale, obs)
    del Z
    active = np.stack([(k >= f.onset) if not f.nominal else np.zeros(T, bool) for f in faults])
    codes = envelope_codes(X)
    bad = codes != 0
    term_at = np.where(bad.any(axis=1), np.argmax(bad, axis=1), -1)
    reasons = tuple(
        TERMINATION_REASONS[codes[b, t]] if t >= 0 else None for b, t in enumerate(term_at)
    )
    return BatchResult(
        observations=obs,
        y_clean=Y,
        fault_active=active,
        inputs=U,
        states=X,
        aux=A,
        seeds=tuple(seeds),
        scenarios=tuple(f.scenario for f in faults),
        fault_onsets=tuple(None if f.nominal else f.onset for f in faults),
        fault_magnitudes=tuple(f.magnitude for f in faults),
        terminated_at=term_at,
        termination_reasons=reasons,
        sample_time_s=config.sample_time_s,
        channels=observation_channels(config),
        setpoints=SP,
        controller_saturated=SAT,
        sensor_dropout=LOST,
        fault_channels=tuple(f.channel for f in faults),
        fault_labels=tuple(f.labels for f in faults),
    )


def _slots(schedules: list[PlantSchedule], k: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Every episode's parameter slots ``(B, K)`` and their multipliers over samples ``k``
    ``(B, T, K)``, padded to the widest episode (slot -1, multiplier 1: untouched)."""
    width = max(s.pidx.shape[0] for s in schedules)
    pidx = np.full((len(schedules), width), -1, dtype=np.int64)
    PM = np.ones((len(schedules), k.shape[0], width))
    for b, s in enumerate(schedules):
        n = s.pidx.shape[0]
        pidx[b, :n] = s.pidx
        PM[b, :, :n] = s.multipliers(k)
    return pidx, PM


def operating_program(
    seed: int, n_samples: int, plant: PlantConfig | None = None
) -> tuple[np.ndarray, np.ndarray | None]:
    """The operating program of episode ``seed`` as the env and :func:`simulate_episodes` draw
    it, without simulating: inputs ``(n_samples, 6)`` (in closed loop the valve and air
    columns are the program's, which the controllers replace) and, in closed loop, the set
    points ``(n_samples, 2)`` (else None). The program does not depend on the fault."""
    config = plant or PlantConfig()
    n_samples = check("n_samples", n_samples, N_SAMPLES_RANGE)
    rng, _ = seeding.np_random(check("seed", seed, Integer(0)))
    setup = setup_episode(rng, config, FaultSpec(), n_samples)
    return setup.take_program(np.arange(n_samples))


@dataclass(frozen=True)
class InputSimulation:
    """Noise-free response to given inputs: arrays with a leading episode axis if one was given."""

    y_clean: np.ndarray  # (..., T, 8)
    states: np.ndarray  # (..., T, 11)
    aux: np.ndarray  # (..., T, len(AUX_NAMES))


def simulate_inputs(
    inputs: np.ndarray,
    *,
    params: FCCParams | None = None,
    param_multipliers: dict[str, np.ndarray] | None = None,
    x0: np.ndarray | None = None,
    sample_time_s: float | None = None,
    rk4_substeps: int | None = None,
) -> InputSimulation:
    """Run the declared model on an input record (simulation, never one-step prediction).

    Args:
        inputs: (T, 6) or (B, T, 6) inputs ordered as :data:`fcc_env.INPUT_NAMES`, held over
            each sample (e.g. measured R_ar, T_ar, T_fp and the commanded valve).
        params: model parameters (default: the declared ones).
        param_multipliers: per-sample multipliers of parameter fields, arrays (T,) or (B, T).
        x0: initial state (default: the steady state of ``params`` at the first input).
        sample_time_s, rk4_substeps: as for the env (``None``: :class:`PlantConfig`'s default).
    """
    U = np.asarray(inputs, dtype=np.float64)
    single = U.ndim == 2
    if single:
        U = U[None]
    if U.ndim != 3 or U.shape[2] != N_INPUTS:
        raise ValueError(
            f"inputs must have shape (T, {N_INPUTS}) or (B, T, {N_INPUTS}); got {U.shape}"
        )
    if not np.isfinite(U).all():
        raise ValueError("inputs contain NaN or inf")
    B, T = U.shape[:2]
    sample_time_s = _PLANT_DEFAULTS["sample_time_s"] if sample_time_s is None else sample_time_s
    rk4_substeps = _PLANT_DEFAULTS["rk4_substeps"] if rk4_substeps is None else rk4_substeps
    sample_time_s = check("sample_time_s", sample_time_s, SAMPLE_TIME_RANGE)
    rk4_substeps = check("rk4_substeps", rk4_substeps, RK4_SUBSTEPS_RANGE)
    p = params or FCCParams()
    mults = param_multipliers or {}
    unknown = sorted(set(mults) - set(PARAM_INDEX))
    if unknown:
        raise ValueError(f"Unknown parameter(s) {unknown} in param_multipliers")
    pidx = np.array([[PARAM_INDEX[n] for n in mults] or [-1]] * B, dtype=np.int64)
    if mults:
        PM = np.stack([np.broadcast_to(np.asarray(v, float), (B, T)) for v in mults.values()], -1)
    else:
        PM = np.ones((B, T, 1))
    PM = np.ascontiguousarray(PM)
    if x0 is None:
        x0 = steady_state(p, U[0, 0])
    X0 = np.ascontiguousarray(np.broadcast_to(np.asarray(x0, float), (B, N_STATES)))
    Y = np.empty((B, T, N_MEASUREMENTS))
    X = np.empty((B, T, N_STATES))
    A = np.empty((B, T, N_AUX))
    dummy = np.empty((B, 1, N_MEASUREMENTS), dtype=np.float32)
    simulate_kernel(
        X0.copy(),
        np.ascontiguousarray(U),
        np.tile(p.as_array(), (B, 1)),
        pidx,
        PM,
        sample_time_s / rk4_substeps,
        rk4_substeps,
        np.empty((B, 1, N_MEASUREMENTS)),
        NOISE_STD_ABS,
        NOISE_STD_REL,
        0.0,
        Y,
        dummy,
        X,
        A,
        False,
        *open_loop_controller_args(B, T),
    )
    if single:
        return InputSimulation(Y[0], X[0], A[0])
    return InputSimulation(Y, X, A)
