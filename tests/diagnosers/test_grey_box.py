"""The grey-box tier: ``ukf-glr`` and the rule that no grey-box diagnoser reads the parameters
of the plant it is scored on (issue 42 item 3).

The guard: episodes are simulated on plants drawn per seed (:class:`fcc_env.PlantUncertainty`,
the ``uncertain`` track's), then every read of an ``FCCParams`` field is watched while a
grey-box diagnoser fits and detects; an object that carries a drawn plant's values (its
kinetic constants, which no fit of the grey box touches and no fit lands on exactly) fails the
test. A diagnoser that built its filter, its simulations or anything else from the drawn plant
would read those fields; the cheating diagnoser below proves the guard fails then.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from scipy import stats

import diagnosers
import fcc_env
from diagnosers import Episode, Tier
from diagnosers.filters import UKFConfig
from diagnosers.filters.parameter_fit import estimate_noise_scale, fit_augmented
from diagnosers.filters.ukf_glr import UKFGLR
from diagnosers.stages.innovation_stage import InnovationStage, union_limits, variance_llr
from fcc_env.params import MEASUREMENT_NAMES, FCCParams
from fcc_env.uncertainty import PlantUncertainty

GREY = [n for n in diagnosers.available() if diagnosers.diagnoser_class(n).tier == Tier.GREY_BOX]
TRAIN, TEST = [1000, 1001], 3
N = 700


class PlantParameterRead(AssertionError):
    """A grey-box diagnoser read a parameter of the plant it is scored on."""


def _drawn_episodes(closed_loop: bool = False) -> tuple[list[Episode], Episode, list[FCCParams]]:
    unc = PlantUncertainty()
    # a diagnoser of the closed loop's channels (stiction-ukf) watches the closed-loop plant
    plant = fcc_env.PlantConfig.build(regulatory=True if closed_loop else None)
    b = fcc_env.simulate_episodes(TRAIN, N, plant_uncertainty=unc, plant=plant)
    f1 = fcc_env.FaultSpec(scenario="f1", onset=400)
    t = fcc_env.simulate_episodes([TEST], N, fault=f1, plant_uncertainty=unc, plant=plant)
    hidden = [unc.draw(s).params for s in [*TRAIN, TEST]]
    return Episode.from_batch(b), Episode.from_batch(t)[0], hidden


def _guarded(monkeypatch: pytest.MonkeyPatch, hidden: list[FCCParams]) -> None:
    """From now on, reading any field of an FCCParams that carries a drawn plant's kinetic
    constants raises :class:`PlantParameterRead`."""
    keys = {(h.k_cb, h.A_cr) for h in hidden}
    assert all(k != (FCCParams().k_cb, FCCParams().A_cr) for k in keys)  # the draws differ
    plain = object.__getattribute__

    def guard(self: FCCParams, name: str) -> Any:
        if (plain(self, "k_cb"), plain(self, "A_cr")) in keys:
            raise PlantParameterRead(f"read {name} of the scored plant's parameters")
        return plain(self, name)

    monkeypatch.setattr(FCCParams, "__getattribute__", guard)


def _fit_and_detect(det: diagnosers.Diagnoser, train: list[Episode], test: Episode) -> Any:
    return det.fit(train).detect(test)


def test_the_registry_has_a_grey_box_tier() -> None:
    assert "ukf-glr" in GREY
    assert diagnosers.diagnoser_class("pca").tier == Tier.BLACK_BOX


@pytest.mark.parametrize("name", GREY)
def test_no_grey_box_diagnoser_reads_the_scored_plants_parameters(
    name: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    cls = diagnosers.diagnoser_class(name)
    closed = "u_F" in getattr(cls, "REQUIRED_CHANNELS", ())
    train, test, hidden = _drawn_episodes(closed)
    online = {"online": "always"} if "online" in cls.param_names() else {}
    det = diagnosers.make(name, **{**cls.fast_params(), **online})
    if cls.isolates:  # an isolator also gets labelled faults, on the same drawn plants
        f2 = fcc_env.FaultSpec(scenario="f2", onset=400)
        unc = PlantUncertainty()
        plant = fcc_env.PlantConfig.build(regulatory=True if closed else None)
        train = train + Episode.from_batch(
            fcc_env.simulate_episodes(TRAIN, N, fault=f2, plant_uncertainty=unc, plant=plant)
        )
    _guarded(monkeypatch, hidden)
    detection = _fit_and_detect(det, train, test)
    assert detection.alarm.shape == (test.n_samples,)


class _Cheater(UKFGLR):
    """A grey box that takes its model from the drawn plant of its first training record."""

    def _fit(self, episodes: list[Episode]) -> None:
        seed = episodes[0].seed
        assert seed is not None
        self.fitted_values_ = np.array(
            [getattr(PlantUncertainty().draw(seed).params, n) for n in self.fit_parameters or ()]
        )
        super()._fit(episodes)


def test_the_guard_catches_a_diagnoser_that_reads_the_plant(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    train, test, hidden = _drawn_episodes()
    det = _Cheater(**UKFGLR.fast_params())
    _guarded(monkeypatch, hidden)
    with pytest.raises(PlantParameterRead):
        _fit_and_detect(det, train, test)


# ---- the parts -----------------------------------------------------------------------------
def test_variance_llr_is_the_gaussian_log_likelihood_ratio() -> None:
    e = np.random.default_rng(0).normal(size=(50, 8))
    v = 2.5
    want = np.sum(stats.norm.logpdf(e, scale=np.sqrt(v)) - stats.norm.logpdf(e), axis=1)
    assert np.allclose(variance_llr(np.sum(e**2, axis=1), 8, v), want)


def test_innovation_stage_streams_as_it_filters_and_holds_its_target() -> None:
    rng = np.random.default_rng(1)
    d = np.linalg.qr(rng.normal(size=(8, 3)))[0].T  # 3 unit directions
    stage = InnovationStage(d, window=100).fit([rng.normal(size=(20_000, 8))], 0.01)
    e = rng.normal(size=(400, 8))
    e[200:] += 0.8 * d[1]  # a step along direction 1
    e[5] = np.nan  # a skipped sample
    batch = stage.statistics(e)
    stage.reset()
    assert np.allclose(np.array([stage.step(x) for x in e]), batch, rtol=1e-12, atol=1e-9)
    alarm = stage.alarm(batch)
    assert alarm[200:260].any() and alarm[:200].mean() < 0.05
    fresh = rng.normal(size=(20_000, 8))
    assert np.mean(stage.alarm(stage.statistics(fresh))) < 0.03
    with pytest.raises(ValueError, match="stats"):
        union_limits(np.zeros(5), 0.01)


def test_the_fit_finds_the_noise_scale_and_a_changed_heat_transfer() -> None:
    true = FCCParams().replace(UA_2=FCCParams().UA_2 * 1.06)
    plant = fcc_env.PlantConfig.build(params=true, noise_scale=2.0)
    ys = [
        np.asarray(y, dtype=np.float64)
        for y in fcc_env.simulate_episodes([1000, 1001, 1002], 1500, plant=plant).observations
    ]
    scale = estimate_noise_scale(FCCParams(), UKFConfig(), ys)
    assert scale == pytest.approx(2.0, rel=0.05)
    fit = fit_augmented(FCCParams(), UKFConfig(noise_scale=scale), ys, ["UA_2"])
    assert fit.values[0] == pytest.approx(true.UA_2, rel=0.02)
    assert abs(fit.values[0] - true.UA_2) < 0.5 * abs(FCCParams().UA_2 - true.UA_2)
    assert not fit.varies  # one plant


def test_ukf_glr_detects_a_paper_f1_at_once_and_its_directions_come_from_its_model() -> None:
    b = fcc_env.simulate_episodes([1000, 1001], 900)
    det = diagnosers.make("ukf-glr", **UKFGLR.fast_params()).fit(Episode.from_batch(b))
    assert det.tier == Tier.GREY_BOX and not det.online_
    assert np.allclose(np.linalg.norm(det.directions_, axis=1), 1.0)
    assert det.directions_[0] @ det.directions_[1] < 0.5  # f1 and f3 apart
    f1 = fcc_env.FaultSpec(scenario="f1", onset=500)
    (ep,) = Episode.from_batch(fcc_env.simulate_episodes([7], 900, fault=f1))
    alarm = det.detect(ep).alarm
    assert alarm[500:505].any() and not alarm[:500].any()


def test_ukf_glr_refuses_episodes_without_the_models_channels() -> None:
    b = fcc_env.simulate_episodes([1000], 400)
    (ep,) = Episode.from_batch(b)
    cut = Episode(ep.y[:, 3:], channels=ep.channels[3:], sample_time_s=ep.sample_time_s)
    with pytest.raises(ValueError, match="lack"):
        diagnosers.make("ukf-glr", **UKFGLR.fast_params()).fit([cut])
    with pytest.raises(ValueError, match="fit_parameters"):
        diagnosers.make("ukf-glr", fit_parameters=None, fit_method="ml").fit([ep])


def test_ukf_glr_sensor_directions_add_one_glr_per_kind_channel_and_window(tmp_path: Any) -> None:
    b = fcc_env.simulate_episodes([1000], 600)
    params = {**UKFGLR.fast_params(), "faults": ["f1"], "sensor_directions": ["drift"]}
    det = diagnosers.make("ukf-glr", **params).fit(Episode.from_batch(b))
    n_ch = len(MEASUREMENT_NAMES)
    assert det.directions_.shape == (1 + n_ch, n_ch)  # f1, then a drift per channel (1 window)
    assert "glr[sensor-drift@T_rx,30]" in det.signal_names_
    # each channel's drift moves its own channel's innovation most (open loop: no controller
    # spreads it)
    drifts = det.directions_[1:]
    assert list(np.abs(drifts).argmax(axis=1)) == list(range(n_ch))
    back = diagnosers.Diagnoser.load(det.save(tmp_path / "det"))
    assert np.array_equal(back.directions_, det.directions_)
    ep = Episode.from_batch(b)[0]
    assert np.array_equal(back.detect(ep).signal, det.detect(ep).signal)


def test_ukf_glr_refuses_an_unknown_sensor_direction_kind() -> None:
    with pytest.raises(ValueError, match=r"sensor_directions.*bias.*drift"):
        diagnosers.make("ukf-glr", sensor_directions=["stuck"]).validate_params()
    with pytest.raises(ValueError, match="sensor_directions"):
        diagnosers.make("ukf-glr", sensor_directions="drift").validate_params()


def test_sensor_fault_entries_name_each_kind_on_each_channel_and_refuse_others() -> None:
    from diagnosers.filters.model_directions import sensor_fault_entries

    assert sensor_fault_entries(["bias", "drift"], ["T_rx"]) == [
        ("sensor-bias", "T_rx"),
        ("sensor-drift", "T_rx"),
    ]
    with pytest.raises(ValueError, match=r"channel.*T_rx"):
        sensor_fault_entries(["drift"], ["T_xx"])
