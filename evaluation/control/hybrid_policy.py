"""A fault-blind agent overridden by a diagnosis only where the diagnosis has found something.

:class:`DiagnosisOverride` runs two policies side by side on every sample: an ``agent`` (the
saved fault-blind PPO agent, :func:`evaluation.control.rl_policy.load_policy`) and a
``supervisor`` that judges the loop transmitters
(:class:`~evaluation.control.sensor_policy.SensorCorrectingSupervisor`). The agent acts; on a
loop the supervisor judges faulty (its ``judged``), the supervisor's set point for that loop
replaces the agent's. Elsewhere (before any judgment, on the other loop, on faults the
supervisor does not see) the agent keeps what it learned.

Both see every observation, so the supervisor's frozen-reading and residual tests run while the
agent acts. The action moves the set points about the program's (:mod:`.policies`); the
override recovers the program's set point from the observation and the move actually applied
(the agent's on one loop, the supervisor's on the other), not from the supervisor's own last
action, which was not applied.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from evaluation.control.policies import Policy, setpoint_action
from evaluation.control.sensor_policy import SensorCorrectingSupervisor
from fcc_env.env import SETPOINT_ACTION_SCALE

__all__ = ["DiagnosisOverride", "ppo_with_sensor_correcting"]


@dataclass
class DiagnosisOverride:
    """``agent`` acts; on each loop ``supervisor.judged`` marks, ``supervisor.setpoints`` do
    (module docstring). ``supervisor`` needs ``judged`` and ``setpoints`` after each ``act``."""

    agent: Policy
    supervisor: SensorCorrectingSupervisor
    name: str = ""
    _move: np.ndarray = field(init=False, repr=False, default_factory=lambda: np.zeros(2))

    def __post_init__(self) -> None:
        for attr in ("judged", "setpoints"):
            if not hasattr(type(self.supervisor), attr):
                raise ValueError(
                    f"supervisor={self.supervisor!r} has no {attr!r}: allowed: a supervisor "
                    "with judged and setpoints (SensorCorrectingSupervisor)"
                )
        if not self.name:
            self.name = f"{self.agent.name}, overridden by {self.supervisor.name}"

    def reset(self, info: Mapping[str, Any]) -> None:
        self._move = np.zeros(2)
        self.agent.reset(info)
        self.supervisor.reset(info)

    def act(self, obs: np.ndarray, info: Mapping[str, Any]) -> np.ndarray:
        agent = np.asarray(self.agent.act(obs, info), dtype=np.float64)
        self.supervisor.act(obs, info)  # its tests read every sample, its action is not used
        wanted = setpoint_action(obs, self._move, self.supervisor.setpoints)
        action = np.where(self.supervisor.judged, wanted, agent)
        self._move = action * SETPOINT_ACTION_SCALE
        return action.astype(np.float32)


def ppo_with_sensor_correcting(directory: Path | str, **supervisor: Any) -> DiagnosisOverride:
    """The PPO agent saved in ``directory`` overridden by a
    :class:`SensorCorrectingSupervisor` built with the keywords ``supervisor``.

    The supervisor's ``hold_frozen`` is off unless asked for: on the loop it cannot rebuild
    (the riser's, no set-point room) the agent, which sees the frozen reading beside its own
    set point, did as well as the hold on validation seeds (lab/control-catalogue.md), so there
    the diagnosis has nothing better to give it."""
    from evaluation.control.rl_policy import load_policy

    supervisor.setdefault("hold_frozen", False)
    agent = load_policy(directory)
    return DiagnosisOverride(
        agent,
        SensorCorrectingSupervisor(**supervisor),
        name="PPO agent overridden by the sensor-correcting supervisor on judged loops",
    )
