"""The relation cache (:mod:`diagnosers.bank.relation_cache`): shared training, the same bits."""

from __future__ import annotations

import zipfile

import numpy as np
from synthetic import inject_step_fault, make_episode, with_fault_twins

import diagnosers
from diagnosers.bank.parallel import BankSettings, train_banks
from diagnosers.bank.relation_cache import RelationCache, job_key, shared_relations
from diagnosers.lrgf.lrgf_glr import LRGFGLR
from diagnosers.lrgf.lrgf_mem import LRGFMEM
from diagnosers.networks.modules import export_module


def _weights(d) -> list[dict[str, np.ndarray]]:
    return [{k: v.numpy() for k, v in export_module(m)[1].items()} for m in [*d.lrgf_, *d.mem_]]


def _same(a, b) -> None:
    for sa, sb in zip(_weights(a), _weights(b), strict=True):
        assert sa.keys() == sb.keys()
        for k in sa:
            np.testing.assert_array_equal(sa[k], sb[k], err_msg=k)
    for key, value in a._get_state().items():
        np.testing.assert_array_equal(value, b._get_state()[key], err_msg=key)


def _entries(directory) -> list:
    return sorted(directory.rglob("*.npz"))


def test_a_cached_fit_has_the_bits_of_a_fresh_one(train, tmp_path) -> None:
    params = LRGFMEM.fast_params()
    fresh = diagnosers.make("lrgf-mem", **params).fit(train)
    with shared_relations(tmp_path):
        first = diagnosers.make("lrgf-mem", **params).fit(train)
        entries = _entries(tmp_path)
        second = diagnosers.make("lrgf-mem", **params).fit(train)
    assert len(entries) == len(fresh.lrgf_)  # one entry per relation job
    assert _entries(tmp_path) == entries  # the second fit trained nothing
    _same(fresh, first)
    _same(fresh, second)
    ep = inject_step_fault(make_episode(900, seed=9), onset=500, magnitude=3.0)
    assert np.array_equal(fresh.detect(ep).alarm, second.detect(ep).alarm)


def test_the_isolators_inner_bank_is_read_from_lrgf_mems(tmp_path) -> None:
    inner = LRGFMEM.fast_params()
    healthy = [make_episode(1500, seed=s, step_scale=0.0) for s in (1, 2)]
    faults = [
        inject_step_fault(make_episode(1500, seed=s, step_scale=0.0), 700, 3.0, channel=ch)
        for ch in ("T_rx", "T_rg1", "T_rg2")
        for s in (21, 22)
    ]
    with shared_relations(tmp_path):
        alone = diagnosers.make("lrgf-mem", **inner).fit(healthy)
        before = _entries(tmp_path)
        iso = diagnosers.make("lrgf-iso", detector=inner).fit(healthy + faults)
    assert _entries(tmp_path) == before  # nothing trained twice
    _same(alone, iso.detector_)


def test_lrgf_glr_and_lrgf_mem_share_the_jobs_they_have_in_common(train, tmp_path) -> None:
    glr = {**LRGFGLR.fast_params(), "fault_scenarios": ["f3"], "fault_seeds": None}
    glr |= {"n_hidden": 3, "n_folds": 3}
    mem = {k: v for k, v in glr.items() if k in LRGFMEM.param_names()}
    with shared_relations(tmp_path):
        diagnosers.make("lrgf-glr", **glr).fit(with_fault_twins(train))
        n_glr = len(_entries(tmp_path))
        diagnosers.make("lrgf-mem", **mem, mem_select="if_better").fit(train)
    # lrgf-mem trains on the first two thirds of the records: lrgf-glr's fold without the last
    assert len(_entries(tmp_path)) == n_glr


def test_a_key_changes_with_every_input(train) -> None:
    s = BankSettings.from_params({**LRGFMEM(**LRGFMEM.fast_params()).get_params()})
    u, y = [train[0].y[:, :2]], [train[0].y[:, [2]]]
    base = job_key(s, u, y, 0, None)
    assert job_key(s, u, y, 0, None) == base
    assert job_key(s, u, y, 1, None) != base
    assert job_key(s, [u[0].copy()], y, 0, None) == base  # contents, not identity
    bumped = u[0].copy()
    bumped[5, 1] += 1e-12
    assert job_key(s, [bumped], y, 0, None) != base
    assert job_key(BankSettings(**{**s.__dict__, "lr": s.lr * 2}), u, y, 0, None) != base
    # drawing a progress bar changes no result
    assert job_key(BankSettings(**{**s.__dict__, "progress": True}), u, y, 0, None) == base


def test_an_unreadable_entry_is_trained_again_never_trusted(train, tmp_path, caplog) -> None:
    s = BankSettings.from_params(
        {**LRGFMEM(**LRGFMEM.fast_params()).get_params(), "n_hidden": 2, "max_epochs": 3}
    )
    in_idx, out_idx = [np.array([0, 1])], np.array([2])
    with shared_relations(tmp_path):
        (first,) = train_banks(s, [[train[0].y]], in_idx, out_idx, 0, 1)
        (entry,) = _entries(tmp_path)
        entry.write_bytes(b"not a zip file")
        with caplog.at_level("WARNING"):
            (again,) = train_banks(s, [[train[0].y]], in_idx, out_idx, 0, 1)
    assert "unreadable" in caplog.text
    a, b = export_module(first.lrgf[0])[1], export_module(again.lrgf[0])[1]
    assert all(np.array_equal(a[k].numpy(), b[k].numpy()) for k in a)
    assert zipfile.is_zipfile(entry)  # replaced by a good entry


def test_entries_hold_no_pickles(train, tmp_path) -> None:
    with shared_relations(tmp_path):
        diagnosers.make("lrgf-mem", **LRGFMEM.fast_params()).fit(train)
    for entry in _entries(tmp_path):
        with np.load(entry, allow_pickle=False) as npz:
            assert all(npz[k].dtype != object for k in npz.files)


def test_the_cache_is_off_outside_a_block(train, tmp_path) -> None:
    with shared_relations(tmp_path):
        pass
    diagnosers.make("lrgf-mem", **LRGFMEM.fast_params()).fit(train)
    assert _entries(tmp_path) == []
    assert RelationCache(tmp_path).path("ab" + "0" * 62).parent.name == "ab"
