"""The plant an episode runs on: :class:`PlantConfig` (parameters and operation, validated once),
the measurement noise and the physical envelope whose crossing ends an episode (spec §2.8)."""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numba
import numpy as np

from fcc_common.validation import Integer, Real, check, invalid
from fcc_env.excitation import Excitation
from fcc_env.params import MEASUREMENTS, NOMINAL_INPUTS, FCCParams
from fcc_env.physics import measure, steady_state
from fcc_env.regulatory import RegulatoryLayer

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


#: The slide-valve head share of the declared plant (``valve_beta``'s default).
DEFAULT_VALVE_BETA: float = FCCParams().beta_sv
#: The paper's sample period [s]: :class:`PlantConfig`'s default, the one place it is written.
DEFAULT_SAMPLE_TIME_S: float = 10.0


@dataclass(frozen=True)
class PlantConfig:
    """Everything that defines the plant and its operation, validated once, on construction.

    The field defaults are the paper's set-up and the one place they are written. The env's
    keywords (``valve_beta``, ``sample_time_s``, ``rk4_substeps``, ``excitation``,
    ``noise_scale``, ``params``) build one with :meth:`build`; ``valve_beta`` is
    ``params.beta_sv``.

    >>> PlantConfig.build(valve_beta=0.15, noise_scale=0.5).params.beta_sv
    0.15
    >>> PlantConfig(sample_time_s=0.1)
    Traceback (most recent call last):
    ...
    ValueError: sample_time_s=0.1 is outside the allowed range: a number in [0.5, 60] s (...)
    """

    params: FCCParams = field(default_factory=FCCParams)
    sample_time_s: float = DEFAULT_SAMPLE_TIME_S
    rk4_substeps: int = 1
    excitation: Excitation | None = field(default_factory=Excitation)
    noise_scale: float = 1.0
    #: ``None``: open loop (the paper's plant); a :class:`RegulatoryLayer`: closed loop.
    regulatory: RegulatoryLayer | None = None

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        if not isinstance(self.params, FCCParams):
            raise invalid("params", self.params, "an FCCParams instance")
        check("valve_beta", self.params.beta_sv, VALVE_BETA_RANGE)
        set_(self, "sample_time_s", check("sample_time_s", self.sample_time_s, SAMPLE_TIME_RANGE))
        set_(self, "rk4_substeps", check("rk4_substeps", self.rk4_substeps, RK4_SUBSTEPS_RANGE))
        if self.excitation is not None and not isinstance(self.excitation, Excitation):
            raise invalid("excitation", self.excitation, "an Excitation or None (no excitation)")
        set_(self, "noise_scale", check("noise_scale", self.noise_scale, NOISE_SCALE_RANGE))
        if self.regulatory is not None and not isinstance(self.regulatory, RegulatoryLayer):
            raise invalid("regulatory", self.regulatory, "a RegulatoryLayer or None (open loop)")

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
        regulatory: Any = None,
    ) -> PlantConfig:
        """The plant of the env's keywords (``None`` = the default): the one bridge from them.

        ``valve_beta`` overrides ``params.beta_sv`` (default :data:`DEFAULT_VALVE_BETA`, also
        when ``params`` are given); ``excitation`` is ``True``/``None`` (the default program),
        ``False`` (none), an :class:`Excitation` or a mapping of its fields; ``regulatory`` is
        ``None``/``False`` (open loop), ``True`` (the default layer), a
        :class:`RegulatoryLayer` or a mapping of its fields.
        """
        if params is not None and not isinstance(params, FCCParams):
            raise invalid("params", params, "an FCCParams instance or None")
        valve_beta = DEFAULT_VALVE_BETA if valve_beta is None else valve_beta
        p = (params or FCCParams()).replace(
            beta_sv=check("valve_beta", valve_beta, VALVE_BETA_RANGE)
        )
        given = {"sample_time_s": sample_time_s, "rk4_substeps": rk4_substeps}
        given["noise_scale"] = noise_scale
        return cls(
            params=p,
            excitation=Excitation.from_option(excitation),
            regulatory=RegulatoryLayer.from_option(regulatory),
            **{k: v for k, v in given.items() if v is not None},
        )

    @property
    def valve_beta(self) -> float:
        return self.params.beta_sv

    @property
    def closed_loop(self) -> bool:
        return self.regulatory is not None

    def initial_state(self) -> np.ndarray:
        return steady_state(self.params, NOMINAL_INPUTS)

    def initial_setpoints(self) -> np.ndarray:
        """T_rx and T_rg1 (°C) of the initial steady state: where the set points start."""
        return np.array(_initial_setpoints(self.params))

    def replace(self, **changes: Any) -> PlantConfig:
        return dataclasses.replace(self, **changes)

    def to_json(self) -> dict[str, Any]:
        """Everything that defines the plant, as JSON values (what result stores hash: two
        plants with equal dicts simulate equal episodes for equal seeds and faults).

        Examples:
            >>> PlantConfig().to_json()["regulatory"] is None
            True
            >>> PlantConfig.build(regulatory=True).to_json()["regulatory"]["loops"]
            ['T_rx', 'T_rg1']
        """
        return _json_value(dataclasses.asdict(self))


def _json_value(value: Any) -> Any:
    """``value`` (nested dicts, tuples, floats of a dataclass's ``asdict``) as JSON values."""
    if isinstance(value, dict):
        return {str(k): _json_value(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_json_value(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    return value


@functools.lru_cache(maxsize=256)
def _initial_setpoints(params: FCCParams) -> tuple[float, float]:
    # cached: every closed-loop episode of a batch starts from it
    x0 = steady_state(params, NOMINAL_INPUTS)
    return float(measure(x0, NOMINAL_INPUTS, params)[3]), float(x0[4])


#: The env / :func:`fcc_env.simulate_episodes` keyword names that :meth:`PlantConfig.build` takes.
ENV_PLANT_KEYWORDS = (
    "valve_beta",
    "sample_time_s",
    "rk4_substeps",
    "excitation",
    "noise_scale",
    "params",
    "regulatory",
)


def plant_from_request(plant: PlantConfig | None, keywords: Mapping[str, Any]) -> PlantConfig:
    """``plant``, or the plant of the env's ``keywords`` (``None`` = not given); both raise."""
    if plant is None:
        return PlantConfig.build(**keywords)
    if not isinstance(plant, PlantConfig):
        raise invalid("plant", plant, "a PlantConfig or None")
    given = sorted(k for k, v in keywords.items() if v is not None)
    if given:
        raise ValueError(
            f"plant={plant!r} and the plant keyword(s) {given} were both given: pass the plant "
            "either as plant=PlantConfig(...) or as keywords, not both"
        )
    return plant


#: Envelope codes of :func:`envelope_code`: ``TERMINATION_REASONS[code]`` (0 = inside).
TERMINATION_REASONS: tuple[str | None, ...] = (
    None,
    "numerical_failure",
    "well_empty",
    "extinguished",
    "afterburn",
)


@numba.njit(cache=True, nogil=True)
def afterburn_delta_C(x: np.ndarray) -> float:
    """The afterburn ΔT of state ``x``: stage-1 dilute phase minus stage-1 bed, T_d1 − T_rg1 [°C]
    (spec §2.8: a warning above :data:`AFTERBURN_WARNING_C`, the end above
    :data:`MAX_AFTERBURN_C`)."""
    return x[9] - x[4]


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
    if afterburn_delta_C(x) > MAX_AFTERBURN_C:
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
