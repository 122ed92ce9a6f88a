"""The uncertain track's plant draws (fcc_env.uncertainty)."""

from __future__ import annotations

import inspect
import json
import math
import random

import numpy as np
import pytest

import fcc_env
from fcc_env import FCCParams
from fcc_env.uncertainty import (
    GROUP_FIELDS,
    MAX_HALF_RANGE,
    AmbientCycle,
    FeedQualityDrift,
    PlantUncertainty,
)

T = 400  # samples per test episode: short, the tests check bookkeeping, not dynamics


def drawn_episodes(seeds, n_samples, **keywords):
    """Episodes on each seed's drawn plant (the ``uncertain`` track's ranges); ``keywords``: the
    env's."""
    scenarios = keywords.pop("scenario", None)
    fault, plant = fcc_env.env_request(**keywords)
    if isinstance(scenarios, list):  # one scenario per seed
        fault = [fault.replace(scenario=s) for s in scenarios]
    elif scenarios is not None:
        fault = fault.replace(scenario=scenarios)
    return fcc_env.simulate_episodes(
        seeds, n_samples, fault=fault, plant=plant, plant_uncertainty=PlantUncertainty()
    )


def test_draw_is_deterministic_in_the_seed_and_json_able():
    unc = PlantUncertainty()
    a, b = unc.draw(11), unc.draw(11)
    assert a == b
    assert a.params == b.params
    assert unc.draw(12).params != a.params
    assert json.loads(json.dumps(a.truth)) == a.truth
    for names in GROUP_FIELDS.values():
        for name in names:
            assert a.truth[name] == getattr(a.params, name)


def test_draw_does_not_take_the_scenario_and_healthy_and_faulty_share_the_plant():
    assert list(inspect.signature(PlantUncertainty.draw).parameters) == ["self", "seed", "base"]
    r = drawn_episodes([5, 5], T, scenario=["nominal", "f1"], fault_time=200)
    np.testing.assert_array_equal(r.y_clean[0, :200], r.y_clean[1, :200])
    np.testing.assert_array_equal(r.observations[0, :200], r.observations[1, :200])
    assert not np.array_equal(r.y_clean[0, 200:], r.y_clean[1, 200:])


def test_one_group_range_leaves_the_other_groups_values_unchanged():
    a = PlantUncertainty().draw(3)
    b = PlantUncertainty(kinetics=0.0, feed=0.0).draw(3)
    for name in GROUP_FIELDS["heat_loss"] + GROUP_FIELDS["valve"]:
        assert a.truth[name] == b.truth[name]
    for name in GROUP_FIELDS["kinetics"] + GROUP_FIELDS["feed"]:
        assert b.truth[name] == getattr(FCCParams(), name)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"kinetics": -0.01}, "kinetics=-0.01 is outside the allowed range: a number in [0, 0.2]"),
        ({"heat_loss": 0.6}, "heat_loss=0.6 is outside the allowed range: a number in [0, 0.5]"),
        ({"feed": math.nan}, "feed=nan is outside the allowed range: a number in [0, 0.1]"),
        ({"valve": math.inf}, "valve=inf is outside the allowed range: a number in [0, 0.05]"),
        ({"valve": True}, "valve=True is outside the allowed range"),
        ({"feed_drift": 0.5}, "feed_drift=0.5 is outside the allowed range: a number in [0, 0.05]"),
        ({"ambient_amplitude_C": 30.0}, "ambient_amplitude_C=30.0 is outside the allowed range"),
        ({"feed_drift_period_h": (8.0, 2.0)}, "feed_drift_period_h[1]=2.0 is outside the allowed"),
        ({"feed_drift_period_h": 3.0}, "feed_drift_period_h=3.0 is outside the allowed range"),
    ],
)
def test_bad_values_are_rejected_naming_value_and_range(kwargs, message):
    with pytest.raises(ValueError) as err:
        PlantUncertainty(**kwargs)
    assert message in str(err.value)


def test_bad_seed_and_effect_sizes_are_rejected():
    with pytest.raises(ValueError, match=r"seed=-1 is outside the allowed range"):
        PlantUncertainty().draw(-1)
    with pytest.raises(ValueError, match=r"amplitude=0.2 is outside the allowed range"):
        FeedQualityDrift(amplitude=0.2, period_s=3600.0)
    with pytest.raises(ValueError, match=r"period_s=1.0 is outside the allowed range"):
        AmbientCycle(amplitude_C=5.0, period_s=1.0)


def test_draws_stay_within_their_ranges():
    unc = PlantUncertainty()
    base = FCCParams()
    lo_h, hi_h = unc.feed_drift_period_h
    for seed in range(60):
        d = unc.draw(seed)
        for group, names in GROUP_FIELDS.items():
            h = getattr(unc, group)
            for name in names:
                m = getattr(d.params, name) / getattr(base, name)
                if group == "valve":
                    m = 1.0 / math.sqrt(m)  # the drawn quantity is the valve gain
                    assert m == pytest.approx(d.truth["valve_gain"])
                assert 1.0 - h - 1e-12 <= m <= 1.0 + h + 1e-12, (seed, name, m)
        drift, ambient = d.effects
        assert drift.amplitude == unc.feed_drift
        assert lo_h * 3600 <= drift.period_s <= hi_h * 3600
        assert ambient.amplitude_C == unc.ambient_amplitude_C
        changed = {f for f in base.__dataclass_fields__ if getattr(d.params, f) != getattr(base, f)}
        assert changed <= {n for names in GROUP_FIELDS.values() for n in names}


def test_effects_start_at_zero_and_stay_within_their_amplitude():
    t = np.linspace(0.0, 40_000.0, 4001)
    drift = FeedQualityDrift(amplitude=0.004, period_s=3 * 3600.0, phase=1.0)
    m = drift.param_multipliers(t, FCCParams())
    assert set(m) == {"y_ccr", "y_cat"}
    assert m["y_ccr"][0] == 1.0
    assert np.abs(m["y_ccr"] - 1.0).max() <= 2 * 0.004 + 1e-12
    amb = AmbientCycle(amplitude_C=8.0, phase=-2.0).param_multipliers(t, FCCParams())["T_amb_C"]
    assert amb[0] == 1.0
    assert np.abs(amb * 25.0 - 25.0).max() <= 16.0 + 1e-9


def test_nothing_of_the_draw_reaches_the_observations_noise_stream():
    """Same seed with and without the draw: the noise (obs − y_clean) is the same stream."""
    seeds = [0, 1]
    plain = fcc_env.simulate_episodes(seeds, T)
    drawn = drawn_episodes(seeds, T)
    assert not np.allclose(plain.y_clean[:, :, 3:], drawn.y_clean[:, :, 3:])
    np.testing.assert_array_equal(plain.inputs, drawn.inputs)  # the draw is not in the inputs
    noise_plain = plain.observations.astype(np.float64) - plain.y_clean
    noise_drawn = drawn.observations.astype(np.float64) - drawn.y_clean
    # equal up to the float32 rounding of the observations (|y| < 1000 → spacing 6e-5)
    np.testing.assert_allclose(noise_drawn, noise_plain, rtol=0, atol=1e-4)
    assert drawn.observations.shape == plain.observations.shape


def test_zero_uncertainty_reproduces_the_nominal_batch():
    plain = fcc_env.simulate_episodes([4, 9], T, fault=fcc_env.FaultSpec(scenario="f3", onset=100))
    none = fcc_env.simulate_episodes(
        [4, 9],
        T,
        fault=fcc_env.FaultSpec(scenario="f3", onset=100),
        plant_uncertainty=PlantUncertainty.none(),
    )
    np.testing.assert_array_equal(plain.observations, none.observations)
    assert none.seeds == (4, 9) and none.scenarios == ("f3", "f3")


def test_no_global_rng_is_touched():
    np.random.seed(123)
    random.seed(123)
    np_state, py_state = np.random.get_state(), random.getstate()
    PlantUncertainty().draw(8)
    drawn_episodes([8], 50)
    after = np.random.get_state()
    assert all(np.array_equal(a, b) for a, b in zip(np_state, after, strict=True))
    assert random.getstate() == py_state


def test_max_half_ranges_are_stated_for_every_option():
    assert set(MAX_HALF_RANGE) == {*GROUP_FIELDS, "feed_drift"}
    unc = PlantUncertainty()
    for name, hi in MAX_HALF_RANGE.items():
        assert 0 <= getattr(unc, name) <= hi


def test_an_episode_does_not_depend_on_its_batch():
    batch = drawn_episodes([2, 3, 4], T, scenario=["f2", "nominal", "f4"], fault_time=50)
    alone = drawn_episodes([3], T, scenario="nominal", fault_time=50)
    np.testing.assert_array_equal(batch.observations[1], alone.observations[0])
    np.testing.assert_array_equal(batch.y_clean[1], alone.y_clean[0])
