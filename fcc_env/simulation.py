"""Episode set-up shared by the env and batch simulation, and the vectorised batch simulator.

Both paths build an episode from one seeded generator in the same order (program, noise and
random-fault streams spawned from it), so :func:`simulate_episodes` reproduces ``FCC-v0`` episodes
with the same seed and options sample for sample (zero actions).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

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
    noisy_batch_kernel,
    noisy_kernel,
    rhs_batch_kernel,
    simulate_kernel,
    steady_state,
)
from fcc_env.scenarios import (
    FAULTS,
    Excitation,
    FaultConfig,
    ProgramGenerator,
    Scenario,
    episode_generators,
    resolve_fault,
)

#: Noise std per channel: absolute (°C) and relative to the value (R_ar, 0.5 %), spec §1.1.
NOISE_STD_ABS = np.array([0.0 if m.noise_relative else m.noise_std for m in MEASUREMENTS])
NOISE_STD_REL = np.array([m.noise_std if m.noise_relative else 0.0 for m in MEASUREMENTS])

#: Envelope limits (spec §2.8): the episode terminates when one is crossed.
MIN_WELL_INVENTORY_KG = 3_000.0
MIN_T_RG1_C = 600.0
AFTERBURN_WARNING_C = 40.0  # spec §2.8 flag: reported in info, the episode goes on
MAX_AFTERBURN_C = 80.0  # the d1 afterburn has ignited (T_d1 ≈ 790 °C): the episode ends


@dataclass(frozen=True)
class PlantConfig:
    """Everything that defines the plant and its operation, validated once (env kwargs)."""

    params: FCCParams = field(default_factory=FCCParams)
    sample_time_s: float = 10.0
    rk4_substeps: int = 1
    excitation: Excitation | None = field(default_factory=Excitation)
    noise_scale: float = 1.0

    @classmethod
    def build(
        cls,
        *,
        valve_beta: Any = 0.3,
        sample_time_s: Any = 10.0,
        rk4_substeps: Any = 1,
        excitation: Any = True,
        noise_scale: Any = 1.0,
        params: FCCParams | None = None,
    ) -> PlantConfig:
        if not _is_number(valve_beta) or not 0.0 <= float(valve_beta) <= 1.0:
            raise ValueError(
                f"valve_beta={valve_beta!r} outside the allowed range [0, 1] "
                "(0 = flow mode, 0.15 = harder benchmark, 0.3 = default)"
            )
        if not _is_number(sample_time_s) or not 0.5 <= float(sample_time_s) <= 60.0:
            raise ValueError(
                f"sample_time_s={sample_time_s!r} outside the allowed range [0.5, 60] s "
                "(RK4 stability and accuracy were verified for the spec's 10 s)"
            )
        if isinstance(rk4_substeps, bool) or not isinstance(rk4_substeps, int | np.integer):
            raise ValueError(f"rk4_substeps must be an integer in [1, 100], got {rk4_substeps!r}")
        if not 1 <= rk4_substeps <= 100:
            raise ValueError(f"rk4_substeps={rk4_substeps} outside the allowed range [1, 100]")
        if not _is_number(noise_scale) or not 0.0 <= float(noise_scale) <= 100.0:
            raise ValueError(
                f"noise_scale={noise_scale!r} outside the allowed range [0, 100] "
                "(a multiplier on the spec's noise stds; 0 = noise off)"
            )
        if params is not None and not isinstance(params, FCCParams):
            raise ValueError(f"params must be an FCCParams instance, got {type(params).__name__}")
        p = (params or FCCParams()).replace(beta_sv=float(valve_beta))
        return cls(
            params=p,
            sample_time_s=float(sample_time_s),
            rk4_substeps=int(rk4_substeps),
            excitation=Excitation.from_option(excitation),
            noise_scale=float(noise_scale),
        )

    def initial_state(self) -> np.ndarray:
        return steady_state(self.params, NOMINAL_INPUTS)


def _is_number(v: Any) -> bool:
    return isinstance(v, int | float | np.number) and not isinstance(v, bool) and math.isfinite(v)


FAULT_OPTION_NAMES = ("scenario", "fault_time", "fault_magnitude", "fault_profile", "ramp_samples")
RESET_OPTION_NAMES = (*FAULT_OPTION_NAMES, "plant_effects")


def draw_fault(rng: np.random.Generator, horizon: int, options: dict[str, Any]) -> FaultConfig:
    """Resolve fault options; ``scenario="random"`` draws scenario, onset and magnitude from ``rng``.

    Random draws: scenario uniform over nominal and f1–f4, onset uniform in the middle half of
    the horizon, magnitude uniform in [0.5, 1.5] × the paper's. Explicit options override draws.
    The draws always consume the same numbers, so the rest of the episode does not depend on them.
    """
    opts = dict(options)
    if opts.get("scenario") == "random":
        sc = list(Scenario)[int(rng.integers(len(Scenario)))]
        onset = int(rng.integers(horizon // 4, max(horizon // 4 + 1, 3 * horizon // 4)))
        scale = float(rng.uniform(0.5, 1.5))
        opts["scenario"] = sc.value
        if sc is not Scenario.NOMINAL:
            if opts.get("fault_time") is None:
                opts["fault_time"] = onset
            if opts.get("fault_magnitude") is None:
                opts["fault_magnitude"] = FAULTS[sc].default_magnitude * scale
    return resolve_fault(
        opts.get("scenario", "nominal"),
        opts.get("fault_time"),
        opts.get("fault_magnitude"),
        opts.get("fault_profile", "abrupt"),
        opts.get("ramp_samples"),
        horizon=horizon,
    )


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
    y = np.column_stack([u[:, 1], u[:, 2], u[:, 3], aux[:, 0], x[:, 4], x[:, 7], x[:, 9], x[:, 10]])
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
    fault_options: dict[str, Any],
    horizon: int,
    plant_effects: list[Any] | None = None,
) -> EpisodeSetup:
    gens = episode_generators(rng)
    fault = draw_fault(gens["fault"], horizon, fault_options)
    effects = plant_effects or []
    fx.reset_all(effects)
    schedule = PlantSchedule(fault, effects, config.params, config.sample_time_s)
    return EpisodeSetup(
        fault, ProgramGenerator(config.excitation, gens["program"]), gens["noise"], schedule
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


def termination_reason(x: np.ndarray) -> str | None:
    """Why the plant left its physical envelope at state ``x`` (spec §2.8), or None."""
    if not np.isfinite(x).all():
        return "numerical_failure"
    if x[8] < MIN_WELL_INVENTORY_KG:
        return "well_empty"
    if x[4] < MIN_T_RG1_C:
        return "extinguished"
    if x[9] - x[4] > MAX_AFTERBURN_C:
        return "afterburn"
    return None


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
    n_samples: int = 4000,
    *,
    scenario: str | Sequence[str] = "nominal",
    fault_time: int | None = None,
    fault_magnitude: float | None = None,
    fault_profile: str = "abrupt",
    ramp_samples: int | None = None,
    valve_beta: float = 0.3,
    sample_time_s: float = 10.0,
    rk4_substeps: int = 1,
    excitation: Any = True,
    noise_scale: float = 1.0,
    plant_effects: Any = (),
    params: FCCParams | None = None,
) -> BatchResult:
    """Simulate many seeded episodes at once, identical to ``FCC-v0`` with zero actions.

    ``scenario`` may be one name for all episodes or one per seed. Episodes run in parallel
    threads of the compiled kernel (numba ``prange``); with a user effect that has ``d_state``
    the integration runs in numpy over the episode axis instead (slower, same numbers as the env).
    ``plant_effects`` as for the env (:mod:`fcc_env.effects`); one effect object serves the
    whole batch, with a leading episode axis on its arrays.
    """
    seeds = [int(s) for s in seeds]
    if not seeds:
        raise ValueError("seeds must name at least one episode")
    if isinstance(n_samples, bool) or not isinstance(n_samples, int | np.integer) or n_samples < 2:
        raise ValueError(f"n_samples must be an integer >= 2, got {n_samples!r}")
    scenarios = [scenario] * len(seeds) if isinstance(scenario, str) else list(scenario)
    if len(scenarios) != len(seeds):
        raise ValueError(f"got {len(scenarios)} scenarios for {len(seeds)} seeds")
    config = PlantConfig.build(
        valve_beta=valve_beta,
        sample_time_s=sample_time_s,
        rk4_substeps=rk4_substeps,
        excitation=excitation,
        noise_scale=noise_scale,
        params=params,
    )
    effects = fx.resolve(plant_effects)
    B, T = len(seeds), int(n_samples)
    k = np.arange(T)
    U = np.empty((B, T, N_INPUTS))
    Z = np.empty((B, T, N_MEASUREMENTS))
    faults: list[FaultConfig] = []
    pidx_rows, pm_rows = [], []
    schedule = None
    for b, (seed, sc) in enumerate(zip(seeds, scenarios, strict=True)):
        rng, _ = seeding.np_random(seed)
        opts = {
            "scenario": sc,
            "fault_time": fault_time,
            "fault_magnitude": fault_magnitude,
            "fault_profile": fault_profile,
            "ramp_samples": ramp_samples,
        }
        setup = setup_episode(rng, config, opts, T, effects)
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
    x0 = np.tile(config.initial_state(), (B, 1))
    p_base = np.tile(config.params.as_array(), (B, 1))
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
    bad = (
        ~np.isfinite(X).all(axis=2)
        | (X[:, :, 8] < MIN_WELL_INVENTORY_KG)
        | (X[:, :, 4] < MIN_T_RG1_C)
        | (X[:, :, 9] - X[:, :, 4] > MAX_AFTERBURN_C)
    )
    term_at = np.where(bad.any(axis=1), np.argmax(bad, axis=1), -1)
    reasons = tuple(
        termination_reason(X[b, term_at[b]]) if term_at[b] >= 0 else None for b in range(B)
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
    sample_time_s: float = 10.0,
    rk4_substeps: int = 1,
) -> InputSimulation:
    """Run the declared model on an input record (simulation, never one-step prediction).

    Args:
        inputs: (T, 6) or (B, T, 6) inputs ordered as :data:`fcc_env.INPUT_NAMES`, held over
            each sample (e.g. measured R_ar, T_ar, T_fp and the commanded valve).
        params: model parameters (default: the declared ones).
        param_multipliers: per-sample multipliers of parameter fields, arrays (T,) or (B, T).
        x0: initial state (default: the steady state of ``params`` at the first input).
        sample_time_s, rk4_substeps: as for the env.
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
