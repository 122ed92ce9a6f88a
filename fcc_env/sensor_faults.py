"""Sensor faults on any measured channel (issue 43 item 1): bias, drift, stuck, noise, dropout.

Each is a registered channel fault (:mod:`fcc_env.faults`): ``FaultSpec(scenario="sensor-bias",
channel="T_rg1", magnitude=3.0)``, ``gym.make("FCC-v0", scenario="sensor-bias",
fault_channel="T_rg1")``. The fault sits in the transmitter, after the plant and the plant
effects and before the controllers read the value: under ``FCC-closedloop-v0`` a fault on T_rx
or T_rg1 (the controlled channels) moves the true process, which the loop steers to the wrong
reading. ``y_clean`` is the transmitter's noise-free reading (the fault included); the true
riser temperature stays in ``aux["T_rx"]``, the true dense-bed temperatures in the states.

=================  ===================================================  ==========  ========
scenario           the channel's reading after the onset                 default     largest
=================  ===================================================  ==========  ========
sensor-bias        reads ``m`` high (channel unit: °C, R_ar t/h)          5           10
sensor-drift       reads ``m`` per hour of fault high, growing            1 /h        2 /h
sensor-stuck       frozen at the reading of the sample before the onset   1           1
sensor-noise       noise std × (1 + m)                                    3           20
sensor-dropout     each sample lost with probability ``m``: held          0.2         0.9
=================  ===================================================  ==========  ========

``m`` grows over ``ramp_samples`` for an incipient profile, as for every fault
(:meth:`~fcc_env.scenarios.EpisodeFault.fraction`); a stuck transmitter of ``m < 1`` follows
the process with gain ``1 − m`` around the frozen value.

**Dropouts appear as a DCS shows them: the last good value held, with a flag.** A lost sample
repeats the channel's last delivered reading (its noise-free value and its noise draw, so the
observation repeats bit for bit), and ``info["sensor_dropout"]`` (env) or
:attr:`fcc_env.BatchResult.sensor_dropout` (batch) is True for it. Observations are never NaN,
so every diagnoser's input path (``diagnosers.Episode`` refuses NaN) takes them unchanged; a
method that wants the flag reads it beside the observation.

**Label.** An episode's label for isolation is the scenario name (``sensor-bias``); the channel
is a field of its own (:attr:`~fcc_env.scenarios.EpisodeFault.channel`, ``info["fault_channel"]``,
:attr:`fcc_env.BatchResult.fault_channels`), so labels stay the registry's names.

**Sizes.** The largest sizes were measured in closed loop on the controlled channels (the only
ones where a sensor fault reaches the process) on training seeds 1000–1009, 4000 samples, onset
at 2000, against the healthy twins (none terminated): ``lab/sensor_fault_envelope.py`` (the
``max_reason`` of each definition quotes its result). On the other channels the fault changes
no process value; the same limit holds for them so that one range names a kind. A fully stuck
*controlled* transmitter is the exception: it opens its loop, the integral winds up and the
plant leaves its envelope (measured below); that is what the fault does to a real unit too
(it trips), so the env ends the episode as for any other excursion, after some hundreds of
samples a diagnoser has to name it.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from fcc_common.validation import invalid
from fcc_env.faults import FaultDefinition, path_fault, register_fault
from fcc_env.params import MEASUREMENT_NAMES
from fcc_env.sensor_kernel import NATIVE_SENSOR_KINDS, NO_SENSOR, sensor_read

__all__ = ["SENSOR_FAULTS", "ChannelSensor", "compiled_transmitter"]

#: The channel a sensor fault acts on when the request names none: the riser outlet
#: thermocouple, the controlled temperature a biased reading steers away from its set point.
DEFAULT_CHANNEL = "T_rx"


class ChannelSensor:
    """One episode's faulty transmitter on one channel (a :class:`fcc_env.faults.SensorPath`).

    ``kind``: ``bias``, ``drift``, ``stuck``, ``noise`` or ``dropout``. The held values (stuck,
    dropout) live here, per episode, because :meth:`read` sees the samples in order. Every kind
    but the dropout reads through the compiled :func:`fcc_env.sensor_kernel.sensor_read`, the
    formula the native vector env runs too.
    """

    def __init__(
        self, kind: str, fault, rng: np.random.Generator, horizon: int, sample_time_s: float
    ):
        self.kind = kind
        self.fault = fault
        self.ch = fault.channel_index
        self.hours_per_sample = sample_time_s / 3600.0
        # the dropout draws: one uniform per sample of the episode, from the fault's own stream
        self.lost_draw = rng.random(horizon) if kind == "dropout" else None
        self.last: tuple[float, float] | None = None  # the last delivered (y, z) of the channel
        self._code = NATIVE_SENSOR_KINDS.get(kind, NO_SENSOR)
        self._held = np.zeros(2)  # the compiled kinds' last delivered (y, z)
        self._has_held = False

    def dropped(self, k: int, frac: float) -> bool:
        draw = self.lost_draw
        return (
            draw is not None and k < draw.shape[0] and bool(draw[k] < self.fault.magnitude * frac)
        )

    def read(self, k: int, y: np.ndarray, z: np.ndarray) -> tuple[np.ndarray, np.ndarray, bool]:
        y = np.array(y, dtype=np.float64, copy=True)
        z = np.array(z, dtype=np.float64, copy=True)
        f = self.fault
        if self._code != NO_SENSOR:
            self._has_held = sensor_read(
                self._code,
                k,
                y,
                z,
                self.ch,
                f.magnitude,
                f.onset,
                f.ramp,
                self.hours_per_sample,
                self._held,
                self._has_held,
            )
            return y, z, False
        # the dropout: the last delivered value held on a lost sample
        frac = float(f.fraction(np.asarray(k)))
        ch, lost = self.ch, False
        if self.last is not None and self.dropped(k, frac):
            y[ch], z[ch] = self.last
            lost = True
        self.last = (float(y[ch]), float(z[ch]))
        return y, z, lost


def compiled_transmitter(
    sensors: tuple[Any, ...], scenario: str
) -> tuple[int, int, float, int, int]:
    """The compiled transmitter (:func:`~fcc_env.sensor_kernel.sensor_read`) of an episode's
    ``sensors`` (:attr:`~fcc_env.episode_setup.PlantSchedule.sensors`), for the native vector
    env: ``(kind code, channel index, magnitude, onset, ramp)``, kind 0 when there is none; a
    clear refusal for what it cannot carry (a dropout, a transmitter not of this module, two
    faulty transmitters)."""
    if not sensors:
        return NO_SENSOR, 0, 0.0, -1, 0
    kinds = [getattr(s, "kind", type(s).__name__) for s in sensors]
    s = sensors[0]
    if len(sensors) > 1 or not isinstance(s, ChannelSensor) or s.kind not in NATIVE_SENSOR_KINDS:
        raise invalid(
            "scenario",
            scenario,
            f"at most one faulty transmitter of kind {sorted(NATIVE_SENSOR_KINDS)} on the "
            "native vector env",
            f"its transmitters are {kinds}: a dropout draws per sample in Python; use "
            "vectorization_mode='sync'",
        )
    f = s.fault
    return NATIVE_SENSOR_KINDS[s.kind], s.ch, float(f.magnitude), int(f.onset), int(f.ramp)


def _factory(kind: str):
    def sensor(fault, rng: np.random.Generator, horizon: int, sample_time_s: float):
        return ChannelSensor(kind, fault, rng, horizon, sample_time_s)

    sensor.__name__ = f"{kind}_sensor"
    return sensor


def _sensor_fault(
    kind: str, default: float, largest: float, unit: str, description: str, reason: str
) -> FaultDefinition:
    return path_fault(
        description,
        default=default,
        largest=largest,
        unit=unit,
        reason=reason,
        channels=MEASUREMENT_NAMES,
        default_channel=DEFAULT_CHANNEL,
        sensor=_factory(kind),
    )


#: The sensor faults by scenario name, registered when :mod:`fcc_env` is imported.
SENSOR_FAULTS: dict[str, FaultDefinition] = {
    "sensor-bias": _sensor_fault(
        "bias",
        5.0,
        10.0,
        "the channel's unit: °C, R_ar t/h",
        "the transmitter reads high by a constant",
        "in closed loop the T_rx loop holds the true riser outlet m below its set point (the "
        "T_rg1 loop the regenerator): at 10 °C no episode of 10 training seeds leaves the "
        "envelope on either loop; at 15 °C on T_rx 1 in 10 ends in an afterburn, at 20 °C 5 in "
        "10",
    ),
    "sensor-drift": _sensor_fault(
        "drift",
        1.0,
        2.0,
        "°C (R_ar t/h) per hour of fault",
        "the transmitter's reading drifts upwards",
        "at 2 /h from sample 2000 the reading is 11 °C high by sample 4000 and no episode of 10 "
        "training seeds leaves the envelope on either loop; at 5 /h on T_rx 8 in 10 end in an "
        "afterburn (the drift then passes the bias's limit of 10 °C)",
    ),
    "sensor-stuck": _sensor_fault(
        "stuck",
        1.0,
        1.0,
        "the share of the reading frozen: 1 fully stuck",
        "the transmitter freezes at the reading before the onset",
        "1 is a fully frozen transmitter: harmless to the process on an uncontrolled channel; "
        "on a controlled one in closed loop it opens the loop and the plant leaves its envelope "
        "(T_rx: 8 in 10 training seeds, afterburn 219–643 samples after the onset; T_rg1: 10 in "
        "10, afterburn or extinguished 279–1013 samples after), while half-frozen (0.5) none "
        "does",
    ),
    "sensor-noise": _sensor_fault(
        "noise",
        3.0,
        20.0,
        "added noise std, in multiples of the channel's own",
        "the transmitter's noise grows",
        "at 20 the channel's noise std is 21 × its own (6.3 °C on a thermocouple) and no episode "
        "of 10 training seeds leaves the envelope on either loop (the true T_rx swings 8 °C at "
        "most); beyond it the reading carries no more information than its own noise",
    ),
    "sensor-dropout": _sensor_fault(
        "dropout",
        0.2,
        0.9,
        "probability that a sample is lost (held)",
        "the transmitter's samples are intermittently lost; the DCS holds the last good value",
        "at 0.9 no episode of 10 training seeds leaves the envelope on either loop (the held T_rx "
        "lets the true riser outlet swing up to 80 °C low at times, 3 °C at 0.5); beyond it the "
        "channel is a dead transmitter, sensor-stuck",
    ),
}

for _name, _definition in SENSOR_FAULTS.items():
    register_fault(_name, _definition)
