"""``sensor-validation``: sensor faults detected and isolated by analytical redundancy (issue 43
item 6, first point).

A bank of nine FCC state estimators (:mod:`diagnosers.sensors.loo_bank`): one on every sensor,
one per sensor leaving it out (the generalised observer scheme, Frank 1990), plus two checks
that need no model, the transmitter's noise level and held values (a DCS's own validation
checks). :mod:`diagnosers.sensors.sensor_checks` turns them into an alarm, the faulty sensor and
the kind of its fault.

**Tier: grey box.** The filters run the published model with the spec's nominal
:class:`~fcc_env.FCCParams` (or those given in ``params``); nothing of the scored plant is read.
The fault data are not learned from: the labelled training faults name the classes
(``classes_``: the sensor-fault kinds among them; a kind not among them is said ``"unknown"``).
Healthy training records set the limits of the checks (their largest value times ``margin``).

**What it says.** :attr:`Detection.diagnosis` is the fault's registry label, the kind
(``sensor-bias``, ...): the tracks score a sensor fault by that name
(:func:`fcc_env.faults.isolation_outcome`); the channel is a field of the fault of its own, and
:meth:`SensorValidation.sensors` gives it per sample (``""`` while not alarmed), and
:attr:`SensorValidation.named_sensor` after each streamed :meth:`update` (a supervisor that
rebuilds a loop needs the channel, not only the kind).
``Detection.residual`` holds each sensor's reading less its leave-out filter's prediction, in
standard deviations. ``class_scores`` is 1 for the kind said and 0 for the others: the rule
decides, it does not weigh (no posterior either).

**Dropouts** arrive as the env delivers them: the last good value held, never NaN
(:mod:`fcc_env.sensor_faults`); the held-value check finds them.
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np

from diagnosers.contract import Tier
from diagnosers.detection import NO_DIAGNOSIS, UNKNOWN, Decision, Detection
from diagnosers.diagnoser import Diagnoser
from diagnosers.episode.record import Episode
from diagnosers.filters import UKFConfig
from diagnosers.filters.ukf_config import check_fcc_channels, model_params
from diagnosers.presets import keyword_init
from diagnosers.registry import register
from diagnosers.sensors.glr_bank import GLRBank
from diagnosers.sensors.loo_bank import LeaveOneOutBank
from diagnosers.sensors.sensor_checks import KINDS, decide_run, new_state
from fcc_common.validation import Integer, Options, Real, check_params
from fcc_env.closed_loop import CLOSED_LOOP_CHANNELS
from fcc_env.params import MEASUREMENT_NAMES, FCCParams

__all__ = ["SensorValidation"]

#: A channel's noise-check clip, in multiples of its mean healthy |Δy|.
CLIP_FACTOR = 5.0


@register("sensor-validation")
class SensorValidation(Diagnoser):
    """Sensor validation by a generalised observer scheme plus noise and held-value checks.

    Args:
        params: the model's parameters: ``None`` (default) the spec's nominal
            :class:`~fcc_env.FCCParams`, or a dict of FCCParams fields changed from nominal.
        noise_scale: the measurement-noise multiplier the filters assume, in (0, 10]; default 1.
        lam: EWMA rate of the filters' whitened innovations, in (0, 1); default 0.02.
        lam_iso: EWMA rate of the slow consistency that names the sensor, in (0, 1); default
            0.001 (:mod:`diagnosers.sensors.sensor_checks`).
        lam_noise: EWMA rate of the noise check, in (0, 1); default 0.02.
        hold_decay: decay per sample of the held-value count, in (0, 1); default 0.01 (two
            repeats within about 70 samples make a hold).
        margin: each check's limit over its largest healthy training value, in [1, 10];
            default 1.2.
        warmup: samples the filters settle before any check counts, in [1, 100000];
            default 200.
        t_drift: the residual slope's t statistic from which a fault is a drift, in (0, 100];
            default 4.
        step_ratio: the residual's mean since the alarm over its level before it from which
            a young fault is a bias (a step), in [1, 1000]; default 3.
        settle: samples of an alarm after which a fault without a slope is a bias, in
            [3, 100000]; default 300.
        glr_window: samples from an alarm's start that the GLR bank of bias hypotheses names
            the sensor (:mod:`diagnosers.sensors.glr_bank`; the slow rule after them), in
            [0, 100000]; 0 turns the bank off; default 0 (off): the bank names a bias's kind
            better but its sensor worse (a T_ar bias as R_ar, whose evidence is within a few
            per cent), and a supervisor that rebuilds a loop acts on the sensor named; 3000
            (the rest of a ``sensor`` track episode) is the setting measured in
            ``lab/sensor-validation.md``.
        glr_offset: the bank's trial offset, in each channel's unit, in (0, 100]; default 5
            (inside the ``sensor`` track's sizes 2-10).
        glr_ramp: within the bank's window, the evidence (nats) a ramp beside the step adds
            from which the fault is a drift, else a bias, in [0, 10⁶]; 0 leaves the kind to
            the residual's tests; default 20 (validation seeds: a bias's ramp evidence stayed
            under 17 over 3000 samples but once, a drift's passed 12-50 at 300 samples).
        glr_ratio: the bank names only where its largest GLR is this many times the second
            (else the slow rule names, and the residual's tests say the kind), in [1, 100];
            default 1.
        glr_settle: samples of the bank's window before it says the kind (the residual's
            tests before: they know the level before the alarm, which tells a young drift),
            in [0, 100000]; default 300.
        glr_names: what the bank names within its window, one of ``"both"`` (default: the
            sensor, and the kind of the fault of that sensor) or ``"kind"`` (only the kind: the
            sensor stays the slow rule's, which tells a T_ar bias from an R_ar one where the
            bank's evidence for the two is within a few per cent).
        glr_restart: quiet samples (no alarm) before an alarm from which it starts the bank
            afresh within a window, in [0, 100000]; 0 (default) never: a window runs its
            ``glr_window`` samples from the alarm that began it, even a short false alarm's
            before the fault (which then holds the fault's step for a ramp); 200 is the
            setting measured in ``lab/sensor-validation.md``.

    Attributes:
        classes_: the sensor-fault kinds among the labelled training faults.
        limits_: the consistency limits per filter (9, fast and slow) and noise limits and clips
            per channel.
    """

    isolates: ClassVar[bool] = True
    tier: ClassVar[Tier] = Tier.GREY_BOX
    CONSTRAINTS: ClassVar[dict[str, Any]] = {
        "noise_scale": Real(0, 10, closed="right"),
        "lam": Real(0, 1, closed="neither"),
        "lam_iso": Real(0, 1, closed="neither"),
        "lam_noise": Real(0, 1, closed="neither"),
        "hold_decay": Real(0, 1, closed="neither"),
        "margin": Real(1, 10),
        "warmup": Integer(1, 100_000),
        "t_drift": Real(0, 100, closed="right"),
        "step_ratio": Real(1, 1000),
        "settle": Integer(3, 100_000),
        "glr_window": Integer(0, 100_000),
        "glr_offset": Real(0, 100, closed="right"),
        "glr_ramp": Real(0, 1e6),
        "glr_ratio": Real(1, 100),
        "glr_settle": Integer(0, 100_000),
        "glr_names": Options(("both", "kind")),
        "glr_restart": Integer(0, 100_000),
    }
    DEFAULTS: ClassVar[dict[str, Any]] = {
        "params": None,
        "noise_scale": 1.0,
        "lam": 0.02,
        "lam_iso": 0.001,
        "lam_noise": 0.02,
        "hold_decay": 0.01,
        "margin": 1.2,
        "warmup": 200,
        "t_drift": 4.0,
        "step_ratio": 3.0,
        "settle": 300,
        "glr_window": 0,
        "glr_offset": 5.0,
        "glr_ramp": 20.0,
        "glr_ratio": 1.0,
        "glr_settle": 300,
        "glr_names": "both",
        "glr_restart": 0,
    }
    __init__ = keyword_init(DEFAULTS)

    params: dict[str, float] | None
    noise_scale: float
    lam: float
    lam_iso: float
    lam_noise: float
    hold_decay: float
    margin: float
    warmup: int
    t_drift: float
    step_ratio: float
    settle: int
    glr_window: int
    glr_offset: float
    glr_ramp: float
    glr_ratio: float
    glr_settle: int
    glr_names: str
    glr_restart: int

    @classmethod
    def fast_params(cls) -> dict[str, Any]:
        return {"warmup": 100}

    def _validate_params(self) -> None:
        check_params(
            {k: v for k, v in self.get_params().items() if k in self.CONSTRAINTS}, self.CONSTRAINTS
        )
        self.model_params()

    def model_params(self) -> FCCParams:
        """The :class:`~fcc_env.FCCParams` the filters use (``params`` resolved)."""
        return model_params(self.params)

    # ---- fitting -------------------------------------------------------------------------------
    def _fit(self, episodes: list[Episode]) -> None:
        labels = {ep.scenario for ep in episodes if ep.fault_onset is not None}
        self.classes_ = tuple(k for k in KINDS if k in labels) or tuple(sorted(labels))
        self._build()
        healthy = [ep for ep in episodes if ep.fault_onset is None]
        C = self.bank_.n_channels
        if any(ep.n_samples <= self.warmup + 10 for ep in healthy):
            raise ValueError(
                f"sensor-validation needs healthy training episodes longer than warmup + 10 = "
                f"{self.warmup + 10} samples; got {[ep.n_samples for ep in healthy]}"
            )
        diffs = np.concatenate([np.abs(np.diff(ep.y[self.warmup :, :C], axis=0)) for ep in healthy])
        self.clip_ = CLIP_FACTOR * np.maximum(diffs.mean(axis=0), 1e-9)
        H = self.bank_.n_filters
        self.lim_m_ = np.ones(H)
        self.lim_s_ = np.ones(H)
        self.lim_d_ = np.ones(C)
        self.lim_e_ = np.ones(C)
        cons_max, slow_max = np.zeros(H), np.zeros(H)
        diff_max, ded_max = np.zeros(C), np.zeros(C)
        for ep in healthy:
            self._reset()
            sig, cons, _, _, ded, slow = self._checks(ep.y)
            cons_max = np.maximum(cons_max, cons[self.warmup :].max(axis=0))
            slow_max = np.maximum(slow_max, slow[self.warmup :].max(axis=0))
            diff_max = np.maximum(diff_max, sig[self.warmup :, 1 : 1 + C].max(axis=0))
            ded_max = np.maximum(ded_max, np.abs(_ewma(ded, self.lam)[self.warmup :]).max(axis=0))
        self.lim_m_ = self.margin * np.maximum(cons_max, 1e-9)
        self.lim_s_ = np.maximum(slow_max, 1e-9)  # the rule's floor is a share of it
        self.lim_d_ = self.margin * np.maximum(diff_max, 1e-12)
        self.lim_e_ = self.margin * np.maximum(ded_max, 1e-9)
        self._finish()

    def _build(self) -> None:
        check_fcc_channels("sensor-validation", self.channels_)
        config = UKFConfig(
            noise_scale=self.noise_scale,
            sample_time_s=self.sample_time_s_,
            closed_loop=self.channels_ == CLOSED_LOOP_CHANNELS,
        )
        self.bank_ = LeaveOneOutBank(self.model_params(), config)
        self.glr_ = GLRBank(self.bank_.estimator, self.glr_offset)

    def _finish(self) -> None:
        names = MEASUREMENT_NAMES
        self.signal_names_ = (
            "consistency of the all-sensor filter",
            *(f"noise level {n}" for n in names),
            *(f"held values {n}" for n in names),
        )

    @property
    def limits_(self) -> dict[str, np.ndarray]:
        return {
            "consistency": self.lim_m_,
            "slow": self.lim_s_,
            "noise": self.lim_d_,
            "clip": self.clip_,
            "dedicated": self.lim_e_,
        }

    # ---- detection -----------------------------------------------------------------------------
    def _reset(self) -> None:
        self._named = ""
        self._M, self._P = self.bank_.start()
        self._state = new_state(self.bank_.n_filters, self.bank_.n_channels)
        self._glr: dict[str, Any] = {"left": 0, "bank": None, "quiet": 0}

    def _checks(self, Y: np.ndarray) -> tuple[np.ndarray, ...]:
        """``(signal, consistency, kind, channel, dedicated residual, slow consistency)`` of the
        next samples."""
        C = self.bank_.n_channels
        out = self.bank_.run(self._M, self._P, Y)
        T = Y.shape[0]
        signal = np.empty((T, 1 + 2 * C))
        cons = np.empty((T, self.bank_.n_filters))
        slow = np.empty((T, self.bank_.n_filters))
        kind = np.empty(T, dtype=np.int64)
        channel = np.empty(T, dtype=np.int64)
        s = self._state
        named, named_kind = np.full(T, -1, dtype=np.int64), np.zeros(T, dtype=np.int64)
        rule_channel = None
        if self.glr_window > 0:
            named, named_kind, rule_channel = self._glr_named(out, Y, s)
        self._decide(out, Y, s, (named, named_kind), signal, cons, slow, kind, channel)
        if rule_channel is not None and self.glr_names == "kind":
            # the trial run's channel is the slow rule's: naming changes no alarm or state
            channel[:] = rule_channel
        return signal, cons, kind, channel, np.nan_to_num(out.dedicated), slow

    def _decide(self, out, Y, s, named, signal, cons, slow, kind, channel) -> None:
        """:func:`decide_run` over the bank's output ``out`` with the state ``s`` (in place)."""
        C = self.bank_.n_channels
        decide_run(
            out.white,
            out.dedicated,
            np.ascontiguousarray(Y[:, :C], dtype=np.float64),
            self.lam,
            self.lam_iso,
            self.lam_noise,
            self.hold_decay,
            float(self.warmup),
            self.lim_m_,
            self.lim_s_,
            self.lim_d_,
            self.clip_,
            self.lim_e_,
            self.t_drift,
            self.step_ratio,
            float(self.settle),
            s["count"],
            s["ewma"],
            s["slow"],
            s["prev"],
            s["diff"],
            s["held"],
            s["breaks"],
            s["last_held"],
            s["reg"],
            s["regj"],
            s["alarmed"],
            s["ded_fast"],
            s["ded_slow"],
            s["pre"],
            *named,
            signal,
            cons,
            slow,
            kind,
            channel,
        )

    def _glr_named(
        self, out, Y: np.ndarray, s: dict[str, np.ndarray]
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per sample, the channel the GLR bank names (−1 outside its windows), the kind it
        says (1 bias, 2 drift, 0 none: ``glr_ramp`` 0) of it and the channel the rule names
        without the bank (−1 while not alarmed): the bank starts
        from the all-sensor filter's prior at an alarm's first sample (the alarms of a trial
        run of the rule on a copy of the state: naming does not change them) and names the
        next ``glr_window`` samples; an alarm that starts after ``glr_restart`` quiet samples
        or more starts it afresh (a window begun at a short false alarm would otherwise hold
        a fault that starts later for a ramp)."""
        T, H, C = out.white.shape
        trial = {k: v.copy() for k, v in s.items()}
        sig, cn, sl = np.empty((T, 1 + 2 * C)), np.empty((T, H)), np.empty((T, H))
        k1, c1 = np.empty(T, dtype=np.int64), np.empty(T, dtype=np.int64)
        none = (np.full(T, -1, dtype=np.int64), np.zeros(T, dtype=np.int64))
        self._decide(out, Y, trial, none, sig, cn, sl, k1, c1)
        alarm = k1 > 0
        starts = alarm & ~np.concatenate([[s["alarmed"][0] > 0], alarm[:-1]])
        restart, self._glr["quiet"] = _restarts(alarm, starts, self._glr["quiet"], self.glr_restart)
        named, named_kind = none
        g, k = self._glr, 0
        while k < T:
            if g["left"] <= 0 and not starts[k]:
                nxt = np.flatnonzero(starts[k:])
                if nxt.size == 0:
                    break
                k += int(nxt[0])
            if g["left"] <= 0 or restart[k]:
                g["bank"] = self.glr_.start(out.prior_m[k], out.prior_p[k])
                g["left"] = self.glr_window
            n = min(g["left"], T - k)
            again = np.flatnonzero(restart[k + 1 : k + n])
            n = int(again[0]) + 1 if again.size else n
            gain, ramp, _ = self.glr_.run(g["bank"], Y[k : k + n], out.white[k : k + n, 0])
            c = np.argmax(gain, axis=1)
            top2 = np.sort(gain, axis=1)[:, -2:]
            sure = top2[:, 1] >= self.glr_ratio * top2[:, 0]
            named[k : k + n] = np.where(sure, c, -1)
            if self.glr_ramp > 0:
                drift = ramp[np.arange(n), c] > self.glr_ramp
                age = g["bank"]["age"][0] - n + 1 + np.arange(n)  # 1 at the window's start
                says = sure & (age > self.glr_settle)
                named_kind[k : k + n] = np.where(says, np.where(drift, 2, 1), 0)
            g["left"] -= n
            k += n
        return named, named_kind, c1

    def _labels(self, kind: np.ndarray, channel: np.ndarray) -> tuple[np.ndarray, ...]:
        """Per sample: the diagnosis, the one-hot class scores and the sensor named."""
        table = np.array(
            [NO_DIAGNOSIS, *(k if k in self.classes_ else UNKNOWN for k in KINDS)], dtype=object
        )
        diagnosis = table[kind].astype(str)
        scores = (diagnosis[:, None] == np.array(self.classes_)[None, :]).astype(np.float64)
        names = np.array([*MEASUREMENT_NAMES, ""], dtype=object)
        return diagnosis, scores, names[channel].astype(str)

    def _run(self, Y: np.ndarray) -> tuple[Detection, np.ndarray]:
        signal, _, kind, channel, ded, _ = self._checks(Y)
        diagnosis, scores, sensors = self._labels(kind, channel)
        det = Detection(
            alarm=kind > 0,
            signal=signal,
            lower=np.full(signal.shape, -np.inf),
            upper=np.ones(signal.shape),
            residual=ded,
            signal_names=self.signal_names_,
            diagnosis=diagnosis,
            class_scores=scores,
            class_names=self.classes_,
        )
        return det, sensors

    def _detect(self, y: np.ndarray) -> Detection:
        return self._run(y)[0]

    def sensors(self, episode: Episode) -> np.ndarray:
        """The sensor named at each sample of ``episode`` (``(T,)`` str, ``""`` while not
        alarmed): the channel of the fault :meth:`detect` diagnoses."""
        self._check_fitted()
        self._check_episode(episode)
        self._reset()
        try:
            return self._run(np.asarray(episode.y, dtype=np.float64))[1]
        finally:
            self._reset()

    @property
    def named_sensor(self) -> str:
        """The sensor named at the last :meth:`update` (``""`` while not alarmed, or before any
        update since :meth:`reset`): the streaming twin of :meth:`sensors`."""
        return getattr(self, "_named", "")

    def _update(self, y: np.ndarray) -> Decision:
        signal, _, kind, channel, ded, _ = self._checks(y[None, :])
        diagnosis, scores, sensors = self._labels(kind, channel)
        self._named = str(sensors[0])
        return Decision(
            alarm=bool(kind[0] > 0),
            signal=signal[0],
            lower=np.full(signal.shape[1], -np.inf),
            upper=np.ones(signal.shape[1]),
            residual=ded[0],
            diagnosis=str(diagnosis[0]),
            class_scores=scores[0],
        )

    # ---- persistence ---------------------------------------------------------------------------
    def _get_state(self) -> dict[str, np.ndarray]:
        return {
            "classes": np.array(self.classes_, dtype=str),
            "lim_m": self.lim_m_,
            "lim_s": self.lim_s_,
            "lim_d": self.lim_d_,
            "clip": self.clip_,
            "lim_e": self.lim_e_,
        }

    def _set_state(self, state: dict[str, np.ndarray]) -> None:
        self.classes_ = tuple(str(c) for c in state["classes"])
        self._build()
        H, C = self.bank_.n_filters, self.bank_.n_channels
        arrays = {"lim_m": H, "lim_s": H, "lim_d": C, "clip": C, "lim_e": C}
        for key, n in arrays.items():
            a = np.asarray(state[key], dtype=np.float64).reshape(-1)
            if a.shape != (n,) or not np.all(np.isfinite(a) & (a > 0)):
                raise ValueError(f"saved {key} must be {n} positive numbers, got {a.tolist()}")
            setattr(self, f"{key}_", a)
        self._finish()


def _restarts(
    alarm: np.ndarray, starts: np.ndarray, quiet_before: int, min_quiet: int
) -> tuple[np.ndarray, int]:
    """The alarm starts (bool ``starts``) after ``min_quiet`` quiet samples or more (none where
    it is 0), given the quiet samples ``quiet_before`` the first sample, and the quiet samples
    after the last."""
    T = alarm.size
    idx = np.arange(T)
    last = np.maximum.accumulate(np.where(alarm, idx, -1))  # the last alarm at or before k
    before = np.concatenate([[-1], last[:-1]])
    quiet = np.where(before >= 0, idx - before - 1, idx + quiet_before)
    after = T - 1 - int(last[-1]) if last[-1] >= 0 else quiet_before + T
    if min_quiet <= 0:
        return np.zeros(T, dtype=bool), after
    return starts & (quiet >= min_quiet), after


def _ewma(x: np.ndarray, lam: float) -> np.ndarray:
    """The EWMA (rate ``lam``, from 0) of the rows of ``x`` (T, k)."""
    out = np.empty_like(x)
    a = np.zeros(x.shape[1])
    for k in range(x.shape[0]):
        a = (1.0 - lam) * a + lam * x[k]
        out[k] = a
    return out
