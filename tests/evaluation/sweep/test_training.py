"""The training stage: every relation of every bank a task of the sweep's pool, the same bits as
a fit in one process, each shared relation trained once, a cached one never again."""

from __future__ import annotations

import json
import tempfile
from pathlib import Path

from diagnosers.lrgf.lrgf_glr import LRGFGLR
from diagnosers.lrgf.lrgf_mem import LRGFMEM
from evaluation.sweep import DiagnoserSpec, SimulatedData, SweepConfig, run_sweep
from evaluation.sweep.tasks import dir_files, training_episodes
from fcc_env.scenarios import FaultSpec

DATA = SimulatedData(
    scenarios=("nominal", "f1"),
    test_seeds=(0,),
    train_seeds=(100, 101, 102),
    n_samples=500,
    fault=FaultSpec(onset=250),
)
MEM = {**LRGFMEM.fast_params(), "max_epochs": 8, "mem_max_epochs": 2}
SPECS = (
    DiagnoserSpec("lrgf-mem", MEM),
    # another band on the same relations: the same jobs, each trained once
    DiagnoserSpec("lrgf-mem", {**MEM, "band_alpha": 0.05}, label="lrgf-mem-wide"),
    # fold banks, then a final bank warm-started from the first: its jobs are asked for in a
    # second round, once the fold banks are known
    DiagnoserSpec(
        "lrgf-glr",
        {
            **LRGFGLR.fast_params(),
            "max_epochs": 8,
            "mem_max_epochs": 2,
            "n_folds": 2,
            "refit_epochs": 4,
        },
    ),
)
CONFIG = SweepConfig(diagnosers=SPECS, data=DATA)


def _fit_here(spec: DiagnoserSpec) -> dict[str, bytes]:
    """The saved files of ``spec`` fitted in this process, its banks trained in place."""
    diag = spec.build()
    diag.fit(training_episodes(diag, DATA, spec.key))
    with tempfile.TemporaryDirectory() as d:
        diag.save(d)
        return dir_files(Path(d))


def _model(store: Path, label: str) -> dict[str, bytes]:
    """A stored model's files, less the store's own record (which holds wall times)."""
    files = dir_files(store / "models" / label)
    files.pop("spec.json")
    return files


def _meta(store: Path, label: str) -> dict:
    return json.loads((store / "models" / label / "spec.json").read_text())


def test_relations_as_pool_tasks_give_the_bits_of_a_fit_in_one_process(tmp_path) -> None:
    cache = tmp_path / "relations"
    res = run_sweep(CONFIG, tmp_path / "pool", n_workers=2, progress=False, relation_cache=cache)
    assert res.n_trained == 3
    for spec in SPECS:  # the same model files, byte for byte, as a fit in this process
        assert _model(tmp_path / "pool", spec.key) == _fit_here(spec), spec.key
    n_relations = _meta(tmp_path / "pool", "lrgf-mem")["spec"]["n_relation_jobs"]
    assert n_relations == 3  # the default bank
    glr = _meta(tmp_path / "pool", "lrgf-glr")
    # lrgf-glr: n_folds fold banks and the warm-started final bank
    assert glr["spec"]["n_relation_jobs"] == 3 * n_relations
    # the two lrgf-mem share their jobs: trained once, into the cache, with lrgf-glr's
    assert _meta(tmp_path / "pool", "lrgf-mem-wide")["spec"]["n_relation_jobs"] == n_relations
    n_jobs = len(list(cache.rglob("*.npz")))
    assert 3 * n_relations <= n_jobs <= 4 * n_relations
    # a second sweep over the same cache trains no relation again, in this process either
    again = run_sweep(CONFIG, tmp_path / "again", n_workers=0, progress=False, relation_cache=cache)
    assert again.n_trained == 3 and len(list(cache.rglob("*.npz"))) == n_jobs
    for spec in SPECS:
        assert _meta(tmp_path / "again", spec.key)["spec"]["relation_wall_s"] == 0.0
        assert _model(tmp_path / "again", spec.key) == _model(tmp_path / "pool", spec.key)
