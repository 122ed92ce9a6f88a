"""``ukf-glr``: the grey-box detector. The FCC model's filter, fitted to the healthy records, and
a GLR on its whitened innovations along each fault's model-derived direction.

A grey-box detector (:attr:`~diagnosers.contract.Tier.GREY_BOX`) knows the published model:
its equations (:mod:`fcc_env.physics`, run by :class:`~diagnosers.filters.FCCStateEstimator`),
the spec's nominal parameters as a prior, the sensor noise model and which parameter each fault
changes (the fault registry). It never reads a parameter of the plant it is scored on; what
differs from the prior it fits from its healthy training records. ``fit``:

1. the noise scale, from the innovations' variance (:func:`~diagnosers.filters.parameter_fit.
   estimate_noise_scale`; the ``noisy`` track's sensors are twice the spec's);
2. a few identifiable parameters (``fit_parameters``, default UA_2, UA_dg, UA_d1: the heat
   transfer coefficients the filter identifies, ``lab/filter-lab.md``) by the augmented filter
   (``fit_method="augmented"``) or by maximum likelihood of the innovations (``"ml"``);
3. whether the records come from one plant: with ``online="auto"``, when the records' own
   estimates of those parameters differ beyond their uncertainty (plants drawn per episode,
   the ``uncertain`` track), the detector estimates them online as random-walk states, with
   the feed coking factor (the drawn plants' feed-quality drift);
4. each fault's direction in the whitened innovations, from its own fitted model
   (:func:`~diagnosers.filters.model_directions.innovation_directions`), never from fault data;
5. the limits of :class:`~diagnosers.stages.innovation_stage.InnovationStage` (a GLR per
   direction, a variance CUSUM, one shared tail) at ``false_alarm_target`` on the training
   records' innovations.

Streaming (``reset`` / ``update``) runs the same compiled filter sample by sample and equals
``detect`` (the conformance suite checks it).
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np

from diagnosers.contract import Tier
from diagnosers.detection import Decision, Detection
from diagnosers.diagnoser import Diagnoser
from diagnosers.episode.record import Episode
from diagnosers.filters.model_directions import (
    SENSOR_DIRECTION_KINDS,
    fault_label,
    innovation_directions,
    sensor_fault_entries,
)
from diagnosers.filters.parameter_fit import (
    estimate_noise_scale,
    filter_records,
    fit_augmented,
    fit_maximum_likelihood,
)
from diagnosers.filters.state_estimator import FCCStateEstimator
from diagnosers.filters.ukf_config import LAG_CHANNELS, UKFConfig
from diagnosers.presets import keyword_init, preset
from diagnosers.registry import register
from diagnosers.stages.innovation_stage import DEFAULT_GLR_WINDOW, InnovationStage
from fcc_common.validation import (
    Boolean,
    Integer,
    IntegerSequence,
    Options,
    OptionSequence,
    Real,
    check_params,
    invalid,
)
from fcc_env.closed_loop import CLOSED_LOOP_CHANNELS
from fcc_env.faults import fault_names
from fcc_env.params import MEASUREMENT_NAMES, PARAM_FIELDS, FCCParams

__all__ = [
    "ONLINE_INITIAL_STATE_STD",
    "UKFGLR",
    "UKF_GLR_CONSTRAINTS",
    "UKF_GLR_DEFAULTS",
    "UKF_GLR_ROBUST",
    "UKF_GLR_SENSOR",
    "UkfGLRRobust",
    "UkfGLRSensor",
]

#: The model states' prior std [filter units] when the plant differs per record: each record
#: starts at its own plant's steady state, not the fitted one's (the lab notes' setting for
#: drawn plants; at the default 0.1 the first few hundred innovations of a drawn plant are
#: far from white, and the limits set on them far too high).
ONLINE_INITIAL_STATE_STD = 3.0


def _online_changes(names: tuple[str, ...]) -> dict[str, Any]:
    """The filter settings for records from different plants: ``names`` as random-walk states,
    the feed coking factor too (a drawn plant's feed-quality drift acts through it), and a
    wide prior of the model states."""
    return {
        "parameters": names,
        "estimate_coking": True,
        "initial_state_std": ONLINE_INITIAL_STATE_STD,
    }


#: :class:`UKFGLR`'s hyperparameters and defaults, in signature order.
UKF_GLR_DEFAULTS: dict[str, Any] = {
    "false_alarm_target": 0.002,
    "window": DEFAULT_GLR_WINDOW,
    "signature_windows": [30, 300],
    "omnibus_variance": 2.0,
    "warm_up": 300,
    "fit_parameters": ["UA_2", "UA_dg", "UA_d1"],
    "fit_method": "augmented",
    "estimate_noise": True,
    "online": "auto",
    "faults": None,
    "direction_seeds": [1000, 1001, 1002],
    "direction_onset": 500,
    "direction_size": 1.0,
    "bias_memory": None,
    "sensor_lags": None,
    "sensor_directions": None,
}
#: their declarative constraints, checked in ``fit``
UKF_GLR_CONSTRAINTS: dict[str, Any] = {
    "false_alarm_target": Real(0.0, 0.5, closed="neither"),
    "window": Integer(1, 5000),
    "signature_windows": IntegerSequence(1, 2000),
    "omnibus_variance": Real(1.0, 100.0, closed="right"),
    "warm_up": Integer(0, 100_000),
    "fit_parameters": (OptionSequence(PARAM_FIELDS), None),
    "fit_method": Options(("augmented", "ml", "none")),
    "estimate_noise": Boolean(),
    "online": Options(("auto", "always", "never")),
    "direction_seeds": IntegerSequence(0, 2**31 - 1),
    "direction_onset": Integer(150, 100_000),
    "direction_size": Real(0.0, 10.0, closed="right"),
    "bias_memory": (Integer(1, 100_000), None),
    "sensor_lags": (OptionSequence(LAG_CHANNELS), None),
    "sensor_directions": (OptionSequence(SENSOR_DIRECTION_KINDS), None),
}


@register("ukf-glr")
class UKFGLR(Diagnoser):
    """The FCC model's unscented Kalman filter fitted to the healthy records, with a GLR per
    model-derived fault direction and a variance CUSUM on its whitened innovations (module
    docstring: what ``fit`` does, in order). Grey box: it reads the published model, never the
    scored plant's parameters.

    Args:
        false_alarm_target: the share of the training records' samples the union of the
            statistics may alarm on, in (0, 0.5); default 0.002 (the reference rows' target).
        window: the GLR's onset search window [samples], in [1, 5000]; default 1000.
        signature_windows: samples after onset each fault direction averages (one GLR per fault
            and window); default [30, 300].
        omnibus_variance: the variance CUSUM's alternative factor, in (1, 100]; default 2.
        warm_up: samples at the start of a record whose innovations the statistics ignore
            while the filter settles (a drawn plant's states and parameters converge over
            hundreds of samples), in [0, 100000]; default 300. No alarm before it.
        fit_parameters: ``FCCParams`` fields fitted to the records (and estimated online when
            online); ``None``: none; default ``["UA_2", "UA_dg", "UA_d1"]``.
        fit_method: ``"augmented"`` (default): the fields as filter states, each record's end
            estimate pooled; ``"ml"``: maximum likelihood of the innovations (about 60 filter
            passes, ``lab/greybox-lab.md``); ``"none"``: the spec's nominal values.
        estimate_noise: fit the sensor-noise scale to the records (default True); False: the
            spec's noise.
        online: ``"auto"`` (default): estimate ``fit_parameters`` and the feed coking factor
            online when the records' estimates say they come from different plants;
            ``"always"``, ``"never"``.
        faults: registered faults to test for (``None``: :func:`fcc_env.fault_names`).
        direction_seeds: seeds of the own-model simulations behind the directions (the
            training range by default: 1000-1002).
        direction_onset: the simulated faults' onset sample, ≥ 150 (after the filter settles).
        direction_size: the simulated size, a multiple of each fault's registered magnitude.
        bias_memory: ``None`` (default): the statistics test the innovations as they are; an
            integer in [1, 100000]: they test them after removing each channel's slowly varying
            mean, learnt over about this many samples
            (:class:`~diagnosers.stages.innovation_stage.BiasTracker`): a plant's undeclared
            effects leave a bias the 1000-sample GLR would add up (``lab/greybox-lab.md``,
            ``mismatch``); a fault's step passes at once and fades over the memory.
        sensor_lags: thermocouples the filter reads through a first-order lag of unknown time
            constant, estimated online (``UKFConfig.sensor_lags``): ``None`` (default): none;
            a list of :data:`~diagnosers.filters.ukf_config.LAG_CHANNELS`.
        sensor_directions: ``None`` (default): directions for ``faults`` only; a list of
            sensor-fault kinds from :data:`~diagnosers.filters.model_directions.
            SENSOR_DIRECTION_KINDS` (``["drift"]``, ``["bias", "drift"]``): also each kind's
            direction on every measured channel (``sensor-drift`` on T_rx, …), from the same
            own-model simulation, one GLR per kind, channel and window.

    Decision arrays, names ``glr[fault,window]`` (``glr[sensor-drift@T_rx,30]``) … and
    ``cusum[nis]``: ``signal`` the statistics, ``upper`` their limits, ``residual`` the matched
    innovations d_gᵀe_t and the NIS.
    """

    DEFAULTS: ClassVar[dict[str, Any]] = UKF_GLR_DEFAULTS
    __init__ = keyword_init(DEFAULTS)
    tier: ClassVar[Tier] = Tier.GREY_BOX
    #: every Table 1 channel is read (the filter's measurement model)
    REQUIRED_CHANNELS: ClassVar[tuple[str, ...]] = MEASUREMENT_NAMES

    false_alarm_target: float
    window: int
    signature_windows: list[int]
    omnibus_variance: float
    warm_up: int
    fit_parameters: list[str] | None
    fit_method: str
    estimate_noise: bool
    online: str
    faults: list[str] | None
    direction_seeds: list[int]
    direction_onset: int
    direction_size: float
    bias_memory: int | None
    sensor_lags: list[str] | None
    sensor_directions: list[str] | None

    @classmethod
    def fast_params(cls) -> dict[str, Any]:
        return {
            "fit_method": "none",
            "estimate_noise": False,
            "online": "never",
            "faults": ["f1", "f3"],
            "direction_seeds": [1000],
            "direction_onset": 150,
            "warm_up": 50,
            "signature_windows": [30],
            "window": 200,
        }

    def _validate_params(self) -> None:
        check_params(self.get_params(), UKF_GLR_CONSTRAINTS)
        if self.faults is not None:
            check_params(
                {"faults": self.faults},
                {"faults": OptionSequence(fault_names(include_path_faults=True))},
            )
        if self.fit_method != "none" and not self.fit_parameters:
            raise invalid(
                "fit_parameters",
                self.fit_parameters,
                "at least one FCCParams field",
                f"fit_method={self.fit_method!r} fits them; 'none' fits nothing",
            )

    # ---- fitting -------------------------------------------------------------------------------
    def _records(self, episodes: list[Episode]) -> list[np.ndarray]:
        return [np.asarray(ep.y, dtype=np.float64)[:, self.channel_idx_] for ep in episodes]

    def _fit(self, episodes: list[Episode]) -> None:
        closed = set(CLOSED_LOOP_CHANNELS) <= set(self.channels_)
        need = CLOSED_LOOP_CHANNELS if closed else MEASUREMENT_NAMES
        missing = [c for c in need if c not in self.channels_]
        if missing:
            raise ValueError(
                f"ukf-glr reads every Table 1 channel {list(MEASUREMENT_NAMES)}; the training "
                f"episodes lack {missing}"
            )
        self.channel_idx_ = np.array([self.channels_.index(c) for c in need])
        records = self._records(episodes)
        prior = FCCParams()  # the spec's nominal values: the only parameters a grey box reads
        config = UKFConfig(
            sample_time_s=self.sample_time_s_,
            closed_loop=closed,
            sensor_lags=tuple(self.sensor_lags or ()),
        )
        if self.estimate_noise:  # first on the prior: the parameter fit weighs by the noise
            config = config.replace(noise_scale=estimate_noise_scale(prior, config, records))
        names = tuple(self.fit_parameters or ())
        params, varies = prior, False
        if names and (self.fit_method == "augmented" or self.online == "auto"):
            fit = fit_augmented(prior, config, records, names)
            varies = fit.varies
            if self.fit_method == "augmented":
                params = fit.params
        if names and self.fit_method == "ml":
            params = fit_maximum_likelihood(prior, config, records, names).params
        online = bool(names) and (self.online == "always" or (self.online == "auto" and varies))
        if online:
            config = config.replace(**_online_changes(names))
        if self.estimate_noise and (online or params != prior):  # again on the final model
            config = config.replace(noise_scale=estimate_noise_scale(params, config, records))
        self.fitted_values_ = np.array([float(getattr(params, n)) for n in names])
        self.noise_scale_ = float(config.noise_scale)
        self.online_ = online
        self.closed_loop_ = closed
        self._build()
        self.directions_ = innovation_directions(
            self.estimator_,
            self.fault_entries_,
            seeds=self.direction_seeds,
            onset=self.direction_onset,
            windows=self.signature_windows,
            size=self.direction_size,
        )
        stage = self._new_stage()
        healthy = [self._settled(r.whitened[0]) for r in filter_records(self.estimator_, records)]
        self.limits_ = stage.fit(healthy, self.false_alarm_target).limits_
        self._finish()

    def _build(self) -> None:
        """The estimator from the learned state (``fit`` and ``load``)."""
        names = tuple(self.fit_parameters or ())
        params = FCCParams().replace(
            **{n: float(v) for n, v in zip(names, self.fitted_values_, strict=True)}
        )
        config = UKFConfig(
            sample_time_s=self.sample_time_s_,
            closed_loop=self.closed_loop_,
            noise_scale=self.noise_scale_,
            sensor_lags=tuple(self.sensor_lags or ()),
        )
        if self.online_:
            config = config.replace(**_online_changes(names))
        self.estimator_ = FCCStateEstimator(params, config)
        self.faults_ = tuple(self.faults) if self.faults is not None else fault_names()
        self.fault_entries_ = (
            *self.faults_,
            *sensor_fault_entries(self.sensor_directions or (), MEASUREMENT_NAMES),
        )

    def _new_stage(self) -> InnovationStage:
        return InnovationStage(
            self.directions_,
            window=self.window,
            omnibus_variance=self.omnibus_variance,
            bias_memory=self.bias_memory,
        )

    def _finish(self) -> None:
        self.stage_ = self._new_stage()
        self.stage_.limits_ = self.limits_
        pairs = [(fault_label(f), w) for f in self.fault_entries_ for w in self.signature_windows]
        self.signal_names_ = (*(f"glr[{f},{w}]" for f, w in pairs), "cusum[nis]")
        self._lower = np.full(len(self.signal_names_), -np.inf)

    def _settled(self, e: np.ndarray) -> np.ndarray:
        """Innovations ``(T, 8)`` with the warm-up's set to NaN (no evidence to the stage)."""
        out = np.array(e, dtype=np.float64)
        out[: self.warm_up] = np.nan
        return out

    # ---- persistence ---------------------------------------------------------------------------
    def _get_state(self) -> dict[str, np.ndarray]:
        return {
            "channel_idx": self.channel_idx_,
            "fitted_values": self.fitted_values_,
            "noise_scale": np.array(self.noise_scale_),
            "online": np.array(self.online_),
            "closed_loop": np.array(self.closed_loop_),
            "directions": self.directions_,
            "limits": self.limits_,
        }

    def _set_state(self, state: dict[str, np.ndarray]) -> None:
        self.channel_idx_ = np.asarray(state["channel_idx"], dtype=np.int64)
        self.fitted_values_ = np.asarray(state["fitted_values"], dtype=np.float64)
        self.noise_scale_ = float(state["noise_scale"])
        self.online_ = bool(state["online"])
        self.closed_loop_ = bool(state["closed_loop"])
        self.directions_ = np.asarray(state["directions"], dtype=np.float64)
        self.limits_ = np.asarray(state["limits"], dtype=np.float64)
        self._build()
        n_sig = len(self.fault_entries_) * len(self.signature_windows) + 1
        if self.directions_.shape[0] != n_sig - 1 or self.limits_.shape != (n_sig,):
            raise ValueError(
                f"{self.directions_.shape[0]} directions and {self.limits_.shape} limits for "
                f"{len(self.fault_entries_)} faults x {len(self.signature_windows)} windows"
            )
        self._finish()

    # ---- detection -----------------------------------------------------------------------------
    def _reset(self) -> None:
        self.estimator_.reset()
        self.stage_.reset()
        self._k = 0

    def _update(self, y: np.ndarray) -> Decision:
        step = self.estimator_.update(y[self.channel_idx_])
        e = step.whitened if self._k >= self.warm_up else np.full_like(step.whitened, np.nan)
        self._k += 1
        s = self.stage_.step(e)
        return Decision(
            bool(self.stage_.alarm(s)),
            s,
            self._lower.copy(),
            self.limits_.copy(),
            self.stage_.matched(e[None])[0],
        )

    def _detect(self, y: np.ndarray) -> Detection:
        est = self.estimator_.filter(y[None, :, self.channel_idx_], innovation_cov=False)
        e = self._settled(est.whitened[0])
        s = self.stage_.statistics(e)
        n = s.shape[0]
        return Detection(
            alarm=self.stage_.alarm(s),
            signal=s,
            lower=np.broadcast_to(self._lower, s.shape).copy(),
            upper=np.broadcast_to(self.limits_, (n, self.limits_.shape[0])).copy(),
            residual=self.stage_.matched(e),
            signal_names=self.signal_names_,
        )


#: ``ukf-glr-robust``'s changes: a lag state per thermocouple, and the stage-1 heat loss and the
#: cracking activity fitted (online where the records' plants differ) beside the three.
UKF_GLR_ROBUST: dict[str, Any] = {
    "sensor_lags": list(LAG_CHANNELS),
    "fit_parameters": ["UA_1", "UA_2", "UA_dg", "UA_d1", "A_cr"],
}

UkfGLRRobust = preset(
    "ukf-glr-robust",
    UKFGLR,
    UKF_GLR_ROBUST,
    """``ukf-glr`` for a plant that does not match its model in ways it is not told: every
    process thermocouple read through a first-order lag whose coefficient the filter estimates
    (``sensor_lags``), and UA_1 and A_cr fitted beside UA_2, UA_dg, UA_d1 (online when the
    training plants differ: an undeclared stage-1 heat loss, a deactivating catalyst). On the
    ``mismatch`` track's validation seeds its healthy alarm share is 0.0019 against
    ``ukf-glr``'s 0.0098 (``lab/greybox-lab.md``, 2026-12-07); about twice its filter's cost.""",
    module=__name__,
)

#: ``ukf-glr-sensor``'s changes: a bias and a drift direction on every measured channel, and a
#: lower false-alarm target: the 16 more GLRs' limits, set on the training records, let more
#: alarms through on new healthy records than the 4 process faults' do (``lab/fault-tracks.md``)
UKF_GLR_SENSOR: dict[str, Any] = {
    "sensor_directions": list(SENSOR_DIRECTION_KINDS),
    "false_alarm_target": 0.001,
}

UkfGLRSensor = preset(
    "ukf-glr-sensor",
    UKFGLR,
    UKF_GLR_SENSOR,
    """``ukf-glr`` that also tests for a transmitter fault on each measured channel: besides each
    process fault's direction, a sensor bias's and a sensor drift's direction on every channel
    (``sensor_directions``), each from its own fitted model like the others, at half the
    false-alarm target.""",
    module=__name__,
)
