"""``oscillation-acf`` and ``stiction-ccf``: a control loop's oscillation and its valve's
stiction, from the loop's own records (set point, controlled variable, controller output).

Both read one loop of the closed-loop observation (``FCC-closedloop-v0``): the measured
controlled variable, its set point and the controller's output, which the observation records
as the controller's command (the valve's true position is not measured, as on most units).
They slide a window over the loop's last ``window_s`` seconds and compute the indexes of
:mod:`diagnosers.loops.loop_indexes` every ``every`` samples (the decision holds in between):

* ``oscillation-acf`` alarms when the control error oscillates (Thornhill, Huang & Zhang 2003:
  the ACF's zero crossings regular, ``r > regularity_limit``, at a period no faster than
  ``min_period_s``, and the ACF one period on above ``peak_limit``: an oscillation that
  stands out of the noise). It names no fault: an oscillating loop has many causes (a sticking valve,
  an aggressive tuning, an oscillating disturbance from upstream; Thornhill & Hägglund 1997),
  so it is a detector, and the diagnosis is :class:`StictionCCF`'s job.
* ``stiction-ccf`` alarms when the loop oscillates *and* Horch (1999)'s cross-correlation
  test says the valve sticks (the CCF of controller output and control error odd: its phase
  at lag zero above ``phase_limit_deg``) *and* He et al. (2007)'s curve fit finds the
  controller output a triangle wave rather than a sine, and names the fault ``label``, the
  fault registry's name of the valve's stiction (``valve-stiction`` on the T_rx loop's slide
  valve). An oscillation with an even CCF or a sinusoidal controller output (from outside
  the valve) does not alarm it.

Neither learns a threshold from data: the limits are the papers' (``r > 1``, ``SI > 0.4``)
or stated (``phase_limit_deg``; ``peak_limit`` and ``min_period_s``, set on validation seeds
5000–5019). ``fit`` checks that the training records carry the loop's channels and vary, and
records the healthy training loops' largest alarm index (``training_index_max_``), with a
warning when it is above 1 (those loops already oscillate). The false-alarm rate on healthy closed-loop
episodes is measured in ``lab/stiction-detection.md``.
"""

from __future__ import annotations

import logging
import math
from typing import Any, ClassVar

import numpy as np

from diagnosers.contract import require_varying
from diagnosers.detection import NO_DIAGNOSIS, Decision, Detection
from diagnosers.diagnoser import Diagnoser
from diagnosers.episode.record import Episode
from diagnosers.loops.loop_indexes import acf_regularity, horch_phase, shape_index
from diagnosers.registry import register
from fcc_common.validation import Integer, Options, Real, check_params, invalid

__all__ = ["LOOP_CHANNELS", "LoopMonitor", "OscillationACF", "StictionCCF"]

logger = logging.getLogger(__name__)

#: Each loop's channels in the closed-loop observation: (controlled variable, set point,
#: controller output). The air loop's output is read from the air flow meter R_ar: the
#: observation records no air command (below the blower's ceiling the two agree within the
#: meter's 0.5 % noise).
LOOP_CHANNELS: dict[str, tuple[str, str, str]] = {
    "T_rx": ("T_rx", "T_rx_sp", "u_F"),
    "T_rg1": ("T_rg1", "T_rg1_sp", "R_ar"),
}

_CONSTRAINTS: dict[str, Any] = {
    "loop": Options(tuple(LOOP_CHANNELS), why="a loop of the closed-loop plant"),
    "window_s": Real(0.0, closed="neither", unit="s", why="a few cycles of the oscillation"),
    "min_period_s": Real(0.0, unit="s", why="faster periods are measurement noise"),
    "n_crossings": Integer(4, 64, why="the ACF's first zero crossings; 4 give 2 periods"),
    "regularity_limit": Real(0.0, closed="neither", why="Thornhill et al. (2003): 1"),
    "peak_limit": Real(0.0, 1.0, closed="left", why="the ACF one period on; 0 turns it off"),
    "every": Integer(1, why="samples between two evaluations of the window"),
    "phase_limit_deg": Real(0.0, 90.0, closed="right", unit="°", why="90: a purely odd CCF"),
    "shape_limit": Real(0.0, 1.0, closed="left", why="He et al. (2007): 0.4; 0 turns it off"),
}


class LoopMonitor(Diagnoser):
    """What both loop monitors share: the loop's channels, the sliding window, the oscillation
    test on it every ``every`` samples and the decision held in between (module docstring).

    Subclasses name their signals (:meth:`_signal_names`, the first the alarm index with its
    limit 1) and compute the rest of a window's row (:meth:`_evaluate`).
    """

    #: the default loop's channels, for the harness (a track without them skips the monitor)
    REQUIRED_CHANNELS: ClassVar[tuple[str, ...]] = LOOP_CHANNELS["T_rx"]

    def _validate_params(self) -> None:
        check_params(self.get_params(), _CONSTRAINTS)

    def _fit(self, episodes: list[Episode]) -> None:
        names = LOOP_CHANNELS[self.loop]
        missing = [c for c in names if c not in self.channels_]
        if missing:
            raise invalid(
                "loop",
                self.loop,
                f"a loop whose channels {list(names)} the episodes carry",
                f"missing {missing} of {list(self.channels_)}: record the closed-loop plant "
                "(FCC-closedloop-v0), whose observation holds set points and controller outputs",
            )
        idx = [self.channels_.index(c) for c in names]
        y = np.concatenate([ep.y[:, idx] for ep in episodes])
        require_varying(y, list(names), self.name or type(self).__name__, every=False)
        self.channel_idx_ = np.asarray(idx, dtype=np.int64)
        self._finish()
        # what the healthy training loops show: one that already oscillates is worth a word
        # (an isolating monitor also receives labelled faulty episodes: those may oscillate)
        peak = 0.0
        for ep in (ep for ep in episodes if ep.fault_onset is None):
            self._reset()
            peak = max([peak, *(self._update(row).signal[0] for row in ep.y)])
        self.training_index_max_ = float(peak)
        if peak > 1.0:
            logger.warning(
                "%s: the training episodes already alarm (largest index %.2f > 1): their loop "
                "%s oscillates; train on healthy records, or expect alarms on such loops",
                self.name or type(self).__name__,
                peak,
                self.loop,
            )

    def _finish(self) -> None:
        window = round(float(self.window_s) / self.sample_time_s_)
        if window < 8:
            raise invalid(
                "window_s",
                self.window_s,
                f"at least 8 samples of {self.sample_time_s_:g} s",
                "the window must hold a few cycles of the oscillation",
            )
        self.window_ = window
        self.min_period_ = float(self.min_period_s) / self.sample_time_s_
        self.signal_names_ = self._signal_names()

    def _get_state(self) -> dict[str, np.ndarray]:
        return {
            "channel_idx": self.channel_idx_,
            "training_index_max": np.asarray(self.training_index_max_),
        }

    def _set_state(self, state: dict[str, np.ndarray]) -> None:
        self.channel_idx_ = np.asarray(state["channel_idx"], dtype=np.int64)
        self.training_index_max_ = float(state["training_index_max"])
        self._finish()

    def _reset(self) -> None:
        self.error_buf_ = np.zeros(self.window_)
        self.output_buf_ = np.zeros(self.window_)
        self.k_ = 0
        self.row_ = np.zeros(len(self.signal_names_))

    def _update(self, y: np.ndarray) -> Decision:
        pv, sp, op = y[self.channel_idx_]
        w, i = self.window_, self.k_ % self.window_
        self.error_buf_[i], self.output_buf_[i] = pv - sp, op
        self.k_ += 1
        if self.k_ >= w and (self.k_ - w) % int(self.every) == 0:
            order = (np.arange(w) + self.k_) % w  # oldest first
            self.row_ = self._evaluate(self.error_buf_[order], self.output_buf_[order])
        return self._decide(self.row_, pv - sp)

    def _oscillation(self, e: np.ndarray) -> tuple[float, float, float, float]:
        """The window's oscillation index ``min(r / regularity_limit, peak / peak_limit)``
        (above 1: it oscillates), ``r``, the ACF peak and the period (samples; ``nan``)."""
        r, period, peak = acf_regularity(
            e, self.window_ // 2, int(self.n_crossings), self.min_period_
        )
        if r == 0.0:
            return 0.0, 0.0, 0.0, period
        index = r / float(self.regularity_limit)
        if float(self.peak_limit) > 0.0:
            index = min(index, peak / float(self.peak_limit))
        return index, r, peak, period

    def _decide(self, row: np.ndarray, error: float) -> Decision:
        alarm = bool(row[0] > 1.0)
        upper = np.full(row.shape, math.inf)
        upper[0] = 1.0
        return Decision(alarm, row.copy(), np.full(row.shape, -math.inf), upper, np.array([error]))

    def _signal_names(self) -> tuple[str, ...]:  # pragma: no cover - abstract
        raise NotImplementedError

    def _evaluate(self, e: np.ndarray, op: np.ndarray) -> np.ndarray:  # pragma: no cover
        raise NotImplementedError


@register("oscillation-acf")
class OscillationACF(LoopMonitor):
    """An oscillating control loop: the regularity of the control error's ACF zero crossings
    (Thornhill, Huang & Zhang 2003; :mod:`diagnosers.loops.loop_indexes`).

    Args:
        loop: ``"T_rx"`` (riser outlet on the slide valve, default) or ``"T_rg1"`` (stage-1
            bed on the air).
        window_s: the sliding window (default 4800 s: about five cycles of the sticking
            slide valve's 10-minute limit cycle, ``lab/stiction-detection.md``).
        min_period_s: the fastest period counted as an oscillation (default 240 s); a healthy
            loop's ACF crosses zero regularly at 2–12 samples (the noise through the PI law).
        n_crossings: the ACF's first zero crossings that give the periods (default 6).
        regularity_limit: ``r`` must exceed it (default 1, the paper's).
        peak_limit: the ACF one period on must exceed it (default 0.3; 0 turns it off).
        every: evaluate the window every this many samples (default 5; the decision holds).

    Decision arrays: signal = (the oscillation index ``min(r / regularity_limit, peak /
    peak_limit)``, ``r``, the ACF peak, the mean period in s), upper = (1, inf, inf, inf): the
    alarm is the index above 1; residual = the control error (controlled variable − set
    point).
    """

    def __init__(
        self,
        *,
        loop: str = "T_rx",
        window_s: float = 4800.0,
        min_period_s: float = 240.0,
        n_crossings: int = 6,
        regularity_limit: float = 1.0,
        peak_limit: float = 0.3,
        every: int = 5,
    ) -> None:
        self.loop = loop
        self.window_s = window_s
        self.min_period_s = min_period_s
        self.n_crossings = n_crossings
        self.regularity_limit = regularity_limit
        self.peak_limit = peak_limit
        self.every = every

    def _signal_names(self) -> tuple[str, ...]:
        return (
            f"{self.loop} oscillation index",
            f"{self.loop} ACF regularity",
            f"{self.loop} ACF peak",
            f"{self.loop} oscillation period [s]",
        )

    def _evaluate(self, e: np.ndarray, op: np.ndarray) -> np.ndarray:
        index, r, peak, period = self._oscillation(e)
        period_s = 0.0 if math.isnan(period) else period * self.sample_time_s_
        return np.array([index, r, peak, period_s])


@register("stiction-ccf")
class StictionCCF(LoopMonitor):
    """A sticking control valve: an oscillating loop (:class:`OscillationACF`'s test) whose
    controller output and control error have an odd cross-correlation (Horch 1999) and whose
    controller output is a triangle wave rather than a sine (He et al. 2007's curve fit);
    :mod:`diagnosers.loops.loop_indexes`.

    Horch's test alone cannot tell a sticking valve from an external sinusoid under an
    integral-dominated controller (the T_rx loop's): both read odd. The curve fit can, so it
    is on by default; ``shape_limit=0`` leaves Horch's test alone.

    Args:
        loop: the loop, as :class:`OscillationACF`'s (default ``"T_rx"``).
        window_s: the sliding window in s (default 4800).
        min_period_s: the fastest period counted as an oscillation, in s (default 240).
        n_crossings: the ACF's first zero crossings that give the periods (default 6).
        regularity_limit: Thornhill's ``r`` must exceed it (default 1).
        peak_limit: the ACF one period on must exceed it (default 0.3; 0 turns it off).
        every: evaluate the window every this many samples (default 5).
        phase_limit_deg: Horch's phase above which the CCF counts as odd (default 60°: the
            CCF at lag zero below half its peak, ``cos 60° = 0.5``).
        shape_limit: He et al.'s index above which the controller output counts as a triangle
            (default 0.4, the paper's bound of "no stiction"; 0 turns the test off).
        label: the fault the alarm names, the fault registry's name of the valve's stiction
            (default ``"valve-stiction"``, the T_rx loop's slide valve).

    Decision arrays: signal = (the stiction index ``min(oscillation index, φ / phase_limit,
    SI / shape_limit)``, ``r``, the ACF peak, Horch's phase ``φ`` in degrees, He's ``SI``),
    upper = (1, inf, inf, inf, inf): the alarm is the index above 1, every test passed;
    residual = the control error. The diagnosis is ``label`` while alarmed (class score: the
    index).
    """

    isolates: ClassVar[bool] = True

    def __init__(
        self,
        *,
        loop: str = "T_rx",
        window_s: float = 4800.0,
        min_period_s: float = 240.0,
        n_crossings: int = 6,
        regularity_limit: float = 1.0,
        peak_limit: float = 0.3,
        every: int = 5,
        phase_limit_deg: float = 60.0,
        shape_limit: float = 0.4,
        label: str = "valve-stiction",
    ) -> None:
        self.loop = loop
        self.window_s = window_s
        self.min_period_s = min_period_s
        self.n_crossings = n_crossings
        self.regularity_limit = regularity_limit
        self.peak_limit = peak_limit
        self.every = every
        self.phase_limit_deg = phase_limit_deg
        self.shape_limit = shape_limit
        self.label = label

    def _validate_params(self) -> None:
        super()._validate_params()
        if not isinstance(self.label, str) or self.label in ("", "unknown", "nominal"):
            raise invalid("label", self.label, "a fault's name (not '', 'unknown' or 'nominal')")

    def _finish(self) -> None:
        super()._finish()
        self.classes_ = (str(self.label),)

    def _signal_names(self) -> tuple[str, ...]:
        return (
            f"{self.loop} stiction index",
            f"{self.loop} ACF regularity",
            f"{self.loop} ACF peak",
            f"{self.loop} Horch phase [deg]",
            f"{self.loop} He shape index",
        )

    def _evaluate(self, e: np.ndarray, op: np.ndarray) -> np.ndarray:
        index, r, peak, period = self._oscillation(e)
        if r == 0.0:  # no oscillation: the other tests have no period to work with
            return np.zeros(5)
        phase = math.degrees(horch_phase(op, e, period))
        si = shape_index(op, period)
        si = 0.0 if math.isnan(si) else si
        index = min(index, phase / float(self.phase_limit_deg))
        if float(self.shape_limit) > 0.0:
            index = min(index, si / float(self.shape_limit))
        return np.array([index, r, peak, phase, si])

    def _detect(self, y: np.ndarray) -> Detection:
        decisions = [self._update(row) for row in y]
        return Detection.from_decisions(decisions, self.signal_names_, self.classes_)

    def _decide(self, row: np.ndarray, error: float) -> Decision:
        d = super()._decide(row, error)
        return Decision(
            d.alarm,
            d.signal,
            d.lower,
            d.upper,
            d.residual,
            diagnosis=self.classes_[0] if d.alarm else NO_DIAGNOSIS,
            class_scores=row[:1].copy(),
        )
