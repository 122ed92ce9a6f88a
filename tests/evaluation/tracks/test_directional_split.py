"""The directional reference row's fit, split into tasks (calibration residuals per chunk of
seeds, then the directions and the stage), gives the bits of the one-task fit, and
run_references schedules it so."""

from __future__ import annotations

import numpy as np
import pytest

from evaluation.sweep.task_log import TIMINGS_FILE, read_timings
from evaluation.tracks import TRACKS
from evaluation.tracks.oracle import OracleConfig, reference_records
from evaluation.tracks.reference_runs import (
    DIRECTIONAL_CHUNK,
    directional_fit_task,
    directional_residuals_task,
    fit_task,
    run_references,
)
from evaluation.tracks.track_data import TrackData

TINY = TRACKS["paper"].replace(n_healthy=1, n_faulty=1, n_train=2, n_validation=3, n_samples=2400)
#: more calibration seeds than one chunk: the residuals come back in two
CONFIG = OracleConfig(inputs="measured", stage="directional", n_calibration=DIRECTIONAL_CHUNK + 2)


@pytest.fixture(scope="module")
def data() -> TrackData:
    return TrackData(track=TINY)


def _stage_bits(row) -> dict[str, bytes]:
    st = row.stage_
    return {
        "v_residual": st.v_residual_.tobytes(),
        "directions": np.asarray(st.directions_).tobytes(),
        "faults": repr(st.faults).encode(),
        "signals": repr(st.signal_names_).encode(),
        "skipped": repr(st.skipped_).encode(),
    }


def test_the_split_fit_has_the_bits_of_the_one_task_fit(data) -> None:
    cal = list(CONFIG.calibration_seeds(TINY))
    seeds = [cal[k : k + DIRECTIONAL_CHUNK] for k in range(0, len(cal), DIRECTIONAL_CHUNK)]
    assert len(seeds) == 2
    chunks = [directional_residuals_task(data, CONFIG, s, _serial=True) for s in seeds]
    split = directional_fit_task(data, CONFIG, chunks, _serial=True)
    one = fit_task(data, CONFIG, _serial=True)
    assert _stage_bits(split) == _stage_bits(one)
    assert len(one.stage_.faults) > 0  # the directions were learned, not skipped
    for sc, seed in (("nominal", 0), ("f1", 0)):
        ep = data.load_test(sc, seed).episode
        a, b = split.detect(ep), one.detect(ep)
        for field in ("alarm", "signal", "lower", "upper"):
            assert getattr(a, field).tobytes() == getattr(b, field).tobytes(), field


def test_run_references_schedules_the_split_fit(data, tmp_path) -> None:
    records, n = run_references(data, [CONFIG], tmp_path / "s", n_workers=0, progress=False)
    assert n == len(data.cells())
    driver = reference_records(data, [CONFIG])

    def strip(rs):
        return [{k: v for k, v in r.to_json().items() if k != "detect_wall_s"} for r in rs]

    assert repr(strip(records)) == repr(strip(driver))
    kinds = [r["kind"] for r in read_timings(tmp_path / "s" / TIMINGS_FILE)]
    assert kinds.count("directional-residuals") == 2 and kinds.count("directional-fit") == 1
