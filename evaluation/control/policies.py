"""Baseline policies of ``FCC-control-v0``: what a supervisory layer does with the set points.

A policy sees what an agent sees (the observation and the step's ``info``) and returns the
action. The action moves the set points about the operating program's
(``FCC-closedloop-v0``: set points = program + action × (15, 20) °C), and the observation shows
the set points in force (program + the last move), so a policy that wants given set points
recovers the program's as "shown − last move" and moves by the difference
(:class:`SetpointPolicy`).

* :class:`ProgramPolicy`: the action 0, the operating program as it is.
* :func:`fixed_setpoints`: the best steady set points of the healthy plant
  (:func:`evaluation.control.setpoints.best_setpoints`), held throughout.
* :func:`oracle`: knows the episode's fault and its onset (``info`` at reset: what no agent may
  read) and moves, from the onset, to the best set points of the faulty plant.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from evaluation.control.setpoints import OperatingPoint, best_setpoints
from fcc_env.closed_loop import CLOSED_LOOP_CHANNELS
from fcc_env.control_task import EconomicReward
from fcc_env.env import SETPOINT_ACTION_SCALE
from fcc_env.scenarios import EpisodeFault, FaultSpec, Scenario

__all__ = ["Policy", "ProgramPolicy", "SetpointPolicy", "fixed_setpoints", "oracle"]

_SP = [CLOSED_LOOP_CHANNELS.index(n) for n in ("T_rx_sp", "T_rg1_sp")]


class Policy(Protocol):
    """What the control study runs: ``reset`` at each episode's start, ``act`` per step."""

    name: str

    def reset(self, info: Mapping[str, Any]) -> None: ...

    def act(self, obs: np.ndarray, info: Mapping[str, Any]) -> np.ndarray: ...


@dataclass
class ProgramPolicy:
    """The operating program as it is: the action 0."""

    name: str = "program (zero action)"

    def reset(self, info: Mapping[str, Any]) -> None:
        pass

    def act(self, obs: np.ndarray, info: Mapping[str, Any]) -> np.ndarray:
        return np.zeros(2, dtype=np.float32)


@dataclass
class SetpointPolicy:
    """Holds the set points ``target(k, info)`` (°C, ``[T_rx_sp, T_rg1_sp]``) at step ``k``."""

    name: str
    target: Callable[[int, Mapping[str, Any]], np.ndarray]
    _move: np.ndarray = field(default_factory=lambda: np.zeros(2), repr=False)
    _k: int = 0
    _info0: Mapping[str, Any] = field(default_factory=dict, repr=False)

    def reset(self, info: Mapping[str, Any]) -> None:
        self._move, self._k, self._info0 = np.zeros(2), 0, dict(info)

    def act(self, obs: np.ndarray, info: Mapping[str, Any]) -> np.ndarray:
        program = np.asarray(obs, dtype=np.float64)[_SP] - self._move
        action = np.clip(
            (self.target(self._k, self._info0) - program) / SETPOINT_ACTION_SCALE, -1, 1
        )
        self._move = action * SETPOINT_ACTION_SCALE
        self._k += 1
        return action.astype(np.float32)


def fixed_setpoints(economics: EconomicReward | None = None) -> SetpointPolicy:
    """The best steady set points of the healthy plant, held whatever happens."""
    best = best_setpoints(economics=economics).setpoints
    return SetpointPolicy("best fixed set points (healthy plant)", lambda k, info: best)


def oracle(economics: EconomicReward | None = None) -> SetpointPolicy:
    """Knows the fault and its onset: the healthy optimum before, the faulty plant's after."""
    healthy = best_setpoints(economics=economics).setpoints
    cache: dict[tuple[str, float], OperatingPoint] = {}

    def target(k: int, info: Mapping[str, Any]) -> np.ndarray:
        onset = info.get("fault_time")
        if info.get("scenario") in (None, Scenario.NOMINAL.value) or onset is None or k < onset:
            return healthy
        key = (str(info["scenario"]), round(float(info["fault_magnitude"]), 4))
        if key not in cache:
            spec = FaultSpec(scenario=key[0], magnitude=key[1], onset=int(onset))
            fault: EpisodeFault = spec.resolve(horizon=int(onset) + 1)
            cache[key] = best_setpoints(fault, economics=economics)
        return cache[key].setpoints

    return SetpointPolicy("oracle (knows the fault and its onset)", target)
