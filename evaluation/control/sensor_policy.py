"""A supervisor that rebuilds a loop whose transmitter fails, through the loop's set point.

A fault-blind supervisor cannot see a faulty T_rx or T_rg1 transmitter: the loop holds the
reading, not the temperature (a stuck one opens the loop; the integral winds up or the actuator
freezes while the process drifts). :class:`SensorCorrectingSupervisor` holds the healthy optimum
``T*``; once it judges a loop transmitter faulty, it sets that loop's set point each sample to
``T* + (reading − T̂)``: the loop's error becomes ``T* − T̂``, the loop runs on ``T̂``, the
transmitter's error is taken out whatever its kind (bias, drift, stuck).

``T̂`` is an **analytical-redundancy estimate** (:class:`SoftSensor`): a linear relation from the
other measured channels and the valve command to the loop temperature, fitted by least squares
on healthy training episodes (seeds 1000..) whose set points step at random within their ranges
(at fixed set points the loop temperatures barely move and the relation is not identified).
On validation seed 5000 it tracks the true T_rg1 to 1.0 °C RMS and T_rx to 1.7 °C.

It judges a transmitter faulty three ways:

* **a frozen reading** (the "frozen value" test of a DCS): a loop transmitter whose reading
  repeats bit for bit over ``frozen_samples`` samples (a live one's noise never repeats);
* **its residual** ``reading − T̂``, averaged (an EWMA of ``1/window``), beyond ``limit_C``;
* **a diagnosis**, from any registered ``diagnoser`` streamed sample by sample from
  ``arm_after`` (as :class:`~evaluation.control.policies.DiagnosisSupervisor` streams it): when it
  alarms and names a sensor fault (:func:`fcc_env.control_draws.fault_class` of its diagnosis
  is ``sensor``), the channel it names is the faulty one: a diagnoser that names the sensor
  while streaming (``named_sensor`` after each ``update``, as ``sensor-validation``'s) is taken
  at its word (a sensor off the loops rebuilds nothing); one that names only the kind leaves
  the choice to the loop of the larger averaged residual. ``diagnoser`` may be a registered
  name: it is then fitted by :func:`fit_sensor_diagnoser`.

A judged loop stays rebuilt while the frozen or residual test holds; a diagnosis latches it.
Only a loop whose optimum leaves room in its set-point range both ways is rebuilt
(:func:`~evaluation.control.setpoints.correctable_loops`: the riser's optimum lies on its
range's top, where the corrections upwards are clipped and a one-sided loop trips more often
than the stuck one left alone). A loop that cannot be rebuilt but whose reading is frozen is
**held** (``hold_frozen``): its set point becomes the frozen reading (clipped to its range), so
the PI error is zero and the valve stays where it was when the transmitter stuck, instead of
the integral winding the valve against a reading that no longer moves.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import gymnasium as gym
import numpy as np

from evaluation.control.policies import ARM_AFTER, SetpointPolicy, setpoint_action
from evaluation.control.setpoints import best_setpoints, correctable_loops
from fcc_env.closed_loop import CLOSED_LOOP_CHANNELS
from fcc_env.control_draws import LOOP_CHANNELS, FaultClass, fault_class
from fcc_env.control_task import CONTROL_ENV_ID
from fcc_env.env import SETPOINT_ACTION_SCALE
from fcc_env.faults import FAULTS
from fcc_env.regulatory import SETPOINT_RANGES

__all__ = [
    "SOFT_SENSOR_INPUTS",
    "SOFT_SENSOR_SEEDS",
    "SensorCorrectingSupervisor",
    "SoftSensor",
    "fit_sensor_diagnoser",
]

_T_RG1_STATE = 4  # the stage-1 bed temperature in the state (spec §1)

_LOOP_INDEX = [CLOSED_LOOP_CHANNELS.index(c) for c in LOOP_CHANNELS]
#: the soft sensor's inputs (observation indices): the other measured channels and the valve command
SOFT_SENSOR_INPUTS = [i for i, c in enumerate(CLOSED_LOOP_CHANNELS[:9]) if c not in LOOP_CHANNELS]
_SP_LOW = np.array([SETPOINT_RANGES[n].low for n in ("T_rx_sp", "T_rg1_sp")])
_SP_HIGH = np.array([SETPOINT_RANGES[n].high for n in ("T_rx_sp", "T_rg1_sp")])
#: training episodes of the soft sensor (never a test or validation seed)
SOFT_SENSOR_SEEDS = range(1000, 1004)


@dataclass(frozen=True)
class SoftSensor:
    """``T̂ = [obs[SOFT_SENSOR_INPUTS], 1] @ coef`` for T_rx and T_rg1 (``coef`` shape ``(k + 1, 2)``)."""

    coef: np.ndarray

    def estimate(self, obs: np.ndarray) -> np.ndarray:
        x = np.asarray(obs, dtype=np.float64)[SOFT_SENSOR_INPUTS]
        return np.append(x, 1.0) @ self.coef

    @classmethod
    def fit(cls, seeds: Sequence[int] = SOFT_SENSOR_SEEDS, n_steps: int = 3999) -> SoftSensor:
        """Least squares on healthy episodes of ``seeds`` whose set points step at random
        every 200 samples (module docstring)."""
        rows, targets = [], []
        lo, hi = _SP_LOW, _SP_HIGH
        for seed in seeds:
            rng = np.random.default_rng(seed)
            env = gym.make(CONTROL_ENV_ID, scenario="nominal")
            obs, _ = env.reset(seed=seed)
            move, target = np.zeros(2), rng.uniform(lo, hi)
            for k in range(n_steps):
                if k % 200 == 0:
                    target = rng.uniform(lo, hi)
                action = setpoint_action(obs, move, target)
                move = action * SETPOINT_ACTION_SCALE
                obs, _, terminated, truncated, info = env.step(action)
                rows.append(np.asarray(obs, dtype=np.float64)[SOFT_SENSOR_INPUTS])
                targets.append((info["T_rx"], info["state"][_T_RG1_STATE]))
                if terminated or truncated:
                    break
            env.close()
        a = np.c_[np.asarray(rows), np.ones(len(rows))]
        coef, *_ = np.linalg.lstsq(a, np.asarray(targets), rcond=None)
        return cls(coef)


def _names_sensor_fault(diagnosis: str) -> bool:
    return diagnosis in FAULTS and fault_class(diagnosis) is FaultClass.SENSOR


#: the diagnoser's training episodes: healthy ones (its limits) and one per sensor-fault kind
#: (its labels); training seeds only
DIAGNOSER_SEEDS = range(1000, 1003)


def fit_sensor_diagnoser(
    name: str,
    seeds: Sequence[int] = DIAGNOSER_SEEDS,
    n_steps: int = 3999,
    params: Mapping[str, Any] | None = None,
) -> Any:
    """Registered diagnoser ``name`` fitted on episodes run at the healthy optimum (the operation
    it will monitor): healthy ones on ``seeds`` and, on the first seed, one per sensor-fault
    kind at its default size (a diagnoser learns which kinds it names from those labels)."""
    from diagnosers import make
    from evaluation.control.policies import fixed_setpoints
    from evaluation.control.returns import operated_episodes

    if not seeds:
        raise ValueError(f"seeds={seeds!r}: allowed: at least one training seed (1000..)")
    fixed = fixed_setpoints()
    train = operated_episodes(fixed, "nominal", seeds, n_steps)
    for fault in (f for f in FAULTS if fault_class(f) is FaultClass.SENSOR):
        train += operated_episodes(fixed, fault, seeds[:1], n_steps)
    return make(name, **dict(params or {})).fit(train)


@dataclass
class SensorCorrectingSupervisor:
    """The healthy optimum; a loop judged to have a faulty transmitter runs on the soft
    sensor through its set point (module docstring)."""

    name: str = "sensor-correcting supervisor (soft sensor, frozen and residual checks)"
    diagnoser: Any = None
    frozen_samples: int = 5
    window: int = 100
    limit_C: float = 3.0
    arm_after: int = ARM_AFTER
    healthy: np.ndarray | None = None
    soft_sensor: SoftSensor | None = None
    #: a frozen loop that cannot be rebuilt is held at its frozen reading (module docstring)
    hold_frozen: bool = True
    _policy: SetpointPolicy = field(init=False, repr=False)
    _k: int = field(init=False, repr=False, default=0)
    _last: np.ndarray = field(init=False, repr=False)
    _repeats: np.ndarray = field(init=False, repr=False)
    _residual: np.ndarray = field(init=False, repr=False)
    _error: np.ndarray = field(init=False, repr=False)
    _latched: np.ndarray = field(init=False, repr=False)
    _judged: np.ndarray = field(init=False, repr=False)
    _correctable: np.ndarray = field(init=False, repr=False)
    _held: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        if not isinstance(self.hold_frozen, (bool, np.bool_)):
            raise ValueError(f"hold_frozen={self.hold_frozen!r}: allowed: True or False")
        if self.healthy is None:
            self.healthy = best_setpoints().setpoints
        if self.soft_sensor is None:
            self.soft_sensor = SoftSensor.fit()
        if isinstance(self.diagnoser, str):
            self.name = f"{self.name} + {self.diagnoser}"
            self.diagnoser = fit_sensor_diagnoser(self.diagnoser)
        if int(self.frozen_samples) < 2:
            raise ValueError(f"frozen_samples={self.frozen_samples!r}: allowed: an integer >= 2")
        if int(self.window) < 1 or not self.limit_C > 0:
            raise ValueError(
                f"window={self.window!r}, limit_C={self.limit_C!r}: allowed: window >= 1 "
                "samples, limit_C > 0 (°C)"
            )
        self._correctable = correctable_loops(self.healthy)
        self._policy = SetpointPolicy(self.name, lambda k, info: self._target())

    def reset(self, info: Mapping[str, Any]) -> None:
        self._k = 0
        self._last = np.full(2, np.nan)
        self._repeats = np.zeros(2, dtype=np.int64)
        self._residual = np.zeros(2)
        self._error = np.zeros(2)
        self._latched = np.zeros(2, dtype=bool)
        self._judged = np.zeros(2, dtype=bool)
        self._held = np.zeros(2, dtype=bool)
        if self.diagnoser is not None:
            self.diagnoser.reset()
        self._policy.reset(info)

    @property
    def judged(self) -> np.ndarray:
        """Which loop transmitters (T_rx, T_rg1) the policy judges faulty now and acts on:
        rebuilt on the soft sensor, or held at a frozen reading."""
        return self._judged | self._held

    @property
    def setpoints(self) -> np.ndarray:
        """The set points (°C, ``[T_rx_sp, T_rg1_sp]``) the policy asks for after the last
        ``act``."""
        return self._target()

    def _target(self) -> np.ndarray:
        assert self.healthy is not None
        target = self.healthy + np.where(self._judged, self._error, 0.0)
        return np.where(self._held, np.clip(self._last, _SP_LOW, _SP_HIGH), target)

    def act(self, obs: np.ndarray, info: Mapping[str, Any]) -> np.ndarray:
        assert self.soft_sensor is not None
        y = np.asarray(obs, dtype=np.float64)
        reading = y[_LOOP_INDEX]
        self._repeats = np.where(reading == self._last, self._repeats + 1, 0)
        self._last = reading
        error = reading - self.soft_sensor.estimate(y)
        self._k += 1
        # the soft sensor's noise is filtered a little for the loop, more for the test
        self._error = error if self._k == 1 else 0.7 * self._error + 0.3 * error
        if self._k > self.arm_after:
            self._residual += (error - self._residual) / self.window
        else:
            self._residual = np.zeros(2)
        if self.diagnoser is not None and self._k > self.arm_after:
            if self._k == self.arm_after + 1:
                self.diagnoser.reset()  # its training records start here
            decision = self.diagnoser.update(y)
            if decision.alarm and _names_sensor_fault(str(decision.diagnosis)):
                named = str(getattr(self.diagnoser, "named_sensor", ""))
                if named in LOOP_CHANNELS:
                    self._latched[LOOP_CHANNELS.index(named)] = True
                elif not named:
                    self._latched[int(np.argmax(np.abs(self._residual)))] = True
        frozen = self._repeats >= self.frozen_samples - 1
        judged = frozen | (np.abs(self._residual) > self.limit_C) | self._latched
        self._judged = judged & self._correctable
        self._held = frozen & ~self._correctable & bool(self.hold_frozen)
        return self._policy.act(obs, info)
