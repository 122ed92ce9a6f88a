"""The physical-limit row, the track data source and the per-track tables (benchmark v2)."""

from __future__ import annotations

import json
import math
import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from synthetic import cell_record

from diagnosers.episode.record import Episode
from diagnosers.stages.alarm import EWMA
from evaluation.metrics.intervals import limit_ratio
from evaluation.sweep.records import CellResult, summarize
from evaluation.sweep.sources import simulate_loaded
from evaluation.tracks import TRACKS, board
from evaluation.tracks.board import run_track
from evaluation.tracks.board_tables import track_table, write_track
from evaluation.tracks.filter_bound import FILTER_LABEL
from evaluation.tracks.optimal import CUSUM_LABEL, GLR_LABEL
from evaluation.tracks.oracle import (
    DEFAULT_REFERENCES,
    DIRECTIONAL_CALIBRATION,
    MEASURED_INPUTS_LABEL,
    ORACLE_LABEL,
    REFERENCE_TARGET,
    STAGE_LABEL,
    OracleConfig,
    PhysicalLimit,
    oracle_records,
)
from evaluation.tracks.rows import TrackRun, track_rows
from evaluation.tracks.track_data import TrackData
from fcc_env.params import MEASUREMENT_NAMES
from fcc_env.scenarios import FaultSpec

TINY = TRACKS["paper"].replace(n_healthy=2, n_faulty=1, n_train=2, n_validation=4)
#: the reference rows that take seconds (the directional, filter and GLR rows take tens)
FAST_REFERENCES = (OracleConfig(), OracleConfig(inputs="measured"), OracleConfig(stage="cusum"))
#: the tiny run's calibration episodes for the rows that take 100 by default (directional and
#: filter: their calibration is most of a run's cost); the rows and labels are the defaults'
TINY_CALIBRATION = 20
#: the tiny run's reference rows: every default row, calibrated on TINY_CALIBRATION episodes
#: (the defaults themselves run in the slow variant of the model-sharing test below and in
#: test_reference_runs.py's slow test)
TINY_REFERENCES = tuple(
    replace(c, n_calibration=TINY_CALIBRATION)
    if len(c.calibration_seeds(TINY)) == DIRECTIONAL_CALIBRATION
    else c
    for c in DEFAULT_REFERENCES
)


def _noise_free_f2(data: TrackData, seed: int) -> Episode:
    """The track's f2 episode of ``seed`` without measurement noise (its clean output)."""
    spec = data.track.fault_spec("f2", seed)
    clean = simulate_loaded([seed], TINY.n_samples, spec)[0].episode.y_clean
    assert clean is not None
    return Episode(
        y=clean,
        channels=tuple(MEASUREMENT_NAMES),
        sample_time_s=10.0,
        fault_onset=spec.onset,
        scenario="f2",
        seed=seed,
    )


@pytest.fixture(scope="module")
def oracle() -> PhysicalLimit:
    return PhysicalLimit(TrackData(track=TINY)).fit()


def test_oracle_is_exact_on_noise_free_episodes(oracle: PhysicalLimit) -> None:
    data = oracle.data
    seed = 0
    ep = _noise_free_f2(data, seed)
    clean, onset = ep.y, ep.fault_onset
    det = oracle.detect(ep)
    assert onset is not None
    # Before the onset the healthy plant is known exactly: the residual is zero, no alarm.
    assert not det.alarm[:onset].any()
    assert np.allclose(det.residual[:onset], 0.0, atol=1e-9)
    # After it, the alarm comes exactly when the fault's signature crosses the limit,
    # recomputed here from the definition (normalised residual, EWMA, Hotelling's T²).
    idx = [MEASUREMENT_NAMES.index(c) for c in oracle.config.channels]
    ref = data.reference(seed)
    r = (clean[:, idx] - ref[:, idx]) / oracle.noise_std
    z = EWMA(oracle.config.ewma_lambda).filter(r)
    stage = oracle.stage_
    d = z - stage.mean_  # the row's T² is centred (PhysicalLimit._t2_stage says why)
    t2 = np.einsum("ti,ij,tj->t", d, stage.s_inv_, d)
    limit = stage.h_[0]
    first = int(np.argmax(t2 > limit))
    assert t2[first] > limit and det.alarm.argmax() == first >= onset


def test_oracle_false_alarm_rate_near_its_target(oracle: PhysicalLimit) -> None:
    recs = oracle_records(TrackData(track=TINY.replace(n_healthy=4, n_faulty=1)))
    healthy = [r for r in recs if r.scenario == "nominal"]
    assert np.mean([r.r_fd for r in healthy]) < 0.01
    faulty = {r.scenario: r for r in recs if r.scenario != "nominal"}
    assert set(faulty) == {"f1", "f2", "f3", "f4"}
    assert all(r.t_dt <= 30 for r in faulty.values()), {k: v.t_dt for k, v in faulty.items()}


def test_oracle_config_rejects_bad_values() -> None:
    with pytest.raises(ValueError, match=r"ewma_lambda=0 is outside the allowed range"):
        OracleConfig(ewma_lambda=0)
    with pytest.raises(ValueError, match=r"target=0.7 is outside the allowed range"):
        OracleConfig(target=0.7)
    with pytest.raises(
        ValueError, match=r"stage='bogus'.*one of \['t2', 'directional', 'cusum', 'glr', 'filter'\]"
    ):
        OracleConfig(stage="bogus")
    with pytest.raises(ValueError, match=r"n_calibration=0 is outside the allowed range"):
        OracleConfig(n_calibration=0)


def test_calibration_seeds_stay_clear_of_test_and_training_seeds() -> None:
    paper = TRACKS["paper"]
    assert OracleConfig().calibration_seeds(paper) == paper.validation_seeds
    directional = OracleConfig(stage="directional")
    start = paper.validation_seed_start
    assert directional.calibration_seeds(paper) == range(start, start + DIRECTIONAL_CALIBRATION)
    crowded = paper.with_seeds(test=start + 50)
    with pytest.raises(ValueError, match=r"n_calibration=100 puts calibration seeds .* test"):
        directional.calibration_seeds(crowded)
    assert OracleConfig(stage="directional", n_calibration=50).calibration_seeds(crowded)
    with pytest.raises(ValueError, match=r"inputs='exact'.*measured"):
        OracleConfig(inputs="exact")


@pytest.mark.parametrize("track", ["paper", "uncertain"])
def test_replaying_the_true_inputs_reproduces_the_reference(track) -> None:
    """The measured-input reference with noise-free 'measurements' is the true-input one, to
    the bit: the replay is aligned sample by sample and keeps the seed's plant."""
    data = TrackData(track=TRACKS[track].replace(n_healthy=1, n_faulty=1))
    ref = data.reference(5)
    np.testing.assert_array_equal(data.reference(5, measured=ref), ref)


@pytest.mark.parametrize(
    ("bad", "match"),
    [
        (np.zeros((10, 5)), r"measured has shape \(10, 5\); allowed: \(T, 8\)"),
        (np.zeros(8), r"measured has shape \(8,\); allowed"),
        (np.full((10, 8), np.nan), r"measured contains NaN or inf"),
    ],
)
def test_a_bad_measured_episode_is_refused_by_name(bad, match) -> None:
    data = TrackData(track=TINY)
    with pytest.raises(ValueError, match=match):
        data.reference(0, measured=bad)


def test_the_measured_input_row_sees_the_input_noise() -> None:
    """On a healthy episode the true-input residual is measurement noise alone; with the
    measured inputs the regenerator temperatures carry the input noise through the plant."""
    data = TrackData(track=TINY)
    y = data.load_test("nominal", 0).episode.y
    i = MEASUREMENT_NAMES.index("T_rg1")
    true_res = y[:, i] - data.reference(0)[: len(y), i]
    meas_res = y[:, i] - data.reference(0, measured=y)[: len(y), i]
    assert abs(true_res.std() - 0.3) < 0.03  # the channel's noise std, 0.3 °C
    assert meas_res.std() > 1.05 * true_res.std()
    orc = PhysicalLimit(data, OracleConfig(inputs="measured")).fit()
    assert orc.name == MEASURED_INPUTS_LABEL
    recs = oracle_records(data, OracleConfig(inputs="measured"))
    assert {r.diagnoser for r in recs} == {MEASURED_INPUTS_LABEL}
    assert all(r.t_dt <= 60 for r in recs if r.scenario == "f1")


def test_uncertain_track_shares_the_plant_and_hides_the_draw() -> None:
    unc = TrackData(track=TRACKS["uncertain"].replace(n_healthy=1, n_faulty=1))
    nominal = TrackData(track=TRACKS["paper"].replace(n_healthy=1, n_faulty=1))
    seed = 3
    healthy = unc.load_test("nominal", seed).episode
    faulty = unc.load_test("f1", seed)
    onset = faulty.fault_onset
    assert onset is not None
    # one plant per seed, whatever the scenario: identical before the onset
    assert np.array_equal(healthy.y[:onset], faulty.episode.y[:onset])
    # the draw changes the plant ...
    plain = nominal.load_test("nominal", seed).episode
    assert not np.allclose(healthy.y_clean, plain.y_clean)
    # ... but not the measurement noise stream, and it is deterministic in the seed
    noise_unc = healthy.y - healthy.y_clean
    noise_plain = plain.y - plain.y_clean
    assert np.allclose(noise_unc[:, 3:], noise_plain[:, 3:], atol=1e-3)
    assert np.array_equal(unc.load_test("nominal", seed).episode.y, healthy.y)


def _rec(label: str, scenario: str, seed: int, r_td: float, t_dt: float) -> CellResult:
    return cell_record(
        label, scenario, seed, r_td=r_td, t_dt=t_dt, r_fd=0.001 * seed, n_alarms=seed
    )


def test_track_rows_ratio_and_ranks() -> None:
    recs = []
    for s in range(6):
        recs.append(_rec("a", "nominal", s, math.nan, math.nan))
        recs.append(_rec(ORACLE_LABEL, "nominal", s, math.nan, math.nan))
        recs.append(_rec("a", "f1", s, 0.5, 9.0 + s))
        recs.append(_rec(ORACLE_LABEL, "f1", s, 0.99, 4.0))
    rows = track_rows(recs, ["a"], ("f1",))
    a, orc = rows
    assert a.label == "a" and orc.label == ORACLE_LABEL
    assert a.faults["f1"].ratio.estimate == pytest.approx(limit_ratio(np.mean(range(9, 15)), 4.0))
    assert orc.faults["f1"].ratio.estimate == pytest.approx(1.0)
    # a reference row is never ranked: the one detector ranks first
    assert (orc.faults["f1"].rank, a.faults["f1"].rank) == ("–", "1")
    assert a.faults["f1"].delay.estimate == pytest.approx(np.mean(range(9, 15)))
    assert a.alarmed_share == pytest.approx(5 / 6)  # seed 0 has no alarm
    assert a.worst_seed == 5


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[TrackRun, Path]:
    """One run of the tiny paper track with every reference row, figures and a model cache
    (its directory is returned): the end-to-end test reads it, and the model-sharing test
    starts from its cache instead of training the same model again (about 30 s a run). The rows
    are TINY_REFERENCES: the directional and filter rows calibrate on 20 episodes, not 100."""
    root = tmp_path_factory.mktemp("tiny-run")
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(board, "DEFAULT_REFERENCES", TINY_REFERENCES)
        run = run_track(
            TINY, ["limits"], root / "paper", workers=0, progress=False, model_cache=root / "models"
        )
    return run, root


def test_run_track_end_to_end(
    tiny_run: tuple[TrackRun, Path], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(board, "DEFAULT_REFERENCES", TINY_REFERENCES)  # the rows of tiny_run
    run, tmp_path = tiny_run
    assert len(TINY_REFERENCES) == len(DEFAULT_REFERENCES) == 6
    labels = [r.label for r in run.rows]
    assert labels == [
        "limits",
        ORACLE_LABEL,
        MEASURED_INPUTS_LABEL,
        STAGE_LABEL,
        FILTER_LABEL,
        CUSUM_LABEL,
        GLR_LABEL,
    ]
    summary = {(s.diagnoser, s.scenario): s for s in summarize(run.records)}
    assert summary[(ORACLE_LABEL, "f1")].t_dt <= 2
    paths = write_track(run, tmp_path / "paper")
    assert {p.name for p in paths} >= {"leaderboard.md", "leaderboard.csv", "leaderboard.json"}
    text = track_table(run)
    assert "oracle (physical limit)" in text and "t_dt/optimal" in text
    assert "Reference rows (read what no detector may; never ranked)" in text
    wide = (tmp_path / "paper" / "leaderboard.md").read_text()
    assert "t_dt/oracle" in wide and "f1 delay" in wide
    assert "Test seeds 0–1; trained on healthy episodes of seeds 1000–1001." in text
    assert list((tmp_path / "paper" / "figures").rglob("*.png"))
    # a second run resumes: nothing computed again
    again = run_track(TINY, ["limits"], tmp_path / "paper", workers=0, progress=False)
    assert again.n_computed == 0 and again.n_reused == len(TINY.test_cells())
    # and the reference rows were stored too (evaluation.tracks.reference_runs)
    assert run.n_reference_computed == 6 * len(TINY.test_cells())
    assert again.n_reference_computed == 0
    assert [json.dumps(r.to_json()) for r in again.rows] == [
        json.dumps(r.to_json()) for r in run.rows
    ]


def test_fault_spec_of_a_track_is_not_random_in_the_env() -> None:
    spec = TRACKS["random"].fault_spec(TRACKS["random"].drawn_fault(4), 4)
    assert isinstance(spec, FaultSpec) and spec.scenario in {"f1", "f2", "f3", "f4"}
    assert spec.onset is not None and spec.magnitude is not None


@pytest.mark.parametrize(
    "references",
    [
        pytest.param(FAST_REFERENCES, id="fast-rows"),
        pytest.param(DEFAULT_REFERENCES, id="every-row", marks=pytest.mark.slow),
    ],
)
def test_tracks_with_one_training_set_share_their_models(
    tiny_run: tuple[TrackRun, Path],
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    references: tuple[OracleConfig, ...],
) -> None:
    """The model cache is shared by tracks of one training set. The reference rows read no
    trained model, so the default run computes only the rows that take seconds on the three
    further tracks (the every-row variant, slow, computes them all: about 90 s more)."""
    monkeypatch.setattr(board, "DEFAULT_REFERENCES", references)
    first, root = tiny_run
    cache = tmp_path / "models"  # a copy: each variant starts from the first track's models
    shutil.copytree(root / "models", cache)
    small = TRACKS["small"].replace(n_healthy=1, n_faulty=1, n_train=2, n_validation=4)
    second = run_track(
        small, ["limits"], tmp_path / "small", workers=0, progress=False, figures=False,
        model_cache=cache,
    )  # fmt: skip
    assert (first.n_trained, first.n_reused_models) == (1, 0)
    assert (second.n_trained, second.n_reused_models) == (0, 1)
    noisy = TRACKS["noisy"].replace(n_healthy=1, n_faulty=1, n_train=2, n_validation=4)
    third = run_track(
        noisy, ["limits"], tmp_path / "noisy", workers=0, progress=False, figures=False,
        model_cache=cache,
    )  # fmt: skip
    assert (third.n_trained, third.n_reused_models) == (1, 0)  # other noise: trained anew
    # a replication on a private test range: the same models, new episodes
    private = run_track(
        TINY.with_seeds(test=100_000), ["limits"], tmp_path / "private", workers=0,
        progress=False, figures=False, model_cache=cache,
    )  # fmt: skip
    assert (private.n_trained, private.n_reused_models) == (0, 1)
    assert {r.seed for r in private.records} == {100_000, 100_001}
    assert "Test seeds 100000–100001" in track_table(private)


def test_directional_row_is_lrgf_glr_stage_on_a_perfect_model(
    tiny_run: tuple[TrackRun, Path],
) -> None:
    """The third reference row: lrgf-glr's alarm stage (same code) on a perfect model's
    residual. With the true inputs the healthy residual is the measurement noise, so the stage's
    scale is the noise std; f3 cools the regenerator beds; a noise-free faulty episode alarms
    only after its onset."""
    assert OracleConfig().false_alarm_target == 0.002
    assert OracleConfig(stage="directional").false_alarm_target == REFERENCE_TARGET
    assert OracleConfig(stage="directional", target=0.01).false_alarm_target == 0.01
    cfg = OracleConfig(inputs="measured", stage="directional")
    assert cfg.label == STAGE_LABEL
    data = TrackData(track=TINY)
    orc = PhysicalLimit(data, OracleConfig(stage="directional")).fit()
    stage = orc.stage_
    assert stage.v_residual_ == pytest.approx(orc.noise_std, rel=0.05)
    f3 = stage.directions_[list(stage.faults).index("f3")]
    assert f3[1] < -0.3 and f3[2] < -0.3  # T_rg1 and T_rg2 fall
    assert stage.false_alarm_target == REFERENCE_TARGET
    ep = _noise_free_f2(data, 0)
    onset = ep.fault_onset
    assert onset is not None
    det = orc.detect(ep)
    assert det.signal_names[0] == "T2[ewma]" and "directional-slow[f3]" in det.signal_names
    assert not det.alarm[:onset].any()
    assert np.allclose(det.residual[:onset], 0.0, atol=1e-9)
    assert det.alarm[onset : onset + 20].any()
    with pytest.raises(NotImplementedError, match="whole episodes with detect"):
        stage.update(ep.y[0])
    # the row's records carry its label and its measured-input variant runs end to end: the
    # tiny run's records of that row (run_references gives oracle_records' bits, see
    # test_reference_runs), not a second calibration
    assert replace(cfg, n_calibration=TINY_CALIBRATION) in TINY_REFERENCES
    recs = [r for r in tiny_run[0].records if r.diagnoser == STAGE_LABEL]
    assert len(recs) == len(TINY.test_cells())
    assert all(r.t_dt <= 60 for r in recs if r.scenario == "f1")
