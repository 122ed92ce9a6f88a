"""``lrgf-glr-adaptive``: ``lrgf-glr`` with a held regression baseline."""

from __future__ import annotations

import numpy as np
import pytest
from synthetic import make_episode, with_fault_twins

import diagnosers
from diagnosers.lrgf.lrgf_glr import LRGFGLR
from diagnosers.lrgf.lrgf_presets import LRGFGLRAdaptive
from diagnosers.stages.baseline import HeldBaseline

FAST = {
    **LRGFGLR.fast_params(),
    "fault_scenarios": ["f3"],
    "fault_seeds": None,
    "baseline_settle": 50,
}


@pytest.fixture(scope="module")
def adaptive() -> LRGFGLRAdaptive:
    return LRGFGLRAdaptive(**FAST).fit(
        with_fault_twins([make_episode(1500, seed=s) for s in (1, 2, 3)])
    )


def test_variant_is_lrgf_glr_with_the_baseline_target_and_all_samples_only() -> None:
    plain = diagnosers.make("lrgf-glr").get_params()
    variant = diagnosers.make("lrgf-glr-adaptive").get_params()
    changed = {k for k in plain if plain[k] != variant[k]}
    assert changed == {
        "baseline_lambda",
        "baseline_hold",
        "baseline_filters",
        "baseline_ridge",
        "false_alarm_target",
        "val_fraction",
    }
    assert variant["baseline_lambda"] == 1e-4 and variant["baseline_hold"] == 1.0
    assert variant["baseline_filters"] == [1, 10, 50] and plain["baseline_filters"] is None
    assert (variant["baseline_ridge"], variant["false_alarm_target"]) == (3.0, 0.04)
    assert variant["val_fraction"] == 0.0 and plain["val_fraction"] == 0.25
    # a user's value still wins over the variant's default
    assert LRGFGLRAdaptive(baseline_hold=0.5).baseline_hold == 0.5


def test_without_filters_the_baseline_is_the_running_mean_of_the_held_samples(adaptive) -> None:
    # below 1/λ = 10,000 samples the gain is 1/n: the baseline removed from sample k is the mean
    # of samples 0..k-1 (0 at the first), computed here by hand
    e = np.random.default_rng(4).normal(size=(600, 3)) + np.array([2.0, -1.0, 0.5])
    det = adaptive
    baseline = HeldBaseline(lam=det.baseline_lambda, hold=1.0, settle=det.baseline_settle)
    baseline.bind(det.in_idx_, det.out_idx_, det.lrgf_)
    out = baseline.track(e, None)
    mean_before = np.vstack([np.zeros(3), np.cumsum(e, axis=0)[:-1] / np.arange(1, 600)[:, None]])
    np.testing.assert_allclose(out, e - mean_before, rtol=1e-10, atol=1e-12)


def _offset(ep, column: str, value: float, onset: int = 0):
    y = ep.y.copy()
    y[onset:, ep.channels.index(column)] += value
    return diagnosers.Episode(y, ep.channels, ep.sample_time_s, fault_onset=ep.fault_onset)


def test_absorbs_a_plant_offset_and_holds_on_a_later_fault(adaptive) -> None:
    # another plant: 4 residual scales off the model from the start. It is learned while the
    # baseline settles; an 8-scale step at sample 800 is not learned, so its alarm lasts.
    det = adaptive
    col = det.channels_[det.out_idx_[1]]
    scale = det.v_residual_[1]
    ep = _offset(make_episode(1500, seed=11), col, 4.0 * scale)
    w = det.steady_window + det.baseline_settle
    assert det.detect(ep).alarm[w:].mean() < 0.05
    plain = LRGFGLR(**{**det.get_params(), "baseline_lambda": 0.0, "baseline_filters": None})
    plain.fit(with_fault_twins([make_episode(1500, seed=s) for s in (1, 2, 3)]))
    assert plain.detect(ep).alarm[w:].mean() > 0.9
    faulty = _offset(ep, col, 8.0 * scale, onset=800)
    alarm = det.detect(faulty).alarm
    assert alarm[800:810].any()
    assert alarm[820:].mean() > 0.95


def test_the_running_mean_variant_round_trips_and_a_bad_state_is_refused(adaptive, tmp_path):
    # baseline_filters=None (the running mean) is saved as such, not replaced by the preset's
    # default (the regression) on loading
    plain = LRGFGLRAdaptive(**{**adaptive.get_params(), "baseline_filters": None})
    plain.fit(with_fault_twins([make_episode(1500, seed=s) for s in (1, 2, 3)]))
    plain.save(tmp_path / "m")
    again = diagnosers.Diagnoser.load(tmp_path / "m")
    assert again.baseline_filters is None
    ep = make_episode(900, seed=9)
    np.testing.assert_array_equal(again.detect(ep).signal, plain.detect(ep).signal)
    adaptive.save(tmp_path / "r")
    assert diagnosers.Diagnoser.load(tmp_path / "r").baseline_filters == [1, 10, 50]
    # a state without the alarm stage's limits is refused with the file's name
    with np.load(tmp_path / "m" / "state.npz") as z:
        state = {k: z[k] for k in z.files if k != "h_dir"}
    np.savez(tmp_path / "m" / "state.npz", **state)
    with pytest.raises(ValueError, match=r"state\.npz.*h_dir"):
        diagnosers.Diagnoser.load(tmp_path / "m")
