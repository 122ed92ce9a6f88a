"""Actuator faults (issue 43 item 2): a sticking, biased or stuck slide valve; a weaker blower.

Each is a registered actuator fault (:mod:`fcc_env.faults`): ``FaultSpec(scenario=
"valve-stiction", magnitude=0.03)``, ``gym.make("FCC-closedloop-v0", scenario="valve-bias")``.
The fault sits between the command and the process: the controllers (or, in open loop, the
operating program and the action) command an input, the faulty device delivers another.
``info["inputs"]`` and :attr:`fcc_env.BatchResult.inputs` hold what the process received; the
closed-loop observation's ``u_F`` stays the controller's *command*, as a DCS records its output
(the valve's true position is not measured, as on most units).

=================  =====================================================  =========  =======
scenario           after the onset                                         default    largest
=================  =====================================================  =========  =======
valve-stiction     the regenerated-catalyst slide valve sticks: S = m of   0.02       0.3
                   its range, slip jump J = S/2 (:mod:`fcc_env.stiction`)
valve-bias         the valve passes m × nominal u_F more than commanded    0.05       0.2
valve-stuck        frozen where it stood before the onset (m: share of     1          1
                   the command's moves lost; 1 fully stuck)
blower-capacity    the air flow capped at (1 − m) × the blower's capacity  0.12       0.12
                   (1.15 × nominal R_ar, the air loop's upper limit)
=================  =====================================================  =========  =======

``m`` grows over ``ramp_samples`` for an incipient profile, as for every fault. The valve's
range is its travel between the actuator limits (u_F 0.5–1.5 × nominal: 416.7 kg/s), so
S = 0.02 is 8.3 kg/s of command, about 2 °C of riser outlet.

**Stiction: the model.** Choudhury, Thornhill & Shah (2005), "Modelling valve stiction",
*Control Engineering Practice* 13, 641–658: two parameters, S (deadband plus stickband) and J
(slip jump), :class:`fcc_env.stiction.StictionValve`. The scenario fixes J = S/2, the paper's
undershoot case (J < S), the one of most sticky valves; another ratio is a registered fault
of its own: ``register_fault("valve-deadband", valve_stiction_definition(jump_ratio=0.0))``.
Under the T_rx loop it makes the limit cycle the stiction literature describes: the integral
ramps the command, the valve slips, T_rx overshoots, the integral reverses (``lab/
actuator-faults.md``: period and amplitude).

**Open loop** (``FCC-v0``). The valve and the air are inputs there, commanded by the operating
program and the action, and the faults act on them the same way: ``valve-bias`` shifts the
valve's flow, ``blower-capacity`` clips the program's air steps at the ceiling. A stuck or
sticking valve needs something that moves the valve, and in open loop nothing does (the program
holds it): ``valve-stiction`` and ``valve-stuck`` are refused there, and on any plant whose
regulatory layer leaves the T_rx loop open, with the reason.

**Labels.** An episode's label for isolation is the scenario name; the actuator is the kind's
own (``u_F`` for the valve faults, ``R_ar`` for the blower: :attr:`FaultDefinition.actuator_input
<fcc_env.faults.FaultDefinition>`), so the request takes no channel.

**Sizes.** The largest sizes were measured on training seeds 1000–1019 (4000 samples, onset
2000) in closed loop and, for the two faults open loop accepts, in open loop as well:
``lab/actuator_fault_envelope.py``, recorded in ``lab/actuator-faults.md`` (each definition's
``max_reason`` quotes it). The blower's range is narrow by the plant's nature: below about
m = 0.10 its ceiling stays above what the air loop asks for and the fault shows nothing, and
beyond 0.12 the closed loop drives the regenerator out (a unit would cut feed first).
"""

from __future__ import annotations

import numpy as np

from fcc_common.validation import Real, check, invalid
from fcc_env.faults import ACTUATED_INPUTS, FaultDefinition, path_fault, register_fault
from fcc_env.params import INPUT_NAMES, NOMINAL_INPUTS
from fcc_env.regulatory import ACTUATOR_LIMITS, LOOP_NAMES, RegulatoryLayer
from fcc_env.stiction import StictionValve

__all__ = [
    "ACTUATOR_FAULTS",
    "ActuatorDevice",
    "require_loops",
    "valve_stiction_definition",
]

#: The slide valve's range (kg/s): its travel between the actuator limits.
VALVE_RANGE = float(ACTUATOR_LIMITS[0, 1] - ACTUATOR_LIMITS[0, 0])
#: The blower's capacity (t/h): the air loop's upper limit.
BLOWER_CAPACITY = float(ACTUATOR_LIMITS[1, 1])
#: The slip jump of ``valve-stiction`` as a share of S (the undershoot case, J < S).
DEFAULT_JUMP_RATIO = 0.5


class ActuatorDevice:
    """One episode's faulty actuator (a :class:`fcc_env.faults.ActuatorPath`).

    ``kind``: ``stiction``, ``bias``, ``stuck`` or ``capacity``. The device sees every sample
    from the start, so a stuck valve knows where it stood before the onset and a sticking one
    where it came to rest; a repeated call for the same sample starts again from the state
    before it (the open-loop env asks twice per sample).
    """

    def __init__(self, kind: str, fault, jump_ratio: float = DEFAULT_JUMP_RATIO) -> None:
        self.kind = kind
        self.fault = fault
        self.jump_ratio = jump_ratio
        self.j = INPUT_NAMES.index(str(fault.definition.actuator_input))
        self.low, self.high = ACTUATOR_LIMITS[ACTUATED_INPUTS.index(INPUT_NAMES[self.j])]
        self.k_last = -1
        self.state: tuple[float, StictionValve | None] = (np.nan, None)  # (last position, valve)
        self.before = self.state

    def _state_copy(self) -> tuple[float, StictionValve | None]:
        held, valve = self.state
        return held, None if valve is None else valve.copy()

    def move(self, k: int, u: np.ndarray) -> np.ndarray:
        if k == self.k_last:
            self.state = self.before
        self.before, self.k_last = self._state_copy(), k
        out = np.array(u, dtype=np.float64, copy=True)
        command = float(out[self.j])
        frac = float(self.fault.fraction(np.asarray(k)))
        m = self.fault.magnitude * frac
        held, valve = self.state
        if not np.isfinite(held):  # a fault from the first sample: the valve stands as commanded
            held = command
        position = command
        if frac and self.kind == "bias":
            position = command + m * float(NOMINAL_INPUTS[self.j])
        elif frac and self.kind == "capacity":
            position = min(command, (1.0 - m) * BLOWER_CAPACITY)
        elif frac and self.kind == "stuck":
            position = held + (1.0 - m) * (command - held)
        elif frac and self.kind == "stiction":
            if valve is None:  # the valve comes to rest where it stands at the onset
                valve = StictionValve(held)
            s = m * VALVE_RANGE
            position = valve.move(command, s, self.jump_ratio * s)
        position = min(max(position, self.low), self.high)  # within the valve's travel
        if self.kind != "stuck" or not frac:
            held = position  # stuck: the position before the onset stays
        self.state = (held, valve)
        out[self.j] = position
        return out


def _factory(kind: str, jump_ratio: float = DEFAULT_JUMP_RATIO):
    def actuator(fault, horizon: int, sample_time_s: float) -> ActuatorDevice:
        return ActuatorDevice(kind, fault, jump_ratio)

    actuator.__name__ = f"{kind}_actuator"
    return actuator


def require_loops(fault, regulatory: RegulatoryLayer | None) -> None:
    """Refuse ``fault`` (an :class:`~fcc_env.scenarios.EpisodeFault`, concurrent ones part by
    part) on a plant whose regulatory layer does not close the loop that moves an actuator
    the fault needs moved (a stuck or sticking valve: module docstring)."""
    loops = () if regulatory is None else regulatory.loops
    for part in fault.components:
        d = part.definition
        if not d.needs_loop:
            continue
        loop = LOOP_NAMES[ACTUATED_INPUTS.index(d.actuator_input)]
        if loop not in loops:
            mode = "open loop" if regulatory is None else f"loops={loops}"
            raise invalid(
                "scenario",
                part.scenario,
                f"a fault the plant can show: {part.scenario} acts on the {d.actuator_input} "
                f"actuator, which only the {loop} loop moves",
                f"the plant runs {mode}, so the fault would change nothing; use "
                "FCC-closedloop-v0 (regulatory=True) with that loop closed",
            )


def _actuator_fault(
    kind: str,
    actuator_input: str,
    default: float,
    largest: float,
    unit: str,
    description: str,
    reason: str,
    *,
    needs_loop: bool = False,
    jump_ratio: float = DEFAULT_JUMP_RATIO,
) -> FaultDefinition:
    return path_fault(
        description,
        default=default,
        largest=largest,
        unit=unit,
        reason=reason,
        actuator=_factory(kind, jump_ratio),
        actuator_input=actuator_input,
        needs_loop=needs_loop,
    )


def valve_stiction_definition(
    jump_ratio: float = DEFAULT_JUMP_RATIO,
    default: float = 0.02,
    largest: float = 0.3,
    reason: str = "",
) -> FaultDefinition:
    """A slide-valve stiction fault with slip jump J = ``jump_ratio`` × S (0: a pure deadband;
    1: no offset; above 1: overshoot), magnitude S as a share of the valve's range; register
    it under a name of its own (module docstring). ``reason``: why ``largest`` (measured)."""
    ratio = check("jump_ratio", jump_ratio, Real(0.0, 4.0, why="J / S of the stiction model"))
    return _actuator_fault(
        "stiction",
        "u_F",
        default,
        largest,
        "S, share of the valve's range (u_F 0.5–1.5 × nominal, 416.7 kg/s)",
        f"the regenerated-catalyst slide valve sticks (Choudhury et al. 2005; J = {ratio:g} S)",
        reason or "measured for J = S/2 (lab/actuator-faults.md); measure another ratio's",
        needs_loop=True,
        jump_ratio=ratio,
    )


#: The actuator faults by scenario name, registered when :mod:`fcc_env` is imported.
ACTUATOR_FAULTS: dict[str, FaultDefinition] = {
    "valve-stiction": valve_stiction_definition(
        largest=0.3,
        reason="the T_rx loop cycles (about 10 min a period; |T_rx − set point| 95th percentile "
        "1.3 °C at 0.02, 4.3 °C at 0.1, 12.8 °C at 0.3, against 1.0 °C healthy) and no episode "
        "of 20 training seeds leaves the envelope up to 0.5; from 0.5 the band reaches the "
        "valve's travel limits and some episodes stop cycling, so the range stops at 0.3",
    ),
    "valve-bias": _actuator_fault(
        "bias",
        "u_F",
        0.05,
        0.2,
        "share of the nominal valve flow (416.7 kg/s)",
        "the slide valve passes more catalyst than commanded",
        "in closed loop the T_rx loop takes a bias out up to 0.45 (its command drops by it; no "
        "episode of 20 training seeds leaves the envelope); in open loop the regenerator cools "
        "by about 8 °C per 0.05, and at 0.3 1 in 20 episodes is extinguished (7 in 20 at 0.4), "
        "none at 0.2",
    ),
    "valve-stuck": _actuator_fault(
        "stuck",
        "u_F",
        1.0,
        1.0,
        "share of the command's moves lost (1: fully stuck)",
        "the slide valve freezes where it stood before the onset",
        "1 is a seized valve: the T_rx loop is open and the riser outlet wanders from its set "
        "point (|T_rx − set point| 95th percentile 8 °C, median of 20 training seeds), but the "
        "air loop holds the regenerator and no episode leaves the envelope",
        needs_loop=True,
    ),
    "blower-capacity": _actuator_fault(
        "capacity",
        "R_ar",
        0.12,
        0.12,
        "share of the blower's capacity lost (1.15 × nominal R_ar, 170.7 t/h)",
        "the air blower loses capacity: the air flow is capped lower",
        "in closed loop the air loop asks for up to about 1.03 × nominal; capped lower, the "
        "regenerator runs short of air, the T_rx loop feeds it more catalyst and it goes out: "
        "at 0.13 2 in 20 training seeds are extinguished, at 0.14 and 0.15 all 20 (at 0.15 "
        "540–1040 samples after the onset), at 0.12 none (T_rg1 2.3 °C low); open loop carries "
        "0.15, not 0.2",
    ),
}

for _name, _definition in ACTUATOR_FAULTS.items():
    register_fault(_name, _definition)
