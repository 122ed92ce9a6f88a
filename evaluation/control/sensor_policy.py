"""A supervisor that corrects the loops' set points for a faulty loop transmitter.

A fault-blind supervisor cannot see a faulty T_rx or T_rg1 transmitter: the loop holds the
reading, not the temperature. :class:`SensorCorrectingSupervisor` holds the healthy optimum and
corrects a loop's set point by what it learns of its transmitter, two ways:

* **a frozen reading** (its own check, the "frozen value" test of a DCS's sensor validation):
  a loop transmitter whose reading repeats bit for bit over ``frozen_samples`` samples is stuck
  (a live thermocouple's noise never repeats its value; a stuck one's held value does). The set
  point goes to the frozen reading, so the loop's error stays 0 and its integral stops: the
  actuator holds where it stood, instead of the wind-up that trips the plant. It returns to
  the optimum as soon as the reading moves again;
* **a diagnosis** (optional ``diagnoser``: any registered one, streamed sample by sample from
  ``arm_after``, as :class:`~evaluation.control.policies.DiagnosisSupervisor` streams it): when
  it alarms and names a sensor fault (:func:`fcc_env.control_draws.fault_class` of its
  diagnosis is ``sensor``), the loop channel among its signals with the largest residual
  relative to its limit is the faulty one, and the mean of that residual over the last
  ``window`` alarmed samples (measured − predicted: the bias, for a diagnoser whose residual
  per sensor is an analytical-redundancy prediction) is added to the loop's set point.
  A diagnoser whose signals do not name a loop channel corrects nothing.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from evaluation.control.policies import ARM_AFTER, SetpointPolicy
from evaluation.control.setpoints import best_setpoints
from fcc_env.closed_loop import CLOSED_LOOP_CHANNELS
from fcc_env.control_draws import LOOP_CHANNELS, FaultClass, fault_class
from fcc_env.faults import FAULTS

__all__ = ["SensorCorrectingSupervisor"]

_LOOP_INDEX = [CLOSED_LOOP_CHANNELS.index(c) for c in LOOP_CHANNELS]


def _names_sensor_fault(diagnosis: str) -> bool:
    return diagnosis in FAULTS and fault_class(diagnosis) is FaultClass.SENSOR


@dataclass
class SensorCorrectingSupervisor:
    """The healthy optimum, each loop's set point corrected for its transmitter (module doc)."""

    name: str = "sensor-correcting supervisor (frozen-reading check)"
    diagnoser: Any = None
    frozen_samples: int = 5
    window: int = 60
    arm_after: int = ARM_AFTER
    healthy: np.ndarray | None = None
    _policy: SetpointPolicy = field(init=False, repr=False)
    _k: int = field(init=False, repr=False, default=0)
    _last: np.ndarray = field(init=False, repr=False)
    _repeats: np.ndarray = field(init=False, repr=False)
    _residuals: deque[float] = field(init=False, repr=False)
    _bias: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        if self.healthy is None:
            self.healthy = best_setpoints().setpoints
        if int(self.frozen_samples) < 2:
            raise ValueError(f"frozen_samples={self.frozen_samples!r}: allowed: an integer >= 2")
        self._policy = SetpointPolicy(self.name, lambda k, info: self._target())

    def reset(self, info: Mapping[str, Any]) -> None:
        self._k = 0
        self._last = np.full(2, np.nan)
        self._repeats = np.zeros(2, dtype=np.int64)
        self._residuals = deque(maxlen=self.window)
        self._bias = np.zeros(2)
        if self.diagnoser is not None:
            self.diagnoser.reset()
        self._policy.reset(info)

    def _target(self) -> np.ndarray:
        assert self.healthy is not None
        target = self.healthy + self._bias
        frozen = self._repeats >= self.frozen_samples - 1
        return np.where(frozen, self._last, target)

    def act(self, obs: np.ndarray, info: Mapping[str, Any]) -> np.ndarray:
        reading = np.asarray(obs, dtype=np.float64)[_LOOP_INDEX]
        self._repeats = np.where(reading == self._last, self._repeats + 1, 0)
        self._last = reading
        self._k += 1
        if self.diagnoser is not None and self._k > self.arm_after:
            if self._k == self.arm_after + 1:
                self.diagnoser.reset()  # its training records start here
            self._read_diagnosis(self.diagnoser.update(np.asarray(obs, dtype=np.float64)))
        return self._policy.act(obs, info)

    def _read_diagnosis(self, decision: Any) -> None:
        if not (decision.alarm and _names_sensor_fault(str(decision.diagnosis))):
            return
        names = list(getattr(self.diagnoser, "signal_names_", ()))
        loops = [(i, names.index(c)) for i, c in enumerate(LOOP_CHANNELS) if c in names]
        if not loops:
            return
        residual = np.asarray(decision.residual, dtype=np.float64)
        upper = np.abs(np.asarray(decision.upper, dtype=np.float64))
        ratio = [abs(residual[j]) / max(upper[j], 1e-12) for _, j in loops]
        loop, j = loops[int(np.argmax(ratio))]
        self._residuals.append(float(residual[j]))
        self._bias = np.zeros(2)
        self._bias[loop] = float(np.mean(self._residuals))
