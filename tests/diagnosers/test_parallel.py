"""Parallel training of the LRGF + MEM banks (``n_jobs``, :mod:`diagnosers.bank.parallel`)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from synthetic import inject_step_fault, make_episode, with_fault_twins

import diagnosers
from diagnosers.bank.parallel import BankSettings, run_jobs, train_banks
from diagnosers.lrgf.lrgf_glr import LRGFGLR
from diagnosers.networks.modules import export_module

LRGF_NAMES = ("lrgf-mem-paper", "lrgf-mem", "lrgf-glr")


@pytest.mark.parametrize("name", LRGF_NAMES)
@pytest.mark.parametrize("bad", [0, -1, 1.5, "2", True])
def test_n_jobs_outside_its_range_is_refused_by_name(name, bad, train) -> None:
    d = diagnosers.make(name, **diagnosers.diagnoser_class(name).fast_params(), n_jobs=bad)
    with pytest.raises(ValueError, match=r"n_jobs=.* is outside the allowed range: an integer"):
        d.fit(train)


def test_isolators_check_the_inner_detectors_n_jobs(train) -> None:
    d = diagnosers.make("lrgf-iso", detector={"n_jobs": 0})
    with pytest.raises(ValueError, match=r"n_jobs=0 is outside the allowed range"):
        d.validate_params()


def test_n_jobs_2_trains_the_same_bits_as_n_jobs_1(train) -> None:
    params = {**LRGFGLR.fast_params(), "fault_scenarios": ["f3"], "fault_seeds": None}
    one = diagnosers.make("lrgf-glr", **params, n_jobs=1).fit(with_fault_twins(train))
    two = diagnosers.make("lrgf-glr", **params, n_jobs=2).fit(with_fault_twins(train))
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


def _settings(max_epochs: int) -> BankSettings:
    return BankSettings.from_params(
        {**LRGFGLR(**LRGFGLR.fast_params()).get_params(), "n_hidden": 3, "max_epochs": max_epochs}
    )


@pytest.mark.parametrize("n_jobs", [1, 2])
def test_a_warm_start_begins_at_the_given_bank(train, n_jobs) -> None:
    """One epoch evaluates the starting point and keeps it (the best loss so far), so a bank
    warm-started on its own training set with one epoch has the starting networks' weights;
    from scratch it has the seed's initialisation instead."""
    records = [e.y for e in train]
    in_idx, out_idx = [np.array([0, 1]), np.array([1, 2])], np.array([2, 3])
    start = train_banks(_settings(20), [records], in_idx, out_idx, seed=3, n_jobs=1)[0]
    warm = train_banks(
        _settings(1), [records], in_idx, out_idx, seed=3, n_jobs=n_jobs, init=[start]
    )[0]
    cold = train_banks(_settings(1), [records], in_idx, out_idx, seed=3, n_jobs=n_jobs)[0]
    for s, w, c in zip(start.lrgf, warm.lrgf, cold.lrgf, strict=True):
        sw, ww, cw = (export_module(m)[1] for m in (s, w, c))
        for k in sw:
            np.testing.assert_array_equal(ww[k].numpy(), sw[k].numpy(), err_msg=k)
        assert not np.array_equal(cw["weight_out"].numpy(), sw["weight_out"].numpy())


def test_initial_banks_must_match_the_sets_and_relations(train) -> None:
    records = [e.y for e in train]
    in_idx, out_idx = [np.array([0, 1])], np.array([2])
    start = train_banks(_settings(2), [records], in_idx, out_idx, seed=0, n_jobs=1)[0]
    with pytest.raises(ValueError, match="1 initial banks for 2 training sets"):
        train_banks(_settings(2), [records, records], in_idx, out_idx, 0, 1, init=[start])
    two = [np.array([0, 1]), np.array([1, 2])]
    with pytest.raises(ValueError, match="an initial bank has 1 networks for 2 relations"):
        train_banks(_settings(2), [records], two, np.array([2, 3]), 0, 1, init=[start])


def test_the_detectors_bank_refits_from_the_first_fold(train, monkeypatch) -> None:
    """``refit_epochs``: the fold banks train first, then the bank on every record starts from
    the first fold's for min(refit_epochs, max_epochs) epochs; ``None`` is one joint call."""
    calls = []
    real = LRGFGLR._train_banks

    def spy(self, sets, init=None, max_epochs=None):
        banks = real(self, sets, init=init, max_epochs=max_epochs)
        calls.append((len(sets), init, max_epochs, banks))
        return banks

    monkeypatch.setattr(LRGFGLR, "_train_banks", spy)
    params = {**LRGFGLR.fast_params(), "fault_scenarios": ["f3"], "n_folds": 3}
    diagnosers.make("lrgf-glr", **{**params, "refit_epochs": 10_000}).fit(train)
    (n_folds, init0, ep0, folds), (n_final, init1, ep1, _) = calls
    assert (n_folds, init0, ep0) == (3, None, None)
    assert n_final == 1 and init1[0] is folds[0] and ep1 == params["max_epochs"]
    calls.clear()
    diagnosers.make("lrgf-glr", **{**params, "refit_epochs": None}).fit(train)
    assert [(n, i, e) for n, i, e, _ in calls] == [(4, None, None)]
