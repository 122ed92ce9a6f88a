"""Amdahl's law and its fit: the serial fraction of a workload from its speed-ups.

Shared by :mod:`bench.scaling` (measured runs) and :mod:`bench.task_profile` (projected ones);
light (NumPy and SciPy only), so the profile printer starts fast.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from scipy.optimize import lsq_linear

__all__ = ["amdahl_fit", "amdahl_speedup"]


def amdahl_speedup(f: float, n: float) -> float:
    """Amdahl's law: the speed-up on ``n`` workers of work whose serial fraction is ``f``."""
    return 1.0 / (f + (1.0 - f) / n)


def amdahl_fit(workers: Sequence[int], speedups: Sequence[float]) -> float:
    """The serial fraction ``f`` in [0, 1] that fits ``1 / S(n) = f + (1 - f) / n`` best, by least
    squares on ``1 / S`` against ``1 / n`` (:func:`scipy.optimize.lsq_linear`, bounded);
    ``nan`` when every run had one worker."""
    n = np.asarray(workers, dtype=float)
    inv_s = 1.0 / np.asarray(speedups, dtype=float)
    if n.shape != inv_s.shape or n.size == 0 or np.any(n < 1) or not np.all(np.isfinite(inv_s)):
        raise ValueError(
            f"amdahl_fit needs matching worker counts >= 1 and finite speed-ups, "
            f"got {list(workers)} and {list(speedups)}"
        )

    if np.all(n == 1):  # one worker count: nothing to fit
        return math.nan
    # 1/S - 1/n = f (1 - 1/n): linear in f, solved exactly within the bounds
    fit = lsq_linear((1.0 - 1.0 / n)[:, None], inv_s - 1.0 / n, bounds=(0.0, 1.0), method="bvls")
    return float(fit.x[0])
