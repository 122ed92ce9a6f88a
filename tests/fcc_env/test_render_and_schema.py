"""Issue 34 ("habits users bring"): the persistent rgb_array renderer, Parquet field metadata with
units and roles, and a warning when a TimeLimit ends an episode before its fault onset."""

from __future__ import annotations

import gc
import itertools
import warnings
import weakref

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.envs.registration import WrapperSpec, register, registry
from gymnasium.utils.env_checker import check_env

import fcc_env
import fcc_env.render as render
from fcc_env.env import OnsetHorizonCheck
from fcc_env.generate import read_dataset, write_dataset
from fcc_env.plotting import trend_figure, trend_title
from fcc_env.render import PAGE_SAMPLES, WINDOW_SAMPLES, TrendRenderer

needs_pyarrow = pytest.mark.skipif(
    __import__("importlib").util.find_spec("pyarrow") is None, reason="pyarrow not installed"
)


def _steps(env: gym.Env, n: int) -> None:
    for _ in range(n):
        env.step(np.zeros(2, dtype=np.float32))


# ---- rgb_array ---------------------------------------------------------------------------------
ALL_IDS = [fcc_env.ENV_ID, fcc_env.CLOSED_LOOP_ENV_ID, fcc_env.CONTROL_ENV_ID]


@pytest.mark.parametrize("env_id", ALL_IDS)
def test_frame_is_uint8_rgb_and_changes_between_steps(env_id):
    env = gym.make(env_id, scenario="f1", fault_time=8, render_mode="rgb_array")
    env.reset(seed=0)
    first = env.render()
    assert first.dtype == np.uint8 and first.ndim == 3 and first.shape[2] == 3
    assert first.flags.owndata  # a copy: later frames do not overwrite it
    frames = [first]
    for _ in range(12):  # across the onset (sample 8): the marker and legend appear
        _steps(env, 1)
        frames.append(env.render())
    assert {f.shape for f in frames} == {first.shape} and first.std() > 0
    assert all(not np.array_equal(a, b) for a, b in itertools.pairwise(frames))
    env.close()


def test_close_frees_the_figure_and_a_later_render_builds_a_new_one():
    env = gym.make("FCC-v0", render_mode="rgb_array")
    env.reset(seed=0)
    shape = env.render().shape
    fig = weakref.ref(env.unwrapped._renderer.figure)
    env.close()
    gc.collect()
    assert fig() is None
    assert env.render().shape == shape


def test_render_before_reset_says_so():
    env = fcc_env.env.FCCEnv(render_mode="rgb_array")
    with pytest.raises(gym.error.ResetNeeded, match=r"reset\(\) before render\(\)"):
        env.render()
    assert fcc_env.env.FCCEnv().render() is None  # no render_mode: nothing to draw


def test_frame_titles_name_scenario_time_and_onset(monkeypatch):
    titles = []

    def spy(*args, **kwargs):
        titles.append(trend_title(*args, **kwargs))
        return titles[-1]

    monkeypatch.setattr(render, "trend_title", spy)
    for scenario in ("nominal", "f1"):
        env = gym.make("FCC-v0", scenario=scenario, fault_time=10, render_mode="rgb_array")
        env.reset(seed=0)
        for k in range(20):
            env.step(np.zeros(2))
            if k in (5, 19):
                env.render()
        assert env.unwrapped._renderer.figure.get_suptitle() == titles[-1]
    assert titles == [
        "FCC-v0, sample 6, t = 0.02 h\nscenario nominal, no fault",
        "FCC-v0, sample 20, t = 0.06 h\nscenario nominal, no fault",
        "FCC-v0, sample 6, t = 0.02 h\nscenario f1, no fault yet",
        "FCC-v0, sample 20, t = 0.06 h\nscenario f1, fault since sample 10 (0.03 h)",
    ]


def test_panels_units_marker_and_legend_follow_the_onset():
    y = 500.0 + np.random.default_rng(5).normal(size=(1200, 8))
    r = TrendRenderer()
    r.frame(y[:200], 199, 10.0, scenario="f1", fault_onset=250)
    labels = [ax.get_ylabel() for ax in r.figure.axes]
    assert labels == [ax.get_ylabel() for ax in trend_figure(y[:200], 199, 10.0).axes]
    assert all("[" in label for label in labels) and not r.figure.legends
    r.frame(y[:300], 299, 10.0, scenario="f1", fault_onset=250)
    onset = [ln for ln in r.figure.axes[0].get_lines() if ln.get_label() == "fault onset"]
    assert len(onset) == 1 and onset[0].get_xdata()[0] == 250 * 10.0 / 3600
    assert [t.get_text() for lg in r.figure.legends for t in lg.get_texts()] == ["fault onset"]
    # the onset leaves the window of the last WINDOW_SAMPLES samples: marker and legend go
    k = 250 + WINDOW_SAMPLES
    r.frame(y[: k + 1], k, 10.0, scenario="f1", fault_onset=250)
    assert not r.figure.legends
    r.close()
    assert r.figure is None


def test_time_axis_pages_and_always_shows_the_window():
    y = 500.0 + np.random.default_rng(6).normal(size=(1200, 8))
    r = TrendRenderer()
    hours = 10.0 / 3600
    for k in (0, 49, 50, 499, 500, 777, 1199):
        r.frame(y[: k + 1], k, 10.0)
        lo, hi = r.figure.axes[0].get_xlim()
        t = r.figure.axes[0].get_lines()[0].get_xdata()
        assert lo <= t[0] and t[-1] <= hi and len(t) == min(k + 1, WINDOW_SAMPLES), k
        assert hi - lo <= (WINDOW_SAMPLES + PAGE_SAMPLES) * hours + 1e-12
        shown = y[max(k - WINDOW_SAMPLES + 1, 0) : k + 1]
        # figure axes are row by row; panel i (column by column) shows measurement i
        for ax, col in zip(r.figure.axes, (0, 4, 1, 5, 2, 6, 3, 7), strict=True):
            a, b = ax.get_ylim()
            assert a <= shown[:, col].min() and shown[:, col].max() <= b, (k, col)


def test_blitted_frame_matches_a_full_redraw_of_its_figure():
    # the cached background plus the redrawn lines and title give what matplotlib draws whole
    # (antialiasing may differ along the lines, hence the small share)
    y = 500.0 + np.random.default_rng(7).normal(size=(700, 8))
    r = TrendRenderer()
    for k in (599, 600, 601, 620):
        frame = r.frame(y[: k + 1], k, 10.0, scenario="f1", fault_onset=610)
    for artist in r.figure.findobj(lambda a: a.get_animated()):
        artist.set_animated(False)
    r.figure.canvas.draw()
    full = np.asarray(r.figure.canvas.buffer_rgba())[..., :3]
    assert (full != frame).any(axis=2).mean() < 0.03


@pytest.mark.parametrize("env_id", ALL_IDS)
def test_check_env_with_rgb_array_is_clean(env_id):
    env = gym.make(env_id, scenario="f2", fault_time=5, render_mode="rgb_array")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env.unwrapped)
    assert [str(w.message) for w in caught] == []


def test_rendering_leaves_the_observations_bit_for_bit():
    plain = gym.make("FCC-v0", scenario="f1", fault_time=5)
    drawn = gym.make("FCC-v0", scenario="f1", fault_time=5, render_mode="rgb_array")
    a, _ = plain.reset(seed=3)
    b, _ = drawn.reset(seed=3)
    for _ in range(15):
        drawn.render()
        np.testing.assert_array_equal(a, b)
        a = plain.step(np.zeros(2))[0]
        b = drawn.step(np.zeros(2))[0]


# ---- Parquet field metadata --------------------------------------------------------------------
@needs_pyarrow
def test_parquet_fields_carry_the_sidecar_units_and_roles(tmp_path):
    import pandas as pd
    import pyarrow.parquet as pq

    from fcc_env.dataset_schema import field_metadata

    path = write_dataset(
        tmp_path / "d.parquet", scenario="f1", seeds=[0], n_samples=30, fault_time=10,
        include_states=True,
    )  # fmt: skip
    meta, cols = read_dataset(path)
    schema = pq.read_schema(path)
    assert schema.field("T_rx").metadata[b"unit"].decode() == "°C"
    assert schema.field("T_rx").metadata[b"role"] == b"measured"
    assert schema.field("cmd_u_F").metadata[b"role"] == b"commanded"
    assert field_metadata(path) == meta["columns"]  # every column, the sidecar's record
    assert str(schema.field("fault_active").type) == "int8"  # types as before
    frame = pd.read_parquet(path)
    assert list(frame.columns) == list(cols)
    np.testing.assert_array_equal(frame["T_rx"].to_numpy(), cols["T_rx"])


@needs_pyarrow
def test_parquet_table_refuses_a_column_without_metadata():
    from fcc_env.dataset_schema import parquet_table

    with pytest.raises(ValueError, match=r"column\(s\) \['T_x'\] have no metadata"):
        parquet_table({"T_x": np.zeros(2)}, {"T_rx": {"unit": "°C", "role": "measured"}})
    with pytest.raises(ValueError, match=r"column 'T_rx': metadata \{'unit': 1\}"):
        parquet_table({"T_rx": np.zeros(2)}, {"T_rx": {"unit": 1, "role": "measured"}})


# ---- a horizon ending before the onset ---------------------------------------------------------
def test_time_limit_before_the_onset_warns_with_onset_and_limit():
    env = OnsetHorizonCheck(gym.make("FCC-v0", scenario="f1", max_episode_steps=1000))
    with pytest.warns(UserWarning, match=r"ends at sample 1000 \(max_episode_steps=1000\) "
                      r"before its f1 fault onset at sample 1900"):  # fmt: skip
        env.reset(seed=0)
    for kwargs in (
        {"scenario": "f1", "max_episode_steps": 1900},  # the onset is the last sample
        {"scenario": "nominal", "max_episode_steps": 10},
    ):
        env = OnsetHorizonCheck(gym.make("FCC-v0", **kwargs))
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            env.reset(seed=0)


def test_time_limit_check_as_a_registered_wrapper():
    # how the registration would carry it: gym.make applies it outside the TimeLimit
    env_id = "FCC-onset-check-test-v0"
    register(
        id=env_id, entry_point="fcc_env.env:FCCEnv", max_episode_steps=fcc_env.MAX_EPISODE_STEPS,
        additional_wrappers=(
            WrapperSpec("OnsetHorizonCheck", "fcc_env.env:OnsetHorizonCheck", {}),
        ),
    )  # fmt: skip
    try:
        env = gym.make(env_id, scenario="random", max_episode_steps=500)
        with pytest.warns(UserWarning, match=r"max_episode_steps=500\) before its f\d fault"):
            env.reset(seed=3)  # random onsets lie in the middle half of 4000 samples
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            gym.make(env_id, scenario="f1").reset(seed=0)  # the registered 3999 steps reach it
    finally:
        del registry[env_id]


def test_env_horizon_before_the_onset_is_an_error_not_a_silent_episode():
    with pytest.raises(ValueError, match=r"fault_time=1900 is outside the allowed range: an "
                       r"integer in \[0, 1000\)"):  # fmt: skip
        gym.make("FCC-v0", scenario="f1", horizon=1000)
    env = gym.make("FCC-v0", horizon=1000, max_episode_steps=999)
    with pytest.raises(ValueError, match=r"fault_time=1900 is outside"):
        env.reset(options={"scenario": "f1"})
