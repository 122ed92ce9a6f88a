"""Where each fault moves a bank's remaining error: ``lrgf-glr``'s fault directions.

A directional test needs, per fault, the direction the fault takes in the normalised
remaining-error space of the relations. It is learned from the model itself: each fault of
``fault_scenarios`` is simulated on the training seeds ``fault_seeds`` (paper magnitude and
onset) together with the healthy episode of the same seed, and the difference of the two
episodes' normalised remaining errors is the fault's signature without the noise (the same
seed draws the same noise and operating program in both). Only training seeds (1000–4999) are
allowed, so no test or validation episode is ever simulated here.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

__all__ = [
    "DEFAULT_FAULTS",
    "DEFAULT_FAULT_SEEDS",
    "FaultDirections",
    "Signature",
    "paired_difference",
]

#: the faults whose directions are learned unless ``fault_scenarios`` says otherwise
DEFAULT_FAULTS = ("f1", "f2", "f3", "f4")


#: the training seeds whose faults give the directions unless ``fault_seeds`` says otherwise
DEFAULT_FAULT_SEEDS = (1000, 1001, 1002)

#: ``signature(faulty, healthy, b, end)``: the normalised remaining error of training fault ``b``
#: (a :func:`fcc_env.simulate_episodes` result) minus its healthy twin's, first ``end`` samples
Signature = Callable[[Any, Any, int, int], np.ndarray]


def paired_difference(normalised: Callable[[np.ndarray], np.ndarray]) -> Signature:
    """The signature of a detector whose normalised remaining error of a record is
    ``normalised(y)``: that of the faulty episode minus that of its healthy twin."""

    def signature(faulty: Any, healthy: Any, b: int, end: int) -> np.ndarray:
        d = normalised(faulty.observations[b][:end].astype(np.float64))
        d -= normalised(healthy.observations[b][:end].astype(np.float64))
        return d

    return signature


class FaultDirections:
    """Learns where each fault moves a detector's normalised remaining error.

    The optional part of ``lrgf-glr``'s directional tests. Args (the hyperparameters
    ``fault_scenarios``, ``fault_seeds``, ``direction_window``): the faults (None:
    :data:`DEFAULT_FAULTS`), the training seeds they are simulated on (None:
    :data:`DEFAULT_FAULT_SEEDS`; only 1000-4999) and the samples after the onset averaged.
    """

    def __init__(
        self,
        scenarios: Sequence[str] | None = None,
        seeds: Sequence[int] | None = None,
        window: int = 300,
    ) -> None:
        self.faults = DEFAULT_FAULTS if scenarios is None else tuple(scenarios)
        self.seeds = list(DEFAULT_FAULT_SEEDS if seeds is None else seeds)
        self.window = window

    def check(self) -> None:
        """Raise ValueError for an unknown fault or a seed outside the training seeds."""
        if not set(self.faults) <= set(DEFAULT_FAULTS):
            raise ValueError(
                f"fault_scenarios must be among {sorted(DEFAULT_FAULTS)}, got {self.faults}"
            )
        for s in self.seeds:
            if not (isinstance(s, int | np.integer) and 1000 <= s < 5000):
                raise ValueError(f"fault_seeds must be training seeds in 1000..4999, got {s!r}")

    def learn(self, channels: Sequence[str], n_relations: int, signature: Signature) -> np.ndarray:
        """Unit fault directions ``(m, k)`` in the normalised remaining-error space.

        Each fault is simulated (paper magnitude and onset) on the training seeds together
        with the healthy episode of each seed; the direction is the mean of ``signature`` over
        ``window`` samples after the onset, on the plant the channels come from (FCC-v0's
        Table 1, or the closed-loop plant's channels: the faults simulated under control).
        Empty for other channels (external data).
        """
        import fcc_env
        from fcc_env.closed_loop import CLOSED_LOOP_CHANNELS

        closed = tuple(channels) == CLOSED_LOOP_CHANNELS
        if not self.faults or (tuple(channels) != tuple(fcc_env.MEASUREMENT_NAMES) and not closed):
            return np.zeros((0, n_relations))
        out = []
        for diffs in self.differences(signature, closed_loop=closed).values():
            mean = np.mean([d.mean(axis=0) for d in diffs], axis=0)
            out.append(mean / np.linalg.norm(mean))
        return np.array(out)

    def differences(
        self, signature: Signature, closed_loop: bool = False
    ) -> dict[str, list[np.ndarray]]:
        """Per fault, the ``signature`` of each training fault over the ``window`` samples
        from the onset: ``(window, k)`` arrays. Episodes that end inside the window are left
        out."""
        import fcc_env
        from fcc_env.scenarios import FaultSpec

        window = self.window
        regulatory = True if closed_loop else None  # the plant the detector reads
        healthy = fcc_env.simulate_episodes(
            self.seeds,
            fcc_env.DEFAULT_N_SAMPLES,
            plant=fcc_env.PlantConfig.build(regulatory=regulatory),
        )
        out = {}
        for f in self.faults:
            res = fcc_env.simulate_episodes(
                self.seeds,
                fcc_env.DEFAULT_N_SAMPLES,
                plant=fcc_env.PlantConfig.build(regulatory=regulatory),
                fault=FaultSpec(scenario=f),
            )
            diffs = []
            for b in range(len(self.seeds)):
                onset, stop = res.fault_onsets[b], res.terminated_at[b]
                if onset is None or (0 <= stop < onset + window):
                    continue
                diffs.append(signature(res, healthy, b, onset + window)[onset:])
            if not diffs:
                raise ValueError(f"no training episode of fault {f} lasted through its window")
            out[f] = diffs
        return out
