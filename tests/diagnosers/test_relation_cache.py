"""The relation cache (:mod:`diagnosers.bank.relation_cache`): shared training, the same bits."""

from __future__ import annotations

import fcntl
import os
import stat
import threading
import zipfile

import numpy as np
import pytest
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


# ---- a cache anyone may have edited (issue 45): refused by name, retrained, never a hang -------
def _small_job(train):
    s = BankSettings.from_params(
        {**LRGFMEM(**LRGFMEM.fast_params()).get_params(), "n_hidden": 2, "max_epochs": 3}
    )
    return s, [[train[0].y]], [np.array([0, 1])], np.array([2])


def _fit(job, cache, seed: int = 0) -> dict[str, np.ndarray]:
    s, sets, in_idx, out_idx = job
    with shared_relations(cache):
        (bank,) = train_banks(s, sets, in_idx, out_idx, seed, 1)
    return {k: v.numpy() for k, v in export_module(bank.lrgf[0])[1].items()}


def _equal(a: dict[str, np.ndarray], b: dict[str, np.ndarray]) -> bool:
    return a.keys() == b.keys() and all(np.array_equal(a[k], b[k]) for k in a)


def _within(seconds: float, fn):
    """``fn()``'s result, or a failure (not a hung test) when it takes longer than ``seconds``."""
    out: dict[str, object] = {}
    worker = threading.Thread(target=lambda: out.update(value=fn()), daemon=True)
    worker.start()
    worker.join(seconds)
    assert not worker.is_alive(), f"still running after {seconds} s: a hang"
    return out["value"]


def test_a_fifo_in_place_of_a_lock_does_not_hang_the_fit(train, tmp_path, caplog) -> None:
    job = _small_job(train)
    fresh = _fit(job, None)
    _fit(job, tmp_path)
    (entry,) = _entries(tmp_path)
    lock = entry.with_suffix(".lock")
    lock.unlink()
    os.mkfifo(lock)
    with caplog.at_level("WARNING"):
        again = _within(60, lambda: _fit(job, tmp_path))
    assert _equal(again, fresh)
    assert str(lock) in caplog.text and "not a regular file" in caplog.text
    assert stat.S_ISFIFO(lock.lstat().st_mode)  # bypassed, not opened for writing


def test_a_lock_held_too_long_is_bypassed_after_the_timeout(tmp_path, caplog) -> None:
    cache = RelationCache(tmp_path, lock_timeout_s=0.2)
    key = "ab" + "0" * 62
    lock = cache.path(key).with_suffix(".lock")
    lock.parent.mkdir(parents=True)
    with open(lock, "w") as held:  # another holder of the key's lock (flock is per open file)
        fcntl.flock(held.fileno(), fcntl.LOCK_EX)
        with caplog.at_level("WARNING"):
            _within(30, lambda: cache.fetch_or_train(key, lambda: "trained"))
    assert "held by another process for over 0.2 s" in caplog.text and str(lock) in caplog.text


def test_a_lock_link_is_not_followed(train, tmp_path, caplog) -> None:
    job = _small_job(train)
    _fit(job, tmp_path / "c")
    (entry,) = _entries(tmp_path / "c")
    victim = tmp_path / "victim"
    victim.write_text("keep me")
    lock = entry.with_suffix(".lock")
    lock.unlink()
    lock.symlink_to(victim)
    with caplog.at_level("WARNING"):
        _fit(job, tmp_path / "c")
    assert victim.read_text() == "keep me" and str(lock) in caplog.text


def test_another_jobs_entry_copied_in_is_refused_and_retrained(train, tmp_path, caplog) -> None:
    job = _small_job(train)
    fresh = _fit(job, None)
    _fit(job, tmp_path)
    _fit(job, tmp_path, seed=7)  # another job: another seed
    first, other = sorted(_entries(tmp_path), key=lambda p: p.stat().st_mtime)
    first.unlink()
    first.symlink_to(other)  # linked in (a copy reads the same)
    with caplog.at_level("WARNING"):
        again = _fit(job, tmp_path)
    assert _equal(again, fresh)  # not the other job's model
    assert str(first) in caplog.text and "entry of another job" in caplog.text
    assert not first.is_symlink()  # replaced by its own entry
    with np.load(first) as npz:
        assert first.stem in str(npz["meta"])  # the entry names its key


def test_a_nan_entry_is_corrupt_and_retrained(train, tmp_path, caplog) -> None:
    job = _small_job(train)
    fresh = _fit(job, None)
    _fit(job, tmp_path)
    (entry,) = _entries(tmp_path)
    with np.load(entry) as npz:
        arrays = {k: npz[k] for k in npz.files}
    name = next(k for k in arrays if k.startswith("net/") and arrays[k].size)
    arrays[name] = np.full_like(arrays[name], np.nan)
    np.savez(entry, **arrays)
    with caplog.at_level("WARNING"):
        again = _fit(job, tmp_path)  # no LinAlgError: the entry is never used
    assert _equal(again, fresh)
    assert str(entry) in caplog.text and f"{name!r} holds non-finite values" in caplog.text
    with np.load(entry) as npz:
        assert all(np.isfinite(npz[k]).all() for k in npz.files if k != "meta")


def test_a_linked_shard_folder_puts_nothing_outside_the_cache(train, tmp_path, caplog) -> None:
    job = _small_job(train)
    fresh = _fit(job, None)
    _fit(job, tmp_path / "probe")
    (entry,) = _entries(tmp_path / "probe")
    cache, outside = tmp_path / "cache", tmp_path / "outside"
    cache.mkdir()
    outside.mkdir()
    (cache / entry.parent.name).symlink_to(outside, target_is_directory=True)
    with caplog.at_level("WARNING"):
        again = _fit(job, cache)
    assert _equal(again, fresh)
    assert list(outside.iterdir()) == []
    assert "outside the cache" in caplog.text and entry.parent.name in caplog.text


def test_a_special_file_as_entry_is_refused_by_name(train, tmp_path, caplog) -> None:
    job = _small_job(train)
    _fit(job, tmp_path)
    (entry,) = _entries(tmp_path)
    entry.unlink()
    os.mkfifo(entry)
    with caplog.at_level("WARNING"):
        _within(60, lambda: _fit(job, tmp_path))
    assert str(entry) in caplog.text and "FIFO" in caplog.text
    assert zipfile.is_zipfile(entry)  # replaced by a good entry


def test_a_bad_key_is_refused_by_value(tmp_path) -> None:
    for key in ("../../etc/passwd", "AB" + "0" * 62, "ab", 5):
        with pytest.raises(ValueError, match=r"key=.* is outside the allowed range: 64"):
            RelationCache(tmp_path).path(key)  # type: ignore[arg-type]
