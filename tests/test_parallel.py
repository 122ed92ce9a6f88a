"""Parallel training of the LRGF + MEM banks (``n_jobs``, :mod:`diagnosers.parallel`)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from synthetic import inject_step_fault, make_episode

import diagnosers
from diagnosers.lrgf_glr import LRGFGLR
from diagnosers.parallel import run_jobs
from diagnosers.training import export_module

LRGF_NAMES = ("lrgf-mem-paper", "lrgf-mem", "lrgf-glr")


@pytest.fixture(scope="module")
def train() -> list:
    return [make_episode(1500, seed=s) for s in (1, 2, 3)]


@pytest.mark.parametrize("name", LRGF_NAMES)
@pytest.mark.parametrize("bad", [0, -1, 1.5, "2", True])
def test_n_jobs_outside_its_range_is_refused_by_name(name, bad, train) -> None:
    d = diagnosers.make(name, **diagnosers.diagnoser_class(name).fast_params(), n_jobs=bad)
    with pytest.raises(ValueError, match=r"n_jobs=.* is outside the allowed range: an integer"):
        d.fit(train)


def test_isolators_check_the_inner_detectors_n_jobs(train) -> None:
    d = diagnosers.make("lrgf-iso", detector={"n_jobs": 0})
    with pytest.raises(ValueError, match=r"n_jobs=0 is outside the allowed range"):
        d._validate_params()


def test_n_jobs_2_trains_the_same_bits_as_n_jobs_1(train) -> None:
    params = {**LRGFGLR.fast_params(), "fault_scenarios": ["f3"]}
    one = diagnosers.make("lrgf-glr", **params, n_jobs=1).fit(train)
    two = diagnosers.make("lrgf-glr", **params, n_jobs=2).fit(train)
    for a, b in zip([*one.lrgf_, *one.mem_], [*two.lrgf_, *two.mem_], strict=True):
        sa, sb = export_module(a)[1], export_module(b)[1]
        assert all(np.array_equal(sa[k].numpy(), sb[k].numpy()) for k in sa)
    for key, value in one._get_state().items():
        np.testing.assert_array_equal(value, two._get_state()[key], err_msg=key)
    ep = inject_step_fault(make_episode(900, seed=9), onset=500, magnitude=3.0)
    d1, d2 = one.detect(ep), two.detect(ep)
    for field in ("alarm", "signal", "upper", "residual"):
        assert np.array_equal(getattr(d1, field), getattr(d2, field)), field


def test_run_jobs_keeps_the_order_and_raises_a_jobs_error() -> None:
    jobs = [4.0, 9.0, 16.0, 25.0]
    assert run_jobs(math.sqrt, jobs, 2, cost=lambda x: x) == [2.0, 3.0, 4.0, 5.0]
    assert run_jobs(math.sqrt, jobs, 1) == [2.0, 3.0, 4.0, 5.0]
    with pytest.raises(ValueError, match="math domain error"):
        run_jobs(math.sqrt, [4.0, -1.0], 2)
