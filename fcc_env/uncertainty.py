"""Plant draws of the ``uncertain`` benchmark track: parameters within stated uncertainties.

In the ``uncertain`` track every episode (training and test alike) runs on its own plant: the
physical constants of :class:`~fcc_env.params.FCCParams` drawn within the relative half-ranges
of :class:`PlantUncertainty`, plus two benign, slow, undeclared disturbances
(:class:`FeedQualityDrift`, :class:`AmbientCycle`). Nothing of the draw appears in the
observations; the healthy and the faulty episode of one seed share the same plant, and the draw
uses its own random stream (``np.random.default_rng([seed, PLANT_STREAM])``), so it does not
depend on the scenario and leaves the episode's program, noise and fault streams unchanged.

The disturbances are effect objects with the :mod:`fcc_env.effects` protocol
(``param_multipliers`` only, so the compiled simulator applies them exactly). Pass a
:class:`PlantUncertainty` to :func:`fcc_env.simulate_episodes`
(``plant_uncertainty=PlantUncertainty()``): each seed's plant (parameters and effects) is drawn
and simulated in the same batch.

>>> draw = PlantUncertainty().draw(7)
>>> draw == PlantUncertainty().draw(7)
True
>>> sorted(draw.truth)[:3]
['A_cr', 'UA_1', 'UA_2']

The ``mismatch`` track's draws are :class:`PlantMismatch`'s: the declared parameters, and
undeclared effects of the library (:mod:`fcc_env.effects`) at sizes a real unit shows.

>>> [e.effect_id for e in PlantMismatch().draw(7).effects][:2]
['heat_loss:stage1', 'heat_loss:stage2']
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from fcc_common.validation import Integer, Real, check, invalid
from fcc_env import effects as fx
from fcc_env.params import FCCParams

__all__ = [
    "GROUP_FIELDS",
    "LAGGED_CHANNELS",
    "MAX_HALF_RANGE",
    "MISMATCH_STREAM",
    "PLANT_STREAM",
    "AmbientCycle",
    "FeedQualityDrift",
    "PlantDraw",
    "PlantMismatch",
    "PlantUncertainty",
]

#: Second word of the draw's seed sequence: keeps the plant stream apart from every episode stream.
PLANT_STREAM = 0x504C414E  # "PLAN"
SECONDS_PER_HOUR = 3_600.0
#: Third word of a mismatch draw's seed sequence (apart from the uncertain track's draws).
MISMATCH_STREAM = 0x4D49534D  # "MISM"
#: The thermocouples a mismatch draw may give a lag (the process temperatures of Table 1).
LAGGED_CHANNELS: tuple[str, ...] = ("T_rx", "T_rg1", "T_rg2", "T_d1", "T_dg")

#: FCCParams fields drawn by each group (``valve`` is the gain of the valve law, via ``rho_b0``).
GROUP_FIELDS: dict[str, tuple[str, ...]] = {
    "kinetics": ("A_cr", "k_cb"),
    "heat_loss": ("UA_1", "UA_2", "UA_d1", "UA_dg"),
    "feed": ("cp_fe", "dH_v", "dH_cr", "y_ccr"),
    "valve": ("rho_b0",),
}

#: Largest accepted half-range per option; beyond it the plant is no longer "the same unit".
MAX_HALF_RANGE: dict[str, float] = {
    "kinetics": 0.2,
    "heat_loss": 0.5,
    "feed": 0.1,
    "valve": 0.05,
    "feed_drift": 0.05,
}
_MAX_AMBIENT_C = 20.0
_WHY = "a relative half-range"


def _wave(t_s: np.ndarray, period_s: float, phase: float) -> np.ndarray:
    """sin(2πt/P + φ) − sin φ: a slow cycle that is zero at t = 0 (no start-up transient)."""
    t = np.asarray(t_s, dtype=np.float64)
    return np.sin(2.0 * math.pi * t / period_s + phase) - math.sin(phase)


@dataclass(frozen=True)
class FeedQualityDrift:
    """Slow feed-quality cycle: coke yields ``y_ccr`` and ``y_cat`` × (1 + a·wave(t)).

    Equivalent to the feed coking factor ``f_coke`` × the same factor (spec §5 "feed coking
    tendency drift"), but through parameters, so the recorded inputs stay the declared ones.
    """

    amplitude: float  # relative, ≥ 0
    period_s: float
    phase: float = 0.0  # rad

    def __post_init__(self) -> None:
        check("amplitude", self.amplitude, Real(0.0, MAX_HALF_RANGE["feed_drift"], why=_WHY))
        check("period_s", self.period_s, Real(600.0, 10 * 86_400.0, unit="s"))
        check("phase", self.phase, Real(-2 * math.pi, 2 * math.pi, unit="rad"))

    def param_multipliers(self, t_s: np.ndarray, base: Any) -> dict[str, np.ndarray]:
        m = 1.0 + self.amplitude * _wave(t_s, self.period_s, self.phase)
        return {"y_ccr": m, "y_cat": m.copy()}

    def reset(self) -> None:
        """Stateless: nothing to reset."""

    def describe(self) -> dict[str, Any]:
        return {"id": "feed_quality_drift", "params": _asdict(self)}


@dataclass(frozen=True)
class AmbientCycle:
    """Ambient temperature ``T_amb_C`` + A·wave(t) (day–night cycle; acts on all heat losses)."""

    amplitude_C: float
    period_s: float = 24 * SECONDS_PER_HOUR
    phase: float = 0.0  # rad

    def __post_init__(self) -> None:
        check("amplitude_C", self.amplitude_C, Real(0.0, _MAX_AMBIENT_C, unit="°C"))
        check("period_s", self.period_s, Real(600.0, 10 * 86_400.0, unit="s"))
        check("phase", self.phase, Real(-2 * math.pi, 2 * math.pi, unit="rad"))

    def param_multipliers(self, t_s: np.ndarray, base: Any) -> dict[str, np.ndarray]:
        t_amb = float(base.T_amb_C)
        if t_amb == 0.0:  # a multiplier cannot move a zero; the cycle is then off
            return {"T_amb_C": np.ones_like(np.asarray(t_s, dtype=np.float64))}
        delta = self.amplitude_C * _wave(t_s, self.period_s, self.phase)
        return {"T_amb_C": (t_amb + delta) / t_amb}

    def reset(self) -> None:
        """Stateless: nothing to reset."""

    def describe(self) -> dict[str, Any]:
        return {"id": "ambient_cycle", "params": _asdict(self)}


def _asdict(obj: Any) -> dict[str, float]:
    return {k: float(getattr(obj, k)) for k in obj.__dataclass_fields__}


@dataclass(frozen=True)
class PlantDraw:
    """One episode's plant: drawn parameters, the benign effects, and every drawn value."""

    seed: int
    params: FCCParams
    effects: tuple[Any, ...]
    truth: dict[str, Any]  # JSON-able: drawn field values, multipliers, effects, the ranges


@dataclass(frozen=True, kw_only=True)
class PlantUncertainty:
    """Relative half-ranges of the drawn parameter groups and sizes of the benign disturbances.

    ``PlantUncertainty()`` is the benchmark's ``uncertain`` track; ``PlantUncertainty.none()``
    draws the nominal plant (with the same stream consumption).

    Every drawn multiplier is ``1 + h·v`` with ``v`` uniform in [−1, 1] and ``h`` the group's
    half-range; the numbers consumed do not depend on the ranges (a zero range draws and
    ignores its number), so changing one group leaves the others' values unchanged. The ranges
    are calibration residuals of a model fitted at the unit's operating point, not the textbook
    spread of each constant: the burn is O2-limited, so every term of the riser and regenerator
    energy balances moves T_rx/T_rg1/T_rg2 almost one to one, and the healthy excited plant
    already comes within about 12 °C of the afterburn limit, so anything that cuts the coke make
    (lower A_cr, y_cat, y_ccr) must stay small. With the defaults a healthy episode rarely ends
    in an afterburn, and the drawn plant's temperatures sit about 4 noise σ from the nominal
    plant's at the median, mostly a constant offset (the drawn plant has its own steady state;
    the measurements are in the lab record, lab/detector-lab.md).

    Fault parameters (``rho_b``, ``K_w1``/``K_w2``, ``k_sigma``, ``V_rx_sp_m3``) are never
    drawn, so a fault's size keeps its meaning; ``beta_sv`` is not drawn because ``valve_beta``
    sets it. Both disturbances are zero at t = 0, so an episode starts at the drawn plant's
    steady state.

    Args:
        kinetics: relative half-range of ``A_cr`` (cracking pre-exponential) and ``k_cb``
            (coke-burning pre-exponential), the activity of the equilibrium catalyst; in
            [0, 0.2], default 0.02. Activation energies are not drawn: 1 % of E is 10-20 % of
            the rate through exp(−E/RT).
        heat_loss: relative half-range of ``UA_1``, ``UA_2``, ``UA_d1``, ``UA_dg``, each vessel
            apart (insulation state and wind); in [0, 0.5], default 0.10.
        feed: relative half-range of ``cp_fe``, ``dH_v``, ``dH_cr``, ``y_ccr`` (gas-oil
            properties as calibrated: ±0.5 % of ``cp_fe`` is about ±1.7 °C on T_rx/T_rg); in
            [0, 0.1], default 0.005.
        valve: relative half-range of the slide-valve gain 1 + δ (the flow coefficient of a
            calibrated valve), applied as ``rho_b0`` × (1 + δ)⁻²; in [0, 0.05], default 0.01.
            No effect in flow mode (``valve_beta=0``), where the density factor is dropped.
        feed_drift: relative amplitude a of :class:`FeedQualityDrift`, the coke yields
            ``y_ccr`` and ``y_cat`` (the feed coking factor) × (1 + a·(sin(2πt/P + φ) − sin φ));
            in [0, 0.05], default 0.004, about 1-2 noise σ (a 1 % coking-factor step moves T_rx
            by about +0.9 °C and the dilute phases by −1 to −1.4 °C, spec §5).
        feed_drift_period_h: the range ``(low, high)`` [h] the drift's period P is drawn from
            uniformly (phase φ uniform), each in [1, 240]; default ``(2.0, 8.0)``.
        ambient_amplitude_C: amplitude A [°C] of :class:`AmbientCycle`, ``T_amb_C`` +
            A·(sin(2πt/P + φ) − sin φ); in [0, 20], default 8.0. Close to invisible (the heat
            losses are a few kW against about 0.5 MW/K of catalyst heat flow): it is there to
            make the benchmark honest about it, not to be detected.
        ambient_period_h: the ambient cycle's period P [h], in [1, 240]; default 24.0.
    """

    kinetics: float = 0.02
    heat_loss: float = 0.10
    feed: float = 0.005
    valve: float = 0.01
    feed_drift: float = 0.004  # amplitude of the coking-factor cycle (relative)
    feed_drift_period_h: tuple[float, float] = (2.0, 8.0)  # period drawn uniformly in this range
    ambient_amplitude_C: float = 8.0
    ambient_period_h: float = 24.0

    def __post_init__(self) -> None:
        for name, hi in MAX_HALF_RANGE.items():
            check(name, getattr(self, name), Real(0.0, hi, why=_WHY))
        check("ambient_amplitude_C", self.ambient_amplitude_C, Real(0.0, _MAX_AMBIENT_C, unit="°C"))
        check("ambient_period_h", self.ambient_period_h, Real(1.0, 240.0, unit="h"))
        lo_hi = self.feed_drift_period_h
        if not (isinstance(lo_hi, tuple) and len(lo_hi) == 2):
            raise invalid("feed_drift_period_h", lo_hi, "a pair (low, high) of hours in [1, 240]")
        lo = check("feed_drift_period_h[0]", lo_hi[0], Real(1.0, 240.0, unit="h"))
        check("feed_drift_period_h[1]", lo_hi[1], Real(lo, 240.0, unit="h"))

    @classmethod
    def none(cls) -> PlantUncertainty:
        """The nominal plant (all ranges and disturbances zero)."""
        return cls(kinetics=0, heat_loss=0, feed=0, valve=0, feed_drift=0, ambient_amplitude_C=0)

    def draw(self, seed: int, base: FCCParams | None = None) -> PlantDraw:
        """The plant of episode ``seed``: deterministic in the seed, independent of the scenario."""
        seed = check("seed", seed, Integer(0, 2**63 - 1))
        base = FCCParams() if base is None else base
        rng = np.random.default_rng([seed, PLANT_STREAM])
        changes: dict[str, float] = {}
        truth: dict[str, Any] = {"seed": seed, "multipliers": {}}
        for group, names in GROUP_FIELDS.items():
            h = float(getattr(self, group))
            v = rng.uniform(-1.0, 1.0, size=len(names))  # always consumed
            for name, vi in zip(names, v, strict=True):
                m = 1.0 + h * float(vi)
                if group == "valve":  # gain m of F = u_F·√(ρ_b/ρ_b0)·…  ⇔  ρ_b0 / m²
                    truth["valve_gain"] = m
                    m = 1.0 / (m * m)
                changes[name] = getattr(base, name) * m
                truth["multipliers"][name] = m
        v_drift = rng.uniform(0.0, 1.0, size=2)  # period fraction, phase fraction
        v_amb = float(rng.uniform(0.0, 1.0))  # phase fraction
        lo, hi = self.feed_drift_period_h
        effects: list[Any] = []
        drift = FeedQualityDrift(
            amplitude=float(self.feed_drift),
            period_s=(lo + (hi - lo) * float(v_drift[0])) * SECONDS_PER_HOUR,
            phase=2.0 * math.pi * float(v_drift[1]) - math.pi,
        )
        ambient = AmbientCycle(
            amplitude_C=float(self.ambient_amplitude_C),
            period_s=float(self.ambient_period_h) * SECONDS_PER_HOUR,
            phase=2.0 * math.pi * v_amb - math.pi,
        )
        if drift.amplitude > 0:
            effects.append(drift)
        if ambient.amplitude_C > 0:
            effects.append(ambient)
        params = base.replace(**changes)
        truth.update({name: float(changes[name]) for name in changes})
        truth["effects"] = [e.describe() for e in (drift, ambient)]
        truth["uncertainty"] = self.describe()
        return PlantDraw(seed, params, tuple(effects), truth)

    def describe(self) -> dict[str, Any]:
        out: dict[str, Any] = {k: getattr(self, k) for k in self.__dataclass_fields__}
        out["feed_drift_period_h"] = list(self.feed_drift_period_h)
        return out


@dataclass(frozen=True, kw_only=True)
class PlantMismatch:
    """Undeclared effects of a real unit, drawn per episode: the ``mismatch`` track's plants.

    Every episode (training and test alike) runs on the declared parameters plus effects of the
    library (:mod:`fcc_env.effects`) that no detector is told of, drawn by the seed on their own
    stream (like :class:`PlantUncertainty`'s, independent of the scenario):

    * ``heat_loss`` on each of the four vessels, the extra loss coefficient uniform in
      [0, ``extra_ua_kw_per_k``] (0.3 kW/K: UA × 1.15-1.3, offsets of 2-3 °C on average; at
      the library's +1 kW/K the dilute phases moved by up to 80 °C and 2 of 12 healthy
      episodes, seeds 5000-5011, ended in an afterburn);
    * ``sensor_lag`` on one thermocouple of :data:`LAGGED_CHANNELS`, its time constant uniform
      in ``lag_s`` (the library's 30-90 s);
    * ``catalyst_deactivation``, the activity loss per day uniform in [0,
      ``deactivation_per_day``] (at most 0.9 % over a 4000-sample episode by default: the
      equilibrium catalyst is kept by fresh make-up; the library's 0.2 per day is a run of days).

    Args:
        extra_ua_kw_per_k: the heat losses' largest extra UA [kW/K], in [0, 5]; default 0.3.
        lag_s: the range ``(low, high)`` [s] of the lag's time constant, each in [1, 600].
        deactivation_per_day: the largest activity loss per day, in [0, 0.5].
    """

    extra_ua_kw_per_k: float = 0.3
    lag_s: tuple[float, float] = (30.0, 90.0)
    deactivation_per_day: float = 0.02

    def __post_init__(self) -> None:
        check("extra_ua_kw_per_k", self.extra_ua_kw_per_k, Real(0.0, 5.0, unit="kW/K"))
        lo_hi = self.lag_s
        if not (isinstance(lo_hi, tuple) and len(lo_hi) == 2):
            raise invalid("lag_s", lo_hi, "a pair (low, high) of seconds in [1, 600]")
        lo = check("lag_s[0]", lo_hi[0], Real(1.0, 600.0, unit="s"))
        check("lag_s[1]", lo_hi[1], Real(lo, 600.0, unit="s"))
        check("deactivation_per_day", self.deactivation_per_day, Real(0.0, 0.5, unit="1/day"))

    def draw(self, seed: int, base: FCCParams | None = None) -> PlantDraw:
        """The plant of episode ``seed``: ``base`` (default the declared parameters) unchanged,
        with its drawn effects."""
        seed = check("seed", seed, Integer(0, 2**63 - 1))
        base = FCCParams() if base is None else base
        rng = np.random.default_rng([seed, PLANT_STREAM, MISMATCH_STREAM])
        v_ua = rng.uniform(0.0, 1.0, size=4)
        channel = LAGGED_CHANNELS[int(rng.integers(len(LAGGED_CHANNELS)))]
        v_lag, v_deact = rng.uniform(0.0, 1.0, size=2)
        lo, hi = self.lag_s
        effects = [
            fx.make(f"heat_loss:{unit}", extra_ua_kw_per_k=float(self.extra_ua_kw_per_k * v))
            for unit, v in zip(("stage1", "stage2", "dilute1", "dilute_general"), v_ua, strict=True)
        ]
        effects.append(fx.make(f"sensor_lag:{channel}", tau_s=float(lo + (hi - lo) * v_lag)))
        rate = float(self.deactivation_per_day * v_deact)
        effects.append(fx.make("catalyst_deactivation", loss_per_day=rate))
        truth = {
            "seed": seed,
            "effects": [e.describe() for e in effects],
            "mismatch": self.describe(),
        }
        return PlantDraw(seed, base, tuple(effects), truth)

    def describe(self) -> dict[str, Any]:
        return {
            "extra_ua_kw_per_k": self.extra_ua_kw_per_k,
            "lag_s": list(self.lag_s),
            "deactivation_per_day": self.deactivation_per_day,
        }
