"""The fault registry: every fault the plant can be asked for, written in one place.

:data:`FAULTS` maps a fault's name to its :class:`FaultDefinition`; the paper's four faults
(Section 5.3, after Sotomayor et al. 2004) are registered here when the module is imported, and
:func:`register_fault` adds another (validated once, there). Everything that lists the faults
(:class:`~fcc_env.scenarios.FaultSpec`'s allowed names, ``scenario="random"``'s draw, the
tracks, the harness's data sources, the closed-loop report, ``lrgf-glr``'s fault directions
through the labelled episodes the harness passes) reads :func:`fault_names` when it runs, so a
registered fault flows through all of them.

=========  ====================================  ================  ================
scenario   parameter change                       default onset     magnitude
=========  ====================================  ================  ================
nominal    none                                   –                 –
f1         catalyst density ρ_b × (1 + m)          1900              m = 0.10
f2         weir constants K_w1, K_w2 × (1 − m)     1900              m = 0.15
f3         CO2/CO ratio constant k_σ × (1 − m)     2020              m = 0.10
f4         reactor holdup set point × (1 + m)      2000              m = 0.05
=========  ====================================  ================  ================

**Scenario and the registry.** A ``StrEnum`` cannot grow at run time, so :class:`Scenario`
stays what it was, the paper's five scenarios, for code that names one of them
(``Scenario.F1``); the registry is keyed by the name as a plain ``str`` (a ``Scenario`` member
is that ``str``, so ``FAULTS[Scenario.F1]`` still works), and a resolved fault
(:class:`~fcc_env.scenarios.EpisodeFault`) carries the name as a ``str``. Code that means "every
fault" reads :func:`fault_names`, never ``Scenario``.

**What a fault acts on.** A fault scales plant parameters (``parameters``, ``direction``: one
multiplier ``1 ± m`` on each, any number of them; the simulator's parameter slots grow to the
widest registered fault, :func:`fault_width`), and/or acts on the measurement or the actuator
path through hooks that mirror the plant effects' (:mod:`fcc_env.effects`):

* ``measure(fault, k, y) -> y'``: ``fault`` the episode's
  :class:`~fcc_env.scenarios.EpisodeFault` (onset, magnitude, how far it has developed:
  :meth:`~fcc_env.scenarios.EpisodeFault.fraction`), ``k`` the
  sample, ``y`` the noise-free measurements of that sample (shape ``(8,)``) after the plant
  effects, before the noise. No state: batch simulation interleaves its episodes' samples. The
  controllers of a closed-loop plant read its output.
* ``transform_inputs(fault, k, u) -> u'``: samples ``k`` ``(n,)`` and the program's inputs
  ``(n, 6)`` (:data:`fcc_env.INPUT_NAMES`) the process sees, after the input effects. In closed
  loop the controllers' outputs replace the valve and air columns afterwards (an actuator
  fault acts after them: below).

**Channel faults** (:mod:`fcc_env.sensor_faults`: ``sensor-bias``, ``sensor-drift``,
``sensor-stuck``, ``sensor-noise``, ``sensor-dropout``) act on one measured channel that the
request names (:attr:`~fcc_env.scenarios.FaultSpec.channel`, among the definition's
``channels``). Their ``sensor`` factory builds one :class:`SensorPath` per episode, so a held
value (stuck, dropout) lives with its episode, never in a shared hook; its ``read(k, y, z)``
takes the sample's noise-free measurements and the noise's standard-normal draws and returns
both as the transmitter delivers them, with the dropout flag. Their magnitudes are in the
kind's own unit (°C, °C per hour, a multiple of the noise std, a probability), so their
``max_magnitude`` is not bound by :data:`MAX_FAULT_MAGNITUDE`. The process-fault lists
(:func:`fault_names`, :func:`scenario_names`, ``scenario="random"``'s draw, the process
tracks' defaults, the control study's default, the closed-loop report) leave them out;
``fault_names(include_path_faults=True)`` lists them too, and the tracks ``sensor``,
``actuator`` and ``concurrent`` and the control task's ``catalogue="all"`` use that list.

**Actuator faults** (:mod:`fcc_env.actuator_faults`: ``valve-stiction``, ``valve-bias``,
``valve-stuck``, ``blower-capacity``) act on one input, their ``actuator_input`` (``u_F`` or
``R_ar``), between the command and the process. Their ``actuator`` factory builds one
:class:`ActuatorPath` per episode (a sticking valve's state lives with its episode); its
``move(k, u)`` takes the inputs as commanded (the controllers', or the program's and the
action's in open loop) and returns those the process receives. ``needs_loop`` marks a fault
that only shows while a controller moves the actuator (a stuck or sticking valve): a plant
whose regulatory layer leaves that loop open refuses it by name. Their magnitudes are in
their own unit too (``magnitude_unit``), and the process-fault lists leave them out like the
channel faults (``fault_names(include_path_faults=True)`` lists every registered fault).

**Concurrent faults** (``concurrent``, a reserved scenario name like ``random``, not a
registry entry): two registered faults, each a whole
:class:`~fcc_env.scenarios.FaultSpec` with its own onset, in
:attr:`~fcc_env.scenarios.FaultSpec.parts`. The episode's fault has both, in onset order, and
each acts through its own definition (parameter slots side by side, hooks one after the
other). Labels: the scenario is ``concurrent`` and its onset the first part's, so detection
scores against the first fault; for isolation the episode carries both names
(:attr:`~fcc_env.scenarios.EpisodeFault.labels`, ``info["fault_labels"]``,
:attr:`fcc_env.BatchResult.fault_labels`), and an isolator must name both or say
``"unknown"`` (:func:`isolation_outcome`: one name of the two is a wrong isolation).

A worker process sees the faults registered by the modules it imports: register a fault at the
import of a module and name it with ``--import`` (as for diagnosers).
"""

from __future__ import annotations

import re
from collections.abc import Callable, Collection
from dataclasses import dataclass
from enum import StrEnum
from typing import Any, Protocol

import numpy as np

from fcc_common.validation import Integer, Options, Real, check, invalid
from fcc_env.params import MEASUREMENT_NAMES, PARAM_INDEX

__all__ = [
    "CONCURRENT_SCENARIO",
    "FAULTS",
    "MAX_FAULT_MAGNITUDE",
    "NOMINAL",
    "PAPER_FAULTS",
    "RANDOM_SCENARIO",
    "UNKNOWN_LABEL",
    "ActuatorFactory",
    "ActuatorPath",
    "FaultDefinition",
    "InputHook",
    "MeasureHook",
    "Scenario",
    "SensorFactory",
    "SensorPath",
    "fault_definition",
    "fault_names",
    "fault_width",
    "has_own_unit",
    "is_actuator_fault",
    "is_channel_fault",
    "isolation_outcome",
    "path_fault",
    "register_fault",
    "scenario_names",
    "unregister_fault",
]


class Scenario(StrEnum):
    """The paper's scenarios (module docstring: the registry holds every fault)."""

    NOMINAL = "nominal"
    F1 = "f1"
    F2 = "f2"
    F3 = "f3"
    F4 = "f4"


#: The healthy scenario's name.
NOMINAL: str = Scenario.NOMINAL.value
#: The scenario name that draws scenario, onset and magnitude per episode.
RANDOM_SCENARIO = "random"
#: The scenario name of two registered faults at once, each with its own onset
#: (:attr:`fcc_env.scenarios.FaultSpec.parts`; module docstring).
CONCURRENT_SCENARIO = "concurrent"
#: The paper's faults, in order (the published tracks hold these).
PAPER_FAULTS: tuple[str, ...] = tuple(s.value for s in Scenario if s is not Scenario.NOMINAL)
#: Upper bound on fault magnitudes: beyond it the plant leaves the hot state (f2 at 100 % stops flow).
MAX_FAULT_MAGNITUDE = 0.9

# (the first argument is a fcc_env.scenarios.EpisodeFault, which imports this module: Any here)
#: ``measure(fault, k, y) -> y'`` (module docstring)
MeasureHook = Callable[[Any, int, np.ndarray], np.ndarray]
#: ``transform_inputs(fault, k, u) -> u'`` (module docstring)
InputHook = Callable[[Any, np.ndarray, np.ndarray], np.ndarray]


class SensorPath(Protocol):
    """One episode's faulty transmitter (a channel fault's per-episode object).

    ``read`` is called once per sample, in order: ``y`` the noise-free measurements ``(8,)``
    after the effects, ``z`` the noise's standard-normal draws ``(8,)``; it returns both as the
    transmitter delivers them (the noise is added afterwards, so a reading that repeats ``y``
    and ``z`` repeats the observation bit for bit) and whether the sample was a dropout."""

    def read(self, k: int, y: np.ndarray, z: np.ndarray) -> tuple[np.ndarray, np.ndarray, bool]:
        """Sample ``k``'s ``(y', z', dropped)``."""
        ...


#: ``sensor(fault, rng, horizon, sample_time_s) -> SensorPath``: one per episode; ``rng`` the
#: episode's fault stream (after the scenario's draws), ``horizon`` its samples.
SensorFactory = Callable[[Any, np.random.Generator, int, float], SensorPath]


class ActuatorPath(Protocol):
    """One episode's faulty actuator (an actuator fault's per-episode object).

    ``move`` is called once per sample, in order (a repeated call for the same sample
    recomputes it from the state before that sample): ``u`` the inputs ``(6,)`` as commanded
    (the program, the action or the controllers, within the actuator limits); it returns the
    inputs the process receives."""

    def move(self, k: int, u: np.ndarray) -> np.ndarray:
        """Sample ``k``'s applied inputs."""
        ...


#: ``actuator(fault, horizon, sample_time_s) -> ActuatorPath``: one per episode.
ActuatorFactory = Callable[[Any, int, float], ActuatorPath]


@dataclass(frozen=True)
class FaultDefinition:
    """One fault: which parameters it scales (or which path its hooks act on), its paper size
    and onset, and the largest size the plant carries (``max_magnitude``, with the physical
    reason). Checked by :func:`register_fault`."""

    parameters: tuple[str, ...]  # FCCParams fields scaled by the fault (may be empty)
    direction: int  # +1: parameter grows, -1: parameter shrinks
    default_magnitude: float
    default_onset: int
    description: str
    max_magnitude: float
    max_reason: str
    #: the measurement path: ``measure(fault, k, y) -> y'``, or None
    measure: MeasureHook | None = None
    #: the actuator path: ``transform_inputs(fault, k, u) -> u'``, or None
    transform_inputs: InputHook | None = None
    #: a channel fault: the measured channels it may act on (empty: it takes no channel)
    channels: tuple[str, ...] = ()
    #: a channel fault's channel when the request names none
    default_channel: str | None = None
    #: a channel fault's transmitter, one per episode (module docstring), or None
    sensor: SensorFactory | None = None
    #: a channel or actuator fault's unit of ``magnitude`` (the others: a relative change)
    magnitude_unit: str = "relative change"
    #: an actuator fault's device, one per episode (module docstring), or None
    actuator: ActuatorFactory | None = None
    #: an actuator fault's input (:data:`fcc_env.INPUT_NAMES`: ``u_F`` or ``R_ar``)
    actuator_input: str | None = None
    #: True when only a controller moves the actuator enough for the fault to act (a stuck or
    #: sticking valve): refused on a plant whose regulatory layer does not close that loop
    needs_loop: bool = False


#: The registry: every fault by name, in registration order (:func:`register_fault`).
FAULTS: dict[str, FaultDefinition] = {}

_NAME = re.compile(r"[a-z][a-z0-9_-]*\Z")
_RESERVED = (NOMINAL, RANDOM_SCENARIO, CONCURRENT_SCENARIO)
#: The inputs an actuator fault may act on: the valve and the air, which the loops move.
ACTUATED_INPUTS: tuple[str, ...] = ("u_F", "R_ar")


def path_fault(
    description: str,
    *,
    default: float,
    largest: float,
    unit: str,
    reason: str,
    onset: int = 2000,
    **path: Any,
) -> FaultDefinition:
    """A fault on the measurement or actuator path (it scales no parameter): its size in
    ``unit``, ``default`` and ``largest`` (``reason``: why, measured), and its hooks in
    ``path`` (``sensor`` with ``channels``, or ``actuator`` with ``actuator_input``; the
    :class:`FaultDefinition` fields). The sensor and actuator catalogues build theirs here."""
    return FaultDefinition(
        (),
        +1,
        default,
        onset,
        description,
        max_magnitude=largest,
        max_reason=reason,
        magnitude_unit=unit,
        **path,
    )


def own_unit(d: FaultDefinition) -> bool:
    """True when ``d``'s magnitude is in a unit of its own (a channel or actuator fault), not a
    relative change bound by :data:`MAX_FAULT_MAGNITUDE`."""
    return bool(d.channels) or d.actuator is not None


def _check_definition(name: str, d: FaultDefinition) -> None:
    if not isinstance(d, FaultDefinition):
        raise invalid("definition", d, "a fcc_env.FaultDefinition")
    params = d.parameters
    if isinstance(params, str) or not isinstance(params, tuple):
        raise invalid(f"{name}.parameters", params, "a tuple of FCCParams field names")
    for p in params:
        check(f"{name}.parameters", p, Options(sorted(PARAM_INDEX)))
    if len(set(params)) != len(params):
        raise invalid(f"{name}.parameters", params, "distinct FCCParams field names")
    check(f"{name}.direction", d.direction, Options([1, -1]))
    for hook in ("measure", "transform_inputs", "sensor", "actuator"):
        fn = getattr(d, hook)
        if fn is not None and not callable(fn):
            raise invalid(f"{name}.{hook}", fn, "a callable or None")
    hooks = (d.measure, d.transform_inputs, d.sensor, d.actuator)
    if not params and all(h is None for h in hooks):
        raise invalid(
            f"{name}.parameters",
            params,
            "at least one parameter, or a measure, transform_inputs, sensor or actuator hook",
            "a fault must act on the plant somewhere",
        )
    if (d.sensor is None) != (not d.channels):
        raise invalid(f"{name}.channels", d.channels, "channels exactly when a sensor is given")
    for c in d.channels:
        check(f"{name}.channels", c, Options(MEASUREMENT_NAMES))
    if d.channels:
        check(f"{name}.default_channel", d.default_channel, Options(d.channels))
    if (d.actuator is None) != (d.actuator_input is None):
        raise invalid(
            f"{name}.actuator_input", d.actuator_input, "an input exactly when an actuator is given"
        )
    if d.actuator is not None:
        check(f"{name}.actuator_input", d.actuator_input, Options(ACTUATED_INPUTS))
    elif d.needs_loop:
        raise invalid(f"{name}.needs_loop", d.needs_loop, "False for a fault without an actuator")
    # a channel or actuator fault's size is in its own unit (module docstring)
    top_range = Real(0.0) if own_unit(d) else Real(0.0, MAX_FAULT_MAGNITUDE)
    top = check(f"{name}.max_magnitude", d.max_magnitude, top_range)
    check(f"{name}.default_magnitude", d.default_magnitude, Real(0.0, top))
    check(f"{name}.default_onset", d.default_onset, Integer(0))
    for text in ("description", "max_reason"):
        value = getattr(d, text)
        if not isinstance(value, str) or not value.strip():
            raise invalid(f"{name}.{text}", value, "a non-empty string")


def register_fault(name: str, definition: FaultDefinition) -> FaultDefinition:
    """Add fault ``name`` to :data:`FAULTS`, checked once here; returns the definition.

    ``name``: lowercase letters, digits, ``-`` or ``_``, starting with a letter, not
    ``nominal`` or ``random``, not registered yet. The definition must act somewhere (a
    parameter or a hook), name :class:`~fcc_env.FCCParams` fields, and keep its paper size
    within ``max_magnitude`` ≤ :data:`MAX_FAULT_MAGNITUDE`. Afterwards the fault is a scenario
    like the paper's: ``FaultSpec(scenario=name)``, ``gym.make("FCC-v0", scenario=name)``, a
    track's ``faults``.

    >>> d = FaultDefinition(("UA_1",), +1, 0.2, 1500, "stage-1 heat loss +20 %",
    ...                     max_magnitude=0.5, max_reason="an example")
    >>> register_fault("heat_loss_1", d) is d, "heat_loss_1" in fault_names()
    (True, True)
    >>> unregister_fault("heat_loss_1")
    """
    if not isinstance(name, str) or not _NAME.match(name) or name in _RESERVED:
        raise invalid(
            "name",
            name,
            "a lowercase name of letters, digits, '-' or '_'",
            f"not {' or '.join(map(repr, _RESERVED))}",
        )
    if name in FAULTS:
        raise ValueError(
            f"fault {name!r} is already registered; registered: {list(FAULTS)} (unregister_fault "
            "it first to replace it)"
        )
    _check_definition(name, definition)
    FAULTS[name] = definition
    return definition


def unregister_fault(name: str) -> None:
    """Remove a fault added by :func:`register_fault` (the paper's faults stay)."""
    if name in PAPER_FAULTS:
        raise invalid("name", name, "a fault added by register_fault", "the paper's faults stay")
    if name not in FAULTS:
        raise ValueError(f"Unknown fault {name!r}. Registered: {list(FAULTS)}")
    del FAULTS[name]


def is_channel_fault(name: str) -> bool:
    """True for a registered fault that acts on a measured channel the request names."""
    d = FAULTS.get(name)
    return d is not None and bool(d.channels)


def is_actuator_fault(name: str) -> bool:
    """True for a registered fault that acts on an actuator (the valve or the air)."""
    d = FAULTS.get(name)
    return d is not None and d.actuator is not None


def has_own_unit(name: str) -> bool:
    """True for a registered fault whose magnitude has a unit of its own (a channel or an
    actuator fault: the definition's ``magnitude_unit``), not a relative change."""
    d = FAULTS.get(name)
    return d is not None and own_unit(d)


def fault_names(include_path_faults: bool = False) -> tuple[str, ...]:
    """The registered faults' names, in registration order (the paper's first): the process
    faults, which the catalogue-wide lists read, and with ``include_path_faults`` the faults on
    the measurement and actuator paths too (the sensor and actuator faults: every registered
    fault; the tracks ``sensor``, ``actuator`` and ``concurrent`` and the control task's
    ``catalogue="all"`` draw them)."""
    return tuple(n for n in FAULTS if include_path_faults or not has_own_unit(n))


def scenario_names(include_path_faults: bool = False) -> tuple[str, ...]:
    """``nominal`` and the registered faults of :func:`fault_names`: the scenarios an episode
    can have (``scenario="random"`` draws among those without ``include_path_faults``)."""
    return (NOMINAL, *fault_names(include_path_faults))


#: What an isolator answers when it will not name the fault(s).
UNKNOWN_LABEL = "unknown"


def isolation_outcome(predicted: str | Collection[str], labels: Collection[str]) -> str:
    """How an isolation of an episode with ``labels`` (its faults' names,
    :attr:`fcc_env.scenarios.EpisodeFault.labels`) scores: ``"correct"``, ``"unknown"`` or
    ``"wrong"``.

    ``predicted`` is a fault's name, a collection of names, or :data:`UNKNOWN_LABEL`. It is
    correct when it names exactly the episode's faults, in any order: a concurrent episode
    needs both names, and one of the two is wrong (a partial isolation sends the operator to
    one fault while the other goes on). ``"unknown"`` abstains.

    >>> isolation_outcome(["valve-stiction", "sensor-bias"], ("sensor-bias", "valve-stiction"))
    'correct'
    >>> isolation_outcome("sensor-bias", ("sensor-bias", "valve-stiction"))
    'wrong'
    >>> isolation_outcome("unknown", ("f1",)), isolation_outcome("f1", ("f1",))
    ('unknown', 'correct')
    """
    names = {predicted} if isinstance(predicted, str) else set(predicted)
    if names == {UNKNOWN_LABEL}:
        return "unknown"
    return "correct" if names == set(labels) else "wrong"


def fault_definition(name: str) -> FaultDefinition:
    """The definition of registered fault ``name``; ``ValueError`` naming the registered ones."""
    try:
        return FAULTS[name]
    except (KeyError, TypeError):
        raise ValueError(f"Unknown fault {name!r}. Registered: {list(FAULTS)}") from None


def fault_width() -> int:
    """Parameter slots of a fault in the simulator: the most parameters a registered fault
    scales (2, f2's, with the paper's faults alone)."""
    return max(len(d.parameters) for d in FAULTS.values())


# The maxima were measured on 20 excited seeds (bisection) and checked on 100 (no termination at
# the maximum except f3): the plant has a finite catalyst well (30 t free inventory) and bed levels
# fixed by the weirs, so a real unit would trip on an unsealed standpipe rather than carry the
# change. The model is not altered to hide that; the allowed range stops where it starts.
register_fault(
    Scenario.F1.value,
    FaultDefinition(
        ("rho_b",),
        +1,
        0.10,
        1900,
        "catalyst density +10 %",
        max_magnitude=0.13,
        max_reason="at weir-fixed bed levels a denser catalyst takes its extra mass from the "
        "30 t well, which unseals (below 3 t) beyond +13.9 %",
    ),
)
register_fault(
    Scenario.F2.value,
    FaultDefinition(
        ("K_w1", "K_w2"),
        -1,
        0.15,
        1900,
        "weir constant of stages 1 and 2 −15 %",
        max_magnitude=0.35,
        max_reason="higher weir crests cut the circulation; beyond −38 % the hotter regenerator "
        "pushes excited episodes into an afterburn",
    ),
)
register_fault(
    Scenario.F3.value,
    FaultDefinition(
        ("k_sigma",),
        -1,
        0.10,
        2020,
        "CO2/CO ratio constant −10 %",
        max_magnitude=0.15,
        max_reason="more CO reaches the dilute phases: from −4 % some excited episodes end in an "
        "afterburn (about 1 in 10 at the paper's −10 %, counted per cell on the leaderboard), "
        "beyond −15 % most do",
    ),
)
register_fault(
    Scenario.F4.value,
    FaultDefinition(
        ("V_rx_sp_m3",),
        +1,
        0.05,
        2000,
        "catalyst reactor holdup +5 %",
        max_magnitude=0.70,
        max_reason="the level loop moves 40 t × m of catalyst from the well into the reactor; "
        "beyond +73 % the well unseals (below 3 t)",
    ),
)
