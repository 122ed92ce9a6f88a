"""The reachable-bound row: the optimal filter on the exact model, from the measured channels.

``optimal filter (exact model, measured channels)`` (:data:`FILTER_LABEL`, issue 42 item 2)
reads what a detector reads, the episode's observations, plus the true model of the plant it
is scored on: :class:`diagnosers.filters.FCCStateEstimator` on the track's plant parameters
(on ``uncertain``, each episode's drawn parameters, as the physical-limit rows simulate the
drawn plant) with the plant's noise model (:meth:`diagnosers.filters.UKFConfig.matching`). It
never reads the scored episode's noise-free output (it runs on an episode with
``y_clean=None``; tested). Where the optimal CUSUM row (:mod:`evaluation.tracks.optimal`)
knows the true inputs and each fault's exact trajectory on the scored seed, this row
*estimates* the true R_ar, T_ar, T_fp (and, in closed loop or on drawn plants, the feed coking
factor) from their noisy readings, and knows each fault only by its direction: the gap between
the two rows is the price of input noise and of an unknown fault path.

The statistic, on the filter's whitened innovations e_t (standard normal and white while the
plant is healthy, ``lab/filter-lab.md``):

1. per fault g and signature window, a window-limited GLR over the fault's size along its
   innovation signature d_g: the fault's size and onset unknown, its direction known;
2. an omnibus for any other departure: Page's CUSUM of the log-likelihood ratio of a doubled
   innovation variance, ``NIS_t / 4 − 4 ln 2`` per sample (8 channels);
3. one alarm when any statistic passes its limit, the limits on one shared tail, the *union*
   at :data:`~evaluation.tracks.oracle.REFERENCE_TARGET` of the healthy calibration samples
   (the track's validation seeds).

The three are :class:`diagnosers.stages.innovation_stage.InnovationStage`, the stage of the
grey-box detector ``ukf-glr`` too: the row differs from that detector in its model (the
plant's exact parameters and noise) and in where its directions come from (below).

Decision, the signatures: *learned from the track's labelled training faults*
(:meth:`TrackData.train_fault_episodes`, training seeds only, the track's size and onset
distributions) as the mean over each of :data:`SIGNATURE_WINDOWS` samples after onset of the whitened
innovations of the faulty episode less those of its healthy twin (the same seed, no fault),
averaged over the first :data:`SIGNATURE_SEEDS` training fault seeds and normalised. The twin shares the episode's noise, so the
difference is nearly noise-free; learned this way a signature covers the track's own sizes,
ramps and plant, and reads nothing of the scored episode. The noise-free alternative (the
filter on clean records) sees a filter that never declares input steps, unlike the one scored.
A constant direction is a compromise: the signatures are dynamic (f1 moves T_rx at once, f3
builds over minutes; the filter's input walks absorb part of each fault later), so this row is
the reachable bound *of a directional test on these innovations*, not of every test.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from diagnosers.detection import Detection
from diagnosers.episode.record import Episode
from diagnosers.filters import FCCStateEstimator, UKFConfig
from diagnosers.stages.innovation_stage import OMNIBUS_VARIANCE, InnovationStage, union_limits
from evaluation.sweep.store import canonical_hash
from evaluation.tracks.optimal import GLR_WINDOW
from evaluation.tracks.track_data import TrackData
from fcc_common.validation import Integer, Real, check
from fcc_env.params import MEASUREMENT_NAMES, FCCParams
from fcc_env.scenarios import FaultSpec

__all__ = [
    "FILTER_LABEL",
    "SIGNATURE_SEEDS",
    "SIGNATURE_WINDOWS",
    "FilterBound",
]

#: The row's label in tables.
FILTER_LABEL = "optimal filter (exact model, measured channels)"
#: Samples after onset over which a training fault's innovation signature is averaged (the
#: window of the lab notes' signal-to-noise table).
SIGNATURE_WINDOWS = (30, 300)
#: Training fault seeds per fault the signatures are averaged over (the first of the track's):
#: a difference to the twin is nearly noise-free, so a few suffice, and each costs a filter run.
SIGNATURE_SEEDS = 5


#: Fits of this process by :meth:`FilterBound._fit_key`: a track's row is fitted once however
#: often its table is built (each fit filters about 125 episodes).
_FITTED: dict[str, tuple[np.ndarray, np.ndarray]] = {}


class FilterBound:
    """The reachable-bound row of one track: :meth:`fit` learns the signatures on training
    faults and the limits on healthy episodes, :meth:`detect` scores an episode.

    Not a diagnoser: it reads the plant's true parameters, which no detector may.

    Args:
        data: the track.
        false_alarm_target: the union's share of healthy calibration samples in alarm.
        window: the GLR's window [samples].
        signature_windows: the windows after onset a fault's signatures are averaged over,
            samples (one direction, and one GLR, per fault and window).
        signature_seeds: training fault seeds per fault the signatures are averaged over.
    """

    name = FILTER_LABEL

    def __init__(
        self,
        data: TrackData,
        *,
        false_alarm_target: float,
        window: int = GLR_WINDOW,
        signature_windows: tuple[int, ...] = SIGNATURE_WINDOWS,
        signature_seeds: int = SIGNATURE_SEEDS,
    ) -> None:
        self.data = data
        self.false_alarm_target = check(
            "false_alarm_target", false_alarm_target, Real(0.0, 0.5, closed="neither")
        )
        self.window = check("window", window, Integer(1))
        self.signature_windows = tuple(
            check("signature_windows", w, Integer(1)) for w in signature_windows
        )
        self.signature_seeds = check("signature_seeds", signature_seeds, Integer(1))
        track = data.track
        # a drawn plant's feed-quality drift is the coking factor's: estimate it there
        coking = True if track.plant_variation else None
        self.config = UKFConfig.matching(track.plant, estimate_coking=coking)
        self._shared = FCCStateEstimator(track.plant.params, self.config)
        pairs = [(f, w) for f in track.faults for w in self.signature_windows]
        self.signal_names = (*(f"glr[{f},{w}]" for f, w in pairs), "cusum[nis]")

    @property
    def faults(self) -> tuple[str, ...]:
        return self.data.track.faults

    def params_of(self, seed: int) -> FCCParams:
        """The true parameters of the plant of episode ``seed`` (its draw on ``uncertain``)."""
        track = self.data.track
        draw = track.plant_draw
        return track.plant.params if draw is None else draw.draw(seed, track.plant.params).params

    def whitened(self, episode: Episode) -> np.ndarray:
        """The filter's whitened innovations ``(T, 8)`` of ``episode``'s observations (its
        ``y`` only), on the exact model of its plant."""
        if episode.seed is None:
            raise ValueError("episode.seed is None; allowed: the seed of a track episode")
        if self.data.track.plant_variation:
            est = FCCStateEstimator(self.params_of(episode.seed), self.config)
        else:
            est = self._shared
        idx = [episode.channels.index(c) for c in est.channels]
        y = np.asarray(episode.y, dtype=np.float64)[None, :, idx]
        return est.filter(y, innovation_cov=False).whitened[0]

    def signature_seeds_used(self) -> list[int]:
        """The training fault seeds the signatures are averaged over, in the order they are
        summed (the first :attr:`signature_seeds` of the track's)."""
        return list(self.data.track.train_fault_seeds[: self.signature_seeds])

    def signature_terms(self, seed: int) -> dict[str, list[tuple[int, np.ndarray]]]:
        """One training fault seed's share of the signatures: per fault, ``(window index, mean
        whitened-innovation difference to the healthy twin over that window after onset)``
        (a fault whose episode ended before its onset, or a window with no sample, adds
        nothing). Each seed is independent of the others: one task each
        (:mod:`evaluation.tracks.reference_runs`)."""
        faulty = self.data.train_fault_episodes([seed])
        h = self.whitened(self.data.simulate([seed], FaultSpec())[0].episode)
        out: dict[str, list[tuple[int, np.ndarray]]] = {}
        for ep in faulty:
            assert ep.fault_onset is not None
            e, k0 = self.whitened(ep), ep.fault_onset
            for j, w in enumerate(self.signature_windows):
                k1 = min(k0 + w, e.shape[0], h.shape[0])
                if k1 > k0:
                    out.setdefault(ep.scenario, []).append(
                        (j, np.mean(e[k0:k1] - h[k0:k1], axis=0))
                    )
        return out

    def combine_signatures(
        self, terms: Sequence[Mapping[str, Sequence[tuple[int, np.ndarray]]]]
    ) -> np.ndarray:
        """Unit directions ``(n_faults · n_windows, 8)`` (fault-major) from the
        :meth:`signature_terms` of the seeds of :meth:`signature_seeds_used`, in that order
        (the order of the sums fixes their last bits)."""
        wins = self.signature_windows
        sums = {f: np.zeros((len(wins), len(MEASUREMENT_NAMES))) for f in self.faults}
        for seed_terms in terms:
            for f, parts in seed_terms.items():
                for j, mean in parts:
                    sums[f][j] += mean
        out = np.concatenate([sums[f] for f in self.faults])
        norm = np.linalg.norm(out, axis=1, keepdims=True)
        return np.divide(out, norm, out=np.zeros_like(out), where=norm > 0)

    def _learn_signatures(self) -> np.ndarray:
        """The training faults' mean whitened-innovation difference to their healthy twins over
        each window after onset, as unit directions (module docstring)."""
        terms = [self.signature_terms(s) for s in self.signature_seeds_used()]
        return self.combine_signatures(terms)

    def _stage(self) -> InnovationStage:
        return InnovationStage(
            self.directions_, window=self.window, omnibus_variance=OMNIBUS_VARIANCE
        )

    def statistics(self, episode: Episode) -> tuple[np.ndarray, np.ndarray]:
        """(the statistics ``(T, n_faults · n_windows + 1)``: the GLR per fault and window, the
        omnibus last; the matched innovations d_gᵀe_t and the NIS, the same shape)."""
        e = self.whitened(episode)
        stage = self._stage()
        return stage.statistics(e), stage.matched(e)

    def fit(self, healthy: Sequence[Episode]) -> FilterBound:
        """Learn the signatures (training faults) and set the limits on ``healthy``
        (validation) episodes."""
        if not healthy:
            raise ValueError("healthy is empty; allowed: at least one healthy episode")
        key = self._fit_key(healthy)
        if key in _FITTED:
            self.directions_, self.limits_ = _FITTED[key]
            return self
        self.directions_ = self._learn_signatures()
        self.set_limits([self.calibration_statistics(healthy)])
        _FITTED[key] = (self.directions_, self.limits_)
        return self

    def calibration_statistics(self, healthy: Sequence[Episode]) -> np.ndarray:
        """The statistics ``(Σ T_i, n_statistics)`` of healthy calibration episodes, stacked in
        their order (``directions_`` set): a part of :meth:`fit` that any split of the
        calibration episodes computes in pieces (one task per chunk)."""
        stage = self._stage()
        return np.concatenate([stage.statistics(self.whitened(ep)) for ep in healthy])

    def set_limits(self, statistics: Sequence[np.ndarray]) -> FilterBound:
        """Set the union's limits on the :meth:`calibration_statistics` of the calibration
        episodes, given in chunks in the episodes' order."""
        if not statistics:
            raise ValueError("statistics is empty; allowed: at least one chunk of statistics")
        self.limits_ = union_limits(np.concatenate(list(statistics)), self.false_alarm_target)
        return self

    def _fit_key(self, healthy: Sequence[Episode]) -> str:
        """What a fit depends on: the track without its test episodes (its plant, faults,
        training seeds), the settings and the calibration episodes' seeds and lengths (the
        episodes are the seeds' simulations)."""
        key = {
            "track": self.data.fault_training_key(),
            "plant": self.data.track.plant.to_json(),
            "settings": [self.false_alarm_target, self.window, self.signature_windows],
            "signature_seeds": self.signature_seeds,
            "healthy": [[ep.seed, ep.scenario, ep.n_samples] for ep in healthy],
        }
        return canonical_hash(key)

    def detect(self, episode: Episode) -> Detection:
        stat, matched = self.statistics(episode)
        return Detection(
            alarm=(stat > self.limits_).any(axis=1),
            signal=stat,
            lower=np.full_like(stat, -np.inf),
            upper=np.broadcast_to(self.limits_, stat.shape).copy(),
            residual=matched,
            signal_names=self.signal_names,
        )
