"""Issue 45 item 5: the ``rgb_array`` frame of the closed-loop ids shows the closed loop.

The frame names its env id; on ``FCC-closedloop-v0`` and ``FCC-control-v0`` it shows the valve
command, the set points and the temperatures they hold; on ``FCC-control-v0`` also the reward and
its cumulative sum. Every axis carries its unit, read from the data's own tables. Checked on the
figure behind the frame (its texts and lines), not on pixels.
"""

from __future__ import annotations

import re

import gymnasium as gym
import numpy as np
import pytest

import fcc_env
from fcc_env.closed_loop import CHANNEL_UNITS, CLOSED_LOOP_CHANNELS
from fcc_env.control_task import REWARD_UNIT
from fcc_env.params import MEASUREMENT_NAMES
from fcc_env.plotting import CLOSED_LOOP_ROWS, trend_layout
from fcc_env.regulatory import LOOP_NAMES, SETPOINT_NAMES

IDS = (fcc_env.ENV_ID, fcc_env.CLOSED_LOOP_ENV_ID, fcc_env.CONTROL_ENV_ID)
UNITS = {**CHANNEL_UNITS, "reward": REWARD_UNIT, "cumulative reward": REWARD_UNIT}


def _rendered(env_id: str, steps: int = 60):
    env = gym.make(env_id, scenario="f1", fault_time=30, render_mode="rgb_array")
    env.reset(seed=3)
    rewards = [0.0]
    for k in range(steps):
        move = np.array([0.5, -0.5]) if 10 <= k < 40 else np.zeros(2)  # move the set points
        rewards.append(float(env.step(move)[1]))
    frame = env.render()
    plant = env.unwrapped.plant if env_id == fcc_env.CONTROL_ENV_ID else env.unwrapped
    return env, frame, plant._renderer.figure, np.array(plant._history), np.array(rewards)


def _lines(fig) -> dict[str, object]:
    return {ln.get_gid(): ln for ax in fig.axes for ln in ax.get_lines() if ln.get_gid()}


@pytest.mark.parametrize("env_id", IDS)
def test_frame_shape_title_and_units_on_every_axis(env_id):
    env, frame, fig, _, _ = _rendered(env_id)
    width, height = fig.get_size_inches() * fig.dpi
    assert frame.dtype == np.uint8 and frame.shape == (round(height), round(width), 3)
    assert fig.get_suptitle().startswith(f"{env_id}, sample 60, t = 0.17 h\n")
    assert "scenario f1, fault since sample 30" in fig.get_suptitle()
    for ax in fig.axes:
        name, unit = re.fullmatch(r"(.+) \[(.+)\]", ax.get_ylabel()).groups()
        assert UNITS[name] == unit, ax.get_ylabel()
    # each column's lowest panel carries the time axis with its unit and tick labels
    bottoms = [ax for ax in fig.axes if ax.get_xlabel()]
    assert {ax.get_xlabel() for ax in bottoms} == {"time [h]"}
    assert len(bottoms) == len(trend_layout(list(_lines(fig)))[0])
    env.close()


def test_open_loop_frame_keeps_table1_only():
    env, _, fig, _, _ = _rendered(fcc_env.ENV_ID)
    assert sorted(_lines(fig)) == sorted(MEASUREMENT_NAMES)
    assert not any(ax.get_title() for ax in fig.axes)
    env.close()


@pytest.mark.parametrize("env_id", [fcc_env.CLOSED_LOOP_ENV_ID, fcc_env.CONTROL_ENV_ID])
def test_closed_loop_frame_shows_valve_setpoints_and_held_temperatures(env_id):
    env, _, fig, history, _ = _rendered(env_id)
    lines = _lines(fig)
    assert set(CLOSED_LOOP_CHANNELS) <= set(lines)
    # the set points are drawn in the panel of the temperature they hold, dashed
    for held, setpoint in zip(LOOP_NAMES, SETPOINT_NAMES, strict=True):
        assert lines[setpoint].axes is lines[held].axes
        assert lines[setpoint].get_linestyle() != "-"
        assert lines[held].axes.get_ylabel() == f"{held} [°C]"
    assert lines["u_F"].axes.get_ylabel() == "u_F [kg/s]"
    # the lines are the observation's channels (the set points moved by the action)
    for i, name in enumerate(CLOSED_LOOP_CHANNELS):
        np.testing.assert_array_equal(lines[name].get_ydata(), history[:, i], err_msg=name)
    assert np.ptp(history[:, CLOSED_LOOP_CHANNELS.index("T_rx_sp")]) > 0
    headings = [ax.get_title() for ax in fig.axes[:3]]
    assert "valve command u_F" in headings[0] and "air R_ar" in headings[1]
    legend = [t.get_text() for lg in fig.legends for t in lg.get_texts()]
    assert legend == ["set point", "fault onset"]
    env.close()


def test_control_frame_adds_reward_and_its_cumulative_sum():
    env, _, fig, _, rewards = _rendered(fcc_env.CONTROL_ENV_ID)
    lines = _lines(fig)
    np.testing.assert_allclose(lines["reward"].get_ydata(), rewards)
    np.testing.assert_allclose(lines["cumulative reward"].get_ydata(), np.cumsum(rewards))
    assert lines["reward"].axes.get_ylabel() == f"reward [{REWARD_UNIT}]"
    assert lines["cumulative reward"].axes.get_ylabel() == f"cumulative reward [{REWARD_UNIT}]"
    # a reset starts the sum again
    env.reset(seed=4)
    env.step(np.zeros(2))
    env.render()
    again = _lines(env.unwrapped.plant._renderer.figure)
    assert len(again["cumulative reward"].get_ydata()) == 2
    assert again["cumulative reward"].get_ydata()[0] == 0.0
    env.close()


def test_rendering_leaves_the_control_task_bit_for_bit():
    def run(render_mode):
        env = gym.make(fcc_env.CONTROL_ENV_ID, scenario="f2", fault_time=5, render_mode=render_mode)
        env.reset(seed=1)
        out = []
        for _ in range(15):
            obs, reward, *_ = env.step(np.array([0.2, 0.1]))
            env.render()
            out.append((obs.copy(), reward))
        return out

    for (a, ra), (b, rb) in zip(run(None), run("rgb_array"), strict=True):
        np.testing.assert_array_equal(a, b)
        assert ra == rb


def test_closed_loop_layout_draws_every_channel_once():
    drawn = [c for row in CLOSED_LOOP_ROWS for panel in row for c in panel]
    assert sorted(drawn) == sorted(CLOSED_LOOP_CHANNELS)
    rows = trend_layout([*CLOSED_LOOP_CHANNELS, "reward", "cumulative reward"])
    assert rows[-1] == [("reward",), ("cumulative reward",), None]


def test_an_env_built_without_make_is_titled_with_its_class_id():
    env = fcc_env.env.FCCClosedLoopEnv(render_mode="rgb_array")  # no spec: the class's id
    env.reset(seed=0)
    env.render()
    assert env._renderer.figure.get_suptitle().startswith(f"{fcc_env.CLOSED_LOOP_ENV_ID}, ")
    env.close()
