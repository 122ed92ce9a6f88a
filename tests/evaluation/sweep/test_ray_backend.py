"""The Ray backend gives the same cells as the in-process run, on a local Ray instance."""

from __future__ import annotations

import math

import pytest

ray = pytest.importorskip("ray", reason="ray is not installed (pip install '.[ray]')")

from evaluation.sweep import (  # noqa: E402  (after the skip)
    SimulatedData,
    SweepConfig,
    default_specs,
    ray_runtime_env,
    run_sweep,
)
from fcc_env.scenarios import FaultSpec  # noqa: E402

CONFIG = SweepConfig(
    diagnosers=default_specs(("limits", "pca")),
    data=SimulatedData(
        scenarios=("nominal", "f2"),
        test_seeds=(0, 1),
        train_seeds=(200, 201),
        n_samples=500,
        fault=FaultSpec(onset=250),
    ),
)


@pytest.fixture(scope="module")
def local_ray():
    # A local instance, as CI runs it; runtime_env lets workers import this checkout.
    ray.init(
        num_cpus=2, include_dashboard=False, log_to_driver=False, runtime_env=ray_runtime_env()
    )
    yield
    ray.shutdown()


def _key(rec):
    d = rec.to_json()
    d.pop("detect_wall_s")
    return {k: ("nan" if isinstance(v, float) and math.isnan(v) else v) for k, v in d.items()}


def test_ray_backend_matches_serial(local_ray, tmp_path) -> None:
    ref = run_sweep(CONFIG, tmp_path / "serial", n_workers=0, progress=False)
    res = run_sweep(CONFIG, tmp_path / "ray", backend="ray", progress=False)
    assert res.n_computed == 8 and res.n_trained == 2
    assert [_key(r) for r in res.records] == [_key(r) for r in ref.records]
    assert ray.is_initialized()  # an instance the caller started is left running
    # models were shipped back to the driver and stored like the local backend stores them
    assert (tmp_path / "ray" / "models" / "pca" / "state.npz").is_file()
    again = run_sweep(CONFIG, tmp_path / "ray", backend="ray", progress=False)
    assert (again.n_computed, again.n_reused) == (0, 8)
