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
* the oracle (:class:`evaluation.control.fault_oracle.FaultOracle`): knows the episode's fault
  and its onset (``info`` at reset: what no agent may read) and moves, from the onset, to the
  best set points of the faulty plant (for a sensor or actuator fault, its module says what).
* :class:`DiagnosisSupervisor`: a fitted diagnoser reads the observation sample by sample
  (``update``); from its first alarm the policy moves to the best set points of the fault the
  diagnoser names (an isolator), or, from a detector that names none, to the set points best on
  average over the faults (:func:`robust_setpoints`). What a diagnosis is worth is the gap
  between it and the fixed set points, and what it lacks, the gap to the oracle.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, NamedTuple, Protocol

import numpy as np

from evaluation.control.setpoints import best_setpoints
from fcc_env.closed_loop import CLOSED_LOOP_CHANNELS
from fcc_env.control_task import EconomicReward
from fcc_env.env import SETPOINT_ACTION_SCALE
from fcc_env.scenarios import FaultSpec, fault_names

__all__ = [
    "ARM_AFTER",
    "DiagnosisSupervisor",
    "Policy",
    "ProgramPolicy",
    "SetpointPolicy",
    "SupervisorEvent",
    "fault_setpoints",
    "fixed_setpoints",
    "robust_setpoints",
    "setpoint_action",
]

_SP = [CLOSED_LOOP_CHANNELS.index(n) for n in ("T_rx_sp", "T_rg1_sp")]


def setpoint_action(obs: np.ndarray, move: np.ndarray, target: np.ndarray) -> np.ndarray:
    """The action (in [-1, 1]) that asks for the set points ``target`` (°C, ``[T_rx_sp,
    T_rg1_sp]``), given the observation ``obs`` after the last step and the ``move`` (°C) that
    step applied: the program's own set points are the observed ones less that move, and the
    action moves them by at most ``SETPOINT_ACTION_SCALE`` (the env's contract)."""
    program = np.asarray(obs, dtype=np.float64)[_SP] - move
    return np.clip((np.asarray(target, dtype=np.float64) - program) / SETPOINT_ACTION_SCALE, -1, 1)


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
        action = setpoint_action(obs, self._move, self.target(self._k, self._info0))
        self._move = action * SETPOINT_ACTION_SCALE
        self._k += 1
        return action.astype(np.float32)


def fixed_setpoints(economics: EconomicReward | None = None) -> SetpointPolicy:
    """The best steady set points of the healthy plant, held whatever happens."""
    best = best_setpoints(economics=economics).setpoints
    return SetpointPolicy("best fixed set points (healthy plant)", lambda k, info: best)


#: Samples after an episode's start before a supervisor acts on its diagnoser (50 min at 10 s):
#: the move from the program's set points to the optimum has settled by then.
ARM_AFTER = 300


def fault_setpoints(economics: EconomicReward | None = None) -> dict[str, np.ndarray]:
    """The best set points of the plant with each registered fault at its default size, by
    fault name."""
    out = {}
    for sc in fault_names():
        fault = FaultSpec(scenario=sc).resolve(horizon=4000)
        out[sc] = best_setpoints(fault, economics=economics).setpoints
    return out


def robust_setpoints(per_fault: Mapping[str, np.ndarray]) -> np.ndarray:
    """The set points for "some fault, not known which": the mean of the faults' best ones."""
    return np.mean(np.stack(list(per_fault.values())), axis=0)


class SupervisorEvent(NamedTuple):
    """A change of what a :class:`DiagnosisSupervisor` reads or does, at sample ``k``."""

    k: int
    alarm: bool
    diagnosis: str | None
    target: str  # "healthy", "robust" or the fault whose set points it moved to


@dataclass
class DiagnosisSupervisor:
    """Fixed healthy set points until ``diagnoser`` alarms, then the diagnosed fault's.

    ``diagnoser`` is fitted on closed-loop episodes with the observation's channels; it reads
    each observation through ``update`` (streaming, as on a unit). Once alarmed the policy
    stays switched (a supervisor that flip-flops on each alarm would move the set points with
    the noise); a later diagnosis of another fault switches again. The diagnoser starts after
    ``arm_after`` samples, from a fresh ``reset``: the episode starts at the program's set
    points, and the move to the healthy optimum is a start-up transient no detector is trained
    for (it is trained on the settled operation from that sample on,
    :func:`evaluation.control.returns.operated_episodes`), so it reads the episode from where
    its training records start, warm-up included. Fed the transient, a detector's statistics
    carry it past the arming and it alarms at once, naming a fault it never saw. ``history``
    holds the episode's
    :class:`SupervisorEvent` s: each change of alarm, diagnosis or target, from the start.
    """

    name: str
    diagnoser: Any
    healthy: np.ndarray
    per_fault: Mapping[str, np.ndarray]
    arm_after: int = ARM_AFTER
    history: list[SupervisorEvent] = field(init=False, default_factory=list)
    _policy: SetpointPolicy = field(init=False, repr=False)
    _k: int = field(init=False, repr=False, default=0)
    _target: np.ndarray = field(init=False, repr=False)
    _target_name: str = field(init=False, repr=False, default="healthy")

    def __post_init__(self) -> None:
        self._policy = SetpointPolicy(self.name, lambda k, info: self._target)

    def reset(self, info: Mapping[str, Any]) -> None:
        self.diagnoser.reset()
        self._target, self._target_name = self.healthy, "healthy"
        self._k = 0
        self.history = []
        self._policy.reset(info)

    def act(self, obs: np.ndarray, info: Mapping[str, Any]) -> np.ndarray:
        self._k += 1
        if self._k <= self.arm_after:
            self._record(SupervisorEvent(self._k, False, None, self._target_name))
            return self._policy.act(obs, info)
        if self._k == self.arm_after + 1:
            self.diagnoser.reset()  # its training records start here
        decision = self.diagnoser.update(np.asarray(obs, dtype=np.float64))
        named = getattr(decision, "diagnosis", None)
        if decision.alarm:
            if named in self.per_fault:
                self._target, self._target_name = self.per_fault[named], named
            elif self._target_name == "healthy":
                self._target = robust_setpoints(self.per_fault)
                self._target_name = "robust"
        self._record(SupervisorEvent(self._k, bool(decision.alarm), named, self._target_name))
        return self._policy.act(obs, info)

    def _record(self, event: SupervisorEvent) -> None:
        if not self.history or self.history[-1][1:] != event[1:]:
            self.history.append(event)
