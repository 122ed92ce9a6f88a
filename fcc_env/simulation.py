"""Episode set-up shared by the env and batch simulation, and the vectorised batch simulator.

Both paths build an episode from one seeded generator in the same order (program, noise and
random-fault streams spawned from it), so :func:`simulate_episodes` reproduces ``FCC-v0`` episodes
with the same seed and options sample for sample (zero actions).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence, Sized
from dataclasses import dataclass, field
from typing import Any

import numba
import numpy as np
from gymnasium.utils import seeding

from fcc_env import effects as fx
from fcc_env.params import (
    MEASUREMENTS,
    N_INPUTS,
    N_MEASUREMENTS,
    N_STATES,
    NOMINAL_INPUTS,
    PARAM_INDEX,
    FCCParams,
)
from fcc_env.physics import (
    AUX_NAMES,
    N_AUX,
    measure_batch_kernel,
    noisy_batch_kernel,
    noisy_kernel,
    rhs_batch_kernel,
    simulate_kernel,
    steady_state,
)
from fcc_env.scenarios import (
    DEFAULT_N_SAMPLES,
    FAULT_OPTION_FIELDS,
    Excitation,
    FaultConfig,
    FaultSpec,
    ProgramGenerator,
    Scenario,
    episode_generators,
)
from fcc_env.uncertainty import PlantUncertainty
from fcc_env.validation import Integer, IntegerSequence, Real, check, invalid

#: Noise std per channel: absolute (°C) and relative to the value (R_ar, 0.5 %), spec §1.1.
NOISE_STD_ABS = np.array([0.0 if m.noise_relative else m.noise_std for m in MEASUREMENTS])
NOISE_STD_REL = np.array([m.noise_std if m.noise_relative else 0.0 for m in MEASUREMENTS])

#: Envelope limits (spec §2.8): the episode terminates when one is crossed.
MIN_WELL_INVENTORY_KG = 3_000.0
MIN_T_RG1_C = 600.0
AFTERBURN_WARNING_C = 40.0  # spec §2.8 flag: reported in info, the episode goes on
MAX_AFTERBURN_C = 80.0  # the d1 afterburn has ignited (T_d1 ≈ 790 °C): the episode ends


#: Allowed slide-valve head share ``valve_beta`` (``FCCParams.beta_sv``).
VALVE_BETA_RANGE = Real(0.0, 1.0, why="0 = flow mode, 0.15 = harder benchmark, 0.3 = default")
#: Allowed sample period.
SAMPLE_TIME_RANGE = Real(
    0.5, 60.0, unit="s", why="RK4 stability and accuracy were verified for the spec's 10 s"
)
#: Allowed RK4 steps per sample.
RK4_SUBSTEPS_RANGE = Integer(1, 100)
#: Allowed multiplier on the spec's noise stds.
NOISE_SCALE_RANGE = Real(0.0, 100.0, why="a multiplier on the spec's noise stds; 0 = noise off")
#: Allowed episode length (samples, counting the reset observation): the env's ``horizon``.
N_SAMPLES_RANGE = Integer(2, why="an episode has an initial and at least one later sample")

#: Allowed episode seeds: at least one, non-negative (Gymnasium's seeding), repeats allowed.
SEEDS_RANGE = IntegerSequence(0, unique=False, why="one episode per seed")

#: Default ceiling on the bytes of the arrays of one :class:`BatchResult` (4 GiB): a request that
#: would need more is refused before simulating, rather than killed by the OS part-way through.
#: Raise it with ``memory_budget_bytes=`` (``python -m fcc_env.generate --memory-budget-gib``).
DEFAULT_MEMORY_BUDGET_BYTES: int = 4 * 2**30

#: Bytes per (episode, sample) of a :class:`BatchResult`: float32 observations, float64 y_clean,
#: inputs, states and aux, bool fault_active.
_BYTES_PER_SAMPLE = 8 * 4 + (8 + 6 + 11 + len(AUX_NAMES)) * 8 + 1


def batch_nbytes(n_episodes: int, n_samples: int) -> int:
    """Bytes of the arrays of a :class:`BatchResult` of ``n_episodes`` x ``n_samples``."""
    return int(n_episodes) * int(n_samples) * _BYTES_PER_SAMPLE


def _gib(n: float) -> str:
    return f"{n / 2**30:.3g} GiB"


def check_memory(
    n_episodes: int, n_samples: int, budget_bytes: float = DEFAULT_MEMORY_BUDGET_BYTES
) -> int:
    """Refuse a batch whose arrays would exceed ``budget_bytes``; returns the estimate.

    The message names the request, the estimate and the budget.
    """
    budget = check("memory_budget_bytes", budget_bytes, Real(0, closed="neither"))
    need = batch_nbytes(n_episodes, n_samples)
    if need > budget:
        raise ValueError(
            f"{n_episodes} episodes x {n_samples} samples need about {_gib(need)} of arrays, "
            f"more than the memory budget of {_gib(budget)}: ask for fewer seeds or samples, "
            "split the request, or raise memory_budget_bytes (CLI: --memory-budget-gib)"
        )
    return need


#: The slide-valve head share of the declared plant (``valve_beta``'s default).
DEFAULT_VALVE_BETA: float = FCCParams().beta_sv


@dataclass(frozen=True)
class PlantConfig:
    """Everything that defines the plant and its operation, validated once (env kwargs).

    The field defaults are the paper's set-up and the one place they are written; :meth:`build`
    takes the env's keyword names (``None`` = the default).
    """

    params: FCCParams = field(default_factory=FCCParams)
    sample_time_s: float = 10.0
    rk4_substeps: int = 1
    excitation: Excitation | None = field(default_factory=Excitation)
    noise_scale: float = 1.0

    @classmethod
    def build(
        cls,
        *,
        valve_beta: Any = None,
        sample_time_s: Any = None,
        rk4_substeps: Any = None,
        excitation: Any = None,
        noise_scale: Any = None,
        params: FCCParams | None = None,
    ) -> PlantConfig:
        """Validate env-style plant options; ``valve_beta`` overrides ``params.beta_sv``
        (default :data:`DEFAULT_VALVE_BETA`, also when ``params`` are given)."""
        if params is not None and not isinstance(params, FCCParams):
            raise invalid("params", params, "an FCCParams instance or None")
        valve_beta = DEFAULT_VALVE_BETA if valve_beta is None else valve_beta
        p = (params or FCCParams()).replace(
            beta_sv=check("valve_beta", valve_beta, VALVE_BETA_RANGE)
        )
        return cls(
            params=p,
            sample_time_s=check(
                "sample_time_s", _or_default(sample_time_s, "sample_time_s"), SAMPLE_TIME_RANGE
            ),
            rk4_substeps=check(
                "rk4_substeps", _or_default(rk4_substeps, "rk4_substeps"), RK4_SUBSTEPS_RANGE
            ),
            excitation=Excitation.from_option(excitation),
            noise_scale=check(
                "noise_scale", _or_default(noise_scale, "noise_scale"), NOISE_SCALE_RANGE
            ),
        )

    @property
    def valve_beta(self) -> float:
        return self.params.beta_sv

    def initial_state(self) -> np.ndarray:
        return steady_state(self.params, NOMINAL_INPUTS)


_PLANT_DEFAULTS = {f.name: f.default for f in dataclasses.fields(PlantConfig)}
#: The env / :func:`simulate_episodes` keyword names that :meth:`PlantConfig.build` takes.
PLANT_OPTION_NAMES = (
    "valve_beta",
    "sample_time_s",
    "rk4_substeps",
    "excitation",
    "noise_scale",
    "params",
)


def _or_default(value: Any, name: str) -> Any:
    return _PLANT_DEFAULTS[name] if value is None else value


def plant_from_request(plant: PlantConfig | None, options: Mapping[str, Any]) -> PlantConfig:
    """``plant=`` or the old plant keywords (``None`` = not given); both at once raise."""
    given = sorted(k for k, v in options.items() if v is not None)
    if plant is None:
        return PlantConfig.build(**options)
    if not isinstance(plant, PlantConfig):
        raise invalid("plant", plant, "a PlantConfig or None")
    if given:
        raise ValueError(
            f"plant={plant!r} and the plant keyword(s) {given} were both given: pass the plant "
            "either as plant=PlantConfig.build(...) or as keywords, not both"
        )
    return plant


FAULT_OPTION_NAMES = tuple(opt for opt, _ in FAULT_OPTION_FIELDS)
RESET_OPTION_NAMES = ("fault", *FAULT_OPTION_NAMES, "plant_effects")


def draw_fault(rng: np.random.Generator, horizon: int, options: dict[str, Any]) -> FaultConfig:
    """Resolve env-style fault options (kept for one release: use :meth:`FaultSpec.resolve`)."""
    return FaultSpec.from_request(None, options).resolve(horizon, rng)


class PlantSchedule:
    """What changes the plant over an episode: the fault and the undeclared plant effects.

    Parameter changes (the fault's and the library process effects') become per-sample
    multipliers of parameter slots ``pidx``; input effects transform the operating program;
    ``measure`` effects transform the noise-free measurements; ``d_state`` effects need the
    generic (Python-level RK4) path. Every method is elementwise in the sample index, so the env
    (chunk by chunk) and batch simulation (whole episodes) compute the same numbers.
    """

    def __init__(
        self, fault: FaultConfig, effects: list[Any], params: FCCParams, sample_time_s: float
    ):
        self.fault = fault
        self.params = params
        self.sample_time_s = sample_time_s
        self.param_effects = [e for e in effects if fx.has_hook(e, "param_multipliers")]
        self.input_effects = [e for e in effects if fx.has_hook(e, "transform_inputs")]
        self.measure_effects = [e for e in effects if fx.has_hook(e, "measure")]
        self.state_effects = [e for e in effects if fx.has_hook(e, "d_state")]
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
        return u

    def measure(self, k: int, y: np.ndarray) -> np.ndarray:
        t = k * self.sample_time_s
        for e in self.measure_effects:
            y = np.asarray(e.measure(t, y), dtype=np.float64)
        return y

    def d_state(self, t: float, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        total = np.zeros_like(x)
        for e in self.state_effects:
            total = total + np.asarray(e.d_state(t, x, u, self.params), dtype=np.float64)
        return total


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
    schedule: PlantSchedule,
    sample_time_s: float,
    substeps: int,
    advance: bool = True,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One sample of B episodes with ``d_state`` effects: RK4 in numpy over the compiled RHS.

    Returns (measurement, aux, next state) at sample k; x, u: (B, ·), p: (B, n_params).

    Why a numpy twin of the compiled RK4 (``physics.step_kernel``): a user effect's ``d_state`` is
    arbitrary Python, which compiled code cannot call, so the stages are combined here around one
    compiled RHS call per stage (:func:`fcc_env.physics.rhs_batch_kernel`). Everything else is
    shared: the RHS, the measurement map (:func:`fcc_env.physics.measure_batch_kernel`) and the
    stage arithmetic, written in the same order as the compiled loop so that both give the same
    numbers (``tests/test_effects.py`` checks env = batch on this path).
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
    fault: FaultConfig
    program: ProgramGenerator
    noise_rng: np.random.Generator
    schedule: PlantSchedule


def setup_episode(
    rng: np.random.Generator,
    config: PlantConfig,
    fault: FaultSpec,
    horizon: int,
    plant_effects: list[Any] | None = None,
) -> EpisodeSetup:
    """Set up one episode from its seeded generator (the env's and batch simulation's order)."""
    gens = episode_generators(rng)
    resolved = fault.resolve(horizon, gens["fault"])
    effects = plant_effects or []
    fx.reset_all(effects)
    schedule = PlantSchedule(resolved, effects, config.params, config.sample_time_s)
    return EpisodeSetup(
        resolved, ProgramGenerator(config.excitation, gens["program"]), gens["noise"], schedule
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


#: Envelope codes of :func:`envelope_code`: ``TERMINATION_REASONS[code]`` (0 = inside).
TERMINATION_REASONS: tuple[str | None, ...] = (
    None,
    "numerical_failure",
    "well_empty",
    "extinguished",
    "afterburn",
)


@numba.njit(cache=True, nogil=True)
def envelope_code(x: np.ndarray) -> int:
    """The one envelope check (spec §2.8): index into :data:`TERMINATION_REASONS` of state ``x``.

    The first reason in that order wins (a non-finite state is a numerical failure whatever else).
    """
    for i in range(x.shape[0]):
        if not math.isfinite(x[i]):
            return 1
    if x[8] < MIN_WELL_INVENTORY_KG:
        return 2
    if x[4] < MIN_T_RG1_C:
        return 3
    if x[9] - x[4] > MAX_AFTERBURN_C:
        return 4
    return 0


@numba.njit(cache=True, nogil=True)
def envelope_codes(X: np.ndarray) -> np.ndarray:
    """:func:`envelope_code` of every sample of states ``X`` (B, T, 11): codes (B, T) int8."""
    out = np.zeros((X.shape[0], X.shape[1]), dtype=np.int8)
    for b in range(X.shape[0]):
        for k in range(X.shape[1]):
            out[b, k] = envelope_code(X[b, k])
    return out


def termination_reason(x: np.ndarray) -> str | None:
    """Why the plant left its physical envelope at state ``x`` (spec §2.8), or None."""
    return TERMINATION_REASONS[envelope_code(np.asarray(x, dtype=np.float64))]


@dataclass(frozen=True)
class BatchResult:
    """Arrays of a batch of episodes; leading axes ``(n_episodes, n_samples)``.

    ``observations`` are exactly what ``FCC-v0`` returns (float32); the other arrays are float64.
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


def simulate_episodes(
    seeds: Sequence[int],
    n_samples: int = DEFAULT_N_SAMPLES,
    *,
    fault: FaultSpec | None = None,
    plant: PlantConfig | None = None,
    plant_effects: Any = (),
    scenario: str | Sequence[str] | None = None,
    fault_time: int | None = None,
    fault_magnitude: float | None = None,
    fault_profile: str | None = None,
    ramp_samples: int | None = None,
    valve_beta: float | None = None,
    sample_time_s: float | None = None,
    rk4_substeps: int | None = None,
    excitation: Any = None,
    noise_scale: float | None = None,
    params: FCCParams | None = None,
    plant_uncertainty: PlantUncertainty | None = None,
    memory_budget_bytes: float = DEFAULT_MEMORY_BUDGET_BYTES,
) -> BatchResult:
    """Simulate many seeded episodes at once, identical to ``FCC-v0`` with zero actions.

    Args:
        seeds: one episode per seed.
        n_samples: samples per episode (:data:`N_SAMPLES_RANGE`), the env's ``horizon``.
        fault: the fault asked for (default: nominal). The env's keywords ``scenario``,
            ``fault_time``, ``fault_magnitude``, ``fault_profile``, ``ramp_samples`` still work;
            given together with ``fault`` they must agree with it. ``scenario`` may also be one
            name per seed: then it replaces the spec's scenario, whose other fields apply to each.
        plant: the plant (default: the paper's); or the env's keywords ``valve_beta``,
            ``sample_time_s``, ``rk4_substeps``, ``excitation``, ``noise_scale``, ``params``
            (``None`` = not given), never both.
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
    """
    n_samples = check("n_samples", n_samples, N_SAMPLES_RANGE)
    if isinstance(seeds, Sized) and not isinstance(seeds, str | bytes):
        check_memory(len(seeds), n_samples, memory_budget_bytes)  # before copying the seeds
    seeds = list(check("seeds", seeds, SEEDS_RANGE))
    check_memory(len(seeds), n_samples, memory_budget_bytes)
    per_seed = scenario is not None and not isinstance(scenario, str)
    base = FaultSpec.from_request(
        fault,
        {
            "scenario": None if per_seed else scenario,
            "fault_time": fault_time,
            "fault_magnitude": fault_magnitude,
            "fault_profile": fault_profile,
            "ramp_samples": ramp_samples,
        },
    )
    if per_seed:
        specs = [base.replace(scenario=sc) for sc in scenario]
        if len(specs) != len(seeds):
            raise ValueError(f"got {len(specs)} scenarios for {len(seeds)} seeds")
    else:
        specs = [base] * len(seeds)
    config = plant_from_request(
        plant,
        {
            "valve_beta": valve_beta,
            "sample_time_s": sample_time_s,
            "rk4_substeps": rk4_substeps,
            "excitation": excitation,
            "noise_scale": noise_scale,
            "params": params,
        },
    )
    effects = fx.resolve(plant_effects)
    B, T = len(seeds), int(n_samples)
    configs = [config] * B
    drawn: list[list[Any]] = [[] for _ in seeds]
    if plant_uncertainty is not None:
        draws = [plant_uncertainty.draw(s, base=config.params) for s in seeds]
        configs = [dataclasses.replace(config, params=d.params) for d in draws]
        drawn = [list(d.effects) for d in draws]
    k = np.arange(T)
    U = np.empty((B, T, N_INPUTS))
    Z = np.empty((B, T, N_MEASUREMENTS))
    faults: list[FaultConfig] = []
    pidx_rows, pm_rows = [], []
    schedule = None
    for b, (seed, spec) in enumerate(zip(seeds, specs, strict=True)):
        rng, _ = seeding.np_random(seed)
        setup = setup_episode(rng, configs[b], spec, T, [*effects, *drawn[b]])
        schedule = setup.schedule
        U[b] = schedule.inputs(k, setup.program.take(T))
        Z[b] = setup.noise_rng.standard_normal((T, N_MEASUREMENTS))
        faults.append(setup.fault)
        pidx_rows.append(schedule.pidx)
        pm_rows.append(schedule.multipliers(k))
    assert schedule is not None
    fx.reset_all(effects)  # measurement effects start afresh for the batch as a whole
    pidx = np.stack(pidx_rows)
    PM = np.stack(pm_rows)
    if plant_uncertainty is None:
        x0 = np.tile(config.initial_state(), (B, 1))
        p_base = np.tile(config.params.as_array(), (B, 1))
    else:  # each episode starts at its own plant's steady state
        x0 = np.stack([c.initial_state() for c in configs])
        p_base = np.stack([c.params.as_array() for c in configs])
    Y = np.empty((B, T, N_MEASUREMENTS))
    obs = np.empty((B, T, N_MEASUREMENTS), dtype=np.float32)
    X = np.empty((B, T, N_STATES))
    A = np.empty((B, T, N_AUX))
    if schedule.generic:
        x = x0
        for kk in range(T):
            p = apply_multipliers(p_base, pidx, PM[:, kk])
            y, aux, x_next = generic_sample(
                x, np.ascontiguousarray(U[:, kk]), p, kk, schedule, config.sample_time_s,
                config.rk4_substeps, advance=kk + 1 < T,
            )  # fmt: skip
            Y[:, kk], A[:, kk], X[:, kk] = y, aux, x
            x = x_next
    else:
        simulate_kernel(
            x0, U, p_base, pidx, PM, config.sample_time_s / config.rk4_substeps,
            config.rk4_substeps, Z, NOISE_STD_ABS, NOISE_STD_REL, config.noise_scale, Y, obs, X,
            A, not schedule.measure_effects,
        )  # fmt: skip
    if schedule.generic or schedule.measure_effects:
        for kk in range(T):
            Y[:, kk] = schedule.measure(kk, Y[:, kk])
        noisy_batch_kernel(Y, Z, NOISE_STD_ABS, NOISE_STD_REL, config.noise_scale, obs)
    del Z
    active = np.stack(
        [
            (k >= f.onset) if f.scenario is not Scenario.NOMINAL else np.zeros(T, bool)
            for f in faults
        ]
    )
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
        scenarios=tuple(f.scenario.value for f in faults),
        fault_onsets=tuple(f.onset if f.scenario is not Scenario.NOMINAL else None for f in faults),
        fault_magnitudes=tuple(f.magnitude for f in faults),
        terminated_at=term_at,
        termination_reasons=reasons,
        sample_time_s=config.sample_time_s,
    )


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
    sample_time_s = check(
        "sample_time_s", _or_default(sample_time_s, "sample_time_s"), SAMPLE_TIME_RANGE
    )
    rk4_substeps = check(
        "rk4_substeps", _or_default(rk4_substeps, "rk4_substeps"), RK4_SUBSTEPS_RANGE
    )
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
        X0.copy(), np.ascontiguousarray(U), np.tile(p.as_array(), (B, 1)), pidx, PM,
        sample_time_s / rk4_substeps, rk4_substeps, np.empty((B, 1, N_MEASUREMENTS)),
        NOISE_STD_ABS, NOISE_STD_REL, 0.0, Y, dummy, X, A, False,
    )  # fmt: skip
    if single:
        return InputSimulation(Y[0], X[0], A[0])
    return InputSimulation(Y, X, A)
