"""Tests of evaluation.metrics.isolation_metrics: worked examples, definitions as properties, input errors."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from evaluation.metrics import r_td, t_dt
from evaluation.metrics.isolation_metrics import (
    MISSED,
    UNKNOWN,
    cdr,
    confusion_matrix,
    episode_label,
    isolation_scores,
    r_fi,
    r_ti,
    t_it,
)

D = np.array(["", "f2", "", "f1", "f1", "unknown", "f1", "f1", "f1"])  # t_hor = 9


# ---- examples ----------------------------------------------------------------------------------
def test_examples() -> None:
    assert t_it(D, "f1", t_from=1, persistence=1) == 2.0  # first f1 at sample 3
    assert t_it(D, "f1", t_from=1, persistence=3) == 5.0  # f1 f1 f1 from sample 6
    assert t_it(D, "f1", t_from=1, persistence=None) == 5.0  # holds to the end from 6
    assert t_it(D, "f1", t_from=1, persistence=100) == 5.0  # cut at the horizon
    assert math.isnan(t_it(D, "f3", t_from=0))
    assert r_ti(D, "f1", t_from=1) == 5 / 8
    assert r_fi(D, "f1", t_from=1) == 1 / 8  # the f2; unknown is not a false isolation
    assert cdr(D, "f1", t_from=1) == 5 / 7
    assert episode_label(D, t_from=0) == "f1"
    assert episode_label(np.array(["", ""]), t_from=0) == MISSED
    assert episode_label(np.array(["f2", "f1"]), t_from=0) == "f1"  # tie: alphabetical
    assert math.isnan(cdr(np.array(["", ""]), "f1", t_from=0))


def test_unknown_fault_is_scored_against_unknown() -> None:
    d = np.array(["", "unknown", "f3", "unknown"])
    assert cdr(d, UNKNOWN, t_from=0) == 2 / 3
    assert r_fi(d, UNKNOWN, t_from=0) == 1 / 4  # f3 is a wrong fault label
    assert isolation_scores(d, UNKNOWN, 0)["label"] == UNKNOWN


def test_confusion_matrix() -> None:
    rows, cols, m = confusion_matrix(
        ["f1", "f1", "f2", "unknown"], ["f1", "f2", MISSED, "unknown"], classes=["f1", "f2"]
    )
    assert rows == ["f1", "f2", "unknown"]
    assert cols == ["f1", "f2", "unknown", "missed"]
    np.testing.assert_array_equal(m, [[1, 1, 0, 0], [0, 0, 0, 1], [0, 0, 1, 0]])


# ---- properties --------------------------------------------------------------------------------
LABELS = st.sampled_from(["", "f1", "f2", "unknown"])


@st.composite
def episodes(draw: st.DrawFn) -> tuple[np.ndarray, int, str]:
    d = np.array(draw(st.lists(LABELS, min_size=1, max_size=60)), dtype="<U7")
    t0 = draw(st.integers(0, d.size - 1))
    truth = draw(st.sampled_from(["f1", "f2", "unknown"]))
    return d, t0, truth


@given(episodes())
def test_rates_partition_the_window(case: tuple[np.ndarray, int, str]) -> None:
    d, t0, truth = case
    alarm = d != ""
    a_td = r_td(alarm, t0)
    ti, fi = r_ti(d, truth, t0), r_fi(d, truth, t0)
    assert 0.0 <= ti <= 1.0 and 0.0 <= fi <= 1.0
    assert ti + fi <= a_td + 1e-12
    c = cdr(d, truth, t0)
    if a_td > 0:
        assert math.isclose(ti, a_td * c, abs_tol=1e-12)
    else:
        assert math.isnan(c) and ti == 0.0


@given(episodes(), st.integers(1, 10))
def test_isolation_time_follows_detection(case: tuple[np.ndarray, int, str], p: int) -> None:
    d, t0, truth = case
    t = t_it(d, truth, t0, persistence=p)
    if math.isnan(t):
        return
    k = t0 + int(t)
    assert t >= t_dt(d != "", t0)  # a right label is an alarmed sample
    run = d[k : k + p]
    assert np.all(run == truth)  # the label holds for the persistence (or to the end)
    # and no earlier start qualifies
    for j in range(t0, k):
        assert not np.all(d[j : j + p] == truth)
    # a longer persistence never isolates sooner
    t2 = t_it(d, truth, t0, persistence=p + 3)
    assert math.isnan(t2) or t2 >= t


@given(episodes())
def test_pre_onset_samples_do_not_matter(case: tuple[np.ndarray, int, str]) -> None:
    d, t0, truth = case
    e = d.copy()
    e[:t0] = "f2"
    for f in (r_ti, r_fi, cdr):
        a, b = f(d, truth, t0), f(e, truth, t0)
        assert (math.isnan(a) and math.isnan(b)) or a == b
    assert episode_label(d, t0) == episode_label(e, t0)


@given(st.lists(st.tuples(st.sampled_from(["f1", "f2", "unknown"]), LABELS), max_size=30))
def test_confusion_counts_every_episode(pairs: list[tuple[str, str]]) -> None:
    truths = [t for t, _ in pairs]
    labels = [lab or MISSED for _, lab in pairs]
    rows, cols, m = confusion_matrix(truths, labels, classes=["f1", "f2"])
    assert m.sum() == len(pairs)
    for t in set(truths):
        assert m[rows.index(t)].sum() == truths.count(t)
    assert cols[-2:] == [UNKNOWN, MISSED]


# ---- input errors ------------------------------------------------------------------------------
def test_errors_name_the_value_and_range() -> None:
    with pytest.raises(ValueError, match=r"t_from=9 outside the allowed range 0 <= t_from < 9"):
        r_ti(D, "f1", 9)
    with pytest.raises(ValueError, match=r"persistence=0 outside the allowed range >= 1"):
        t_it(D, "f1", 0, persistence=0)
    with pytest.raises(ValueError, match=r"diagnosis must be a string array.*got dtype bool"):
        cdr(np.array([True, False]), "f1", 0)
    with pytest.raises(ValueError, match=r"diagnosis must be 1-D.*shape \(1, 2\)"):
        cdr(np.array([["f1", "f1"]]), "f1", 0)
    with pytest.raises(ValueError, match=r"truth must be a fault label.*got ''"):
        r_ti(D, "", 0)
    with pytest.raises(ValueError, match=r"one entry per episode; got 2 and 1"):
        confusion_matrix(["f1", "f2"], ["f1"])
    with pytest.raises(ValueError, match="t_from must be an integer"):
        r_ti(D, "f1", 1.5)  # type: ignore[arg-type]
