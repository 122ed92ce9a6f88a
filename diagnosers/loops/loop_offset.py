"""``loop-offset``: a loop that cannot hold its set point, its actuator short (a member of
``catalogue-isolator``: the air blower's lost capacity).

A PI loop takes any steady error out unless its actuator cannot deliver: the integral then
winds against the limit and the controlled variable stays off its set point. A blower that
lost capacity caps the air below what the T_rg1 loop asks for, and the dense bed runs cold
(``lab/actuator-faults.md``: T_rg1 2.3 °C low on average at the default size). The state
estimator cannot see it: it reads the air flow meter, which shows the capped air, and the
model with that air is right. The loop's own record does: the EWMA (rate ``lam``) of the
control error ``sp − y`` (``sign`` +1: below the set point) over ``margin`` times its largest
healthy training value. Set-point steps make brief errors of either sign that the slow EWMA
averages away; a binding cap holds one sign while it binds.

Information limit: the cap binds only while the loop asks for more than 1.01 × nominal air,
which the set-point program and the disturbances decide per episode; an episode whose cap
barely binds shows nothing (``lab/catalogue-isolator.md`` measures the binding share).
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np

from diagnosers.detection import NO_DIAGNOSIS, Decision, Detection
from diagnosers.diagnoser import Diagnoser
from diagnosers.episode.record import Episode
from diagnosers.loops.loop_detectors import LOOP_CHANNELS
from diagnosers.presets import keyword_init
from diagnosers.registry import register
from fcc_common.validation import Integer, Options, Real, check_params
from fcc_env.closed_loop import CLOSED_LOOP_CHANNELS

__all__ = ["EwmaLimitDecisions", "LoopOffset"]


class EwmaLimitDecisions:
    """The decisions of a one-sided limit on a per-sample statistic (shared by ``loop-offset``
    and ``air-deficit``): the host class gives ``_start`` (reset the recursion), ``_step`` (one
    sample in, the statistic out, ``_k`` counting samples), ``_build``, ``warm_up``, ``margin``,
    ``limit_``, ``classes_`` and ``signal_names_``; an alarm names the host's one class."""

    def _start(self) -> None:
        raise NotImplementedError

    def _step(self, row: np.ndarray) -> float:
        raise NotImplementedError

    def _build(self) -> None:
        raise NotImplementedError

    def _calibrate_limit(self, episodes: list[Episode], name: str, need: str = "") -> None:
        """``limit_``: ``margin`` times the statistic's peak over the healthy episodes after
        ``warm_up``; ``name`` and ``need`` word the refusal when there is no positive peak."""
        peak = 0.0
        for ep in episodes:
            if ep.fault_onset is None and ep.n_samples > self.warm_up:
                peak = max(peak, float(np.max(self._statistic(ep.y)[self.warm_up :])))
        if peak <= 0.0:
            raise ValueError(
                f"{name} needs healthy training episodes longer than warm_up = "
                f"{self.warm_up} samples{need}"
            )
        self.limit_ = self.margin * peak

    def _statistic(self, y: np.ndarray) -> np.ndarray:
        self._start()
        return np.array([self._step(row) for row in y])

    def _reset(self) -> None:
        self._start()

    def _decision(self, s: float, k: int) -> Decision:
        alarm = bool(k >= self.warm_up and s > self.limit_)
        return Decision(
            alarm=alarm,
            signal=np.array([s if k >= self.warm_up else 0.0]),
            lower=np.array([-np.inf]),
            upper=np.array([self.limit_]),
            residual=np.array([s]),
            diagnosis=self.classes_[0] if alarm else NO_DIAGNOSIS,
            class_scores=np.array([float(alarm)]),
        )

    def _update(self, y: np.ndarray) -> Decision:
        s = self._step(y)
        return self._decision(s, self._k - 1)

    def _detect(self, y: np.ndarray) -> Detection:
        s = self._statistic(y)
        return Detection.from_decisions(
            [self._decision(float(x), k) for k, x in enumerate(s)],
            self.signal_names_,
            self.classes_,
        )

    def _get_state(self) -> dict[str, np.ndarray]:
        return {"limit": np.array(self.limit_)}

    def _set_state(self, state: dict[str, np.ndarray]) -> None:
        limit = float(state["limit"])
        if not limit > 0:
            raise ValueError(f"saved limit must be positive, got {limit}")
        self.limit_ = limit
        self._build()


@register("loop-offset")
class LoopOffset(EwmaLimitDecisions, Diagnoser):
    """A persistent control error of one loop (module docstring), named ``label``.

    Args:
        loop: ``"T_rg1"`` (default, the air loop) or ``"T_rx"`` (the slide-valve loop).
        sign: +1 (default) watches ``sp − y`` (the variable below its set point), −1 above.
        lam: EWMA rate of the control error, in (0, 1); default 0.003 (about 330 samples).
        margin: the limit over the largest healthy training value, in [1, 10]; default 1.5.
        warm_up: samples before the statistic counts, in [0, 100000]; default 300.
        label: the fault named; default ``"blower-capacity"``.

    Attributes:
        classes_: ``(label,)``.
        limit_: the limit of the EWMA [the loop's unit, °C].
    """

    isolates: ClassVar[bool] = True
    #: the closed-loop observation (the set points are recorded only there)
    REQUIRED_CHANNELS: ClassVar[tuple[str, ...]] = CLOSED_LOOP_CHANNELS
    CONSTRAINTS: ClassVar[dict[str, Any]] = {
        "loop": Options(tuple(LOOP_CHANNELS)),
        "sign": Options((1, -1)),
        "lam": Real(0, 1, closed="neither"),
        "margin": Real(1, 10),
        "warm_up": Integer(0, 100_000),
    }
    DEFAULTS: ClassVar[dict[str, Any]] = {
        "loop": "T_rg1",
        "sign": 1,
        "lam": 0.003,
        "margin": 1.5,
        "warm_up": 300,
        "label": "blower-capacity",
    }
    __init__ = keyword_init(DEFAULTS)

    loop: str
    sign: int
    lam: float
    margin: float
    warm_up: int
    label: str

    def _validate_params(self) -> None:
        check_params(
            {k: v for k, v in self.get_params().items() if k in self.CONSTRAINTS}, self.CONSTRAINTS
        )

    def _fit(self, episodes: list[Episode]) -> None:
        y, sp, _ = LOOP_CHANNELS[self.loop]
        missing = [c for c in (y, sp) if c not in self.channels_]
        if missing:
            raise ValueError(
                f"loop-offset on loop {self.loop!r} reads {y} and {sp}; the training episodes "
                f"lack {missing}"
            )
        self._build()
        self._calibrate_limit(
            episodes, "loop-offset", " whose control error ever leans to the watched side"
        )

    def _build(self) -> None:
        y, sp, _ = LOOP_CHANNELS[self.loop]
        self.idx_ = (self.channels_.index(y), self.channels_.index(sp))
        self.classes_ = (str(self.label),)
        self.signal_names_ = (f"control error EWMA {self.loop}",)

    def _start(self) -> None:
        self._k, self._a = 0, 0.0

    def _step(self, row: np.ndarray) -> float:
        e = self.sign * (row[self.idx_[1]] - row[self.idx_[0]])
        self._a = (1.0 - self.lam) * self._a + self.lam * float(e)
        self._k += 1
        return self._a
