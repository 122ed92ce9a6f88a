"""The reference rows as backend tasks, stored like cells (issue 44 items 1 and 2): the same
records, bit for bit, computed in the driver, in this process, in one or two local workers, on
Ray, or read back from the store; a fully stored track computes nothing."""

from __future__ import annotations

import json
import math

import pytest

from evaluation.sweep.records import CellResult
from evaluation.sweep.store import StoreError
from evaluation.tracks import TRACKS
from evaluation.tracks.oracle import DEFAULT_REFERENCES, OracleConfig, reference_records
from evaluation.tracks.reference_runs import (
    code_version,
    reference_hash,
    reference_label,
    run_references,
    sharing_groups,
)
from evaluation.tracks.track_data import TrackData

TINY = TRACKS["paper"].replace(n_healthy=2, n_faulty=1, n_train=2, n_validation=3)
#: the rows that fit in seconds (the filter and directional rows: the slow test below)
FAST = (OracleConfig(), OracleConfig(inputs="measured"), OracleConfig(stage="cusum"))


def _bits(records: list[CellResult]) -> list[str]:
    """Each record as canonical JSON without its wall time (no two runs share one): equal
    strings are equal bits (a float's repr round-trips exactly; NaN as a token)."""
    out = []
    for r in records:
        d = r.to_json()
        d.pop("detect_wall_s")
        d = {k: ("nan" if isinstance(v, float) and math.isnan(v) else v) for k, v in d.items()}
        out.append(json.dumps(d, sort_keys=True))
    return out


@pytest.fixture(scope="module")
def driver() -> list[str]:
    return _bits(reference_records(TrackData(track=TINY), FAST))


@pytest.mark.parametrize("workers", [0, 1, 2])
def test_local_backends_give_the_driver_bits_and_store_them(driver, tmp_path, workers) -> None:
    data = TrackData(track=TINY)
    recs, n = run_references(data, FAST, tmp_path, n_workers=workers, progress=False)
    assert n == len(FAST) * len(TINY.test_cells())
    assert _bits(recs) == driver
    again, n_again = run_references(data, FAST, tmp_path, n_workers=workers, progress=False)
    assert n_again == 0 and _bits(again) == driver  # read back from the store


def test_a_row_added_later_computes_only_that_row(driver, tmp_path) -> None:
    data = TrackData(track=TINY)
    run_references(data, FAST[:1], tmp_path, n_workers=0, progress=False)
    recs, n = run_references(data, FAST, tmp_path, n_workers=0, progress=False)
    assert n == 2 * len(TINY.test_cells()) and _bits(recs) == driver


def test_the_address_names_row_track_and_code(tmp_path) -> None:
    data_hash = "d" * 64
    h = reference_hash(OracleConfig(), data_hash)
    assert h != reference_hash(OracleConfig(inputs="measured"), data_hash)
    assert h != reference_hash(OracleConfig(ewma_lambda=0.2), data_hash)
    assert h != reference_hash(OracleConfig(), "e" * 64)
    assert h != reference_hash(OracleConfig(), data_hash, t_on=10)
    assert len(code_version()) == 64 and code_version() != code_version(("json",))
    label = reference_label(OracleConfig(stage="cusum"), h)
    assert label == f"reference+true+cusum+{h[:16]}"
    with pytest.raises(ValueError, match="OracleConfig"):
        reference_hash({"stage": "t2"}, data_hash)  # type: ignore[arg-type]


def test_an_edited_stored_record_is_refused(tmp_path) -> None:
    data = TrackData(track=TINY.replace(n_healthy=1, n_faulty=1))
    run_references(data, FAST[:1], tmp_path, n_workers=0, progress=False)
    cell = next(tmp_path.glob("cells/reference+true+t2+*/nominal/seed-0.json"))
    obj = json.loads(cell.read_text())
    obj["record"]["r_fd"] = 2.0
    cell.write_text(json.dumps(obj))
    with pytest.raises(StoreError, match="r_fd"):
        run_references(data, FAST[:1], tmp_path, n_workers=0, progress=False)


def test_the_filter_row_is_scored_apart() -> None:
    # its fit is the longest; the others share their simulations seed by seed
    assert [c.stage for c in DEFAULT_REFERENCES].index("filter") == 3
    assert sharing_groups(DEFAULT_REFERENCES) == [[0, 1, 2, 4, 5], [3]]
    assert sharing_groups(FAST) == [[0, 1, 2]]


def test_unknown_backend_is_refused(tmp_path) -> None:
    with pytest.raises(ValueError, match="backend='dask'"):
        run_references(TrackData(track=TINY), FAST, tmp_path, backend="dask")
    with pytest.raises(ValueError, match=r"allowed: evaluation\.tracks\.oracle\.OracleConfig"):
        run_references(TrackData(track=TINY), [{"stage": "t2"}], tmp_path)  # type: ignore[list-item]


@pytest.mark.slow  # about 30 s, most of it Ray starting its workers
def test_ray_gives_the_driver_bits(driver, tmp_path) -> None:
    ray = pytest.importorskip("ray", reason="ray is not installed (pip install '.[ray]')")
    from evaluation.sweep import ray_runtime_env

    ray.init(
        num_cpus=2, include_dashboard=False, log_to_driver=False, runtime_env=ray_runtime_env()
    )
    try:
        data = TrackData(track=TINY)
        recs, n = run_references(data, FAST, tmp_path, backend="ray", progress=False)
    finally:
        ray.shutdown()
    assert n == len(FAST) * len(TINY.test_cells()) and _bits(recs) == driver


@pytest.mark.slow
def test_every_default_row_gives_the_driver_bits_in_two_workers(tmp_path) -> None:
    rows = [
        c
        if c.stage not in ("directional", "filter")
        else OracleConfig(**{**c.__dict__, "n_calibration": 3})
        for c in DEFAULT_REFERENCES
    ]
    data = TrackData(track=TINY)
    driver = _bits(reference_records(data, rows))
    recs, _ = run_references(data, rows, tmp_path, n_workers=2, progress=False)
    assert _bits(recs) == driver
