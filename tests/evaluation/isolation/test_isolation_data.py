"""The isolation study's data: labelled training faults, gated unknown faults, isolability, and
the harness training isolators on labelled faults."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from diagnosers import Diagnoser
from diagnosers.isolation.isolators import LRGFISO
from evaluation.tracks import TRACKS
from evaluation.tracks.track_data import TrackData
from fcc_env.params import FCCParams


def test_train_fault_episodes_use_training_seeds_and_track_draws() -> None:
    track = TRACKS["paper"].replace(n_train=2, n_train_faults=3, n_samples=2400)
    data = TrackData(track=track)
    eps = data.train_fault_episodes()
    assert [(e.scenario, e.seed) for e in eps] == [
        (f, s) for f in track.faults for s in track.train_fault_seeds
    ]
    assert list(track.train_fault_seeds) == [1000, 1001, 1002]  # training seeds too
    for e in eps:
        assert e.seed is not None and e.seed >= 1000
        assert e.fault_onset == track.fault_spec(e.scenario, e.seed).onset
    assert data.fault_training_key() != TrackData(track=TRACKS["small"]).fault_training_key()


def test_gated_effect_starts_at_its_onset() -> None:
    import fcc_env.effects as fx
    from evaluation.isolation.unknown_faults import GatedEffect

    heat = GatedEffect(fx.make("heat_loss:stage1", extra_ua_kw_per_k=2.0), onset=5)
    t = np.arange(10) * 10.0
    (mult,) = heat.param_multipliers(t, FCCParams()).values()
    assert np.all(mult[:5] == 1.0) and np.all(mult[5:] > 1.0)
    deact = GatedEffect(fx.make("catalyst_deactivation", loss_per_day=0.5), onset=5)
    (m2,) = deact.param_multipliers(t, FCCParams()).values()
    assert np.all(m2[:6] == 1.0) and np.all(np.diff(m2[5:]) < 0)  # decays from the onset on
    with pytest.raises(ValueError, match=r"onset.*-1"):
        GatedEffect(fx.make("sensor_bias:T_rg1"), onset=-1)


def test_unknown_fault_episodes_act_from_the_onset_only() -> None:
    from evaluation.isolation.unknown_faults import unknown_fault_episodes

    data = TrackData(track=TRACKS["paper"].replace(n_samples=600))
    (le,) = unknown_fault_episodes(data, [5000], ["sensor_bias:T_rg1"], onset=300)
    ep = le.episode
    assert ep.scenario == "sensor_bias:T_rg1" and ep.fault_onset == 300
    diff = ep.y_clean[:, 4] - data.reference(5000)[:, 4]
    assert np.allclose(diff[:300], 0.0) and np.allclose(diff[300:], 4.0)


def test_isolability_separates_f1_from_f3_at_once() -> None:
    from evaluation.isolation.isolability import isolability, isolability_markdown

    res = isolability("paper", faults=["f1", "f3"], n_seeds=1, horizon=200, window=50)
    assert res.t_sep.shape == (2, 2) and np.all(np.diag(res.t_sep) == 0)
    assert res.t_sep[0, 1] <= 5 and res.t_sep[1, 0] <= 50  # f1 jumps, f3 builds up
    assert res.angle[0, 1] == pytest.approx(res.angle[1, 0]) and res.angle[0, 1] > 90
    assert "| f1 |" in isolability_markdown(res)


def test_harness_trains_isolators_on_labelled_faults_and_tables_them(tmp_path: Path) -> None:
    from evaluation.sweep import DiagnoserSpec, SweepConfig, run_sweep
    from evaluation.tracks.board_tables import isolation_table, write_track
    from evaluation.tracks.oracle import oracle_records
    from evaluation.tracks.rows import TrackRun, track_rows

    tiny = TRACKS["paper"].replace(n_healthy=1, n_faulty=1, n_train=2, n_validation=2)
    data = TrackData(track=tiny)
    specs = (DiagnoserSpec("lrgf-iso", LRGFISO.fast_params()), DiagnoserSpec("limits"))
    config = SweepConfig(diagnosers=specs, data=data)
    res = run_sweep(config, tmp_path / "store", n_workers=0, progress=False)
    iso = [r for r in res.records if r.diagnoser == "lrgf-iso" and r.fault_onset is not None]
    assert {r.scenario for r in iso} == {"f1", "f2", "f3", "f4"}
    for r in iso:  # every faulty cell carries its isolation scores
        assert r.diagnosis in {"f1", "f2", "f3", "f4", "unknown", "missed"}
        assert 0.0 <= r.r_ti <= 1.0 and 0.0 <= r.r_fi <= 1.0
    assert all(r.diagnosis == "" for r in res.records if r.diagnoser == "limits")
    model = next((tmp_path / "store").rglob("lrgf-iso/**/config.json")).parent
    assert Diagnoser.load(model).classes_ == ("f1", "f2", "f3", "f4")  # type: ignore[attr-defined]
    records = (*res.records, *oracle_records(data))
    rows = track_rows(records, ["lrgf-iso", "limits"], tiny.faults)
    run = TrackRun(tiny, records, tuple(rows), 0.0, res.n_computed, res.n_reused)
    text = isolation_table(run)
    assert "### Isolation" in text and "| lrgf-iso |" in text and "| limits |" not in text
    paths = write_track(run, tmp_path / "out")
    assert (tmp_path / "out" / "figures" / "confusion-lrgf-iso.png") in paths


def test_simulated_data_labels_its_training_faults() -> None:
    from evaluation.sweep.sources import SimulatedData

    data = SimulatedData(
        scenarios=("nominal", "f1", "f3"), train_seeds=(1000, 1001), n_samples=2300
    )
    eps = data.train_fault_episodes()
    assert [(e.scenario, e.seed, e.fault_onset) for e in eps] == [
        ("f1", 1000, 1900),
        ("f1", 1001, 1900),
        ("f3", 1000, 2020),
        ("f3", 1001, 2020),
    ]
