"""The FCC filter's configuration (:class:`UKFConfig`): what the plant is, which unmeasured
quantities are estimated, and the tuning constants, each documented with where it came from.

The plant side (``noise_scale``, ``sample_time_s``, ``rk4_substeps``, ``closed_loop``) must
match the plant the observations come from; :meth:`UKFConfig.matching` copies them from a
:class:`fcc_env.PlantConfig` and nothing else (never its parameters: the model's parameters
are the estimator's own argument).

The tuning constants were chosen on training seeds (1000+) and validation seeds (5000+) of the
paper's set-up and the closed-loop plant, never test seeds; their measurements are in
``lab/filter-lab.md``.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

from fcc_common.validation import Boolean, OptionSequence, Real, check, invalid
from fcc_env.closed_loop import CLOSED_LOOP_CHANNELS
from fcc_env.params import MEASUREMENT_NAMES, PARAM_FIELDS, FCCParams
from fcc_env.plant import (
    DEFAULT_SAMPLE_TIME_S,
    NOISE_SCALE_RANGE,
    RK4_SUBSTEPS_RANGE,
    SAMPLE_TIME_RANGE,
    PlantConfig,
)

__all__ = [
    "CLOSED_LOOP_AIR_WALK_STD_REL",
    "LAG_CHANNELS",
    "OPEN_LOOP_AIR_WALK_STD_REL",
    "UKF_RANGES",
    "UKFConfig",
    "check_fcc_channels",
    "model_params",
]

#: Random-walk std of the true air flow per sample, relative to the flow, in open loop: the
#: air moves in APRBS steps (caught by the step gate), so the walk only absorbs what the gate
#: misses.
OPEN_LOOP_AIR_WALK_STD_REL = 5e-4
#: ... in closed loop: the air is the T_rg1 loop's output, which moves every sample with the
#: controller's gain on the noisy T_rg1 (0.89 t/h per °C × 0.3 °C ≈ 0.27 t/h, 0.18 % of the
#: flow): a white jitter around a slow level, which a walk fits only roughly; this value was the
#: best compromise (R_ar's innovations: variance 1.02, lag-1 autocorrelation −0.08).
CLOSED_LOOP_AIR_WALK_STD_REL = 1.5e-3

#: The channels a lag state may be given (``sensor_lags``): the process thermocouples, whose
#: readings a real sensor's time constant delays (not the inputs' channels: their states are
#: the readings' own values).
LAG_CHANNELS: tuple[str, ...] = MEASUREMENT_NAMES[3:]

#: Allowed values of the :class:`UKFConfig` fields (the plant's own ranges for the plant side).
UKF_RANGES: dict[str, Any] = {
    "noise_scale": Real(
        0.0, NOISE_SCALE_RANGE.high, closed="right", why="the filter needs measurement noise"
    ),
    "sample_time_s": SAMPLE_TIME_RANGE,
    "rk4_substeps": RK4_SUBSTEPS_RANGE,
    "closed_loop": Boolean(),
    "estimate_coking": (Boolean(), None),
    "input_walk_std_C": Real(0.0, 10.0, closed="right", unit="°C per sample"),
    "air_walk_std_rel": (Real(0.0, 0.1, closed="right", why="relative per sample"), None),
    "step_gate": (Real(1.0, math.inf, why="standard deviations; None: no step detection"), None),
    "step_std_C": Real(0.0, 100.0, closed="right", unit="°C"),
    "air_step_std_rel": Real(0.0, 0.5, closed="right"),
    "coking_walk_std": Real(0.0, 0.1, closed="right", why="per sample"),
    "coking_initial_std": Real(0.0, 1.0, closed="right"),
    "parameter_walk_std_rel": Real(0.0, 0.1, closed="right", why="per sample"),
    "parameter_initial_std_rel": Real(0.0, 1.0, closed="right"),
    "state_noise_std": Real(0.0, 100.0, closed="right", why="filter units per sample"),
    "initial_state_std": Real(0.0, 1e4, closed="right", why="filter units"),
    "lag_coefficient_prior": Real(0.0, 0.95, why="the reading's share kept per sample"),
    "lag_coefficient_std": Real(0.0, 1.0, closed="right"),
    "lag_walk_std": Real(0.0, 0.1, why="per sample"),
    "alpha": Real(0.0, 1.0, closed="right"),
    "beta": Real(0.0, 10.0),
    "kappa": Real(0.0, 100.0),
}


@dataclass(frozen=True)
class UKFConfig:
    """The FCC state-and-disturbance estimator's settings, validated on construction.

    Plant side (must match the plant observed):

    * ``noise_scale``: the plant's multiplier on the spec's noise stds (> 0);
    * ``sample_time_s``, ``rk4_substeps``: the plant's integration;
    * ``closed_loop``: observations carry the closed-loop channels; the valve command u_F is
      read from them (channel 8, exact), else it is the nominal command.

    What is estimated beside the 11 model states and the true R_ar, T_ar, T_fp (always):

    * ``estimate_coking``: the feed coking factor f_coke as a random walk (default: in closed
      loop, where the set-point program drifts it; otherwise it is 1);
    * ``parameters``: :class:`fcc_env.FCCParams` field names estimated as random walks around
      the given parameters (the ``uncertain`` track); each must be non-zero;
    * ``sensor_lags``: channels of :data:`LAG_CHANNELS` read through a first-order lag of
      unknown time constant (a thermocouple's, the ``mismatch`` track): per channel the lagged
      reading and its coefficient ``a = exp(−T_s/τ)`` (0: no lag) are states, the coefficient a
      random walk of prior ``lag_coefficient_prior`` ± ``lag_coefficient_std`` and walk
      ``lag_walk_std`` per sample, clipped to [0, 0.95] where the model reads it.

    Tuning (process noise of the random walks; the filter's units are °C, t/h, 1 kg·10³ for
    holdups and 10⁻⁵ kg/kg for coke, 1 % for parameters):

    * ``input_walk_std_C``: T_fp, T_ar random walk per sample;
    * ``air_walk_std_rel``: R_ar's, relative (None: :data:`OPEN_LOOP_AIR_WALK_STD_REL` or
      :data:`CLOSED_LOOP_AIR_WALK_STD_REL`);
    * ``step_gate``: an input reading this many stds from its prediction declares a step of
      the input, of prior std ``step_std_C`` (T_fp, T_ar) or ``air_step_std_rel`` (R_ar) (None:
      never; the operating program moves its inputs in steps, spec §7.5);
    * ``coking_walk_std``, ``coking_initial_std``: f_coke's walk per sample and prior std;
    * ``parameter_walk_std_rel``, ``parameter_initial_std_rel``: the parameters', relative;
    * ``state_noise_std``: process noise of the 11 model states (model error), filter units;
    * ``initial_state_std``: their prior std around the steady state, filter units;
    * ``alpha``, ``beta``, ``kappa``: van der Merwe's sigma-point spread.

    >>> UKFConfig(alpha=0.0)
    Traceback (most recent call last):
    ...
    ValueError: alpha=0.0 is outside the allowed range: a number in (0, 1]
    >>> UKFConfig(parameters=("k_sigma", "not_a_field")).parameters
    Traceback (most recent call last):
    ...
    ValueError: parameters=('k_sigma', 'not_a_field') is outside the allowed range: ...
    """

    noise_scale: float = 1.0
    sample_time_s: float = DEFAULT_SAMPLE_TIME_S
    rk4_substeps: int = 1
    closed_loop: bool = False
    estimate_coking: bool | None = None
    parameters: tuple[str, ...] = ()
    input_walk_std_C: float = 0.02
    air_walk_std_rel: float | None = None
    step_gate: float | None = 3.5
    step_std_C: float = 10.0
    air_step_std_rel: float = 0.05
    coking_walk_std: float = 6e-4
    coking_initial_std: float = 0.005
    parameter_walk_std_rel: float = 1e-4
    parameter_initial_std_rel: float = 0.05
    state_noise_std: float = 1e-3
    initial_state_std: float = 0.1
    sensor_lags: tuple[str, ...] = ()
    lag_coefficient_prior: float = 0.4
    lag_coefficient_std: float = 0.3
    lag_walk_std: float = 1e-3
    alpha: float = 1.0
    beta: float = 2.0
    kappa: float = 0.0

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        for name, cons in UKF_RANGES.items():
            cons = cons if isinstance(cons, tuple) else (cons,)
            set_(self, name, check(name, getattr(self, name), *cons))
        names = self.parameters
        if isinstance(names, list):
            names = tuple(names)
        if names != ():
            names = check("parameters", names, OptionSequence(PARAM_FIELDS))
        set_(self, "parameters", names)
        lags = self.sensor_lags
        lags = tuple(lags) if isinstance(lags, list) else lags
        if lags != ():
            lags = check("sensor_lags", lags, OptionSequence(LAG_CHANNELS))
        set_(self, "sensor_lags", lags)

    @classmethod
    def matching(cls, plant: PlantConfig, **changes: Any) -> UKFConfig:
        """The settings of ``plant``'s noise, integration and loop mode (not its parameters),
        with ``changes`` to the other fields."""
        if not isinstance(plant, PlantConfig):
            raise invalid("plant", plant, "a PlantConfig")
        return cls(
            noise_scale=plant.noise_scale,
            sample_time_s=plant.sample_time_s,
            rk4_substeps=plant.rk4_substeps,
            closed_loop=plant.closed_loop,
            **changes,
        )

    def check_parameters(self, params: FCCParams) -> None:
        """Refuse estimated parameters that are zero in ``params`` (their walk is relative)."""
        for name in self.parameters:
            if getattr(params, name) == 0.0:
                raise invalid(
                    "parameters",
                    self.parameters,
                    "FCCParams fields that are non-zero in the given parameters",
                    f"{name} is 0: its random walk is relative to its value",
                )

    def replace(self, **changes: Any) -> UKFConfig:
        return dataclasses.replace(self, **changes)

    @property
    def coking(self) -> bool:
        """Whether f_coke is estimated (``estimate_coking``, by default in closed loop)."""
        return self.closed_loop if self.estimate_coking is None else bool(self.estimate_coking)

    @property
    def air_walk(self) -> float:
        """R_ar's relative random-walk std per sample (``air_walk_std_rel`` or the mode's)."""
        if self.air_walk_std_rel is not None:
            return float(self.air_walk_std_rel)
        return CLOSED_LOOP_AIR_WALK_STD_REL if self.closed_loop else OPEN_LOOP_AIR_WALK_STD_REL


def model_params(params: FCCParams | dict[str, Any] | None) -> FCCParams:
    """The model parameters a grey-box diagnoser's ``params`` hyperparameter names: ``None``
    (the specification's nominal :class:`~fcc_env.FCCParams`), an ``FCCParams``, or a dict of
    field values replacing the nominal ones (a fitted set, JSON-friendly for ``get_params``)."""
    if params is None or isinstance(params, FCCParams):
        return FCCParams() if params is None else params
    if not isinstance(params, dict) or not set(params) <= set(PARAM_FIELDS):
        raise invalid("params", params, f"None, an FCCParams, or a dict of {list(PARAM_FIELDS)}")
    try:
        return dataclasses.replace(FCCParams(), **{k: float(v) for k, v in params.items()})
    except (TypeError, ValueError) as e:
        raise invalid("params", params, "FCCParams field values (numbers)", str(e)) from e


def check_fcc_channels(name: str, channels: tuple[str, ...]) -> None:
    """Refuse ``channels`` unless they are the FCC's measured channels in the plant's order,
    open loop or closed loop: a filter of the published model reads each by its position."""
    if channels not in (MEASUREMENT_NAMES, CLOSED_LOOP_CHANNELS):
        raise ValueError(
            f"{name} reads the FCC's measured channels in order: {list(MEASUREMENT_NAMES)} (open "
            f"loop) or {list(CLOSED_LOOP_CHANNELS)} (closed loop); got {list(channels)}"
        )
