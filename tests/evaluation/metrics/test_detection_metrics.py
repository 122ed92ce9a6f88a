"""Tests of evaluation.metrics: worked examples, definitions as properties, and input errors."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from evaluation.metrics import episode_scores, r_fd, r_td, t_dt

A = np.array([False, True, False, False, True, True, False, True])  # t_hor = 8


# ---- examples ----------------------------------------------------------------------------------
def test_examples() -> None:
    assert r_fd(A, t_from=4) == 0.25  # one alarm in [0, 4)
    assert r_fd(A, t_from=4, t_on=2) == 0.0  # [2, 4) is quiet
    assert r_fd(A, t_from=8) == 0.5  # healthy episode: share of the whole episode
    assert r_td(A, t_from=4) == 0.75  # 3 of [4, 8)
    assert r_td(A, t_from=7) == 1.0
    assert t_dt(A, t_from=2) == 2.0
    assert t_dt(A, t_from=4) == 0.0  # alarm at the onset sample itself
    assert math.isnan(t_dt(np.zeros(5, dtype=bool), t_from=1))


def test_accepts_list_of_bools_and_numpy_integers() -> None:
    assert r_fd([True, False], t_from=np.int64(2)) == 0.5
    assert t_dt([False, False, True], t_from=np.int32(0)) == 2.0


def test_episode_scores_healthy_and_faulty() -> None:
    healthy = episode_scores(A, None)
    assert healthy["r_fd"] == 0.5
    assert math.isnan(healthy["r_td"]) and math.isnan(healthy["t_dt"])
    assert episode_scores(A, None, t_on=4)["r_fd"] == 0.75
    faulty = episode_scores(A, 4, t_on=1)
    assert faulty == {"r_fd": 1 / 3, "r_td": 0.75, "t_dt": 0.0}
    # Fault at (or before) start-up: there is no fault-free window to score.
    at_start = episode_scores(A, 2, t_on=2)
    assert math.isnan(at_start["r_fd"]) and at_start["r_td"] == 0.5


# ---- properties --------------------------------------------------------------------------------
alarm_arrays = st.lists(st.booleans(), min_size=1, max_size=200).map(
    lambda v: np.array(v, dtype=bool)
)


@st.composite
def alarms_and_from(draw: st.DrawFn) -> tuple[np.ndarray, int]:
    """Alarm array with a valid onset 0 <= t_from < t_hor."""
    a = draw(alarm_arrays)
    return a, draw(st.integers(0, a.size - 1))


@given(alarms_and_from(), st.data())
def test_r_fd_is_mean_of_window(case: tuple[np.ndarray, int], data: st.DataObject) -> None:
    a, _ = case
    t_from = data.draw(st.integers(1, a.size))
    t_on = data.draw(st.integers(0, t_from - 1))
    value = r_fd(a, t_from, t_on)
    assert value == pytest.approx(a[t_on:t_from].mean())
    assert 0.0 <= value <= 1.0


@given(alarms_and_from())
def test_r_td_is_mean_after_onset_and_complements(case: tuple[np.ndarray, int]) -> None:
    a, t_from = case
    value = r_td(a, t_from)
    assert value == pytest.approx(a[t_from:].mean())
    assert 0.0 <= value <= 1.0
    # Alarmed share + quiet share of the same window is the whole window.
    assert value + r_td(~a, t_from) == pytest.approx(1.0)
    # Splitting the episode at t_from: the two rates weight up to the overall alarm share.
    if t_from > 0:
        n = a.size
        whole = r_fd(a, n)
        parts = (t_from * r_fd(a, t_from) + (n - t_from) * value) / n
        assert parts == pytest.approx(whole)


@given(alarms_and_from())
def test_t_dt_is_first_alarm_index_minus_onset(case: tuple[np.ndarray, int]) -> None:
    a, t_from = case
    idx = np.flatnonzero(a)
    later = idx[idx >= t_from]
    value = t_dt(a, t_from)
    if later.size:
        assert value == later[0] - t_from
        assert a[t_from + int(value)]
        assert not a[t_from : t_from + int(value)].any()
    else:
        assert math.isnan(value)
        assert r_td(a, t_from) == 0.0


@given(alarms_and_from(), st.data())
def test_adding_alarms_never_lowers_rates_nor_delays_detection(
    case: tuple[np.ndarray, int], data: st.DataObject
) -> None:
    a, t_from = case
    extra = data.draw(st.lists(st.integers(0, a.size - 1), max_size=10))
    b = a.copy()
    b[extra] = True
    assert r_td(b, t_from) >= r_td(a, t_from)
    if t_from > 0:
        assert r_fd(b, t_from) >= r_fd(a, t_from)
    before, after = t_dt(a, t_from), t_dt(b, t_from)
    if not math.isnan(before):
        assert after <= before
    if any(i >= t_from for i in extra):
        assert not math.isnan(after)


@given(alarms_and_from())
def test_episode_scores_agrees_with_the_single_metrics(case: tuple[np.ndarray, int]) -> None:
    a, onset = case
    s = episode_scores(a, onset)
    assert s["r_td"] == r_td(a, onset)
    assert s["t_dt"] == t_dt(a, onset) or (math.isnan(s["t_dt"]) and math.isnan(t_dt(a, onset)))
    if onset > 0:
        assert s["r_fd"] == r_fd(a, onset)
    else:
        assert math.isnan(s["r_fd"])


# ---- errors ------------------------------------------------------------------------------------
@pytest.mark.parametrize("fn", [r_td, t_dt])
@pytest.mark.parametrize("t_from", [-1, 8, 100])
def test_after_onset_metrics_reject_t_from_outside_episode(fn, t_from: int) -> None:
    with pytest.raises(ValueError, match=rf"t_from={t_from} outside .*0 <= t_from < 8"):
        fn(A, t_from)


@pytest.mark.parametrize("t_from", [0, -3, 9])
def test_r_fd_rejects_t_from_outside_episode(t_from: int) -> None:
    with pytest.raises(ValueError, match=rf"t_from={t_from} outside .*0 < t_from <= 8"):
        r_fd(A, t_from)


@pytest.mark.parametrize("t_on", [-1, 4, 5])
def test_r_fd_rejects_bad_t_on(t_on: int) -> None:
    with pytest.raises(ValueError, match=rf"t_on={t_on} outside .*0 <= t_on < 4"):
        r_fd(A, 4, t_on=t_on)


@pytest.mark.parametrize("fn", [r_fd, r_td, t_dt])
@pytest.mark.parametrize(
    ("alarms", "match"),
    [
        (np.array([0, 1, 1]), "boolean array .*got dtype int"),
        (np.array([0.0, 1.0, 1.0]), "boolean array .*got dtype float"),
        (np.array([], dtype=bool), "empty"),
        (np.ones((2, 3), dtype=bool), r"1-D .*shape \(2, 3\)"),
    ],
)
def test_rejects_bad_alarm_arrays(fn, alarms: np.ndarray, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        fn(alarms, 1)


@pytest.mark.parametrize("fn", [r_fd, r_td, t_dt])
@pytest.mark.parametrize("t_from", [1.0, 2.5, True, "3"])
def test_rejects_non_integer_times(fn, t_from: object) -> None:
    with pytest.raises(ValueError, match="t_from must be an integer"):
        fn(A, t_from)


def test_rejects_non_integer_t_on() -> None:
    with pytest.raises(ValueError, match="t_on must be an integer"):
        r_fd(A, 4, t_on=0.0)


def test_episode_scores_rejects_bad_onset_and_t_on() -> None:
    with pytest.raises(ValueError, match=r"fault_onset=8 outside .*< 8"):
        episode_scores(A, 8)
    with pytest.raises(ValueError, match=r"t_on=8 outside .*0 <= t_on < 8"):
        episode_scores(A, None, t_on=8)
    with pytest.raises(ValueError, match="boolean"):
        episode_scores(A.astype(int), None)
