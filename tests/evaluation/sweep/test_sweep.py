"""Harness: sweep results, resume after interruption, parallel = serial, aggregation, bad input."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest

from diagnosers import Episode
from evaluation.sweep import (
    CellResult,
    DiagnoserSpec,
    LoadedEpisode,
    SimulatedData,
    SweepConfig,
    default_specs,
    detect_episode,
    run_sweep,
    score_episode,
    summarize,
)
from evaluation.sweep.store import ResultStore, StoreError
from fcc_env.scenarios import FaultSpec

# Short episodes with an early onset keep each simulation ≈ 10 ms.
DATA = SimulatedData(
    scenarios=("nominal", "f1"),
    test_seeds=(0, 1),
    train_seeds=(100, 101),
    n_samples=600,
    fault=FaultSpec(onset=300),
)
CONFIG = SweepConfig(diagnosers=default_specs(("limits", "arx-band")), data=DATA)
N_CELLS = 2 * 2 * 2


def _scores(results) -> list[tuple]:
    """Everything of the records except wall times (which differ between runs)."""
    return [
        tuple(v for k, v in r.to_json().items() if k != "detect_wall_s") for r in results.records
    ]


def _same(a: list[tuple], b: list[tuple]) -> bool:
    def norm(x):
        return "nan" if isinstance(x, float) and math.isnan(x) else x

    return [tuple(map(norm, r)) for r in a] == [tuple(map(norm, r)) for r in b]


@pytest.fixture(scope="module")
def serial(tmp_path_factory):
    store = tmp_path_factory.mktemp("serial")
    return store, run_sweep(CONFIG, store, n_workers=0, progress=False)


def test_sweep_records(serial) -> None:
    _, res = serial
    assert len(res.records) == N_CELLS and res.n_computed == N_CELLS and res.n_trained == 2
    keys = [(r.diagnoser, r.scenario, r.seed) for r in res.records]
    assert keys == [
        (d, s, k) for d in ("limits", "arx-band") for s in ("nominal", "f1") for k in (0, 1)
    ]
    for r in res.records:
        assert r.n_samples == 600 and r.terminated_at is None
        assert 0.0 <= r.r_fd <= 1.0
        if r.scenario == "nominal":
            assert r.fault_onset is None and math.isnan(r.r_td) and math.isnan(r.t_dt)
            assert r.n_fault_samples == 0 and not r.missed
        else:
            assert r.fault_onset == 300 and r.n_fault_samples == 300
            assert 0.0 <= r.r_td <= 1.0
            assert math.isnan(r.t_dt) or r.t_dt_s == pytest.approx(10.0 * r.t_dt)
    # arx-band sees the catalyst-density fault on T_rx almost at once (a real detector check)
    f1 = [r for r in res.records if r.diagnoser == "arx-band" and r.scenario == "f1"]
    assert all(r.t_dt < 50 and r.r_td > 0.5 for r in f1)


def test_training_uses_only_train_seeds_and_is_stored(serial) -> None:
    store, _ = serial
    spec = json.loads((store / "models" / "limits" / "spec.json").read_text())
    assert spec["spec"]["n_train_episodes"] == 2
    assert spec["spec"]["n_train_samples"] == 2 * 600
    eps = DATA.train_episodes()
    assert [ep.seed for ep in eps] == [100, 101]
    assert all(ep.fault_onset is None and ep.scenario == "nominal" for ep in eps)


def test_process_pool_equals_serial(serial, tmp_path) -> None:
    _, ref = serial
    res = run_sweep(CONFIG, tmp_path / "pool", n_workers=2, progress=False)
    assert _same(_scores(res), _scores(ref))


def test_resume_after_interruption(serial, tmp_path, monkeypatch) -> None:
    _, ref = serial
    store = tmp_path / "s"
    real_write = ResultStore.write_cell
    calls = {"n": 0}

    def write_then_die(self, *a, **k):
        if calls["n"] == 3:
            raise KeyboardInterrupt  # Ctrl-C after three finished cells
        calls["n"] += 1
        return real_write(self, *a, **k)

    monkeypatch.setattr(ResultStore, "write_cell", write_then_die)
    with pytest.raises(KeyboardInterrupt):
        run_sweep(CONFIG, store, n_workers=0, progress=False)
    monkeypatch.undo()
    assert len(list((store / "cells").rglob("*.json"))) == 3
    res = run_sweep(CONFIG, store, n_workers=0, progress=False)
    assert (res.n_reused, res.n_computed, res.n_trained) == (3, N_CELLS - 3, 0)
    assert _same(_scores(res), _scores(ref))
    again = run_sweep(CONFIG, store, n_workers=0, progress=False)
    assert (again.n_reused, again.n_computed) == (N_CELLS, 0)


def test_more_seeds_reuse_finished_cells(serial, tmp_path) -> None:
    store = tmp_path / "s"
    run_sweep(CONFIG, store, n_workers=0, progress=False)
    bigger = dataclasses.replace(CONFIG, data=dataclasses.replace(DATA, test_seeds=(0, 1, 2)))
    res = run_sweep(bigger, store, n_workers=0, progress=False)
    assert (res.n_reused, res.n_computed, res.n_trained) == (N_CELLS, 4, 0)


def test_corrupted_cell_is_reported_not_overwritten(tmp_path) -> None:
    store = tmp_path / "s"
    run_sweep(CONFIG, store, n_workers=0, progress=False)
    cell = store / "cells" / "limits" / "f1" / "seed-1.json"
    cell.write_text('{"format": "fcc-sweep-cell", "ver')  # torn by hand
    with pytest.raises(StoreError, match=r"seed-1\.json"):
        run_sweep(CONFIG, store, n_workers=0, progress=False)
    assert cell.read_text() == '{"format": "fcc-sweep-cell", "ver'


def test_other_settings_are_refused(tmp_path) -> None:
    store = tmp_path / "s"
    run_sweep(CONFIG, store, n_workers=0, progress=False)
    other_data = dataclasses.replace(CONFIG, data=dataclasses.replace(DATA, n_samples=700))
    with pytest.raises(StoreError, match="different sweep"):
        run_sweep(other_data, store, n_workers=0, progress=False)
    other_params = SweepConfig(diagnosers=(DiagnoserSpec("limits", {"alpha": 0.05}),), data=DATA)
    with pytest.raises(StoreError, match="other diagnoser settings"):
        run_sweep(other_params, store, n_workers=0, progress=False)


def test_detect_episode_matches_stored_cell(serial) -> None:
    store, res = serial
    loaded, det = detect_episode(CONFIG, store, "arx-band", "f1", 1)
    rec = next(r for r in res.records if (r.diagnoser, r.scenario, r.seed) == ("arx-band", "f1", 1))
    assert det.alarm.shape == (600,) and int(det.alarm.sum()) == rec.n_alarms
    assert loaded.fault_onset == 300 and loaded.episode.seed == 1
    with pytest.raises(ValueError, match="Unknown diagnoser label"):
        detect_episode(CONFIG, store, "nope", "f1", 1)


@pytest.mark.parametrize(
    ("change", "match"),
    [
        ({"diagnosers": (DiagnoserSpec("no-such"),)}, "Unknown diagnoser 'no-such'"),
        ({"diagnosers": (DiagnoserSpec("limits", {"alfa": 0.1}),)}, "Unknown hyperparameter"),
        ({"diagnosers": (DiagnoserSpec("limits"), DiagnoserSpec("limits"))}, "unique"),
        ({"diagnosers": (DiagnoserSpec("limits", label="a/b"),)}, "path component"),
        ({"diagnosers": ()}, "at least one diagnoser"),
        (
            {"data": dataclasses.replace(DATA, scenarios=("f9",))},
            r"scenarios=\('f9',\) is outside the allowed range: .*'nominal', 'f1'.*\('f9' is not\)",
        ),
        ({"data": dataclasses.replace(DATA, train_seeds=(1, 100))}, "disjoint"),
        ({"data": dataclasses.replace(DATA, test_seeds=())}, "non-empty"),
        (
            {"data": dataclasses.replace(DATA, test_seeds=(-1,))},
            r"test_seeds=\(-1,\) is outside the allowed range: .*integers in \[0, inf\)",
        ),
        ({"data": dataclasses.replace(DATA, fault=None)}, "fault_time|onset"),
        ({"data": dataclasses.replace(DATA, n_samples=1)}, "n_samples"),
        ({"t_on": -1}, "t_on"),
    ],
)
def test_bad_config(tmp_path, change: dict, match: str) -> None:
    cfg = dataclasses.replace(CONFIG, **change)
    with pytest.raises(ValueError, match=match):
        run_sweep(cfg, tmp_path / "s", n_workers=0, progress=False)
    assert not (tmp_path / "s").exists()  # nothing written for a rejected sweep


def test_bad_run_arguments(tmp_path) -> None:
    with pytest.raises(ValueError, match="Unknown backend 'dask'"):
        run_sweep(CONFIG, tmp_path, backend="dask")
    with pytest.raises(ValueError, match="n_workers"):
        run_sweep(CONFIG, tmp_path, n_workers=-1)
    with pytest.raises(ValueError, match="ray_address"):
        run_sweep(CONFIG, tmp_path, ray_address="auto")


def test_default_specs_use_test_params(monkeypatch) -> None:
    from diagnosers.classical.limit_checker import LimitChecker

    monkeypatch.setattr(
        LimitChecker, "fast_params", classmethod(lambda cls: {"alpha": 0.05}), raising=False
    )
    (spec,) = default_specs(["limits"], test=True)
    assert spec.params == {"alpha": 0.05} and spec.key == "limits"
    assert default_specs(["limits"])[0].params == {}
    with pytest.raises(ValueError, match="Available"):
        default_specs(["nope"])


# ---- pure parts --------------------------------------------------------------------------------
def _cell(**kw) -> CellResult:
    base = dict(
        diagnoser="d",
        diagnoser_name="d",
        scenario="f1",
        seed=0,
        fault_onset=10,
        n_samples=20,
        n_samples_planned=20,
        n_fault_samples=10,
        terminated_at=None,
        termination_reason=None,
        r_fd=0.0,
        r_td=0.5,
        t_dt=2.0,
        t_dt_s=20.0,
        n_alarms=5,
        sample_time_s=10.0,
        detect_wall_s=0.0,
    )
    return CellResult(**{**base, **kw})


def test_summarize_means_stds_and_misses() -> None:
    nan = float("nan")
    recs = [
        _cell(seed=0, r_fd=0.1, r_td=0.5, t_dt=2.0, t_dt_s=20.0),
        _cell(seed=1, r_fd=0.3, r_td=0.7, t_dt=4.0, t_dt_s=40.0),
        _cell(seed=2, r_fd=0.2, r_td=0.0, t_dt=nan, t_dt_s=nan),  # missed
        _cell(
            scenario="nominal",
            fault_onset=None,
            n_fault_samples=0,
            r_fd=0.05,
            r_td=nan,
            t_dt=nan,
            t_dt_s=nan,
        ),
    ]
    f1, nom = summarize(recs)
    assert (f1.scenario, f1.n_seeds, f1.misses, f1.n_detected) == ("f1", 3, 1, 2)
    assert f1.r_fd == pytest.approx(0.2) and f1.r_fd_std == pytest.approx(0.1)
    assert f1.r_td == pytest.approx(0.4) and f1.r_td_std == pytest.approx(
        np.std([0.5, 0.7, 0], ddof=1)
    )
    assert f1.t_dt == pytest.approx(3.0)  # over detected faults only
    assert f1.t_dt_std == pytest.approx(np.sqrt(2.0)) and f1.t_dt_s == pytest.approx(30.0)
    assert nom.faulty is False and nom.misses == 0 and math.isnan(nom.r_fd_std)
    assert nom.r_fd == pytest.approx(0.05) and math.isnan(nom.t_dt)


def test_cell_json_roundtrip() -> None:
    c = _cell(t_dt=float("nan"), t_dt_s=float("nan"))
    raw = json.loads(
        json.dumps(
            {
                k: (None if isinstance(v, float) and math.isnan(v) else v)
                for k, v in c.to_json().items()
            }
        )
    )
    back = CellResult.from_json(raw)
    assert math.isnan(back.t_dt) and back.missed and back.seed == 0
    with pytest.raises(ValueError, match="lacks the field"):
        CellResult.from_json({"diagnoser": "d"})


class _Always:
    """Minimal fitted diagnoser stand-in that alarms from a given sample on."""

    name = "always"

    def __init__(self, start: int) -> None:
        self.start = start

    def detect(self, ep: Episode):
        from diagnosers import Detection

        n = ep.n_samples
        z = np.zeros((n, 1))
        return Detection(np.arange(n) >= self.start, z, z, z, z, ("x",))


def _episode(n: int, onset: int | None) -> Episode:
    return Episode(np.zeros((n, 1)), ("x",), 10.0, onset, "f1", 5)


def test_score_episode_terminated_before_onset() -> None:
    # planned onset 80, but the plant left its envelope at sample 50: no faulty sample remains
    loaded = LoadedEpisode(_episode(50, None), 80, 100, 50, "afterburn")
    r = score_episode(_Always(40), loaded, label="a")
    assert r.n_samples == 50 and r.terminated_at == 50 and r.termination_reason == "afterburn"
    assert r.r_fd == pytest.approx(10 / 50) and math.isnan(r.r_td) and math.isnan(r.t_dt)
    assert r.n_fault_samples == 0 and not r.missed


def test_score_episode_terminated_after_onset() -> None:
    loaded = LoadedEpisode(_episode(70, 40), 40, 100, 70, "afterburn")
    r = score_episode(_Always(45), loaded, label="a", t_on=10)
    assert r.n_fault_samples == 30 and r.t_dt == 5.0 and r.t_dt_s == 50.0
    assert r.r_td == pytest.approx(25 / 30) and r.r_fd == 0.0
    missed = score_episode(_Always(1000), loaded, label="a")
    assert missed.missed and missed.r_td == 0.0


def test_terminated_simulated_episode_is_cut(monkeypatch) -> None:
    """A simulator episode with terminated_at >= 0 keeps only the samples before it."""
    import fcc_env

    real = fcc_env.simulate_episodes

    def early(*a, **k):
        res = real(*a, **k)
        return dataclasses.replace(
            res, terminated_at=np.full(len(res.seeds), 250), termination_reasons=("test",)
        )

    monkeypatch.setattr(fcc_env, "simulate_episodes", early)
    loaded = DATA.load_test("f1", 0)
    assert loaded.episode.n_samples == 250 and loaded.terminated_at == 250
    assert loaded.fault_onset == 300 and loaded.episode.fault_onset is None
    assert loaded.termination_reason == "test"


def test_harness_never_touches_global_rng(serial, tmp_path) -> None:
    state = np.random.get_state()[1].copy()
    run_sweep(CONFIG, tmp_path / "s", n_workers=0, progress=False)
    assert np.array_equal(np.random.get_state()[1], state)


def test_failing_diagnoser_names_the_cell(tmp_path) -> None:
    # arx-band cannot fit on a channel that is not there: the error says which diagnoser failed
    bad = SweepConfig(
        diagnosers=(DiagnoserSpec("arx-band", {"output": "T_rx", "inputs": ["nope"]}),),
        data=DATA,
    )
    with pytest.raises(RuntimeError, match=r"training arx-band: ValueError: inputs: unknown"):
        run_sweep(bad, tmp_path / "s", n_workers=0, progress=False)


def test_failing_cell_keeps_finished_cells(tmp_path, monkeypatch) -> None:
    import evaluation.sweep.tasks as sweep_module

    real = sweep_module.detect_and_score

    def flaky(diag, loaded, **kw):
        if loaded.episode.scenario == "f1" and loaded.episode.seed == 1:
            raise FloatingPointError("boom")
        return real(diag, loaded, **kw)

    monkeypatch.setattr(sweep_module, "detect_and_score", flaky)
    with pytest.raises(RuntimeError, match=r"limits on f1, seed 1: FloatingPointError: boom"):
        run_sweep(CONFIG, tmp_path / "s", n_workers=0, progress=False)
    monkeypatch.undo()
    done = len(list((tmp_path / "s" / "cells").rglob("*.json")))
    assert done == 6  # nominal 0, 1 and f1 0, for both diagnosers
    res = run_sweep(CONFIG, tmp_path / "s", n_workers=0, progress=False)
    assert (res.n_reused, res.n_computed) == (6, 2)


def test_model_hash_uses_resolved_hyperparameters():
    """A changed default must never reuse stale models: the hash sees the resolved values."""
    implicit = CONFIG.model_hash(DiagnoserSpec("limits", {}), "d")
    explicit = CONFIG.model_hash(DiagnoserSpec("limits", {"alpha": 0.01}), "d")
    other = CONFIG.model_hash(DiagnoserSpec("limits", {"alpha": 0.05}), "d")
    assert implicit == explicit != other
    assert CONFIG.model_hash(DiagnoserSpec("limits", {}), "e") != implicit


@pytest.mark.parametrize(
    ("name", "execution", "result"),
    [
        ("lrgf-mem", {"n_jobs": 2, "progress": True}, {"max_epochs": 10}),
        ("lrgf-glr", {"n_jobs": 2, "progress": True}, {"n_folds": 4}),
        ("lrgf-iso", {"detector": {"n_jobs": 2}}, {"detector": {"max_epochs": 10}}),
    ],
)
def test_model_hash_leaves_out_execution_parameters(name, execution, result):
    """n_jobs and progress do not change the fit: changing them must not retrain a stored model."""
    default = CONFIG.model_hash(DiagnoserSpec(name, {}), "d")
    assert CONFIG.model_hash(DiagnoserSpec(name, execution), "d") == default
    assert CONFIG.model_hash(DiagnoserSpec(name, result), "d") != default


def test_trainings_of_a_sweep_share_their_relations(tmp_path) -> None:
    from diagnosers.lrgf.lrgf_mem import LRGFMEM

    fast = LRGFMEM.fast_params()
    specs = (
        DiagnoserSpec("lrgf-mem", fast),
        # another band on the same relations: the same relation jobs, trained once
        DiagnoserSpec("lrgf-mem", {**fast, "band_alpha": 0.05}, label="lrgf-mem-wide"),
    )
    config = SweepConfig(diagnosers=specs, data=DATA)
    cache = tmp_path / "relations"
    res = run_sweep(config, tmp_path / "s", n_workers=0, progress=False, relation_cache=cache)
    assert res.n_trained == 2
    n_relations = len(LRGFMEM(**fast).fit(DATA.train_episodes()).lrgf_)
    assert len(list(cache.rglob("*.npz"))) == n_relations
    alone = run_sweep(config, tmp_path / "t", n_workers=0, progress=False)
    assert _same(_scores(res), _scores(alone))  # the cache changes no result
