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

from fcc_env.params import (
    MEASUREMENTS,
    N_INPUTS,
    N_MEASUREMENTS,
    N_STATES,
    NOMINAL_INPUTS,
    FCCParams,
)
from fcc_env.physics import AUX_NAMES, N_AUX, noisy_kernel, simulate_kernel, steady_state
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


@dataclass
class EpisodeSetup:
    fault: FaultConfig
    program: ProgramGenerator
    noise_rng: np.random.Generator


def setup_episode(
    rng: np.random.Generator, config: PlantConfig, fault_options: dict[str, Any], horizon: int
) -> EpisodeSetup:
    gens = episode_generators(rng)
    fault = draw_fault(gens["fault"], horizon, fault_options)
    return EpisodeSetup(fault, ProgramGenerator(config.excitation, gens["program"]), gens["noise"])


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
    terminated_at: np.ndarray  # (B,) first sample outside the envelope, -1 if none
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
    params: FCCParams | None = None,
) -> BatchResult:
    """Simulate many seeded episodes at once, identical to ``FCC-v0`` with zero actions.

    ``scenario`` may be one name for all episodes or one per seed. Episodes are simulated in
    parallel threads by the compiled kernel (numba ``prange``).
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
    B, T = len(seeds), int(n_samples)
    U = np.empty((B, T, N_INPUTS))
    Z = np.empty((B, T, N_MEASUREMENTS))
    faults = []
    for b, (seed, sc) in enumerate(zip(seeds, scenarios, strict=True)):
        rng, _ = seeding.np_random(seed)
        opts = {
            "scenario": sc,
            "fault_time": fault_time,
            "fault_magnitude": fault_magnitude,
            "fault_profile": fault_profile,
            "ramp_samples": ramp_samples,
        }
        setup = setup_episode(rng, config, opts, T)
        U[b] = setup.program.take(T)
        Z[b] = setup.noise_rng.standard_normal((T, N_MEASUREMENTS))
        faults.append(setup.fault)
    x0 = np.tile(config.initial_state(), (B, 1))
    p_base = np.tile(config.params.as_array(), (B, 1))
    Y = np.empty((B, T, N_MEASUREMENTS))
    obs = np.empty((B, T, N_MEASUREMENTS), dtype=np.float32)
    X = np.empty((B, T, N_STATES))
    A = np.empty((B, T, N_AUX))
    simulate_kernel(
        x0,
        U,
        p_base,
        np.stack([f.param_indices for f in faults]),
        np.array([f.onset for f in faults], dtype=np.int64),
        np.array([f.ramp for f in faults], dtype=np.int64),
        np.array([f.final_multiplier for f in faults]),
        config.sample_time_s / config.rk4_substeps,
        config.rk4_substeps,
        Z,
        NOISE_STD_ABS,
        NOISE_STD_REL,
        config.noise_scale,
        Y,
        obs,
        X,
        A,
    )
    del Z
    k = np.arange(T)
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
