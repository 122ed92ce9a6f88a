"""``stiction-ukf``: a sticking slide valve found by the excess variance of the FCC model's
riser-outlet innovation (grey box; a member of ``catalogue-isolator``).

The closed-loop filter (:class:`~diagnosers.filters.FCCStateEstimator`) reads the valve
*command* u_F as the catalyst flow. A sticking valve does not follow it: while it sticks, the
command ramps and the riser outlet does not answer; when it slips, the outlet jumps. The
riser is quasi-steady, so the T_rx innovation carries the gap between command and position
as a saw-tooth of the stick-slip period (about 10 minutes) and amplitude about the band S
(2 °C at S = 0.02 of the valve's range, ~6 noise stds). A sensor bias or drift on T_rx, a
valve bias or a process step shift the innovation's *mean* instead.

**Statistic.** ``h_k = e_k − m_k``, the whitened T_rx innovation less its EWMA mean
(rate ``highpass``: a mean shift leaves ``h`` within ~1/highpass samples), clipped at
``±clip``; ``s_k`` the EWMA (rate ``lam``) of ``h_k²``: about 1 on a healthy loop, 2.5-3 under
stiction at S = 0.02 (``lab/catalogue-isolator.md``). A step in the mean adds a bounded energy
to ``h²`` (at most ``clip²/(1 − (1 − highpass)²)``), so a small ``lam`` averages it away, while
the stick-slip cycle's excess lasts. The limit is ``margin`` times the largest ``s`` of the
healthy training records after the warm-up; above it, the diagnosis is ``valve-stiction``.

A model-based twin of ``stiction-ccf`` (:mod:`diagnosers.loops`), which reads the loop's own
records without a model and needs a cycle large enough to stand out of the noise
(``lab/stiction-detection.md``: 2 of 6 found at S = 0.02).
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np

from diagnosers.contract import Tier
from diagnosers.detection import NO_DIAGNOSIS, Decision, Detection
from diagnosers.diagnoser import Diagnoser
from diagnosers.episode.record import Episode
from diagnosers.filters.state_estimator import FCCStateEstimator
from diagnosers.filters.ukf_config import UKFConfig
from diagnosers.presets import keyword_init
from diagnosers.registry import register
from fcc_common.validation import Integer, Options, Real, check_params
from fcc_env.closed_loop import CLOSED_LOOP_CHANNELS
from fcc_env.params import MEASUREMENT_NAMES, FCCParams

__all__ = ["StictionUKF"]


@register("stiction-ukf")
class StictionUKF(Diagnoser):
    """A sticking valve: the excess variance of the model's T_rx innovation (module docstring).

    Args:
        channel: the measured channel whose innovation is watched (the loop's controlled
            variable); default ``"T_rx"``.
        highpass: EWMA rate of the innovation's mean that is taken out, in (0, 1); default 0.1.
        lam: EWMA rate of the squared remainder, in (0, 1); default 0.002 (about 500 samples).
        clip: the remainder's clip [innovation stds], in (0, 100]; default 3.
        margin: the limit over the largest healthy training value, in [1, 10]; default 1.55
            (chosen on validation seeds 5100-5102 of the ``concurrent`` track: the other faults'
            steps peak at 1.36 × the healthy peak, stiction at S = 0.02 holds above 1.9 ×).
        warm_up: samples the filter settles before the statistic starts, in [0, 100000];
            default 300.
        label: the fault named; default ``"valve-stiction"``.

    Attributes:
        classes_: ``(label,)``.
        limit_: the statistic's limit.
    """

    isolates: ClassVar[bool] = True
    tier: ClassVar[Tier] = Tier.GREY_BOX
    REQUIRED_CHANNELS: ClassVar[tuple[str, ...]] = CLOSED_LOOP_CHANNELS
    CONSTRAINTS: ClassVar[dict[str, Any]] = {
        "channel": Options(MEASUREMENT_NAMES),
        "highpass": Real(0, 1, closed="neither"),
        "lam": Real(0, 1, closed="neither"),
        "clip": Real(0, 100, closed="right"),
        "margin": Real(1, 10),
        "warm_up": Integer(0, 100_000),
    }
    DEFAULTS: ClassVar[dict[str, Any]] = {
        "channel": "T_rx",
        "highpass": 0.1,
        "lam": 0.002,
        "clip": 3.0,
        "margin": 1.55,
        "warm_up": 300,
        "label": "valve-stiction",
    }
    __init__ = keyword_init(DEFAULTS)

    channel: str
    highpass: float
    lam: float
    clip: float
    margin: float
    warm_up: int
    label: str

    def _validate_params(self) -> None:
        check_params(
            {k: v for k, v in self.get_params().items() if k in self.CONSTRAINTS}, self.CONSTRAINTS
        )

    # ---- fitting -------------------------------------------------------------------------------
    def _fit(self, episodes: list[Episode]) -> None:
        missing = [c for c in CLOSED_LOOP_CHANNELS if c not in self.channels_]
        if missing:
            raise ValueError(
                f"stiction-ukf reads the closed-loop channels {list(CLOSED_LOOP_CHANNELS)}; the "
                f"training episodes lack {missing}"
            )
        self.classes_ = (str(self.label),)
        self._build()
        peak = 0.0
        for ep in episodes:
            if ep.fault_onset is not None:
                continue
            s = self._statistic(self._innovations(np.asarray(ep.y, dtype=np.float64)))
            settled = s[self.warm_up :]
            if settled.size:
                peak = max(peak, float(np.max(settled)))
        if peak <= 0.0:
            raise ValueError(
                f"stiction-ukf needs healthy training episodes longer than warm_up = "
                f"{self.warm_up} samples"
            )
        self.limit_ = self.margin * peak
        self._finish()

    def _build(self) -> None:
        self.channel_idx_ = np.array([self.channels_.index(c) for c in CLOSED_LOOP_CHANNELS])
        config = UKFConfig(sample_time_s=self.sample_time_s_, closed_loop=True)
        self.estimator_ = FCCStateEstimator(FCCParams(), config)
        self.watch_ = MEASUREMENT_NAMES.index(self.channel)

    def _finish(self) -> None:
        self.signal_names_ = (f"innovation variance {self.channel}",)

    # ---- the statistic -------------------------------------------------------------------------
    def _innovations(self, y: np.ndarray) -> np.ndarray:
        est = self.estimator_.filter(y[None, :, self.channel_idx_], innovation_cov=False)
        return est.whitened[0][:, self.watch_]

    def _start(self) -> None:
        self._k, self._m, self._s = 0, 0.0, 1.0

    def _step(self, e: float) -> float:
        """One sample of the statistic (NaN during the warm-up)."""
        k = self._k
        self._k += 1
        if k < self.warm_up or not np.isfinite(e):
            return float("nan") if k < self.warm_up else self._s
        h = e - self._m
        self._m += self.highpass * h
        h = min(max(h, -self.clip), self.clip)
        self._s = (1.0 - self.lam) * self._s + self.lam * h * h
        return self._s

    def _statistic(self, e: np.ndarray) -> np.ndarray:
        self._start()
        return np.array([self._step(float(x)) for x in e])

    # ---- detection -----------------------------------------------------------------------------
    def _reset(self) -> None:
        self.estimator_.reset()
        self._start()

    def _decision(self, s: float) -> Decision:
        alarm = bool(np.isfinite(s) and s > self.limit_)
        return Decision(
            alarm=alarm,
            signal=np.array([s if np.isfinite(s) else 0.0]),
            lower=np.array([-np.inf]),
            upper=np.array([self.limit_]),
            residual=np.array([s if np.isfinite(s) else 0.0]),
            diagnosis=self.classes_[0] if alarm else NO_DIAGNOSIS,
            class_scores=np.array([float(alarm)]),
        )

    def _update(self, y: np.ndarray) -> Decision:
        step = self.estimator_.update(y[self.channel_idx_])
        return self._decision(self._step(float(step.whitened[self.watch_])))

    def _detect(self, y: np.ndarray) -> Detection:
        s = self._statistic(self._innovations(y))
        return Detection.from_decisions(
            [self._decision(float(x)) for x in s], self.signal_names_, self.classes_
        )

    # ---- persistence ---------------------------------------------------------------------------
    def _get_state(self) -> dict[str, np.ndarray]:
        return {"limit": np.array(self.limit_)}

    def _set_state(self, state: dict[str, np.ndarray]) -> None:
        limit = float(state["limit"])
        if not limit > 0:
            raise ValueError(f"saved limit must be positive, got {limit}")
        self.classes_ = (str(self.label),)
        self.limit_ = limit
        self._build()
        self._finish()
