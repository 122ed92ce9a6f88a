"""What ``FCC-control-v0``'s random episodes draw from: the paper's faults or the whole catalogue.

``gym.make("FCC-control-v0", catalogue="all")`` draws each episode's fault from every
registered fault (issue 43 item 7): the control task then meets the faults a closed loop
suffers (a biased or stuck thermocouple the loop follows, a sticking valve, a weak blower), not
only the paper's process faults. ``catalogue="paper"`` (the default) keeps today's draw
(:meth:`fcc_env.scenarios.FaultSpec.resolve`, ``scenario="random"``) bit for bit.

The draw of ``"all"`` (:func:`draw_catalogue_fault`), in this order, each uniform:

1. the fault **class** (:class:`FaultClass`): healthy, process (f1–f4 and any parameter fault
   registered since), sensor, actuator. By class, not by scenario, so that each class carries
   a quarter of the episodes and its value of information an interval of the same width (by
   scenario, the five sensor faults would outweigh the one healthy plant five to one);
2. the **scenario** within the class (read from the registry at each draw: a fault registered
   since joins its class), but for the faults of :data:`LEFT_OUT`: a noisier or intermittent
   transmitter moves no steady state, so no set point (the task's action) can answer it; its
   cost falls on the loop's tuning, which the supervisory layer does not reach. They stay
   fixed scenarios (``scenario="sensor-noise"``);
3. a sensor fault's **channel**: a loop sensor (``T_rx`` or ``T_rg1``, the controlled
   temperatures whose fault moves the true process) with probability 1/2, else one of the
   other six measured channels. Drawn by channel alone, a loop sensor would come one time in
   four, and the faults that matter to control would be the rare ones;
4. the **onset**, in the middle half of the horizon, and the **size**, ``[0.5, 1.5] ×`` the
   fault's default clipped at its validated largest size, as ``scenario="random"`` draws them.

Every draw consumes the same numbers, so that the episode's noise never depends on the fault.
The draw reads a generator of its own (the env spawns it from its ``np_random``): the plant's
noise and program stay those of the same seed under any fixed fault.

``catalogue="sensor"`` is the same draw over two classes only, healthy and sensor (each half
of the episodes; then the scenario, the channel, the onset and the size as above): the issue's
"sensor-fault scenarios" as a training draw. It is what the native vector env
(:class:`fcc_env.control_vector.FCCControlVectorEnv`) carries besides the paper's draw: its
compiled loop has the sensor faults' transmitter (:mod:`fcc_env.sensor_kernel`) but no
actuator device, so ``"all"`` (a quarter of it actuator faults) runs on Python envs only
(``vectorization_mode="sync"``). Why a catalogue of its own rather than ``"all"`` with the
actuator draws skipped: that would be a different draw under the same name on the two paths.
"""

from __future__ import annotations

from collections.abc import Mapping
from enum import StrEnum
from typing import Any

import numpy as np

from fcc_common.validation import Options, check, invalid
from fcc_env.faults import FAULTS, NOMINAL, RANDOM_SCENARIO, fault_definition
from fcc_env.scenarios import FaultSpec

__all__ = [
    "CATALOGUES",
    "DRAWN_FIELDS",
    "LEFT_OUT",
    "LOOP_CHANNELS",
    "FaultClass",
    "catalogue_classes",
    "catalogue_option",
    "check_drawn_fields",
    "class_scenarios",
    "draw_catalogue_fault",
    "draws_random",
    "fault_class",
]

#: The catalogues a random episode draws from: the paper's faults (today's draw), all, or the
#: healthy plant and the sensor faults.
CATALOGUES: tuple[str, ...] = ("paper", "all", "sensor")
#: Registered faults the whole catalogue's draw leaves out (module docstring: why).
LEFT_OUT: tuple[str, ...] = ("sensor-noise", "sensor-dropout")
#: The measured channels the regulatory loops control (a fault there moves the true process).
LOOP_CHANNELS: tuple[str, ...] = ("T_rx", "T_rg1")


class FaultClass(StrEnum):
    """What kind of fault an episode has (the control study's rows)."""

    HEALTHY = "healthy"
    PROCESS = "process"
    SENSOR = "sensor"
    ACTUATOR = "actuator"


def catalogue_option(value: object) -> str:
    """``value`` if it names a catalogue of :data:`CATALOGUES`, else a clear refusal."""
    return str(check("catalogue", value, Options(CATALOGUES, why="what scenario='random' draws")))


def fault_class(scenario: str) -> FaultClass:
    """The class of ``scenario`` (``"nominal"`` or a registered fault), read from its
    definition: a transmitter is a sensor fault, a device an actuator fault, the rest change
    the plant's parameters."""
    if scenario == NOMINAL:
        return FaultClass.HEALTHY
    d = fault_definition(scenario)
    if d.sensor is not None or d.channels:
        return FaultClass.SENSOR
    if d.actuator is not None:
        return FaultClass.ACTUATOR
    return FaultClass.PROCESS


def class_scenarios() -> dict[FaultClass, tuple[str, ...]]:
    """Every class's scenarios that the whole catalogue draws, from the registry as it is now
    (registration order; without :data:`LEFT_OUT`)."""
    out: dict[FaultClass, list[str]] = {c: [] for c in FaultClass}
    for name in (NOMINAL, *FAULTS):
        if name in LEFT_OUT:
            continue
        out[fault_class(name)].append(name)
    return {c: tuple(v) for c, v in out.items()}


#: The env keywords of the fault fields a catalogue draws (a fixed one would be overridden).
DRAWN_FIELDS: tuple[str, ...] = (
    "fault",
    "fault_time",
    "fault_magnitude",
    "fault_channel",
    "fault_profile",
)


def check_drawn_fields(catalogue: str, kwargs: Mapping[str, Any]) -> None:
    """Refuse env keywords ``kwargs`` that fix a field ``catalogue`` draws (all but
    ``"paper"`` draw the fault whole), naming them."""
    fixed = [k for k, v in kwargs.items() if k in DRAWN_FIELDS and v is not None]
    if catalogue != "paper" and fixed:
        raise invalid(
            "catalogue",
            catalogue,
            "'paper' with fixed fault fields",
            f"catalogue={catalogue!r} draws the fault whole; {fixed} would be ignored",
        )


def catalogue_classes(catalogue: str) -> tuple[FaultClass, ...]:
    """The fault classes ``catalogue`` (``"all"`` or ``"sensor"``) draws, in draw order."""
    if catalogue_option(catalogue) == "sensor":
        return (FaultClass.HEALTHY, FaultClass.SENSOR)
    if catalogue == "all":
        return tuple(FaultClass)
    raise invalid("catalogue", catalogue, "'all' or 'sensor'", "'paper' draws through FaultSpec")


def draws_random(options: Mapping[str, Any] | None, make_scenario: str) -> bool:
    """True when a reset's fault is ``scenario="random"`` (the ``make`` scenario
    ``make_scenario``, or a ``reset`` option's) with no other fault field fixed: the resets
    whose fault a catalogue draws."""
    options = options or {}
    if "fault" in options:
        return options["fault"] is not None and options["fault"].scenario == RANDOM_SCENARIO
    keys = set(options) - {"plant_effects"}
    if keys - {"scenario"}:
        return False
    return options.get("scenario", make_scenario) == RANDOM_SCENARIO


def draw_catalogue_fault(
    rng: np.random.Generator, horizon: int, catalogue: str = "all"
) -> FaultSpec:
    """One episode's fault from ``catalogue``'s classes (module docstring: the draw), as a
    :class:`FaultSpec` with every field fixed."""
    by_class = class_scenarios()
    classes = [c for c in catalogue_classes(catalogue) if by_class[c]]
    # a fixed number of draws, whatever comes out
    u_class, u_scenario, u_loop, u_channel, u_scale = rng.random(5)
    onset = int(rng.integers(horizon // 4, max(horizon // 4 + 1, 3 * horizon // 4)))
    cls = classes[int(u_class * len(classes))]
    names = by_class[cls]
    scenario = names[int(u_scenario * len(names))]
    if scenario == NOMINAL:
        return FaultSpec(scenario=NOMINAL)
    d = fault_definition(scenario)
    magnitude = min(d.default_magnitude * (0.5 + u_scale), d.max_magnitude)
    channel = None
    if d.channels:
        loops = [c for c in LOOP_CHANNELS if c in d.channels]
        others = [c for c in d.channels if c not in loops]
        pool = loops if (u_loop < 0.5 and loops) or not others else others
        channel = pool[int(u_channel * len(pool))]
    return FaultSpec(scenario=scenario, onset=onset, magnitude=magnitude, channel=channel)
