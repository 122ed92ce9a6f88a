"""``air-deficit``: the air the blower delivers against what the air loop commands (a member of
``catalogue-isolator``: the blower's lost capacity, named ``blower-capacity``).

The closed-loop observation records no air command (``diagnosers.loops.loop_detectors.
LOOP_CHANNELS``), but the command is the published PI law (:mod:`fcc_env.regulatory`: velocity
form, clamped to the actuator limits, started bumpless at the nominal air) applied to the very
error the control system recorded (``T_rg1_sp − T_rg1``, the float32 observation the controller
read): it can be computed again sample for sample. The air in force at sample k is the command
of sample k − 1 (the loop's one-sample delay), and the air flow meter reads it within its 0.5 %
noise. The deficit ``command − R_ar`` is that noise alone on a healthy plant, whatever the set
points and the disturbances do; a blower capped below the command delivers the cap, and the
deficit is the command's excess over it (the integral winds on while the bed stays cold).

Against ``loop-offset`` (the control error held off its set point): the control error of a
healthy loop swings with every set-point step, so its limit must clear those swings
(``lab/catalogue-isolator.md``: a weakly binding cap stayed under it); the deficit's healthy
spread is the meter's noise only. Its EWMA (rate ``lam``) over ``margin`` times its largest
healthy training value is the alarm.

Information limit: the deficit exists only while the loop asks for more air than the cap (the
set-point program and the feed decide it per episode); a cap never reached shows nothing.

Assumptions (grey box): the episode starts where the control system started (the env's bumpless
start at nominal air), the loop runs the default :class:`~fcc_env.regulatory.RegulatoryLayer`
tuning, and the R_ar meter is sound (a fault of that meter is a deficit too).
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np

from diagnosers.contract import Tier
from diagnosers.diagnoser import Diagnoser
from diagnosers.episode.record import Episode
from diagnosers.loops.loop_offset import EwmaLimitDecisions
from diagnosers.presets import keyword_init
from diagnosers.registry import register
from fcc_common.validation import Integer, Real, check_params
from fcc_env.closed_loop import CLOSED_LOOP_CHANNELS
from fcc_env.params import INPUT_NAMES, NOMINAL_INPUTS
from fcc_env.regulatory import ACTUATOR_LIMITS, LOOP_NAMES, RegulatoryLayer

__all__ = ["AirDeficit", "air_commands"]

#: What the deficit reads: the controlled variable, its set point, the metered air.
_CHANNELS = ("T_rg1", "T_rg1_sp", "R_ar")
_AIR = INPUT_NAMES.index("R_ar")
_LOOP = LOOP_NAMES.index("T_rg1")


def _air_law(sample_time_s: float) -> tuple[float, float, float, float]:
    """The air loop's velocity-form PI of the default layer: ``(Kc [t/h per °C], Kc·Ts/τI,
    low, high [t/h])``."""
    g = RegulatoryLayer().gains(sample_time_s)
    slot = g.size // len(LOOP_NAMES) * _LOOP
    low, high = (float(x) for x in ACTUATOR_LIMITS[_LOOP])
    return float(g[slot + 1]), float(g[slot + 1] * g[slot + 2]), low, high


def _pi_step(u: float, e_prev: float, e: float, law: tuple[float, float, float, float]) -> float:
    """One sample of the controller (:func:`fcc_env.regulatory.controller_update`): the new
    output, clamped to the actuator limits."""
    kc, ki, low, high = law
    return min(max(u + kc * (e - e_prev) + ki * e, low), high)


def air_commands(error_C: np.ndarray, sample_time_s: float) -> np.ndarray:
    """The air command in force at each sample [t/h] of an episode whose recorded air-loop
    error ``T_rg1_sp − T_rg1`` is ``error_C`` (from the bumpless start at nominal air; the
    command computed at sample k holds from k + 1)."""
    law = _air_law(sample_time_s)
    out = np.empty(len(error_C))
    u, e_prev = float(NOMINAL_INPUTS[_AIR]), 0.0
    for k, e in enumerate(np.asarray(error_C, dtype=np.float64)):
        out[k] = u
        u, e_prev = _pi_step(u, e_prev, float(e), law), float(e)
    return out


@register("air-deficit")
class AirDeficit(EwmaLimitDecisions, Diagnoser):
    """The metered air short of the air loop's recomputed command (module docstring), named
    ``label``.

    Args:
        lam: EWMA rate of the deficit, in (0, 1); default 0.01 (about 100 samples).
        margin: the limit over the largest healthy training value, in [1, 10]; default 1.5.
        warm_up: samples before the statistic counts, in [0, 100000]; default 100.
        label: the fault named; default ``"blower-capacity"``.

    Attributes:
        classes_: ``(label,)``.
        limit_: the limit of the deficit's EWMA [t/h].
    """

    isolates: ClassVar[bool] = True
    #: grey box: it runs the published controller law of the regulatory layer
    tier: ClassVar[Tier] = Tier.GREY_BOX
    #: the closed-loop observation (the set points are recorded only there)
    REQUIRED_CHANNELS: ClassVar[tuple[str, ...]] = CLOSED_LOOP_CHANNELS
    CONSTRAINTS: ClassVar[dict[str, Any]] = {
        "lam": Real(0, 1, closed="neither"),
        "margin": Real(1, 10),
        "warm_up": Integer(0, 100_000),
    }
    DEFAULTS: ClassVar[dict[str, Any]] = {
        "lam": 0.01,
        "margin": 1.5,
        "warm_up": 100,
        "label": "blower-capacity",
    }
    __init__ = keyword_init(DEFAULTS)

    lam: float
    margin: float
    warm_up: int
    label: str

    def _validate_params(self) -> None:
        check_params(
            {k: v for k, v in self.get_params().items() if k in self.CONSTRAINTS}, self.CONSTRAINTS
        )

    def _fit(self, episodes: list[Episode]) -> None:
        missing = [c for c in _CHANNELS if c not in self.channels_]
        if missing:
            raise ValueError(f"air-deficit reads {list(_CHANNELS)}; the episodes lack {missing}")
        self._build()
        self._calibrate_limit(episodes, "air-deficit")

    def _build(self) -> None:
        self.idx_ = tuple(self.channels_.index(c) for c in _CHANNELS)
        self.classes_ = (str(self.label),)
        self.signal_names_ = ("air deficit EWMA R_ar",)
        self._law = _air_law(self.sample_time_s_)

    def _start(self) -> None:
        # the controller's bumpless start: nominal air, no previous error
        self._k, self._a = 0, 0.0
        self._u, self._e = float(NOMINAL_INPUTS[_AIR]), 0.0

    def _step(self, row: np.ndarray) -> float:
        y, sp, air = (float(row[i]) for i in self.idx_)
        if np.isfinite(air):  # a lost sample leaves the statistic where it was
            self._a = (1.0 - self.lam) * self._a + self.lam * (self._u - air)
        if np.isfinite(y) and np.isfinite(sp):
            e = sp - y
            self._u, self._e = _pi_step(self._u, self._e, e, self._law), e
        self._k += 1
        return self._a
