"""``FCC-control-v0``: the closed-loop plant with an economic reward (issue 35, item 1)."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import fcc_env
from fcc_env.control_task import REWARD_TERMS, EconomicReward, reward_terms


@pytest.mark.parametrize("render_mode", [None, "rgb_array"])
def test_check_env_is_clean(render_mode):
    check_env(gym.make(fcc_env.CONTROL_ENV_ID, render_mode=render_mode).unwrapped)


def test_the_plant_is_the_closed_loop_env_and_the_reward_sums_its_terms():
    ctrl = gym.make("FCC-control-v0", scenario="f1", fault_time=30)
    plant = gym.make("FCC-closedloop-v0", scenario="f1", fault_time=30)
    o1, i1 = ctrl.reset(seed=4)
    o2, _ = plant.reset(seed=4)
    np.testing.assert_array_equal(o1, o2)
    assert i1["reward_terms"] == dict.fromkeys(REWARD_TERMS, 0.0)
    rng = np.random.default_rng(0)
    for _ in range(60):
        a = rng.uniform(-0.3, 0.3, 2).astype(np.float32)
        o1, r, *_, info = ctrl.step(a)
        o2, r_plant, *_ = plant.step(a)
        np.testing.assert_array_equal(o1, o2)
        assert r_plant == 0.0 and tuple(info["reward_terms"]) == REWARD_TERMS
        assert r == math.fsum(info["reward_terms"].values())
        # the margin written out from the step's info, independently of reward_terms
        e, dt = EconomicReward(), 10.0
        feed, air = info["inputs"][4], info["inputs"][1]
        margin = (
            feed * info["X"] * dt / 1000 * e.conversion_usd_per_t
            - info["coke_make"] * dt / 1000 * e.coke_usd_per_t
            - air * dt / 3600 * e.air_usd_per_t
        )
        terms = info["reward_terms"]
        assert terms["conversion"] + terms["coke"] + terms["air"] == pytest.approx(margin)
    assert 5.0 < r < 30.0  # about 16 USD per 10-s sample at the nominal point


@pytest.mark.parametrize("scenario", ["nominal", "f1", "f2", "f3", "f4"])
def test_reward_is_finite_for_every_action_corner_and_fault(scenario):
    env = gym.make("FCC-control-v0", scenario=scenario, fault_time=50, fault_magnitude=None)
    corners = [np.array([a, b], np.float32) for a in (-1, 0, 1) for b in (-1, 0, 1)]
    for i, action in enumerate(corners):
        env.reset(seed=i)
        for _ in range(120):
            _, r, terminated, truncated, info = env.step(action)
            assert math.isfinite(r) and all(math.isfinite(v) for v in info["reward_terms"].values())
            if terminated or truncated:
                assert info["reward_terms"]["trip"] == (
                    -EconomicReward().trip_usd if terminated else 0
                )
                break


def _info(**state):
    x = np.array([4e4, 0.01, 9e4, 0.0035, 685.0, 9e4, 0.002, 719.4, 3e4, 697.2, 710.2])
    for i, v in state.items():
        x[int(i[1:])] = v
    return {
        "state": x,
        "inputs": np.array([416.7, 148.4, 200.0, 230.0, 61.111, 1.0]),
        "X": 0.75,
        "coke_make": 3.46,
        "controller_saturated": False,
    }


def test_each_penalty_enters_where_its_constraint_is_crossed():
    e, dt = EconomicReward(), 10.0
    base = reward_terms(_info(), False, e, dt)
    assert all(base[k] == 0.0 for k in REWARD_TERMS[3:])
    # afterburn 50 °C: 10 °C over the 40 °C warning
    assert reward_terms(_info(x9=735.0), False, e, dt)["afterburn"] == pytest.approx(
        -10 * dt / 3600 * e.afterburn_usd_per_C_h
    )
    assert reward_terms(_info(x7=740.0), False, e, dt)["regenerator"] == pytest.approx(
        -10 * dt / 3600 * e.regenerator_usd_per_C_h
    )
    assert reward_terms(_info(x4=630.0, x9=640.0), False, e, dt)["regenerator"] < 0
    assert reward_terms(_info(x8=5500.0), False, e, dt)["well"] == pytest.approx(
        -2.0 * dt / 3600 * e.well_usd_per_t_h
    )
    sat = _info() | {"controller_saturated": True}
    assert reward_terms(sat, False, e, dt)["saturation"] == pytest.approx(-dt / 3600 * 2000)
    assert reward_terms(_info(), True, e, dt)["trip"] == -e.trip_usd
    zero = EconomicReward(trip_usd=0.0)
    assert reward_terms(_info(), True, zero, dt)["trip"] == 0.0


def test_economics_are_checked_and_reweightable():
    with pytest.raises(ValueError, match=r"coke_usd_per_t=-1"):
        EconomicReward(coke_usd_per_t=-1.0)
    with pytest.raises(ValueError, match="not_a_price"):
        gym.make("FCC-control-v0", economics={"not_a_price": 1.0})
    env = gym.make("FCC-control-v0", economics={"coke_usd_per_t": 0.0}, scenario="nominal")
    env.reset(seed=0)
    _, _, _, _, info = env.step(np.zeros(2, np.float32))
    assert info["reward_terms"]["coke"] == 0.0


def test_nan_action_is_refused_by_value():
    env = gym.make("FCC-control-v0")
    env.reset(seed=0)
    with pytest.raises(ValueError, match="nan"):
        env.step(np.array([np.nan, 0.0], np.float32))


def test_faults_are_drawn_per_episode_healthy_included():
    env = gym.make("FCC-control-v0")
    seen = {env.reset(seed=s)[1]["scenario"] for s in range(30)}
    assert seen == {"nominal", "f1", "f2", "f3", "f4"}


def test_the_term_lists_and_price_ranges_are_read_from_the_one_table():
    import dataclasses

    from fcc_common.validation import Real
    from fcc_env.control_task import (
        CONSTRAINT_TERMS,
        REWARD_TABLE,
        RewardTerm,
        TermKind,
        field_ranges,
        term_names,
    )

    assert term_names(REWARD_TABLE) == REWARD_TERMS
    assert CONSTRAINT_TERMS == ("afterburn", "regenerator", "well", "saturation")
    # every field of EconomicReward has its range in the table, in the same order, and no other
    assert list(field_ranges(REWARD_TABLE)) == [f.name for f in dataclasses.fields(EconomicReward)]
    # a new term joins the lists of its kind by its row alone: no other list to edit
    price = Real(0.0, 1e7)
    grown = (
        *REWARD_TABLE,
        RewardTerm("steam", TermKind.MARGIN, (("steam_usd_per_t", price),)),
        RewardTerm("flare", TermKind.CONSTRAINT, (("flare_usd_per_h", price),)),
    )
    assert term_names(grown) == (*REWARD_TERMS, "steam", "flare")
    assert term_names(grown, TermKind.CONSTRAINT) == (*CONSTRAINT_TERMS, "flare")
    assert term_names(grown, TermKind.MARGIN)[-1] == "steam"
    assert list(field_ranges(grown))[-2:] == ["steam_usd_per_t", "flare_usd_per_h"]
