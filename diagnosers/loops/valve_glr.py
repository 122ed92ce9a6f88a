"""``valve-glr``: a slide valve that stops following its command, from the riser's balance.

The closed-loop observation records the T_rx loop's command ``u_F`` (exact) but not the valve's
position. The riser is quasi-steady: its outlet ``T_rx`` follows the catalyst flow within a
sample, and besides the flow it moves with the regenerated catalyst's temperature ``T_rg2`` and
the feed's ``T_fp`` (the riser energy balance of :mod:`fcc_env.physics`, its structure only).
``fit`` regresses ``T_rx`` on the command and those measured inputs over healthy records (the
local linear map: no parameter of the plant is read), so the residual

    r_t = T_rx,t − (c_0 + gain · u_F,t + Σ c_i x_i,t)

reads ``gain · (position − command)``: noise while the valve follows its command, and the
command's moves since the valve stuck once it sticks (:mod:`diagnosers.loops.valve_statistics`:
a windowed GLR over the onset of that signature, and one of a step for a valve bias). The
alarm is either GLR over its limit, or the step's GLR held: a valve bias steps ``r`` by
``gain · bias`` for good (the loop moves the command by the bias to hold T_rx), but the
windowed test sees the step only while its onset lies in the window. Once the step GLR
passes its limit, its onset's reference mean is kept and the same GLR is taken over the
latest ``hold`` samples against it, until it falls to ``hold_threshold``.

What the loop hides a black-box monitor must wait for (the limit cycle,
:mod:`diagnosers.loops.loop_detectors`); this test sees the first stuck samples, as the command
moves and the riser does not answer. What it cannot tell apart, measured in
``lab/stiction-detection.md``: any unmeasured disturbance on T_rx that the loop takes out by
moving the valve (a T_rx transmitter's drift among them) reads like a valve that does not pass
the move, only slower; the window bounds how slow a signature counts.
"""

from __future__ import annotations

import math
from typing import Any, ClassVar

import numpy as np

from diagnosers.contract import require_varying
from diagnosers.detection import Decision
from diagnosers.diagnoser import Diagnoser
from diagnosers.episode.record import Episode
from diagnosers.loops.valve_statistics import OnsetStatistics, onset_statistics, step_glr
from diagnosers.presets import keyword_init, preset
from diagnosers.registry import register
from fcc_common.validation import Integer, OptionSequence, Real, check_params, invalid
from fcc_env.params import MEASUREMENT_NAMES

__all__ = ["VALVE_GLR_CONSTRAINTS", "VALVE_GLR_DEFAULTS", "ValveGLR", "ValveGLRPartial"]

#: :class:`ValveGLR`'s hyperparameters and defaults, in signature order (set on validation
#: seeds, ``lab/stiction-detection.md``).
VALVE_GLR_DEFAULTS: dict[str, Any] = {
    "regressors": ["T_rg2", "T_fp"],
    "smooth_samples": 0.0,
    "window": 30,
    "reference": 30,
    "a_min": 1.0,
    "threshold": 15.0,
    "bias_threshold": 100.0,
    "hold": 30,
    "hold_threshold": 100.0,
}
#: their declarative constraints, checked in ``fit``
VALVE_GLR_CONSTRAINTS: dict[str, Any] = {
    "regressors": OptionSequence(
        tuple(c for c in MEASUREMENT_NAMES if c != "T_rx"), why="measured inputs of the riser"
    ),
    "smooth_samples": Real(0.0, 1000.0, why="the regressors' EWMA time constant; 0: none"),
    "window": Integer(1, 2000, why="samples since the onset searched"),
    "reference": Integer(2, 2000, why="samples before the onset the reference mean takes"),
    "a_min": Real(0.0, 1.0, closed="right", why="the least share of the moves a fault loses"),
    "threshold": Real(0.0, closed="neither", why="the stuck GLR's limit"),
    "bias_threshold": Real(0.0, closed="neither", why="the bias GLR's limit"),
    "hold": Integer(0, 2000, why="latest samples the held step GLR takes; 0: no hold"),
    "hold_threshold": Real(0.0, closed="neither", why="the held step GLR's limit"),
}
_CONTROLLED, _COMMAND = "T_rx", "u_F"


@register("valve-glr")
class ValveGLR(Diagnoser):
    """The T_rx loop's valve against its command: a regression of the riser outlet on the
    command and the riser's measured inputs, fitted on healthy records, and two windowed GLRs
    on its residual (module docstring; :mod:`diagnosers.loops.valve_statistics`).

    Args:
        regressors: measured channels besides the command that move T_rx (default
            ``["T_rg2", "T_fp"]``: the catalyst's and the feed's temperatures).
        smooth_samples: the regressors' EWMA time constant in samples (0, default: raw).
        window: the onsets searched, samples back from the current one (default 30: a
            sticking valve is found in 3-35 samples, and a slower signature is the loop's
            own, an unmeasured disturbance it takes out; ``lab/stiction-detection.md``).
        reference: samples before an onset whose residual mean is its reference (default 30).
        a_min: the least share of the command's moves a faulty valve loses (default 1: a valve
            that passes none while it sticks; ``valve-glr-partial`` takes 0.5, the
            ``valve-stuck`` column's smallest share).
        threshold: the stuck GLR's limit (default 15).
        bias_threshold: the step GLR's limit (default 100: the smallest valve bias of the
            ``actuator`` track, 0.05 of the nominal flow, steps the residual by 5 °C, a GLR
            of about 100 on its first sample; the loop's set-point transients step it by up
            to 1 °C).
        hold: once the bias GLR passes its limit, the latest samples (at most ``hold``,
            default 30) whose step GLR against the reference mean kept from its onset is
            held (0: no hold, the windowed test alone, which forgets a bias once its onset
            leaves the window).
        hold_threshold: the held GLR's limit, at most ``bias_threshold``; the hold ends when
            it falls to it (default 100; the smallest valve bias of the ``actuator`` track
            holds it at 300 and more, healthy loops never start one: lab/stiction-detection.md).

    Decision arrays, names ``stuck GLR``, ``bias GLR``, ``share lost``, ``samples stuck``,
    ``bias held GLR``: ``signal`` the two GLRs, the fitted ``a``, the stuck GLR's onset age
    and the held step GLR (0 while none is held); ``upper`` the three limits (inf for the
    others); ``residual`` the regression's residual ``r_t`` (°C).
    """

    DEFAULTS: ClassVar[dict[str, Any]] = VALVE_GLR_DEFAULTS
    __init__ = keyword_init(DEFAULTS)
    REQUIRED_CHANNELS: ClassVar[tuple[str, ...]] = (_CONTROLLED, _COMMAND, "T_rg2", "T_fp")

    regressors: list[str]
    smooth_samples: float
    window: int
    reference: int
    a_min: float
    threshold: float
    bias_threshold: float
    hold: int
    hold_threshold: float

    def _validate_params(self) -> None:
        check_params(self.get_params(), VALVE_GLR_CONSTRAINTS)
        if self.hold_threshold > self.bias_threshold:
            # a hold starts where the bias GLR passes its limit, its GLR then the same: a
            # higher hold limit would end every hold on its first sample
            raise invalid(
                "hold_threshold",
                self.hold_threshold,
                f"(0, bias_threshold={self.bias_threshold:g}]",
                "a hold starts at the bias limit and would end at once",
            )

    # ---- fitting -------------------------------------------------------------------------------
    def _fit(self, episodes: list[Episode]) -> None:
        names = [_CONTROLLED, _COMMAND, *self.regressors]
        missing = [c for c in names if c not in self.channels_]
        if missing:
            raise invalid(
                "regressors",
                self.regressors,
                f"channels the episodes carry (with {_CONTROLLED} and {_COMMAND})",
                f"missing {missing} of {list(self.channels_)}: record the closed-loop plant "
                "(FCC-closedloop-v0), whose observation holds the valve command",
            )
        self.channel_idx_ = np.array([self.channels_.index(c) for c in names], dtype=np.int64)
        data = [np.asarray(ep.y, dtype=np.float64)[:, self.channel_idx_] for ep in episodes]
        require_varying(np.concatenate(data), names, "valve-glr")
        inputs = [self._inputs(d) for d in data]
        x = np.concatenate([np.column_stack([np.ones(len(i)), i]) for i in inputs])
        y = np.concatenate([d[:, 0] for d in data])
        coef, *_ = np.linalg.lstsq(x, y, rcond=None)
        residuals = [
            d[:, 0] - np.column_stack([np.ones(len(i)), i]) @ coef
            for d, i in zip(data, inputs, strict=True)
        ]
        # the white part of the residual: its slow model error is the reference mean's job
        diffs = np.concatenate([np.diff(r) for r in residuals])
        self.coef_ = coef
        self.sigma_ = float(np.std(diffs) / math.sqrt(2.0))
        if not self.sigma_ > 0.0 or coef[1] == 0.0:
            raise ValueError(
                f"valve-glr cannot be trained: residual noise {self.sigma_:g}, gain {coef[1]:g} "
                "(the riser outlet does not move with the command in these records)"
            )
        self._finish()

    def _inputs(self, d: np.ndarray) -> np.ndarray:
        """The regression's inputs ``(n, 1 + len(regressors))`` of a record ``d`` (T_rx,
        u_F, regressors columns): the command, the regressors EWMA-smoothed."""
        out = np.array(d[:, 1:], dtype=np.float64, copy=True)
        if float(self.smooth_samples) > 0.0 and out.shape[0]:
            alpha = 1.0 / (1.0 + float(self.smooth_samples))
            for k in range(1, out.shape[0]):
                out[k, 1:] = out[k - 1, 1:] + alpha * (out[k, 1:] - out[k - 1, 1:])
        return out

    def _finish(self) -> None:
        self.gain_ = float(self.coef_[1])
        self.signal_names_ = (
            "stuck GLR",
            "bias GLR",
            "share lost",
            "samples stuck",
            "bias held GLR",
        )
        self._upper = np.array(
            [self.threshold, self.bias_threshold, math.inf, math.inf, self.hold_threshold]
        )
        self._lower = np.full(5, -math.inf)
        self._alpha = 1.0 / (1.0 + float(self.smooth_samples))

    # ---- persistence ---------------------------------------------------------------------------
    def _get_state(self) -> dict[str, np.ndarray]:
        return {
            "channel_idx": self.channel_idx_,
            "coef": self.coef_,
            "sigma": np.asarray(self.sigma_),
        }

    def _set_state(self, state: dict[str, np.ndarray]) -> None:
        self.channel_idx_ = np.asarray(state["channel_idx"], dtype=np.int64)
        self.coef_ = np.asarray(state["coef"], dtype=np.float64)
        self.sigma_ = float(state["sigma"])
        if self.coef_.shape != (2 + len(self.regressors),):
            raise ValueError(
                f"{self.coef_.shape[0]} coefficients for {len(self.regressors)} regressors"
            )
        self._finish()

    # ---- detection -----------------------------------------------------------------------------
    def _reset(self) -> None:
        size = max(int(self.window) + int(self.reference), int(self.hold))
        self.r_buf_ = np.zeros(size)
        self.u_buf_ = np.zeros(size)
        self.k_ = 0
        self.smoothed_: np.ndarray | None = None
        # the held step: the count ``k_`` at its onset's first sample and its reference mean
        self.held_: tuple[int, float] | None = None
        # the count from which a reference mean is clean: a held step's samples are not (the
        # step back down after a transient would be held against them, for good)
        self.clean_from_ = 0

    def _update(self, y: np.ndarray) -> Decision:
        d = y[self.channel_idx_]
        x = np.array(d[2:], dtype=np.float64)
        if self.smoothed_ is None:
            self.smoothed_ = x
        else:
            self.smoothed_ = self.smoothed_ + self._alpha * (x - self.smoothed_)
        r = float(d[0] - self.coef_[0] - self.gain_ * d[1] - self.coef_[2:] @ self.smoothed_)
        size = self.r_buf_.shape[0]
        self.r_buf_[self.k_ % size], self.u_buf_[self.k_ % size] = r, d[1]
        self.k_ += 1
        n = min(self.k_, int(self.window) + int(self.reference))
        order = (np.arange(self.k_ - n, self.k_)) % size  # oldest first
        s = onset_statistics(
            self.r_buf_[order],
            self.u_buf_[order],
            gain=self.gain_,
            sigma=self.sigma_,
            reference=int(self.reference),
            a_min=float(self.a_min),
        )
        held = self._held(s)
        signal = np.array([s.stuck, s.bias, s.size, float(s.since), held])
        alarm = bool(
            s.stuck > self.threshold or s.bias > self.bias_threshold or held > self.hold_threshold
        )
        return Decision(alarm, signal, self._lower.copy(), self._upper.copy(), np.array([r]))

    def _held(self, s: OnsetStatistics) -> float:
        """The held step GLR (module docstring): taken from the bias GLR's onset when that
        passes its limit, over the latest ``hold`` samples since, ended at its own limit."""
        if int(self.hold) == 0:
            return 0.0
        start = self.k_ - s.bias_since
        if (
            self.held_ is None
            and s.bias > self.bias_threshold
            and start - int(self.reference) >= self.clean_from_
        ):
            self.held_ = (start, s.bias_reference)
        if self.held_ is None:
            return 0.0
        start, mean = self.held_
        n = min(self.k_ - start, int(self.hold))
        size = self.r_buf_.shape[0]
        latest = self.r_buf_[np.arange(self.k_ - n, self.k_) % size]
        glr = float(
            step_glr(
                float(np.sum(latest - mean)), n, sigma=self.sigma_, reference=int(self.reference)
            )
        )
        if glr <= self.hold_threshold:
            self.held_, self.clean_from_ = None, self.k_
        return glr


ValveGLRPartial = preset(
    "valve-glr-partial",
    ValveGLR,
    {"a_min": 0.5},
    """``valve-glr`` for a valve that still passes part of each move (``valve-stuck`` with
    m from 0.5): the stuck GLR fits the share lost in [0.5, 1] instead of taking it as 1. It
    finds such a valve sooner and pays with more false alarms, as a model a few per cent off
    in a large command move reads as a share lost (``lab/stiction-detection.md``).
    """,
    module=__name__,
)
