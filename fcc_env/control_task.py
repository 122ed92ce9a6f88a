"""``FCC-control-v0``: the closed-loop plant as a control task with an economic reward.

The agent is a supervisory layer: once per sample it moves the set points of the regulatory
layer (the riser outlet temperature on the slide valve, the stage-1 bed temperature on the air;
:class:`~fcc_env.regulatory.RegulatoryLayer`), exactly as on ``FCC-closedloop-v0`` (action ±1 =
±15 °C on ``T_rx_sp``, ±20 °C on ``T_rg1_sp`` about the program's set points; a set point pushed
out of its range is clipped and flagged in ``info["setpoint_clipped"]``). Every episode draws its
fault (healthy, f1–f4; size and onset as ``scenario="random"`` draws them) unless the
``scenario`` keyword fixes it; ``catalogue="all"`` draws from the whole catalogue instead
(healthy, process, sensor and actuator faults: :mod:`fcc_env.control_draws`), and
``catalogue="sensor"`` from the healthy plant and the sensor faults. The observation
is ``FCC-closedloop-v0``'s.

The reward is the unit's economic margin over the sample, in US dollars, minus penalties for
entering constraint regions and for a trip; every term is in ``info["reward_terms"]`` (same
units, summing to the reward) so that a user can re-weight them. The terms, from model
quantities (:data:`fcc_env.physics.AUX_NAMES` and the state):

=============  ==========================================================================
term           definition (per sample of ``dt`` seconds)
=============  ==========================================================================
conversion     ``+ F_feed·X·dt/1000 · conversion_usd_per_t``: feed converted to lighter
               products (gasoline, LPG) is worth more than gas oil; the crack spread.
coke           ``− coke_make·dt/1000 · coke_usd_per_t``: coke laid on the catalyst is feed
               that leaves as flue gas, not product.
air            ``− R_ar·dt/3600 · air_usd_per_t``: the combustion-air blower's power.
afterburn      ``− max(0, T_d1 − T_rg1 − 40 °C)·dt/3600 · afterburn_usd_per_C_h``: above the
               afterburn warning (spec §2.8) the dilute phase heats the cyclones; the episode
               ends at 80 °C (a trip).
regenerator    ``− [max(0, T_rg2 − regenerator_max_C) + max(0, regenerator_min_C − T_rg1)]
               ·dt/3600 · regenerator_usd_per_C_h``: a stage-2 bed too hot ages the catalyst
               and the internals; a stage-1 bed too cold burns incompletely (the envelope
               ends the episode at 600 °C).
well           ``− max(0, well_min_t − W_sp/1000)·dt/3600 · well_usd_per_t_h``: a catalyst
               well near empty starves the slide valve (the envelope ends at 3 t).
saturation     ``− dt/3600 · saturation_usd_per_h`` while a controller is at its actuator
               limit: the loop has lost its authority.
trip           ``− trip_usd`` once, on termination (any envelope exit): shutdown and restart.
=============  ==========================================================================

The terms' names, their order, their kinds (:class:`TermKind`: the margin's three, the
constraint regions' four, the trip) and the allowed ranges of their prices are one table,
:data:`REWARD_TABLE`; :data:`REWARD_TERMS` and :data:`CONSTRAINT_TERMS` (what the control study
counts as time in a constraint region) are read from it.

The prices are reconstructed orders of magnitude, not a refinery's: a crack spread of 60 USD/t,
coke at 300 USD/t (gas oil lost as product, less the heat its burning returns to the riser),
2.4 USD per tonne of air (30 kWh/t at 0.08 USD/kWh), and penalties scaled to the margin (about
5,800 USD/h at the nominal point, 16 USD per 10-s sample): 10 °C of afterburn over its warning
costs about the margin, a trip about a day and a half of it. With these prices the best steady
operation raises the riser outlet to the top of its set-point range (545 °C), as units that
maximise conversion run against a limit (:mod:`evaluation.control.setpoints`). They are fields
of :class:`EconomicReward` (pass ``economics=`` to ``gym.make``).
"""

from __future__ import annotations

import dataclasses
import math
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from enum import StrEnum
from typing import Any, SupportsFloat

import gymnasium as gym
import numpy as np

from fcc_common.validation import Real, check_params, from_fields, invalid
from fcc_env.control_draws import (
    catalogue_option,
    check_drawn_fields,
    draw_catalogue_fault,
    draws_random,
)
from fcc_env.env import FCCEnv, closed_loop_keyword, env_id, trend_frame
from fcc_env.plant import AFTERBURN_WARNING_C, afterburn_delta_C
from fcc_env.render import WINDOW_SAMPLES

__all__ = [
    "CONSTRAINT_TERMS",
    "CONTROL_ENV_ID",
    "REWARD_TABLE",
    "REWARD_TERMS",
    "REWARD_UNIT",
    "EconomicReward",
    "FCCControlEnv",
    "RewardTerm",
    "TermKind",
    "field_ranges",
    "reward_term_arrays",
    "reward_terms",
    "term_names",
    "total_reward",
]

#: The control task's registered id.
CONTROL_ENV_ID = "FCC-control-v0"
#: The unit of the reward and of its terms (over one sample) and of their sums.
REWARD_UNIT = "USD"


class TermKind(StrEnum):
    """What a reward term stands for (module doc: the reward is the margin minus penalties)."""

    #: the unit's economic margin: revenue (conversion) and operating costs (coke, air)
    MARGIN = "margin"
    #: a penalty while the plant is inside a constraint region (below zero there, 0 outside)
    CONSTRAINT = "constraint"
    #: the penalty of a termination, once
    TRIP = "trip"


@dataclass(frozen=True)
class RewardTerm:
    """One term of the reward (USD over a sample): its name, its kind, and the fields of
    :class:`EconomicReward` that price or bound it, each with its allowed range."""

    name: str
    kind: TermKind
    fields: tuple[tuple[str, Real], ...]


# state indices (spec §1): stage-1 bed, stage-2 bed, catalyst well
_T_RG1, _T_RG2, _W_SP = 4, 7, 8
# input indices (fcc_env.params.INPUT_NAMES): air, feed
_R_AR, _F_FEED = 1, 4

_PRICE = Real(0.0, 1e7, closed="both")
# afterburn_delta_C's Python body (the same source): the compiled one, called from Python with
# a list of floats or a transposed array, spent most of the single env's reward on typing its
# argument (issue 44)
_afterburn_delta = afterburn_delta_C.py_func

#: The reward's terms, the one list (module doc: each term's definition): names, order, kinds
#: and the ranges of their prices are read from here.
REWARD_TABLE: tuple[RewardTerm, ...] = (
    RewardTerm("conversion", TermKind.MARGIN, (("conversion_usd_per_t", _PRICE),)),
    RewardTerm("coke", TermKind.MARGIN, (("coke_usd_per_t", _PRICE),)),
    RewardTerm("air", TermKind.MARGIN, (("air_usd_per_t", _PRICE),)),
    RewardTerm("afterburn", TermKind.CONSTRAINT, (("afterburn_usd_per_C_h", _PRICE),)),
    RewardTerm(
        "regenerator",
        TermKind.CONSTRAINT,
        (
            ("regenerator_usd_per_C_h", _PRICE),
            ("regenerator_max_C", Real(600.0, 900.0, unit="°C")),
            ("regenerator_min_C", Real(500.0, 700.0, unit="°C")),
        ),
    ),
    RewardTerm(
        "well",
        TermKind.CONSTRAINT,
        (
            ("well_min_t", Real(0.0, 30.0, unit="t", why="the well holds 30 t at nominal")),
            ("well_usd_per_t_h", _PRICE),
        ),
    ),
    RewardTerm("saturation", TermKind.CONSTRAINT, (("saturation_usd_per_h", _PRICE),)),
    RewardTerm("trip", TermKind.TRIP, (("trip_usd", _PRICE),)),
)


def term_names(table: Sequence[RewardTerm], kind: TermKind | None = None) -> tuple[str, ...]:
    """The names of ``table``'s terms (of ``kind`` only, if given), in the table's order.

    >>> term_names(REWARD_TABLE, TermKind.CONSTRAINT)
    ('afterburn', 'regenerator', 'well', 'saturation')
    """
    return tuple(t.name for t in table if kind is None or t.kind is kind)


def field_ranges(table: Sequence[RewardTerm]) -> dict[str, Real]:
    """The allowed range of each :class:`EconomicReward` field ``table`` names, in its order."""
    return {name: allowed for t in table for name, allowed in t.fields}


#: The reward's terms, in the order of :func:`reward_terms`.
REWARD_TERMS: tuple[str, ...] = term_names(REWARD_TABLE)
#: The terms whose being below zero marks a sample inside a constraint region.
CONSTRAINT_TERMS: tuple[str, ...] = term_names(REWARD_TABLE, TermKind.CONSTRAINT)
_RANGES = field_ranges(REWARD_TABLE)


@dataclass(frozen=True)
class EconomicReward:
    """Prices and penalty weights of ``FCC-control-v0``'s reward (module doc: each term, its unit
    and its reason). All are non-negative; set a weight to 0 to drop its term."""

    conversion_usd_per_t: float = 60.0
    coke_usd_per_t: float = 300.0
    air_usd_per_t: float = 2.4
    afterburn_usd_per_C_h: float = 600.0
    regenerator_usd_per_C_h: float = 600.0
    regenerator_max_C: float = 730.0
    regenerator_min_C: float = 640.0
    well_min_t: float = 7.5
    well_usd_per_t_h: float = 1_000.0
    saturation_usd_per_h: float = 2_000.0
    trip_usd: float = 200_000.0

    def __post_init__(self) -> None:
        # stored as checked, as floats: an int or a float32 price is the same number in float64,
        # and the single env's reward (Python floats) then needs no conversion per step
        for name, value in check_params(dataclasses.asdict(self), _RANGES).items():
            object.__setattr__(self, name, value)

    @classmethod
    def from_option(cls, value: EconomicReward | Mapping[str, Any] | None) -> EconomicReward:
        """``None`` (the defaults), an instance, or a mapping of its fields."""
        if value is None:
            return cls()
        if isinstance(value, cls):
            return value
        if not isinstance(value, Mapping):
            raise invalid("economics", value, "an EconomicReward, a mapping of its fields or None")
        return from_fields(cls, value, "economics")


def _excess(v: np.ndarray) -> np.ndarray:
    """``max(0, v)`` elementwise with Python's ``max(0.0, v)`` semantics (0 unless ``v > 0``)."""
    return np.where(v > 0.0, v, 0.0)


def _excess_float(v: float) -> float:
    """:func:`_excess` of one float."""
    return v if v > 0.0 else 0.0


def _select_float(condition: Any, a: float, b: float) -> float:
    """``np.where(condition, a, b)`` of one condition."""
    return a if condition else b


def _term_formulas(
    x: Any,
    u: Any,
    conversion: Any,
    coke_make: Any,
    saturated: Any,
    terminated: Any,
    economics: EconomicReward,
    dt_s: float,
    excess: Callable[[Any], Any],
    select: Callable[[Any, Any, Any], Any],
) -> dict[str, Any]:
    """The reward's terms (module doc), written once for numpy arrays of many envs and for the
    Python floats of one: ``x[i]`` / ``u[i]`` is state / input ``i`` (an array over the envs or a
    float), ``excess`` is ``max(0, ·)`` and ``select`` is ``np.where`` in the same arithmetic.
    Every operation is one IEEE-754 double operation in the same order either way, so the two
    give the same bits (``tests/fcc_env/test_control_speed.py``)."""
    e = economics
    hours = dt_s / 3600.0
    too_hot = excess(x[_T_RG2] - e.regenerator_max_C)
    too_cold = excess(e.regenerator_min_C - x[_T_RG1])
    return {
        "conversion": u[_F_FEED] * conversion * dt_s / 1000.0 * e.conversion_usd_per_t,
        "coke": -coke_make * dt_s / 1000.0 * e.coke_usd_per_t,
        "air": -u[_R_AR] * hours * e.air_usd_per_t,
        "afterburn": -excess(_afterburn_delta(x) - AFTERBURN_WARNING_C)
        * hours
        * e.afterburn_usd_per_C_h,
        "regenerator": -(too_hot + too_cold) * hours * e.regenerator_usd_per_C_h,
        "well": -excess(e.well_min_t - x[_W_SP] / 1000.0) * hours * e.well_usd_per_t_h,
        "saturation": select(saturated, -hours * e.saturation_usd_per_h, 0.0),
        "trip": select(terminated, -e.trip_usd, 0.0),
    }


def reward_term_arrays(
    info: Mapping[str, Any], terminated: Any, economics: EconomicReward, dt_s: float
) -> dict[str, np.ndarray]:
    """The reward's terms (USD over one sample of ``dt_s`` seconds), the one definition (module
    doc) for one env or many: ``info`` holds ``X``, ``coke_make``, ``controller_saturated``
    (scalars, or shape ``(n,)`` over ``n`` envs), ``state`` (``(11,)`` or ``(n, 11)``) and
    ``inputs`` (``(6,)`` or ``(n, 6)``); ``terminated`` a bool or ``(n,)``. Each term has the
    envs' shape (``()`` for one env). Their sum is the reward (:func:`total_reward`)."""
    # transposed, row i is variable i of every env (of the one env for a 1-D state)
    terms = _term_formulas(
        np.asarray(info["state"], dtype=np.float64).T,
        np.asarray(info["inputs"], dtype=np.float64).T,
        np.asarray(info["X"], dtype=np.float64),
        np.asarray(info["coke_make"], dtype=np.float64),
        info["controller_saturated"],
        terminated,
        economics,
        dt_s,
        _excess,
        np.where,
    )
    shape = np.broadcast_shapes(*(np.shape(v) for v in terms.values()))
    return {name: np.broadcast_to(v, shape).astype(np.float64) for name, v in terms.items()}


def reward_terms(
    info: Mapping[str, Any], terminated: bool, economics: EconomicReward, dt_s: float
) -> dict[str, float]:
    """:func:`reward_term_arrays` of one env step's ``info``, as floats, bit for bit; computed
    in Python floats, as numpy's per-call overhead on 0-d arrays was three quarters of the
    control env's step (issue 44)."""
    terms = _term_formulas(
        np.asarray(info["state"], dtype=np.float64).tolist(),
        np.asarray(info["inputs"], dtype=np.float64).tolist(),
        float(info["X"]),
        float(info["coke_make"]),
        bool(info["controller_saturated"]),
        bool(terminated),
        economics,
        float(dt_s),
        _excess_float,
        _select_float,
    )
    return terms  # floats: every operand is one (the prices too, EconomicReward stores floats)


def total_reward(terms: Mapping[str, Any]) -> np.ndarray:
    """The reward: the exactly rounded sum (``math.fsum``) of the terms, per env (shape of a
    term: ``()`` for one env, ``(n,)`` for ``n``); exact, so that no order of the terms or
    vectorisation changes a bit of it."""
    values = np.broadcast_arrays(*(np.asarray(v, dtype=np.float64) for v in terms.values()))
    rows = np.stack(values, axis=-1)
    sums = [math.fsum(r) for r in rows.reshape(-1, rows.shape[-1]).tolist()]
    return np.array(sums, dtype=np.float64).reshape(rows.shape[:-1])


class FCCControlEnv(gym.Env):
    """``FCC-closedloop-v0`` with the economic reward of :mod:`fcc_env.control_task`.

    Keywords are ``FCC-closedloop-v0``'s (``scenario`` defaults to ``"random"``: healthy or a
    fault per episode; ``regulatory`` to ``True``, and ``False`` or ``None`` are refused as there)
    plus ``economics`` (an :class:`EconomicReward` or a mapping of its
    fields) and ``catalogue`` (what ``scenario="random"`` draws: ``"paper"``, the default,
    healthy or f1–f4 as ``FCC-closedloop-v0`` draws them; ``"all"``, every registered fault by
    class; ``"sensor"``, healthy or a sensor fault: :mod:`fcc_env.control_draws`; ``info["scenario"]``, ``info["fault_channel"]`` name
    the drawn fault). ``info["reward_terms"]`` holds the terms of the step's reward. The plant is an
    ``FCCEnv`` inside (``plant``); spaces and seeding are its own. ``render_mode="rgb_array"``
    draws the plant's closed-loop frame titled ``FCC-control-v0`` with two panels more: the
    reward of each sample and its cumulative sum since ``reset`` (USD).
    """

    metadata = FCCEnv.metadata

    def __init__(
        self,
        *,
        economics: Any = None,
        scenario: str = "random",
        regulatory: Any = True,
        catalogue: str = "paper",
        **kwargs: Any,
    ) -> None:
        self.economics = EconomicReward.from_option(economics)
        self.catalogue = catalogue_option(catalogue)
        regulatory = closed_loop_keyword(regulatory, CONTROL_ENV_ID)
        self.plant = FCCEnv(scenario=scenario, regulatory=regulatory, **kwargs)
        check_drawn_fields(self.catalogue, kwargs)
        self.observation_space = self.plant.observation_space
        self.action_space = self.plant.action_space
        self.render_mode = self.plant.render_mode
        self._dt_s = float(self.plant.config.sample_time_s)
        # the frame's reward channels: one value a sample (0 at the reset sample), the last 500
        self._rewards: deque[float] = deque([0.0], maxlen=WINDOW_SAMPLES)
        self._returns: deque[float] = deque([0.0], maxlen=WINDOW_SAMPLES)

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        super().reset(seed=seed)
        if self.catalogue != "paper" and draws_random(options, self.plant.fault_spec.scenario):
            # the draw's own stream (spawned): the plant's noise is that of the same seed
            rng = self.np_random.spawn(1)[0]
            fault = draw_catalogue_fault(rng, self.plant.horizon, self.catalogue)
            options = {**(options or {}), "fault": fault}
            options.pop("scenario", None)
        obs, info = self.plant.reset(seed=seed, options=options)
        info["reward_terms"] = dict.fromkeys(REWARD_TERMS, 0.0)
        self._rewards = deque([0.0], maxlen=WINDOW_SAMPLES)
        self._returns = deque([0.0], maxlen=WINDOW_SAMPLES)
        return obs, info

    def step(self, action: Any) -> tuple[np.ndarray, SupportsFloat, bool, bool, dict[str, Any]]:
        obs, _, terminated, truncated, info = self.plant.step(action)
        terms = reward_terms(info, terminated, self.economics, self._dt_s)
        info["reward_terms"] = terms
        reward = math.fsum(terms.values())  # total_reward's exact sum, of one env's floats
        self._rewards.append(reward)
        self._returns.append(self._returns[-1] + reward)
        return obs, reward, terminated, truncated, info

    def render(self) -> np.ndarray | None:
        """The plant's closed-loop frame titled with this env's id, plus the reward of each
        sample and its cumulative sum (``None`` without ``render_mode``)."""
        if self.render_mode != "rgb_array":
            return None
        extra = {
            "reward": (REWARD_UNIT, self._rewards),
            "cumulative reward": (REWARD_UNIT, self._returns),
        }
        return trend_frame(self.plant, env_id(self, CONTROL_ENV_ID), extra)

    def close(self) -> None:
        self.plant.close()
