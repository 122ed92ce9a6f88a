"""Isolating diagnosers, labelled training faults, gated unknown faults, isolability."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from synthetic import inject_step_fault, make_episode

import diagnosers
from diagnosers import Diagnoser, Episode, make
from diagnosers.isolation.isolating_detector import AGE_EDGES
from diagnosers.isolation.isolators import LRGFISO, LRGFLDA, spherical_kmeans
from evaluation.metrics.isolation_metrics import cdr, episode_label

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


@pytest.mark.parametrize("name", ["lrgf-iso", "lrgf-lda"])
def test_fit_on_a_fitted_detector_equals_fit(
    name: str, training: list[Episode], fitted: dict[str, Diagnoser]
) -> None:
    # one bank, several isolators: the isolation fitted on a detector trained elsewhere is the
    # one fit() builds around its own copy of the same detector
    inner_params = diagnosers.diagnoser_class("lrgf-mem").fast_params()
    healthy = [ep for ep in training if ep.fault_onset is None]
    faulty = [ep for ep in training if ep.fault_onset is not None]
    inner = make("lrgf-mem", **inner_params).fit(healthy)
    iso = make(name, detector=inner_params).fit_on_detector(inner, faulty)
    ep = inject_step_fault(steady(32), onset=700, magnitude=3.0, channel="T_rg2")
    a, b = iso.detect(ep), fitted[name].detect(ep)
    np.testing.assert_array_equal(a.alarm, b.alarm)
    np.testing.assert_array_equal(a.diagnosis, b.diagnosis)
    np.testing.assert_array_equal(a.class_scores, b.class_scores)
    with pytest.raises(ValueError, match=r"detector must be a fitted 'lrgf-mem', got PCA"):
        make(name).fit_on_detector(make("pca").fit(healthy), faulty)
    with pytest.raises(diagnosers.NotFittedError, match="not fitted"):
        make(name).fit_on_detector(make("lrgf-mem"), faulty)


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
