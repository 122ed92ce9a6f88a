"""The optimal-detector rows: the exact LLR, Page's CUSUM, the size GLR and their bank."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import pytest
from scipy import stats

from diagnosers.episode.record import Episode
from evaluation.sweep.sources import LoadedEpisode, simulate_loaded
from evaluation.tracks import TRACKS
from evaluation.tracks.optimal import (
    CUSUM_LABEL,
    GLR_LABEL,
    cusum,
    log_likelihood_ratio,
    noise_std,
    window_glr,
)
from evaluation.tracks.oracle import (
    DEFAULT_REFERENCES,
    ORACLE_LABEL,
    REFERENCE_LABELS,
    OracleConfig,
    PhysicalLimit,
    reference_records,
)
from evaluation.tracks.track_data import TrackData
from fcc_env.plant import PlantConfig
from fcc_env.scenarios import FaultSpec


def test_llr_is_the_gaussian_log_likelihood_ratio() -> None:
    rng = np.random.default_rng(0)
    T, c = 50, 8
    h = rng.normal(size=(T, c)) * 10 + 100
    f = h + rng.normal(size=(T, c))
    y = h + rng.normal(size=(T, c)) * 0.5
    sigma = np.full(c, 0.4)
    # equal noise under both hypotheses: the brief's formula
    direct = np.sum(((y - h) ** 2 - (y - f) ** 2) / (2 * sigma**2), axis=1)
    llr = log_likelihood_ratio(y, h, f, sigma, sigma)
    np.testing.assert_allclose(llr, direct, rtol=1e-12)
    # a relative-noise channel makes σ differ between the hypotheses: scipy's log densities
    s_h, s_f = noise_std(h, 2.0), noise_std(f, 2.0)
    assert not np.allclose(s_h[:, 0], s_f[:, 0]) and np.allclose(s_h[:, 1:], s_f[:, 1:])
    oracle = np.sum(stats.norm.logpdf(y, f, s_f) - stats.norm.logpdf(y, h, s_h), axis=1)
    np.testing.assert_allclose(log_likelihood_ratio(y, h, f, s_h, s_f), oracle, rtol=1e-10)


def test_noise_std_is_the_env_noise() -> None:
    """(y − y_clean) / noise_std has unit std on every channel of a simulated episode."""
    ep = simulate_loaded([3], 1500, FaultSpec(), plant=PlantConfig(noise_scale=2.0))[0].episode
    assert ep.y_clean is not None
    z = (ep.y - ep.y_clean) / noise_std(ep.y_clean, 2.0)
    np.testing.assert_allclose(z.std(axis=0), 1.0, atol=0.06)


def test_cusum_is_the_max_over_onsets() -> None:
    llr = np.random.default_rng(1).normal(-0.2, 1.0, size=(300, 2))
    s = cusum(llr)
    for j in range(2):
        brute = [max(0.0, max(llr[k : t + 1, j].sum() for k in range(t + 1))) for t in range(300)]
        np.testing.assert_allclose(s[:, j], brute, atol=1e-9)


@pytest.mark.parametrize("window", [1, 7, 500])
def test_window_glr_is_the_brute_force_max(window: int) -> None:
    rng = np.random.default_rng(2)
    b = np.r_[np.zeros(40), rng.uniform(0.1, 2.0, 160)]  # the signature starts at 40
    a = b * 0.3 + rng.normal(size=200) * np.sqrt(b)
    g = window_glr(a, b, window)
    for t in range(200):
        best = 0.0
        for k in range(max(0, t - window + 1), t + 1):
            sa, sb = a[k : t + 1].sum(), b[k : t + 1].sum()
            if sb > 0:
                best = max(best, max(sa, 0.0) ** 2 / (2 * sb))
        assert g[t] == pytest.approx(best, rel=1e-9, abs=1e-12)
    assert not g[:40].any()
    with pytest.raises(ValueError, match=r"allowed: two equal shapes"):
        window_glr(a, b[:-1], window)


def test_the_rows_are_registered_after_the_others() -> None:
    labels = [c.label for c in DEFAULT_REFERENCES]
    assert labels[-2:] == [CUSUM_LABEL, GLR_LABEL]
    assert list(REFERENCE_LABELS.values())[-2:] == [CUSUM_LABEL, GLR_LABEL]
    assert OracleConfig(stage="glr").false_alarm_target == OracleConfig().false_alarm_target
    with pytest.raises(ValueError, match=r"inputs='measured' with stage='cusum'; allowed"):
        OracleConfig(inputs="measured", stage="cusum")


@dataclass(frozen=True, kw_only=True)
class _LoggedData(TrackData):
    """A track's data source that logs every episode it simulates."""

    loaded: list[tuple[str, int]] = field(default_factory=list)

    def load_test(self, scenario: str, seed: int) -> LoadedEpisode:
        self.loaded.append((scenario, seed))
        return super().load_test(scenario, seed)


def test_limits_come_from_validation_seeds_only() -> None:
    track = TRACKS["paper"].replace(n_healthy=2, n_faulty=1, n_validation=3)
    data = _LoggedData(track=track)
    bank = PhysicalLimit(data, OracleConfig(stage="cusum")).fit()
    seeds = {s for _, s in data.loaded}
    assert seeds == set(track.validation_seeds)
    assert {sc for sc, _ in data.loaded} == {"nominal", *track.faults}
    assert math.isfinite(bank.stage_.limit_) and bank.stage_.limit_ > 0


def _noise_free(data: TrackData, fault: str, seed: int) -> Episode:
    ep = data.load_test(fault, seed).episode
    assert ep.y_clean is not None
    return Episode(
        y=ep.y_clean,
        channels=ep.channels,
        sample_time_s=ep.sample_time_s,
        fault_onset=ep.fault_onset,
        scenario=fault,
        seed=seed,
    )


def test_the_llr_of_the_true_fault_is_its_kullback_leibler_rate() -> None:
    """On the fault's own noise-free trajectory the LLR of that fault is Σ Δ²/(2σ²) ≥ 0 and
    zero before the onset."""
    data = TrackData(track=TRACKS["small"].replace(n_healthy=1, n_faulty=1, n_validation=2))
    row = PhysicalLimit(data, OracleConfig(stage="cusum")).fit()
    ep = _noise_free(data, "f2", 0)
    _, llr = row.stage_.scores(ep)
    j = data.track.faults.index("f2")
    assert ep.fault_onset is not None
    assert not llr[: ep.fault_onset, j].any()
    delta = ep.y - data.reference(0)[: ep.y.shape[0]]
    kl = np.sum(delta**2 / (2 * noise_std(data.reference(0), 1.0) ** 2), axis=1)
    np.testing.assert_allclose(llr[:, j], kl, rtol=1e-6, atol=1e-9)


def test_no_detector_beats_the_cusum_row_on_the_small_track() -> None:
    """At a comparable realised r_fd the CUSUM row detects every fault no later on average than
    the physical-limit row (the strongest existing reference)."""
    track = TRACKS["small"].replace(n_healthy=3, n_faulty=3, n_validation=10)
    recs = reference_records(TrackData(track=track), [OracleConfig(), OracleConfig(stage="cusum")])

    def mean(label: str, scenario: str, key: str) -> float:
        v = [getattr(r, key) for r in recs if r.diagnoser == label and r.scenario == scenario]
        # a miss counts as the longest possible delay
        return float(np.mean([track.n_samples if math.isnan(x) else x for x in v]))

    for label in (ORACLE_LABEL, CUSUM_LABEL):
        assert mean(label, "nominal", "r_fd") < 0.006, label  # 3 × the 0.002 target
    for fault in track.faults:
        assert mean(CUSUM_LABEL, fault, "t_dt") <= mean(ORACLE_LABEL, fault, "t_dt"), fault


def test_a_healthy_twin_that_trips_first_ends_the_signature() -> None:
    # incipient seed 59: the healthy plant trips at sample 1389, the faulty plants run on
    from evaluation.tracks.catalogue import TRACKS
    from evaluation.tracks.optimal import FaultSignatures
    from evaluation.tracks.track_data import TrackData

    data = TrackData(track=TRACKS["incipient"])
    twin = data.reference(59)
    assert twin.shape[0] < 4000
    for delta in FaultSignatures(data).of(59):
        assert delta.shape[0] <= twin.shape[0]
        assert np.all(np.isfinite(delta))


def test_a_reference_is_cut_or_continued_with_the_episodes_own_measurements() -> None:
    from evaluation.tracks.oracle import reference_over

    y = np.arange(30.0).reshape(10, 3)
    long = np.full((12, 2), -1.0)
    np.testing.assert_array_equal(reference_over(long, y), long[:10])
    short = np.full((4, 2), -1.0)
    out = reference_over(short, y)
    assert out.shape == (10, 2)
    np.testing.assert_array_equal(out[:4], short)
    np.testing.assert_array_equal(out[4:], y[4:, :2])  # a zero residual past its end
