"""The filter reference row's fit, split into tasks (signatures per training fault seed,
statistics per chunk of calibration seeds, then the limits), gives the bits of the one-task fit,
and the signatures those of the fit before the split (the batch of twins)."""

from __future__ import annotations

import numpy as np
import pytest

from diagnosers.stages.innovation_stage import OMNIBUS_VARIANCE, InnovationStage
from evaluation.tracks import TRACKS
from evaluation.tracks.filter_bound import SIGNATURE_SEEDS, FilterBound
from evaluation.tracks.oracle import OracleConfig, reference_records
from evaluation.tracks.reference_runs import (
    FILTER_CHUNK,
    filter_limits_task,
    filter_signature_task,
    filter_statistics_task,
    fit_task,
    run_references,
)
from evaluation.tracks.track_data import TrackData
from fcc_env.params import MEASUREMENT_NAMES
from fcc_env.scenarios import FaultSpec

TINY = TRACKS["paper"].replace(n_healthy=1, n_faulty=1, n_train=2, n_validation=3, n_samples=2400)
#: more calibration seeds than one chunk: the statistics come back in two
CONFIG = OracleConfig(inputs="measured", stage="filter", n_calibration=FILTER_CHUNK + 2)


@pytest.fixture(scope="module")
def data() -> TrackData:
    return TrackData(track=TINY)


def _signatures_before_the_split(bound: FilterBound) -> np.ndarray:
    """``FilterBound._learn_signatures`` as it was: the twins simulated as one batch, the
    faults' episodes as one list (fault-major)."""
    faulty = bound.data.train_fault_episodes(
        bound.data.track.train_fault_seeds[: bound.signature_seeds]
    )
    seeds = sorted({ep.seed for ep in faulty})
    twins = {
        s: bound.whitened(le.episode)
        for s, le in zip(seeds, bound.data.simulate(seeds, FaultSpec()), strict=True)
    }
    wins = bound.signature_windows
    sums = {f: np.zeros((len(wins), len(MEASUREMENT_NAMES))) for f in bound.faults}
    for ep in faulty:
        e, h, k0 = bound.whitened(ep), twins[ep.seed], ep.fault_onset
        for j, w in enumerate(wins):
            k1 = min(k0 + w, e.shape[0], h.shape[0])
            if k1 > k0:
                sums[ep.scenario][j] += np.mean(e[k0:k1] - h[k0:k1], axis=0)
    out = np.concatenate([sums[f] for f in bound.faults])
    norm = np.linalg.norm(out, axis=1, keepdims=True)
    return np.divide(out, norm, out=np.zeros_like(out), where=norm > 0)


def test_the_parts_give_the_bits_of_the_fit_before_the_split(data) -> None:
    """Fast: one signature seed, two calibration chunks of one episode, against the code as it
    was (the twins as one batch; the stage fitted on the list of every episode)."""
    bound = FilterBound(data, false_alarm_target=CONFIG.false_alarm_target, signature_seeds=1)
    terms = [bound.signature_terms(s) for s in bound.signature_seeds_used()]
    directions = bound.combine_signatures(terms)
    assert directions.tobytes() == _signatures_before_the_split(bound).tobytes()
    assert np.allclose(np.linalg.norm(directions, axis=1), 1.0)
    bound.directions_ = directions
    healthy = [data.load_test("nominal", s).episode for s in CONFIG.calibration_seeds(TINY)[:2]]
    chunks = [bound.calibration_statistics([ep]) for ep in healthy]
    before = InnovationStage(directions, window=bound.window, omnibus_variance=OMNIBUS_VARIANCE)
    before.fit([bound.whitened(ep) for ep in healthy], CONFIG.false_alarm_target)
    assert bound.set_limits(chunks).limits_.tobytes() == before.limits_.tobytes()


@pytest.mark.slow  # about 2 minutes on the loaded two-core machine: 75 filter runs
def test_the_split_fit_has_the_bits_of_the_one_task_fit(data) -> None:
    seeds = list(TINY.train_fault_seeds[:SIGNATURE_SEEDS])
    terms = [filter_signature_task(data, CONFIG, s, _serial=True) for s in seeds]
    cal = list(CONFIG.calibration_seeds(TINY))
    chunks = [cal[k : k + FILTER_CHUNK] for k in range(0, len(cal), FILTER_CHUNK)]
    assert len(chunks) == 2
    stats = [filter_statistics_task(data, CONFIG, terms, c, _serial=True) for c in chunks]
    split = filter_limits_task(data, CONFIG, terms, stats, _serial=True).stage_
    one = fit_task(data, CONFIG, _serial=True).stage_
    assert isinstance(split, FilterBound) and isinstance(one, FilterBound)
    assert split.directions_.tobytes() == one.directions_.tobytes()
    assert split.limits_.tobytes() == one.limits_.tobytes()
    assert np.all(np.isfinite(split.limits_)) and split.limits_.shape == (
        split.directions_.shape[0] + 1,
    )
    # the signatures are those of the code before the split, to the bit
    assert _signatures_before_the_split(one).tobytes() == one.directions_.tobytes()


@pytest.mark.slow  # about 40 s on the loaded two-core machine
def test_run_references_schedules_the_split_fit(data, tmp_path) -> None:
    records, n = run_references(data, [CONFIG], tmp_path / "s", n_workers=0, progress=False)
    assert n == len(data.cells())
    driver = reference_records(data, [CONFIG])
    strip = lambda rs: [{k: v for k, v in r.to_json().items() if k != "detect_wall_s"} for r in rs]  # noqa: E731
    assert repr(strip(records)) == repr(strip(driver))
