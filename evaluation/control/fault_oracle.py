"""The oracle of the whole fault catalogue: what a supervisor that knows the fault would do.

The study's reference policy (``oracle`` in :mod:`evaluation.control.policy_registry`) knows the episode's fault, its size and onset (the
reset ``info``: no agent may read it) and from the onset holds the best fixed set points of the
faulty plant. A process fault (f1–f4) changes the plant's parameters and the steady-state
search (:func:`~evaluation.control.setpoints.best_setpoints`) takes the faulty plant whole. The
sensor and actuator faults change no parameter; what the oracle does with each, and why:

================  =============================================================================
fault             the oracle's set points from the onset
================  =============================================================================
sensor-bias,      the loop rebuilt through its set point: each sample the set point is the
-drift, -stuck    healthy optimum plus the transmitter's error (its noise-free reading minus
on T_rx or T_rg1  the true temperature: ``info["y_clean"]`` and ``info["T_rx"]``/the stage-1
                  bed state, what no agent may read), so the loop's error is the true
                  temperature's error and the plant runs as healthy. A fully stuck T_rg1 would
                  otherwise open its loop (the air holds while the regenerator drifts: 1 in 3
                  training seeds extinguished, the others up to 70,000 USD lost); for T_rx the
                  set-point range's top (545 °C, where the healthy optimum lies) clips the
                  upward corrections: a loop with less than 2 °C of room either way keeps the
                  healthy optimum (``correctable_loops``), as a one-sided rebuilt T_rx loop
                  tripped more often than the stuck one left alone (lab/control-catalogue.md)
any sensor fault  the healthy optimum: no controller reads those channels, the process does
on another        not move
channel
blower-capacity   the best set points with the air's ceiling at ``(1 − m)`` × the blower's
                  capacity, less 1 % for the loop's noise (``best_setpoints(limits=...)``):
                  above it the air loop winds up and saturates
valve-stuck       fully stuck (``m = 1``): the best set points with ``u_F`` pinned where the
                  valve stood at the onset (``info["inputs"]`` of the sample before); T_rx's
                  set point is the steady riser outlet there, so the open T_rx loop does not
                  wind up to saturation. Partly stuck, the healthy optimum (the loop still moves
                  the valve, slower)
valve-bias        the healthy optimum: the T_rx loop takes the bias out, and the healthy valve
                  position (493 kg/s) stays reachable (the command's floor moves up by
                  ``m`` × 417 kg/s, to 292 kg/s at most)
valve-stiction    the healthy optimum: no set point removes the limit cycle (retuning or a
                  stiction compensator would, out of the supervisory action's reach)
================  =============================================================================
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from evaluation.control.policies import SetpointPolicy
from evaluation.control.setpoints import OperatingPoint, best_setpoints, correctable_loops
from fcc_env.control_draws import LOOP_CHANNELS
from fcc_env.control_task import EconomicReward
from fcc_env.params import INPUT_NAMES, MEASUREMENT_NAMES
from fcc_env.regulatory import ACTUATOR_LIMITS
from fcc_env.scenarios import NOMINAL, FaultSpec

__all__ = ["BLOWER_MARGIN", "FaultOracle"]

#: The share of the blower's faulty ceiling the oracle leaves for the air loop's noise.
BLOWER_MARGIN = 0.01
_U_F = INPUT_NAMES.index("u_F")
_T_RG1_STATE = 4  # the stage-1 bed temperature in the state (spec §1)
_Y = {c: MEASUREMENT_NAMES.index(c) for c in LOOP_CHANNELS}


@dataclass
class FaultOracle:
    """Knows the fault, its size and onset (module docstring: the set points per fault).

    A :class:`~evaluation.control.policies.Policy`: ``reset`` reads the fault from the reset
    ``info`` (``scenario``, ``fault_time``, ``fault_magnitude``, ``fault_channel``), ``act``
    reads the observation and ``info`` of each sample, which a stuck transmitter or valve needs
    (where it froze). The operating points are searched once per fault and size, and cached.
    """

    name: str = "oracle (knows the fault and its onset)"
    economics: EconomicReward | None = None
    _cache: dict[tuple[Any, ...], OperatingPoint] = field(default_factory=dict, repr=False)
    _healthy: np.ndarray = field(init=False, repr=False)
    _policy: SetpointPolicy = field(init=False, repr=False)
    _fault: dict[str, Any] = field(init=False, repr=False, default_factory=dict)
    _k: int = field(init=False, repr=False, default=0)
    _frozen: tuple[float, float] = field(init=False, repr=False, default=(np.nan, np.nan))
    _sensor_error: tuple[float, float] = field(init=False, repr=False, default=(0.0, 0.0))
    _target: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        self._healthy = self._point(("healthy",)).setpoints
        self._target = self._healthy
        self._policy = SetpointPolicy(self.name, lambda k, info: self._target)

    @property
    def healthy(self) -> np.ndarray:
        """The healthy plant's best set points (°C, T_rx and T_rg1): held before the onset."""
        return self._healthy.copy()

    def _point(self, key: tuple[Any, ...], **search: Any) -> OperatingPoint:
        if key not in self._cache:
            fault = search.pop("fault", None)
            self._cache[key] = best_setpoints(fault, economics=self.economics, **search)
        return self._cache[key]

    def reset(self, info: Mapping[str, Any]) -> None:
        onset = info.get("fault_time")
        scenario = info.get("scenario")
        self._fault = {}
        if scenario not in (None, NOMINAL) and onset is not None:
            self._fault = {
                "scenario": str(scenario),
                "onset": int(onset),
                "magnitude": float(info["fault_magnitude"]),
                "channel": info.get("fault_channel"),
            }
        self._k = 0
        self._frozen = (np.nan, np.nan)
        self._sensor_error = (0.0, 0.0)
        self._target = self._healthy
        self._policy.reset(info)

    def act(self, obs: np.ndarray, info: Mapping[str, Any]) -> np.ndarray:
        f = self._fault
        if f and self._k == f["onset"] - 1:  # the sample before the onset: what freezes
            self._frozen = (np.nan, float(np.asarray(info["inputs"])[_U_F]))
        if f and f["channel"] in LOOP_CHANNELS:
            y = np.asarray(info["y_clean"], dtype=np.float64)
            true = (float(info["T_rx"]), float(np.asarray(info["state"])[_T_RG1_STATE]))
            self._sensor_error = tuple(
                y[_Y[c]] - t for c, t in zip(LOOP_CHANNELS, true, strict=True)
            )
        if f and self._k >= f["onset"]:
            self._target = self._faulty_target(self._k)
        self._k += 1
        return self._policy.act(obs, info)

    def _faulty_target(self, k: int) -> np.ndarray:
        f = self._fault
        sc, m, channel = f["scenario"], f["magnitude"], f["channel"]
        key = (sc, channel, round(m, 4))
        if sc.startswith("sensor-"):
            if channel not in LOOP_CHANNELS:
                return self._healthy
            loop = LOOP_CHANNELS.index(channel)
            if not correctable_loops(self._healthy)[loop]:
                return self._healthy
            target = self._healthy.copy()
            target[loop] += self._sensor_error[loop]
            return target
        if sc == "blower-capacity":
            limits = ACTUATOR_LIMITS.astype(np.float64)
            limits[1, 1] = (1.0 - m) * limits[1, 1] * (1.0 - BLOWER_MARGIN)
            return self._point(key, limits=limits).setpoints
        if sc == "valve-stuck":
            if m < 1.0:
                return self._healthy
            u_f = round(self._frozen[1], 1)
            limits = ACTUATOR_LIMITS.astype(np.float64)
            limits[0] = (u_f - 0.05, u_f + 0.05)
            return self._point((*key, u_f), limits=limits).setpoints
        if sc in ("valve-bias", "valve-stiction"):
            return self._healthy
        spec = FaultSpec(scenario=sc, magnitude=m, onset=f["onset"])
        return self._point(key, fault=spec.resolve(horizon=f["onset"] + 1)).setpoints
