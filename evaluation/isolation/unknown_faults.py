"""Faults no isolator is trained on: undeclared plant effects switched on at an onset.

The library effects of :mod:`fcc_env.effects` act from the start of an episode (they describe a
plant, not an event). :class:`GatedEffect` wraps one so that it starts at an onset sample:
before it the plant is the healthy one; from it the effect acts as if the episode started there
(a sensor bias jumps, a heat loss steps up, a catalyst starts to lose activity). The simulator
files the wrapper by the wrapped effect's hooks, so it takes the same compiled path.

:data:`UNKNOWN_FAULTS` are the test set of the "unknown fault" goal: an isolator must call them
``"unknown"``, not one of f1–f4. Sizes are ones the detectors see (checked in
tests/test_isolation.py): a 4 °C bias on the stage-1 bed thermocouple (13 σ), +2 kW/K extra
heat loss from stage 1, and a cracking activity that falls by 50 %/day from the onset (6 % by
the end of a 4000-sample episode with onset 2000).

>>> e = GatedEffect(fx.make("sensor_bias:T_rg1", bias=4.0), onset=10, sample_time_s=10.0)
>>> import numpy as np
>>> float(e.measure(90.0, np.zeros(8))[4]), float(e.measure(100.0, np.zeros(8))[4])
(0.0, 4.0)
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

import fcc_env
import fcc_env.effects as fx
from diagnosers.episode.record import Episode
from evaluation.sweep.sources import LoadedEpisode
from evaluation.tracks.track_data import TrackData
from fcc_common.validation import Integer, Real, check
from fcc_env.plant import DEFAULT_SAMPLE_TIME_S

__all__ = ["UNKNOWN_FAULTS", "UNKNOWN_ONSET", "GatedEffect", "unknown_fault_episodes"]

#: id -> effect parameters of the unknown faults of the isolation benchmark
UNKNOWN_FAULTS: dict[str, dict[str, float]] = {
    "sensor_bias:T_rg1": {"bias": 4.0},
    "heat_loss:stage1": {"extra_ua_kw_per_k": 2.0},
    "catalyst_deactivation": {"loss_per_day": 0.5},
}
#: onset sample of the unknown faults (the paper's onsets are 1900–2020)
UNKNOWN_ONSET = 2000


@dataclass
class GatedEffect:
    """``effect`` acting from sample ``onset`` on, its clock restarted there.

    Args:
        effect: a library effect (:func:`fcc_env.effects.make`).
        onset: first sample at which the effect acts, ``>= 0``.
        sample_time_s: the episode's sample period [s].
    """

    effect: fx.LibraryEffect
    onset: int
    sample_time_s: float = DEFAULT_SAMPLE_TIME_S

    def __post_init__(self) -> None:
        self.onset = check("onset", self.onset, Integer(0))
        self.sample_time_s = check("sample_time_s", self.sample_time_s, Real(0, closed="neither"))

    @property
    def onset_s(self) -> float:
        return self.onset * self.sample_time_s

    @property
    def hooks(self) -> frozenset[str]:
        return self.effect.hooks

    def reset(self) -> None:
        self.effect.reset()

    def param_multipliers(self, t_s: np.ndarray, base: Any) -> dict[str, np.ndarray]:
        t_s = np.asarray(t_s, dtype=np.float64)
        on = t_s >= self.onset_s
        mult = self.effect.param_multipliers(np.maximum(t_s - self.onset_s, 0.0), base)
        return {k: np.where(on, v, 1.0) for k, v in mult.items()}

    def transform_inputs(self, t_s: np.ndarray, u: np.ndarray) -> np.ndarray:
        t_s = np.asarray(t_s, dtype=np.float64)
        moved = self.effect.transform_inputs(np.maximum(t_s - self.onset_s, 0.0), u)
        on = (t_s >= self.onset_s).reshape((*t_s.shape, 1))
        return np.where(on, moved, u)

    def measure(self, t: float, y: np.ndarray) -> np.ndarray:
        if t < self.onset_s:
            return y
        return self.effect.measure(t - self.onset_s, y)


def unknown_fault_episodes(
    data: TrackData,
    seeds: Sequence[int],
    faults: Sequence[str] | None = None,
    onset: int = UNKNOWN_ONSET,
) -> list[LoadedEpisode]:
    """Episodes of ``data``'s track (noise, plant variation) with each unknown fault on ``seeds``.

    Each episode's ``scenario`` is the effect id and its ``fault_onset`` the onset.
    """
    faults = list(UNKNOWN_FAULTS if faults is None else faults)
    t = data.track
    onset = check("onset", onset, Integer(1, t.n_samples - 1))
    out = []
    for fid in faults:
        if fid not in UNKNOWN_FAULTS:
            raise ValueError(f"Unknown unknown-fault {fid!r}. Available: {list(UNKNOWN_FAULTS)}")
        effect = GatedEffect(fx.make(fid, **UNKNOWN_FAULTS[fid]), onset)
        res = fcc_env.simulate_episodes(
            list(seeds),
            t.n_samples,
            fault=fcc_env.FaultSpec(scenario="nominal"),
            plant=t.plant,
            plant_effects=[effect],
            plant_uncertainty=t.plant_draw,
        )
        for b, seed in enumerate(res.seeds):
            term = int(res.terminated_at[b])
            n = term if term >= 0 else t.n_samples
            if n <= onset:
                continue  # ended before the fault: nothing to isolate
            ep = _episode(res, b, n, fid, onset, int(seed))
            out.append(
                LoadedEpisode(
                    episode=ep,
                    fault_onset=onset,
                    n_samples_planned=t.n_samples,
                    terminated_at=term if term >= 0 else None,
                    termination_reason=res.termination_reasons[b] if term >= 0 else None,
                )
            )
    return out


def _episode(res: Any, b: int, n: int, scenario: str, onset: int, seed: int) -> Episode:
    """Episode ``b`` of a batch result, cut at ``n`` samples, labelled ``scenario``."""
    return Episode(
        y=np.asarray(res.observations[b, :n], dtype=np.float64),
        channels=tuple(fcc_env.MEASUREMENT_NAMES),
        sample_time_s=float(res.sample_time_s),
        fault_onset=onset,
        scenario=scenario,
        seed=seed,
        y_clean=np.asarray(res.y_clean[b, :n]),
    )
