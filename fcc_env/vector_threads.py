"""The native vector envs' thread policy: how many numba threads a step runs on.

Threads (``threads=``): a step runs the envs on that many numba threads; the default
(:func:`vector_threads`) is one per :data:`MIN_ENVS_PER_THREAD` envs, at most
``numba.get_num_threads()`` and the cores this process may use, and one thread is a serial
compiled loop with no parallel region. The numbers do not depend on it: each env reads and
writes its own rows only (``tests/fcc_env/test_vector_threads.py``). A parallel step ends at a
barrier where the threads that finished wait for the others, and how they wait is the numba
threading layer's (``NUMBA_THREADING_LAYER``; numba picks ``tbb``, then ``omp``, then
``workqueue``, whichever is installed):

- ``omp`` (libgomp, numba's choice on Linux without tbb): ``OMP_WAIT_POLICY=ACTIVE`` spins
  (``GOMP_SPINCOUNT`` iterations), which on a busy machine takes the cores from the threads
  still working (two threads at 1024 envs ran at half the speed of one); ``PASSIVE`` sleeps.
  Importing :mod:`fcc_env` sets ``PASSIVE`` unless the environment sets the variable; libgomp
  reads it once, when numba's pool starts, so code that ran a parallel numba kernel before
  importing :mod:`fcc_env` must set it in the environment. Intel's runtime (libiomp5, conda's
  ``intel-openmp``) reads ``KMP_BLOCKTIME`` (ms of spinning; ``0`` is passive) as well.
- ``workqueue`` (numba's own): waits on condition variables (passive); it refuses kernels
  launched from several Python threads at once.
- ``tbb`` (the ``tbb`` package): work stealing; its idle workers also spin briefly.

The figures (1 and 2 threads at 16 to 1024 envs) are in ``lab/env-speed.md``;
``python -m bench.vector_speed --envs 16,1024 --threads 1,2,auto`` measures them.
"""

from __future__ import annotations

from typing import Any

import numba

from fcc_common.validation import Integer, check
from fcc_common.workers import cpu_count

__all__ = ["MIN_ENVS_PER_THREAD", "check_threads", "vector_threads"]


#: Envs per numba thread below which a step runs serially (``threads=None``; lab/env-speed.md).
MIN_ENVS_PER_THREAD = 128


def check_threads(threads: Any) -> int | None:
    """``threads`` as the native vector envs take it: ``None`` (:func:`vector_threads` picks) or
    1 up to numba's pool size (``NUMBA_NUM_THREADS``)."""
    pool = numba.config.NUMBA_NUM_THREADS
    why = f"numba's thread pool holds {pool} (NUMBA_NUM_THREADS)"
    return check("threads", threads, Integer(1, pool, why=why), None)


def vector_threads(num_envs: int, threads: int | None = None) -> int:
    """The numba threads a step of ``num_envs`` envs runs on: ``threads`` when given, else one
    per :data:`MIN_ENVS_PER_THREAD` envs, at most ``numba.get_num_threads()`` (which a user or a
    pool worker may have lowered) and the cores this process may use; 1 means the serial
    kernel, without a parallel region."""
    if threads is not None:
        return threads
    cap = min(numba.get_num_threads(), cpu_count())
    return max(1, min(cap, num_envs // MIN_ENVS_PER_THREAD))
