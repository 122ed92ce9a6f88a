"""Where each fault moves a bank's remaining error: ``lrgf-glr``'s fault directions as a mixin.

A directional test needs, per fault, the direction the fault takes in the normalised
remaining-error space of the relations. It is learned from the model itself: each fault of
``fault_scenarios`` is simulated on the training seeds ``fault_seeds`` (paper magnitude and
onset) together with the healthy episode of the same seed, and the difference of the two
episodes' normalised remaining errors is the fault's signature without the noise (the same
seed draws the same noise and operating program in both). Only training seeds (1000–4999) are
allowed, so no test or validation episode is ever simulated here.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

__all__ = ["DEFAULT_FAULTS", "FaultDirections"]

#: the faults whose directions are learned unless ``fault_scenarios`` says otherwise
DEFAULT_FAULTS = ("f1", "f2", "f3", "f4")


class FaultDirections:
    """The fault directions of a fitted bank (a mixin of :class:`diagnosers.lrgf_glr.LRGFGLR`).

    The host supplies the hyperparameters ``fault_scenarios``, ``fault_seeds`` and
    ``direction_window``, the fitted ``channels_`` and ``out_idx_``, and ``_normalised`` (a
    record's normalised remaining error with the current models).
    """

    fault_scenarios: Sequence[str] | None
    fault_seeds: Sequence[int] | None
    direction_window: int
    channels_: Sequence[str]
    out_idx_: np.ndarray

    def _normalised(self, y: np.ndarray) -> np.ndarray:  # pragma: no cover - the host's
        raise NotImplementedError

    def _faults(self) -> tuple[str, ...]:
        return DEFAULT_FAULTS if self.fault_scenarios is None else tuple(self.fault_scenarios)

    def _fault_seeds(self) -> list[int]:
        return [1000, 1001, 1002] if self.fault_seeds is None else list(self.fault_seeds)

    def _learn_directions(self) -> np.ndarray:
        """Unit fault directions ``(m, k)`` in the normalised remaining-error space.

        Each fault of ``fault_scenarios`` is simulated (paper magnitude and onset) on the training
        seeds ``fault_seeds`` together with the healthy episode of each seed; the direction is
        the mean difference of their normalised remaining errors over ``direction_window``
        samples after the onset. Empty when the episodes are not FCC-v0's channels.
        """
        import fcc_env

        if tuple(self.channels_) != tuple(fcc_env.MEASUREMENT_NAMES) or not self._faults():
            return np.zeros((0, len(self.out_idx_)))
        out = []
        for diffs in self._fault_differences(self.direction_window).values():
            mean = np.mean([d.mean(axis=0) for d in diffs], axis=0)
            out.append(mean / np.linalg.norm(mean))
        return np.array(out)

    def _fault_differences(self, window: int) -> dict[str, list[np.ndarray]]:
        """Per fault of ``fault_scenarios``, the normalised remaining error of each training
        fault (seeds ``fault_seeds``, paper magnitude and onset) minus its healthy twin's, over
        the ``window`` samples from the onset: ``(window, k)`` arrays, the fault's signature
        without noise. Episodes that end inside the window are left out."""
        import fcc_env
        from fcc_env.scenarios import FaultSpec

        seeds = self._fault_seeds()
        healthy = fcc_env.simulate_episodes(seeds, fcc_env.DEFAULT_N_SAMPLES)
        out = {}
        for f in self._faults():
            res = fcc_env.simulate_episodes(
                seeds, fcc_env.DEFAULT_N_SAMPLES, fault=FaultSpec(scenario=f)
            )
            diffs = []
            for b in range(len(seeds)):
                onset, stop = res.fault_onsets[b], res.terminated_at[b]
                if onset is None or (0 <= stop < onset + window):
                    continue
                diffs.append(self._pair_difference(res, healthy, b, onset + window)[onset:])
            if not diffs:
                raise ValueError(f"no training episode of fault {f} lasted through its window")
            out[f] = diffs
        return out

    def _pair_difference(self, faulty: Any, healthy: Any, b: int, end: int) -> np.ndarray:
        """The normalised remaining error of training fault ``b`` (a
        :func:`fcc_env.simulate_episodes` result) minus its healthy twin's, first ``end``
        samples: ``(end, k)``."""
        d = self._normalised(faulty.observations[b][:end].astype(np.float64))
        d -= self._normalised(healthy.observations[b][:end].astype(np.float64))
        return d
