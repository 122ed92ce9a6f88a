"""The scaling benchmark (bench.scaling): Amdahl's fit against its closed form, the worker
counts, and the same results on a two-node Ray cluster as on the local pool."""

from __future__ import annotations

import numpy as np
import pytest

from bench.scaling import (
    WORKLOADS,
    amdahl_fit,
    amdahl_speedup,
    default_workers,
    main,
    measure,
)

N = np.array([1, 2, 4, 8, 16])


def test_amdahl_fit_recovers_the_serial_fraction() -> None:
    for f in (0.0, 0.05, 0.3, 1.0):
        speedups = [amdahl_speedup(f, n) for n in N]
        assert amdahl_fit(N, speedups) == pytest.approx(f, abs=1e-9)


def test_amdahl_fit_is_the_least_squares_solution() -> None:
    # oracle: 1/S - 1/n = f (1 - 1/n) is linear in f, so least squares has a closed form
    rng = np.random.default_rng(1000)
    inv_s = np.array([1.0 / amdahl_speedup(0.2, n) for n in N]) * (
        1 + 0.05 * rng.standard_normal(5)
    )
    x, y = 1 - 1 / N, inv_s - 1 / N
    assert amdahl_fit(N, 1 / inv_s) == pytest.approx(float(x @ y / (x @ x)), abs=1e-9)


def test_worker_counts(capsys) -> None:
    assert default_workers(16) == [1, 2, 4, 8, 16]
    assert default_workers(6) == [1, 2, 4, 6]
    assert default_workers(1) == [1]
    for bad, why in (("2,4", "1 among them"), ("1,two", "comma-separated integers")):
        with pytest.raises(SystemExit) as exit_:
            main(["--workers", bad])
        assert exit_.value.code == 2
        err = capsys.readouterr().err
        assert f"--workers={bad!r}" in err and why in err


#: a small workload with every kind of task: scoring, diagnoser trainings, relation trainings
TINY = WORKLOADS["tiny"]


@pytest.mark.slow  # starts a two-node Ray cluster: about a minute on a busy machine
def test_a_two_node_ray_cluster_gives_the_local_table(tmp_path) -> None:
    ray = pytest.importorskip("ray", reason="ray is not installed (pip install '.[ray]')")
    from ray.cluster_utils import Cluster

    from evaluation.sweep.backends import RayBackend, ray_runtime_env

    # nested, so that Ray ships it by value (the test module is not importable on a node)
    def node_and_threads(_serial: bool = False) -> tuple[str, dict[str, int]]:
        """Which node a Ray task ran on, and its thread counts."""
        import time

        import numba  # noqa: F401  (as a task loads them)
        import ray
        import torch  # noqa: F401

        from fcc_common.workers import limit_threads, thread_counts

        limit_threads()  # what every sweep task does first
        time.sleep(1.0)  # long enough that two tasks run at once, one per node
        return ray.get_runtime_context().get_node_id(), thread_counts()

    local = measure(TINY, [1, 2], "local")
    cluster = Cluster(initialize_head=True, head_node_args={"num_cpus": 1})
    try:
        cluster.add_node(num_cpus=1)
        ray.init(address=cluster.address, runtime_env=ray_runtime_env(), log_to_driver=False)
        backend = RayBackend(2, cluster.address, max_in_flight=2)
        handles = [backend.submit(node_and_threads) for _ in range(2)]
        seen = dict(backend.completed(handles)).values()
        assert len({node for node, _ in seen}) == 2  # both nodes worked
        for _, threads in seen:
            assert threads["torch"] == 1 and threads["numba"] == 1
        on_ray = measure(TINY, [1, 2], "ray", cluster.address)
    finally:
        ray.shutdown()
        cluster.shutdown()
    digests = {r.digest for r in local + on_ray}
    assert len(digests) == 1, [(r.workers, r.digest[:12]) for r in local + on_ray]
