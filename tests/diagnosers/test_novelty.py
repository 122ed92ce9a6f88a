"""The operating-point novelty of ``lrgf-glr`` (diagnosers.lrgf.novelty): the range, the distance,
which relations measure it, and that the detector divides by exactly ``1 + gain · d``."""

from __future__ import annotations

import copy

import numpy as np
import pytest
from synthetic import make_episode, with_fault_twins

from diagnosers.bank.relations import BANK_RELATIONS, DILUTE_RELATIONS
from diagnosers.lrgf.lrgf_glr import LRGFGLR
from diagnosers.lrgf.novelty import (
    NoveltyScale,
    PredictionRange,
    exogenous_relations,
    novelty_scale,
)


def test_exogenous_relations_are_those_no_fault_moves() -> None:
    # T_rx reads T_rg2 and T_rg2 reads T_rg1, both outputs of the bank: only T_rg1 is exogenous
    assert exogenous_relations(BANK_RELATIONS).tolist() == [1]
    assert exogenous_relations(BANK_RELATIONS + DILUTE_RELATIONS).tolist() == [1]
    assert exogenous_relations([["a", ["b"]], ["b", ["a"]]]).tolist() == []


def test_distance_in_training_standard_deviations() -> None:
    train = [np.array([[0.0, 10.0], [2.0, 14.0]]), np.array([[1.0, 12.0]])]
    rng = PredictionRange.of(train)
    sd = np.std([[0.0, 10.0], [2.0, 14.0], [1.0, 12.0]], axis=0)
    np.testing.assert_allclose(rng.scale, sd)
    p = np.array([[1.0, 12.0], [2.0, 14.0], [3.0, 12.0], [1.0, 10.0 - 2 * sd[1]], [5.0, 20.0]])
    expected = [0.0, 0.0, 1.0 / sd[0], 2.0, max(3.0 / sd[0], 6.0 / sd[1])]
    np.testing.assert_allclose(rng.distance(p), expected)
    np.testing.assert_allclose(novelty_scale(rng.distance(p), 5.0), 1.0 + 5.0 * np.array(expected))
    back = PredictionRange.from_array(rng.to_array())
    np.testing.assert_array_equal(back.distance(p), rng.distance(p))


def test_bad_ranges_are_refused() -> None:
    with pytest.raises(ValueError, match=r"at least 2 samples in all; got shape \(1, 2\)"):
        PredictionRange.of([np.zeros((1, 2))])
    with pytest.raises(ValueError, match=r"\(3, channels\) array; got shape \(2, 2\)"):
        PredictionRange.from_array(np.zeros((2, 2)))


FAST = {**LRGFGLR.fast_params(), "fault_scenarios": ["f3"], "fault_seeds": None, "n_folds": 2}


@pytest.fixture(scope="module")
def det() -> LRGFGLR:
    return LRGFGLR(**FAST).fit(with_fault_twins([make_episode(1500, seed=s) for s in (1, 2, 3)]))


def _beyond_training(det: LRGFGLR):
    """A copy of ``det`` whose training range is narrowed to the lower three quarters of a
    healthy episode's predictions, so that the episode leaves it often (the fast settings'
    networks saturate, so no input drives them far out of their real range), with that
    distance."""
    ep = make_episode(1200, seed=9)
    narrow = copy.deepcopy(det)
    p = det.novelty_.predictions(det.bank_, ep.y)[det.steady_window :]
    high = np.quantile(p, 0.75, axis=0)
    narrow.novelty_.range_ = PredictionRange(p.min(axis=0), high, p.std(axis=0))
    d = narrow.novelty_.range_.distance(det.novelty_.predictions(det.bank_, ep.y))
    assert (d > 0.1).mean() > 0.1, "the episode must leave the range often"
    return narrow, ep, d


def test_the_error_is_divided_by_one_plus_gain_times_distance(det) -> None:
    det, ep, d = _beyond_training(det)
    w = det.steady_window
    off = copy.deepcopy(det)
    off.novelty_.gain = 0.0  # the part without its scale
    # oracle: the T² of the EWMA of (raw normalised error) / (1 + gain d), by hand
    raw = (ep.y[:, det.out_idx_] - det.bank_.centre(ep.y)) / det.v_residual_
    scaled = raw / (1.0 + det.novelty_gain * d)[:, None]
    scaled[:w] = 0.0
    z = np.zeros(raw.shape[1])
    t2 = []
    for row in scaled:
        z = det.ewma_lambda * row + (1.0 - det.ewma_lambda) * z
        t2.append(z @ det.stage_.s_inv_ @ z)
    got = det.detect(ep).signal[:, 0]
    np.testing.assert_allclose(got[w:], np.array(t2)[w:], rtol=1e-9, atol=1e-12)
    # inside the range (before the first excursion) the gain changes nothing
    first = w + int(np.argmax(d[w:] > 0))
    assert first > w + 10
    np.testing.assert_allclose(off.detect(ep).signal[w:first, 0], got[w:first], rtol=1e-12)
    assert not np.allclose(off.detect(ep).signal[first:, 0], got[first:])
    stream = np.array([det.update(row).signal for row in ep.y])
    np.testing.assert_allclose(stream, det.detect(ep).signal, rtol=1e-9, atol=1e-12)


def test_the_range_survives_save_and_a_state_without_it_is_refused(det, tmp_path) -> None:
    det, ep, _ = _beyond_training(det)
    det.save(tmp_path / "m")
    back = LRGFGLR.load(tmp_path / "m")
    np.testing.assert_array_equal(back.novelty_.range_.to_array(), det.novelty_.range_.to_array())
    np.testing.assert_array_equal(back.detect(ep).signal, det.detect(ep).signal)
    state = dict(np.load(tmp_path / "m" / "state.npz"))
    state.pop("prediction_range")
    np.savez(tmp_path / "m" / "state.npz", **state)
    with pytest.raises(ValueError, match="prediction_range"):
        LRGFGLR.load(tmp_path / "m")


def test_a_saved_range_that_does_not_fit_the_relations_is_refused(det, tmp_path) -> None:
    det.save(tmp_path / "m")
    state = dict(np.load(tmp_path / "m" / "state.npz"))
    state["prediction_range"] = np.zeros((3, 2))  # the bank has one exogenous relation
    np.savez(tmp_path / "m" / "state.npz", **state)
    with pytest.raises(ValueError, match=r"prediction_range has 2 columns; allowed: one per"):
        LRGFGLR.load(tmp_path / "m")


def test_more_linear_neurons_than_the_smallest_network_has_are_refused() -> None:
    with pytest.raises(
        ValueError, match=r"n_linear=6 .*from 0 to the smallest network's size \(5\)"
    ):
        LRGFGLR(**{**FAST, "n_linear": 6}).fit([make_episode(600, seed=1)] * 2)


def test_a_negative_gain_is_refused() -> None:
    with pytest.raises(ValueError, match=r"novelty_gain=-1"):
        LRGFGLR(**{**FAST, "novelty_gain": -1.0}).fit([make_episode(600, seed=1)] * 2)


def test_out_of_fold_novelty_is_measured_against_the_fold_banks_own_range(monkeypatch) -> None:
    """Each out-of-fold record's distance comes from the fold bank that never saw it, against
    the range of that bank's predictions on its own training records; the detector keeps the
    final bank's range on all records."""
    train = [make_episode(1500, seed=s) for s in (1, 2, 3)]
    seen: list[tuple[list[int], list[int], PredictionRange]] = []
    real = NoveltyScale.distances

    def spy(self, bank, train_records, cal_records):
        def ids(records):
            return [next(i for i, e in enumerate(train) if e.y is r) for r in records]

        rng = self.training_range(bank, train_records)
        seen.append((ids(train_records), ids(cal_records), rng))
        out = real(self, bank, train_records, cal_records)
        for y, d in zip(cal_records, out, strict=True):
            np.testing.assert_array_equal(d, rng.distance(self.predictions(bank, y)))
        return out

    monkeypatch.setattr(NoveltyScale, "distances", spy)
    det = LRGFGLR(**{**FAST, "n_folds": 3}).fit(with_fault_twins(train))
    assert [(t, c) for t, c, _ in seen] == [([1, 2], [0]), ([0, 2], [1]), ([0, 1], [2])]
    # the fold banks' ranges differ from each other and from the final bank's
    finals = det.novelty_.range_.to_array()
    assert all(not np.array_equal(r.to_array(), finals) for _, _, r in seen)
    final = PredictionRange.of(
        [det.novelty_.predictions(det.bank_, e.y)[det.steady_window :] for e in train]
    )
    np.testing.assert_array_equal(finals, final.to_array())
