"""A sweep worker computes with one thread (numba, torch, BLAS) unless a task asks for more."""

from __future__ import annotations

import pytest

from evaluation.sweep.backends import LocalBackend
from fcc_common.workers import cpu_count, task_threads, thread_counts


def counts_in_worker(n: int | None) -> dict[str, int]:
    """What a task sees: the worker's own counts, or within ``task_threads(n)``."""
    import numba  # noqa: F401  (as a task imports them)
    import torch  # noqa: F401

    if n is None:
        return thread_counts()
    with task_threads(n):
        inside = thread_counts()
    return {**{f"in_{k}": v for k, v in inside.items()}, **thread_counts()}


def test_a_worker_computes_with_one_thread() -> None:
    pytest.importorskip("threadpoolctl")
    pool = LocalBackend(1)
    try:
        plain = pool.submit(counts_in_worker, None)
        asked = pool.submit(counts_in_worker, 2)
        results = dict(pool.completed([plain, asked]))
    finally:
        pool.close(cancel=False)
    assert results[plain] == {"torch": 1, "numba": 1, "blas": 1}
    # a task that asks for two threads gets them for torch and BLAS (numba: up to its pool's
    # size, the cores), and the worker is back at one thread after it
    got = results[asked]
    if cpu_count() >= 2:  # a library may cap its pool at the cores
        assert got["in_torch"] == 2 and got["in_blas"] == 2
    assert {k: got[k] for k in ("torch", "numba", "blas")} == {"torch": 1, "numba": 1, "blas": 1}


def test_task_threads_refuses_a_bad_count() -> None:
    with pytest.raises(ValueError, match="n=0"):
        with task_threads(0):
            pass
