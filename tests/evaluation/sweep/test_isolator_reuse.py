"""The isolators reuse their inner detector's detection through the store: an isolator's cell
is the same, bit for bit, whether its inner detection is computed in its own cell, handed on by
the detector's cell of the same task, or read from the store."""

from __future__ import annotations

import hashlib
import io
import json
import shutil

import numpy as np
import pytest

from diagnosers.lrgf.bank_detector import BankDetector
from diagnosers.lrgf.lrgf_mem import LRGFMEM
from evaluation.sweep import DiagnoserSpec, SimulatedData, SweepConfig, run_sweep
from evaluation.sweep.runner import inner_detectors, load_cell
from evaluation.sweep.store import ResultStore
from fcc_env.scenarios import FaultSpec

DATA = SimulatedData(
    scenarios=("nominal", "f1", "f2"),
    test_seeds=(0,),
    train_seeds=(100, 101),
    n_samples=400,
    fault=FaultSpec(onset=200),
)
MEM = {**LRGFMEM.fast_params(), "max_epochs": 8, "mem_max_epochs": 2}
DETECTOR = DiagnoserSpec("lrgf-mem", MEM)
ISOLATORS = (
    DiagnoserSpec("lrgf-iso", {"detector": MEM}),
    DiagnoserSpec("lrgf-lda", {"detector": MEM}),
    # other inner settings: not lrgf-mem's model, so it detects itself
    DiagnoserSpec("lrgf-iso", {"detector": {**MEM, "band_alpha": 0.05}}, label="iso-other"),
)
FIGURE = [("f1", 0)]


def _records(res) -> dict[tuple[str, str, int], str]:
    """Each cell's record as canonical JSON, less its wall time (no two runs share one)."""
    out = {}
    for r in res.records:
        rec = {k: v for k, v in r.to_json().items() if not k.endswith("wall_s")}
        out[r.diagnoser, r.scenario, r.seed] = json.dumps(rec, sort_keys=True)
    return out


def _fingerprint(store, config, label: str) -> str:
    """SHA-256 of a figure cell's stored decisions (alarm, statistic, band, diagnosis)."""
    st = ResultStore.open(store, config.data.store_key())
    spec = next(s for s in config.diagnosers if s.key == label)
    arrays = st.read_detection(label, *FIGURE[0], config.cell_hash(spec, st.data_hash))
    assert arrays is not None
    h = hashlib.sha256()
    for key in ("det_alarm", "det_signal", "det_lower", "det_upper", "det_diagnosis"):
        h.update(np.ascontiguousarray(arrays[key]).tobytes())
    return h.hexdigest()


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("reuse")
    cache = tmp / "relations"
    alone = SweepConfig(diagnosers=ISOLATORS, data=DATA)
    pair = SweepConfig(diagnosers=(DETECTOR, *ISOLATORS), data=DATA)
    kw = {"n_workers": 0, "progress": False, "relation_cache": cache, "figure_cells": FIGURE}
    return (
        tmp,
        alone,
        pair,
        run_sweep(alone, tmp / "alone", **kw),
        run_sweep(pair, tmp / "pair", **kw),
    )


def test_an_isolator_reads_its_detectors_detection_with_the_same_result(runs, monkeypatch) -> None:
    tmp, alone, pair, res_alone, res_pair = runs
    st = ResultStore.open(tmp / "pair", pair.data.store_key())
    # the inner model is lrgf-mem's, file for file; iso-other's is not
    assert inner_detectors(st, pair.diagnosers) == {"lrgf-iso": "lrgf-mem", "lrgf-lda": "lrgf-mem"}
    assert inner_detectors(st, ISOLATORS) == {}
    # lrgf-mem's detections are stored under its cell hash, for its isolators
    for sc, seed in DATA.cells():
        assert st.read_detection(
            "lrgf-mem", sc, seed, pair.cell_hash(DETECTOR, st.data_hash), inner=True
        )
    # handed on in the task: the same records and figure detections as each isolator alone
    pair_recs, alone_recs = _records(res_pair), _records(res_alone)
    for key, rec in alone_recs.items():
        assert pair_recs[key] == rec, key
    for spec in ISOLATORS:
        assert _fingerprint(tmp / "pair", pair, spec.key) == _fingerprint(
            tmp / "alone", alone, spec.key
        )

    # handed on in the task: the inner detector runs once per episode, for lrgf-mem's cell
    task = tmp / "task"
    shutil.copytree(tmp / "pair", task)
    for label in ("lrgf-mem", "lrgf-iso", "lrgf-lda"):
        shutil.rmtree(task / "cells" / label)
    shutil.rmtree(task / "inner")
    calls = []
    detect = BankDetector.detect

    def counted(self, episode):
        calls.append(self.name)
        return detect(self, episode)

    with monkeypatch.context() as m:
        m.setattr(BankDetector, "detect", counted)
        res = run_sweep(pair, task, n_workers=0, progress=False)
    assert res.n_computed == 3 * len(DATA.cells())
    assert calls == ["lrgf-mem"] * len(DATA.cells())
    assert _records(res) == pair_recs

    # read from the store: the isolators' cells and figure detections computed again, with no
    # inner detection run (a bank detector's detect would raise)
    again = tmp / "again"
    shutil.copytree(tmp / "pair", again)
    for spec in ISOLATORS[:2]:
        shutil.rmtree(again / "cells" / spec.key)
        shutil.rmtree(again / "detections" / spec.key)

    def no_detect(self, episode):
        raise AssertionError(f"{self.name} detected again")

    with monkeypatch.context() as m:
        m.setattr(BankDetector, "detect", no_detect)
        res = run_sweep(pair, again, n_workers=0, progress=False, figure_cells=FIGURE)
    assert res.n_computed == 2 * len(DATA.cells())
    assert _records(res) == pair_recs
    for spec in ISOLATORS[:2]:
        assert _fingerprint(again, pair, spec.key) == _fingerprint(tmp / "alone", alone, spec.key)

    # neither stored nor in the task: the isolator detects with its own inner model, and
    # stores that detection for the others, the same bits as lrgf-mem's
    own = tmp / "own"
    shutil.copytree(tmp / "pair", own)
    saved = {p.relative_to(own): p.read_bytes() for p in (own / "inner").rglob("*.npz")}
    shutil.rmtree(own / "inner")
    shutil.rmtree(own / "cells" / "lrgf-iso")
    res = run_sweep(pair, own, n_workers=0, progress=False)
    assert _records(res) == pair_recs
    assert {p.relative_to(own) for p in (own / "inner").rglob("*.npz")} == saved.keys()
    for rel, data in saved.items():
        before, after = np.load(io.BytesIO(data)), np.load(own / rel)
        assert sorted(before.files) == sorted(after.files)
        for key in before.files:
            assert before[key].tobytes() == after[key].tobytes(), (rel, key)


def test_diagnose_detection_is_detect(runs) -> None:
    """The identity the reuse rests on, with every array of the detection (class scores too)."""
    tmp, _, pair, _, _ = runs
    loaded, iso = load_cell(pair, tmp / "pair", "lrgf-iso", "f1", 0)
    _, det = load_cell(pair, tmp / "pair", "lrgf-mem", "f1", 0)
    a, b = iso.detect(loaded.episode), iso.diagnose_detection(det.detect(loaded.episode))
    for f in ("alarm", "signal", "lower", "upper", "residual", "diagnosis", "class_scores"):
        assert np.array_equal(
            getattr(a, f), getattr(b, f), equal_nan=f != "alarm" and f != "diagnosis"
        ), f
