"""The regulatory layer of a closed-loop FCC (issue 31): two decentralised PI loops and their
set-point program, as an operating mode of the plant (:class:`RegulatoryLayer`).

Every real converter runs under such a layer, and so does every benchmark process-monitoring
researchers trust (the Tennessee Eastman process; the independent FCC model of Santander et al.
2022 behind ``shared/data/fccu-santander-mlpse``). The loops:

* **T_rx → u_F**: the riser outlet temperature on the regenerated-catalyst slide valve, the
  pairing of every FCC control text. The valve moves T_rx at once (the riser is quasi-steady).
* **T_rg1 → R_ar**: the stage-1 dense-bed temperature on the combustion air. Chosen over the
  afterburn ΔT (T_d1 − T_rg1) because (a) the air sets the regenerator's heat balance with one
  sign and a large gain on T_rg1 (+1.5 % air: +8 °C after 1 h), while the ΔT's response to air
  mixes a bed and a dilute-phase effect of opposite sign; (b) T_rg1 is measured with the lower
  noise (0.3 against 0.5 °C); (c) it is what the independent model's TC3 does (regenerator
  temperature → air). Held T_rg1 is also what makes the T_rx loop work: at fixed air the heat
  release is fixed and circulation moves T_rx only transiently (spec §2.7: a T_rx PI alone at
  fixed air is unstable); with T_rg1 held, more catalyst means a hotter riser for good.
* The reactor level loop (spec §2.2) is part of the plant and stays as it is.

The controllers are discrete PI laws at the sample period, in velocity form with the output
clamped to the actuator limits (u_F 0.5–1.5 ×, R_ar 0.85–1.15 × nominal): the integrator is
the output itself, so a saturated loop cannot wind up (clamping anti-windup). They read the
noisy measurement of sample k, as a DCS reads its transmitter, and their new output holds from
sample k + 1 on: a one-sample (10 s) delay standing for scan and valve travel, which also keeps
the quasi-steady riser (T_rx depends on the valve in force) out of an algebraic loop.

Tuning (the SIMC rules of Skogestad 2003 on first-order-plus-delay fits of step tests on this
model, the air loop first with the valve held, then the valve loop with the air loop closed) is
in ``lab/closed_loop_tuning.py``; the stability proof (eigenvalues of the linearised closed
loop at nominal, each fault's largest size, the ``uncertain`` extremes) in
:mod:`fcc_env.closed_loop_analysis` and the docs' closed-loop page.

>>> layer = RegulatoryLayer()
>>> layer.loops, layer.setpoint_names
(('T_rx', 'T_rg1'), ('T_rx_sp', 'T_rg1_sp'))
>>> RegulatoryLayer(loops=("T_rx", "P_rg"))
Traceback (most recent call last):
...
ValueError: loops=('T_rx', 'P_rg') is outside the allowed range: ...
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numba
import numpy as np
from scipy.signal import lfilter

from fcc_common.validation import Integer, Real, check_params, from_fields, invalid
from fcc_env.params import NOMINAL_INPUTS

__all__ = [
    "ACTUATOR_LIMITS",
    "CONTROLLER_STATE_SIZE",
    "LOOP_NAMES",
    "SETPOINT_NAMES",
    "RegulatoryLayer",
    "SetpointProgram",
    "clip_rows",
    "controller_update",
]

#: The loops a layer may close: controlled measurement → manipulated input.
LOOP_NAMES: tuple[str, ...] = ("T_rx", "T_rg1")
#: Loop j reads Table 1 channel 3 + j (T_rx, T_rg1) and sets input j (u_F, R_ar).
_FIRST_CONTROLLED = 3
#: The set-point channels, in observation order.
SETPOINT_NAMES: tuple[str, ...] = ("T_rx_sp", "T_rg1_sp")
#: Actuator limits on the applied u_F (kg/s) and R_ar (t/h): the open-loop env's limits.
ACTUATOR_LIMITS = np.array(
    [
        [0.5 * NOMINAL_INPUTS[0], 1.5 * NOMINAL_INPUTS[0]],
        [0.85 * NOMINAL_INPUTS[1], 1.15 * NOMINAL_INPUTS[1]],
    ]
)
ACTUATOR_LIMITS.flags.writeable = False

#: Controller state per episode: [u_F, previous T_rx error, R_ar, previous T_rg1 error].
CONTROLLER_STATE_SIZE = 4
#: Kernel gain vector layout: per loop [closed (0/1), Kc, Ts/τI, low, high].
_GAIN_SLOTS = 5

#: Allowed set points (°C): where the layer can hold the plant inside its envelope with the
#: actuators inside their limits (steady states checked by ``lab/closed_loop_tuning.py``).
SETPOINT_RANGES: dict[str, Real] = {
    "T_rx_sp": Real(515.0, 545.0, unit="°C", why="riser outlet a supervisory layer may ask for"),
    "T_rg1_sp": Real(665.0, 705.0, unit="°C", why="stage-1 bed: hot state, no afterburn"),
}

_RANGES = {
    "T_rx_gain": Real(0.0, 50.0, unit="kg/s per °C", closed="right"),
    "T_rx_integral_time_s": Real(1.0, 1e6, unit="s"),
    "T_rg1_gain": Real(0.0, 20.0, unit="t/h per °C", closed="right"),
    "T_rg1_integral_time_s": Real(1.0, 1e6, unit="s"),
}

_PROGRAM_RANGES = {
    "T_rx_sp_halfrange_C": Real(0.0, 10.0, unit="°C"),
    "T_rg1_sp_halfrange_C": Real(0.0, 15.0, unit="°C"),
    "hold_min": Integer(1),
    "hold_max": Integer(1),
    "feed_quality_halfrange_rel": Real(
        0.0, 0.05, why="coking-factor drift; beyond 5 % the air runs out of range"
    ),
    "feed_quality_time_constant_samples": Real(1.0, 10_000.0, unit="samples"),
    "warmup_samples": Integer(0),
}


@dataclass(frozen=True)
class SetpointProgram:
    """The closed-loop operating program's own moves: set-point steps and a feed-quality drift.

    Set points step (APRBS, as the open-loop program's inputs) around the plant's initial
    steady state within ± the half-ranges, each level held ``hold_min``–``hold_max`` samples.
    The feed coking factor ``f_coke`` drifts: APRBS levels in 1 ± ``feed_quality_halfrange_rel``
    through a first-order lag of ``feed_quality_time_constant_samples`` (a slow change of feed
    quality, the disturbance the air loop exists for). Feed and air temperatures keep the
    open-loop :class:`~fcc_env.excitation.Excitation`; its air channel is not applied in closed
    loop (the air belongs to the regenerator loop).
    """

    T_rx_sp_halfrange_C: float = 4.0
    T_rg1_sp_halfrange_C: float = 6.0
    hold_min: int = 200
    hold_max: int = 600
    feed_quality_halfrange_rel: float = 0.03
    feed_quality_time_constant_samples: float = 150.0
    warmup_samples: int = 100

    def __post_init__(self) -> None:
        check_params({n: getattr(self, n) for n in _PROGRAM_RANGES}, _PROGRAM_RANGES)
        if self.hold_max < self.hold_min:
            raise invalid("hold_max", self.hold_max, f"an integer >= hold_min={self.hold_min}")


@dataclass(frozen=True)
class RegulatoryLayer:
    """The closed-loop operating mode: which loops run, their PI tuning, their set-point program.

    Gains are in manipulated units per °C of error (u_F kg/s, R_ar t/h); integral times in s.
    ``loops`` names the closed loops (:data:`LOOP_NAMES`); the input of a loop left out
    follows the open-loop operating program (as in ``FCC-v0``). ``setpoint_ranges`` bound what a supervisory action may ask for.
    """

    # SIMC tuning (lab/closed_loop_tuning.py): valve loop τc = 60 s on k = 0.234 °C per kg/s,
    # θ = 10 s, τ ≈ 1 s (the riser is quasi-steady: delay-dominant, hence integral-dominant,
    # with Skogestad's τ + θ/3 correction); air loop τc = τ/4 on k = 4.39 °C per t/h,
    # τ = 1607 s, θ = 10 s. Rounded.
    T_rx_gain: float = 0.26
    T_rx_integral_time_s: float = 4.3
    T_rg1_gain: float = 0.89
    T_rg1_integral_time_s: float = 1600.0
    loops: tuple[str, ...] = LOOP_NAMES
    program: SetpointProgram | None = dataclasses.field(default_factory=SetpointProgram)

    def __post_init__(self) -> None:
        check_params({n: getattr(self, n) for n in _RANGES}, _RANGES)
        loops = self.loops
        if isinstance(loops, str) or not all(isinstance(n, str) for n in loops):
            raise invalid("loops", loops, f"a tuple of names from {list(LOOP_NAMES)}")
        loops = tuple(loops)
        if not loops or len(set(loops)) != len(loops) or not set(loops) <= set(LOOP_NAMES):
            raise invalid(
                "loops", loops, f"a non-empty tuple of distinct names from {list(LOOP_NAMES)}"
            )
        object.__setattr__(self, "loops", loops)
        if self.program is not None and not isinstance(self.program, SetpointProgram):
            raise invalid("program", self.program, "a SetpointProgram or None (set points held)")

    @classmethod
    def from_option(cls, value: Any) -> RegulatoryLayer | None:
        """``None``/``False`` → open loop; ``True`` → the default layer; a mapping → overrides
        (its ``program`` may itself be a mapping of :class:`SetpointProgram` fields)."""
        if value is None or value is False:
            return None
        if value is True:
            return cls()
        if isinstance(value, RegulatoryLayer):
            return value
        if isinstance(value, Mapping):
            fields = dict(value)
            if isinstance(fields.get("program"), Mapping):
                fields["program"] = from_fields(
                    SetpointProgram, fields["program"], "set-point program"
                )
            if isinstance(fields.get("loops"), list):
                fields["loops"] = tuple(fields["loops"])
            return from_fields(cls, fields, "regulatory")
        raise invalid(
            "regulatory", value, "True, False, None, a RegulatoryLayer or a mapping of its fields"
        )

    @property
    def setpoint_names(self) -> tuple[str, ...]:
        return SETPOINT_NAMES

    def gains(self, sample_time_s: float) -> np.ndarray:
        """The kernel's gain vector (:func:`controller_update`) at sample period ``sample_time_s``."""
        g = np.zeros(2 * _GAIN_SLOTS)
        for j, (name, gain, ti) in enumerate(
            (
                ("T_rx", self.T_rx_gain, self.T_rx_integral_time_s),
                ("T_rg1", self.T_rg1_gain, self.T_rg1_integral_time_s),
            )
        ):
            row = g[j * _GAIN_SLOTS : (j + 1) * _GAIN_SLOTS]
            row[:] = (float(name in self.loops), gain, sample_time_s / ti, *ACTUATOR_LIMITS[j])
        return g

    def replace(self, **changes: Any) -> RegulatoryLayer:
        return dataclasses.replace(self, **changes)


def initial_controller_state(u0: np.ndarray) -> np.ndarray:
    """Controller state of a plant at steady state under inputs ``u0`` (bumpless start)."""
    return np.array([u0[0], 0.0, u0[1], 0.0])


_SP_LOW = np.array([SETPOINT_RANGES[n].low for n in SETPOINT_NAMES])
_SP_HIGH = np.array([SETPOINT_RANGES[n].high for n in SETPOINT_NAMES])


@numba.njit(cache=True, nogil=True)
def clip_rows(sp: np.ndarray, low: np.ndarray, high: np.ndarray) -> bool:
    """Each row of ``sp`` clipped in place to ``[low, high]`` per column; True if any was:
    the one clipping rule of set points (the env, batch programs, the vector env)."""
    clipped = False
    for i in range(sp.shape[0]):
        for j in range(sp.shape[1]):
            v = min(max(sp[i, j], low[j]), high[j])
            if v != sp[i, j]:
                sp[i, j] = v
                clipped = True
    return clipped


def check_setpoints(setpoints: np.ndarray) -> tuple[np.ndarray, bool]:
    """Set points (``(2,)`` or ``(n, 2)``) clipped to :data:`SETPOINT_RANGES`, and whether a
    clip was needed: the one clipping rule of the env's steps and of batch programs."""
    out = np.array(setpoints, dtype=np.float64)
    return out, clip_rows(out.reshape(-1, 2), _SP_LOW, _SP_HIGH)


@numba.njit(cache=True, nogil=True, error_model="numpy")
def apply_controller_outputs(u: np.ndarray, c: np.ndarray, gains: np.ndarray) -> None:
    """Put the closed loops' outputs into the input vector ``u`` (in place)."""
    if gains[0] != 0.0:
        u[0] = c[0]
    if gains[_GAIN_SLOTS] != 0.0:
        u[1] = c[2]


@numba.njit(cache=True, nogil=True, error_model="numpy")
def controller_update(
    c: np.ndarray, setpoint: np.ndarray, obs: np.ndarray, gains: np.ndarray
) -> bool:
    """One sample of both PI loops, in place on the controller state ``c``; True if clamped.

    Velocity form, P on the error: Δu = Kc·(e_k − e_k−1) + Kc·(Ts/τI)·e_k, the output clamped
    to the actuator limits (the integrator is the output, so clamping is the anti-windup).
    ``obs`` is the float32 observation the control system recorded at this sample.
    """
    saturated = False
    for j in range(2):
        g = j * _GAIN_SLOTS
        if gains[g] == 0.0:
            continue
        y = float(obs[_FIRST_CONTROLLED + j])
        e = setpoint[j] - y
        kc = gains[g + 1]
        u = c[2 * j] + kc * (e - c[2 * j + 1]) + kc * gains[g + 2] * e
        if u < gains[g + 3]:
            u = gains[g + 3]
            saturated = True
        elif u > gains[g + 4]:
            u = gains[g + 4]
            saturated = True
        c[2 * j] = u
        c[2 * j + 1] = e
    return saturated


class SetpointStream:
    """Streams one closed-loop episode's program: set points ``(n, 2)`` and ``f_coke`` ``(n,)``.

    Three generators of their own (T_rx set point, T_rg1 set point, feed quality), so the stream
    does not depend on chunking and the open-loop streams are untouched. ``centre`` is the
    plant's initial steady state (T_rx, T_rg1): the operators' set points are where the unit
    runs.
    """

    def __init__(
        self, program: SetpointProgram | None, centre: np.ndarray, rngs: list[np.random.Generator]
    ) -> None:
        from fcc_env.excitation import APRBSChannel  # the one APRBS implementation

        self.program = program
        self.centre = np.asarray(centre, dtype=np.float64)
        # the lag's filter state: the previous coking factor 1.0, times (1 − a)
        a = 1.0 / program.feed_quality_time_constant_samples if program is not None else 0.0
        self._zi = np.array([1.0 - a])
        self.channels: list[APRBSChannel] = []
        if program is not None:
            pr = program
            halves = (
                pr.T_rx_sp_halfrange_C,
                pr.T_rg1_sp_halfrange_C,
                pr.feed_quality_halfrange_rel,
            )
            centres = (self.centre[0], self.centre[1], 1.0)
            self.channels = [
                APRBSChannel(c, h, pr.hold_min, pr.hold_max, pr.warmup_samples, rng)
                for c, h, rng in zip(centres, halves, rngs, strict=True)
            ]

    def take(self, n: int) -> tuple[np.ndarray, np.ndarray]:
        sp = np.empty((n, 2))
        sp[:] = self.centre
        f_level = np.ones(n)
        if self.program is None:
            return sp, f_level
        self.channels[0].take(n, sp[:, 0])
        self.channels[1].take(n, sp[:, 1])
        self.channels[2].take(n, f_level)
        # Feed quality drifts: the coking factor follows its APRBS levels through a first-order
        # lag, f_k = a·level_k + (1 − a)·f_k−1; the filter state carries over between chunks,
        # so chunking does not change a bit.
        a = 1.0 / self.program.feed_quality_time_constant_samples
        out, self._zi = lfilter([a], [1.0, -(1.0 - a)], f_level, zi=self._zi)
        return sp, out
