"""Isolating diagnosers, labelled training faults, gated unknown faults, isolability."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from synthetic import inject_step_fault, make_episode

import diagnosers
from diagnosers import Diagnoser, Episode, make
from diagnosers.isolation import AGE_EDGES
from diagnosers.isolators import LRGFISO, LRGFLDA, spherical_kmeans
from evaluation.metrics.isolation_metrics import cdr, episode_label
from evaluation.tracks import TRACKS
from evaluation.tracks.track_data import TrackData

CLASSES = ("step_T_rg1", "step_T_rg2", "step_T_rx")


def steady(seed: int, n: int = 1500) -> Episode:
    """A synthetic episode of a plant at rest (noise only): the models fit it exactly, so a
    fault's residual direction is clean, the small case in which isolation must work."""
    return make_episode(n, seed=seed, step_scale=0.0)


@pytest.fixture(scope="module")
def training() -> list[Episode]:
    healthy = [steady(s) for s in (1, 2)]
    faults = [
        inject_step_fault(steady(s), onset=700, magnitude=3.0, channel=ch)
        for ch in ("T_rx", "T_rg1", "T_rg2")
        for s in (21, 22, 23, 24)
    ]
    return healthy + faults


@pytest.fixture(scope="module")
def fitted(training: list[Episode]) -> dict[str, Diagnoser]:
    return {
        n: make(n, **diagnosers.diagnoser_class(n).fast_params()).fit(training)
        for n in ("lrgf-iso", "lrgf-lda")
    }


@pytest.mark.parametrize("name", ["lrgf-iso", "lrgf-lda"])
@pytest.mark.parametrize("channel", ["T_rx", "T_rg1", "T_rg2"])
def test_isolates_a_clear_fault(name: str, channel: str, fitted: dict[str, Diagnoser]) -> None:
    d = fitted[name]
    assert d.classes_ == CLASSES  # type: ignore[attr-defined]
    ep = inject_step_fault(steady(31), onset=700, magnitude=3.0, channel=channel)
    det = d.detect(ep)
    assert det.diagnosis is not None
    assert episode_label(det.diagnosis, 700) == f"step_{channel}"
    assert cdr(det.diagnosis, f"step_{channel}", 700) >= 0.9


@pytest.mark.parametrize("name", ["lrgf-iso", "lrgf-lda"])
def test_unknown_fault_is_called_unknown(name: str, fitted: dict[str, Diagnoser]) -> None:
    # a negative step on T_rx: the opposite direction of every trained signature
    ep = inject_step_fault(steady(32), onset=700, magnitude=-3.0)
    det = fitted[name].detect(ep)
    assert det.diagnosis is not None and det.alarm[700:].mean() > 0.5
    assert cdr(det.diagnosis, "unknown", 700) >= 0.9


@pytest.mark.parametrize("name", ["lrgf-iso", "lrgf-lda"])
def test_alarms_are_those_of_the_inner_lrgf_mem(name: str, fitted: dict[str, Diagnoser]) -> None:
    d = fitted[name]
    ep = inject_step_fault(steady(33, 1200), onset=600, magnitude=3.0)
    inner = d.detector_  # type: ignore[attr-defined]
    assert type(inner).name == "lrgf-mem"
    a, b = d.detect(ep), inner.detect(ep)
    np.testing.assert_array_equal(a.alarm, b.alarm)
    np.testing.assert_array_equal(a.signal, b.signal)
    # and it is what lrgf-mem trained on the healthy episodes alone gives
    healthy = [steady(s) for s in (1, 2)]
    alone = make("lrgf-mem", **diagnosers.diagnoser_class("lrgf-mem").fast_params()).fit(healthy)
    np.testing.assert_array_equal(alone.detect(ep).alarm, a.alarm)


@pytest.mark.parametrize("name", ["lrgf-iso", "lrgf-lda"])
def test_isolates_around_lrgf_glr_with_its_alarms(
    name: str, training: list[Episode], tmp_path: Path
) -> None:
    # any LRGF detector can be the inner detector: lrgf-glr's alarms, sample for sample
    inner_params = {**diagnosers.diagnoser_class("lrgf-glr").fast_params(), "n_folds": 2}
    d = make(name, detector_name="lrgf-glr", detector=inner_params).fit(training)
    inner = d.detector_  # type: ignore[attr-defined]
    assert type(inner).name == "lrgf-glr"
    ep = inject_step_fault(steady(31), onset=700, magnitude=3.0, channel="T_rg1")
    a, b = d.detect(ep), inner.detect(ep)
    np.testing.assert_array_equal(a.alarm, b.alarm)
    assert episode_label(a.diagnosis, 700) == "step_T_rg1"
    d.reset()
    stream = [d.update(row) for row in ep.y]
    np.testing.assert_array_equal([s.diagnosis for s in stream], a.diagnosis)
    d.save(tmp_path / "m")
    back = Diagnoser.load(tmp_path / "m")
    np.testing.assert_array_equal(back.detect(ep).diagnosis, a.diagnosis)


def test_an_inner_detector_that_is_not_an_lrgf_detector_is_refused(training) -> None:
    with pytest.raises(ValueError, match=r"detector_name='pca' is outside the allowed range"):
        make("lrgf-iso", detector_name="pca").fit(training)


def test_saved_files_hold_no_pickles(fitted: dict[str, Diagnoser], tmp_path: Path) -> None:
    d = fitted["lrgf-lda"]
    d.save(tmp_path / "m")
    with np.load(tmp_path / "m" / "state.npz", allow_pickle=False) as z:
        assert {"classes", "means", "precision", "log_priors", "threshold"} <= set(z.files)
    assert (tmp_path / "m" / "detector" / "config.json").is_file()
    with pytest.raises(ValueError, match=r"lacks the array 'threshold'"):
        state = dict(np.load(tmp_path / "m" / "state.npz"))
        del state["threshold"]
        np.savez(tmp_path / "m" / "state.npz", **state)
        Diagnoser.load(tmp_path / "m")


def test_lda_predicts_as_scikit_learn(
    fitted: dict[str, Diagnoser], training: list[Episode]
) -> None:
    from sklearn.discriminant_analysis import LinearDiscriminantAnalysis

    d = fitted["lrgf-lda"]
    rng = np.random.default_rng(0)
    X = rng.normal(size=(300, d.means_.shape[2]))  # type: ignore[attr-defined]
    y = np.repeat([0, 1, 2], 100)
    X += 2.0 * y[:, None]
    lda = LinearDiscriminantAnalysis(solver="lsqr", store_covariance=True).fit(X, y)
    mine = LRGFLDA()
    mine.classes_ = ("a", "b", "c")
    mine.detector_ = d.detector_  # type: ignore[attr-defined]
    per_class = {c: X[y == j] for j, c in enumerate(mine.classes_)}
    mine._fit_classes(dict.fromkeys(range(len(AGE_EDGES)), per_class))
    for b in range(len(AGE_EDGES)):
        np.testing.assert_array_equal(np.argmax(mine._scores(X, b)[0], axis=1), lda.predict(X))


def test_trained_on_no_fault_calls_every_alarm_unknown() -> None:
    healthy = [make_episode(1500, seed=s) for s in (1, 2)]
    d = make("lrgf-iso", **LRGFISO.fast_params()).fit(healthy)
    ep = inject_step_fault(make_episode(1200, seed=3), onset=600, magnitude=3.0)
    det = d.detect(ep)
    assert d.classes_ == ()
    assert set(det.diagnosis[det.alarm].tolist()) == {"unknown"}


def test_bad_input_names_the_value_and_range(training: list[Episode]) -> None:
    with pytest.raises(ValueError, match=r"unknown_quantile.*0\.7"):
        make("lrgf-iso", unknown_quantile=0.7).fit(training)
    with pytest.raises(ValueError, match=r"n_prototypes.*0"):
        make("lrgf-iso", n_prototypes=0).fit(training)
    with pytest.raises(ValueError, match=r"score_lambda.*1\.5"):
        make("lrgf-iso", score_lambda=1.5).fit(training)
    with pytest.raises(ValueError, match=r"alarm_gap.*0"):
        make("lrgf-lda", alarm_gap=0).fit(training)
    with pytest.raises(ValueError, match=r"detector.*'fast'"):
        make("lrgf-lda", detector="fast").fit(training)
    with pytest.raises(ValueError, match=r"at least one healthy episode"):
        make("lrgf-iso").fit([e for e in training if e.fault_onset is not None])
    bad = inject_step_fault(make_episode(800, seed=5), onset=400)
    bad = Episode(bad.y, bad.channels, 10.0, fault_onset=400, scenario="unknown")
    with pytest.raises(ValueError, match=r"scenario='unknown'"):
        make("lrgf-iso").fit([training[0], bad])
    few = [training[0], inject_step_fault(make_episode(800, seed=6), onset=795, magnitude=3.0)]
    with pytest.raises(ValueError, match=r"alarmed post-onset training samples; at least 10"):
        make("lrgf-iso", **LRGFISO.fast_params()).fit(few)


def test_spherical_kmeans_finds_separate_directions() -> None:
    rng = np.random.default_rng(1)
    u = np.concatenate([np.tile([1.0, 0, 0], (50, 1)), np.tile([0, 1.0, 0], (50, 1))])
    u += 0.01 * rng.normal(size=u.shape)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    c = spherical_kmeans(u, 2, seed=0)
    assert np.allclose(np.sort(np.abs(c).max(axis=1)), 1.0, atol=1e-3)
    assert abs(c[0] @ c[1]) < 0.05


# ---- harness data -------------------------------------------------------------------------------
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
    (mult,) = heat.param_multipliers(t, fx_params()).values()
    assert np.all(mult[:5] == 1.0) and np.all(mult[5:] > 1.0)
    deact = GatedEffect(fx.make("catalyst_deactivation", loss_per_day=0.5), onset=5)
    (m2,) = deact.param_multipliers(t, fx_params()).values()
    assert np.all(m2[:6] == 1.0) and np.all(np.diff(m2[5:]) < 0)  # decays from the onset on
    with pytest.raises(ValueError, match=r"onset.*-1"):
        GatedEffect(fx.make("sensor_bias:T_rg1"), onset=-1)


def fx_params() -> object:
    from fcc_env.params import FCCParams

    return FCCParams()


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


def test_figure_and_packed_detection_carry_the_diagnosis(fitted: dict[str, Diagnoser]) -> None:
    from evaluation.reports.plots import detection_figure
    from evaluation.sweep.records import pack_detection, unpack_detection
    from evaluation.sweep.sources import LoadedEpisode

    ep = inject_step_fault(steady(34, 1200), onset=600, magnitude=3.0, channel="T_rg1")
    det = fitted["lrgf-iso"].detect(ep)
    arrays = pack_detection(LoadedEpisode(ep, 600, 1200), det)
    _, _, back, _ = unpack_detection(arrays)
    assert back.diagnosis is not None
    np.testing.assert_array_equal(back.diagnosis, det.diagnosis)
    fig = detection_figure(ep, det)
    # one figure legend below the panels (evaluation.reports.plots), and a named row in the strip
    texts = [t.get_text() for leg in fig.legends for t in leg.get_texts()]
    assert "diagnosis: step_T_rg1" in texts
    ticks = [t.get_text() for t in fig.axes[-1].get_yticklabels()]
    assert "diagnosis: step_T_rg1" in ticks


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
