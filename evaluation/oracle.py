"""The physical-limit row: an observer that knows the healthy plant exactly.

It is not a diagnoser: it reads what no diagnoser may, the same seed's noise-free output of the
healthy plant (same inputs, same plant). Its residual on each temperature is therefore pure
measurement noise until the fault acts, and its detection time is the earliest a detector with
a perfect model could reach at the same false-alarm rate. Every diagnoser's ``t_dt`` is reported
against it as ``(t_dt + 1) / (oracle t_dt + 1)`` (:func:`evaluation.intervals.limit_ratio`).

The statistic (the same alarm stage as ``lrgf-mem``, :mod:`diagnosers.alarm`):

1. residual r_k = (y_k − y_ref,k) / σ on the five temperatures T_rx, T_rg1, T_rg2, T_d1, T_dg,
   σ the channel's noise standard deviation times the track's noise scale;
2. an EWMA of weight λ (default 0.3, ``lrgf-mem``'s) per channel;
3. Hotelling's T² of the EWMA vector, its mean and covariance fitted on calibration episodes;
4. an alarm when T² exceeds the ``chi2-tail`` limit at the false-alarm target (default 0.002),
   calibrated on healthy episodes of the track's *validation* seeds, never the test seeds.

>>> OracleConfig().channels
('T_rx', 'T_rg1', 'T_rg2', 'T_d1', 'T_dg')
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from diagnosers.alarm import EWMA, HotellingT2, LimitMethod, calibrate_limit
from diagnosers.base import Detection, Episode
from evaluation.records import CellResult, score_episode
from evaluation.sources import LoadedEpisode, TrackData
from fcc_env.params import MEASUREMENT_NAMES, MEASUREMENTS
from fcc_env.validation import Real, check

__all__ = ["ORACLE_LABEL", "OracleConfig", "PhysicalLimit", "oracle_records"]

#: The row's label in tables (never a registry name).
ORACLE_LABEL = "oracle (physical limit)"


@dataclass(frozen=True, kw_only=True)
class OracleConfig:
    """Settings of the physical-limit observer (see the module docstring)."""

    channels: tuple[str, ...] = ("T_rx", "T_rg1", "T_rg2", "T_d1", "T_dg")
    ewma_lambda: float = 0.3
    target: float = 0.002

    def __post_init__(self) -> None:
        check("ewma_lambda", self.ewma_lambda, Real(0.0, 1.0, closed="right"))
        check("target", self.target, Real(0.0, 0.5, closed="neither"))


class PhysicalLimit:
    """The observer of one track: :meth:`fit` calibrates on validation seeds, then scores.

    It follows the detection contract only as far as scoring needs (``detect`` returns a
    :class:`Detection`), but it is built from references, not trained on episodes.
    """

    name = ORACLE_LABEL

    def __init__(self, data: TrackData, config: OracleConfig | None = None) -> None:
        self.data = data
        self.config = config or OracleConfig()
        idx = [MEASUREMENT_NAMES.index(c) for c in self.config.channels]
        self._idx = np.array(idx)
        noise = np.array([MEASUREMENTS[i].noise_std for i in idx])
        #: noise std [channel unit] of each monitored channel on this track
        self.noise_std = noise * data.track.noise_scale

    def _statistic(self, y: np.ndarray, y_ref: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        r = (y[:, self._idx] - y_ref[: y.shape[0], self._idx]) / self.noise_std
        return r, EWMA(self.config.ewma_lambda).filter(r)

    def fit(self, seeds: Sequence[int] | None = None) -> PhysicalLimit:
        """Calibrate T² and its limit on healthy episodes of ``seeds`` (default: the track's
        validation seeds)."""
        seeds = list(self.data.track.validation_seeds if seeds is None else seeds)
        zs = []
        for s in seeds:
            le = self.data.load_test("nominal", s)
            zs.append(self._statistic(le.episode.y, self.data.reference(s))[1])
        Z = np.concatenate(zs)
        self.t2_ = HotellingT2().fit(Z)
        stat = np.asarray(self.t2_.score(Z))
        self.limit_ = float(
            calibrate_limit(
                stat[:, None],
                self.config.target,
                method=LimitMethod.CHI2_TAIL,
                dof=len(self._idx),
            )[0]
        )
        return self

    def detect(self, episode: Episode) -> Detection:
        assert episode.seed is not None, "the physical limit needs the episode's seed"
        r, z = self._statistic(episode.y, self.data.reference(episode.seed))
        stat = np.asarray(self.t2_.score(z)).reshape(-1, 1)
        upper = np.full_like(stat, self.limit_)
        return Detection(
            alarm=stat[:, 0] > self.limit_,
            signal=stat,
            lower=np.full_like(stat, -np.inf),
            upper=upper,
            residual=np.linalg.norm(r, axis=1, keepdims=True),
            signal_names=("T2[oracle]",),
        )


def oracle_records(
    data: TrackData, config: OracleConfig | None = None, *, t_on: int = 0
) -> list[CellResult]:
    """The physical-limit row's records on every test cell of ``data`` (pure computation)."""
    oracle = PhysicalLimit(data, config).fit()
    out = []
    for sc, seed in data.cells():
        loaded: LoadedEpisode = data.load_test(sc, seed)
        # score_episode only calls .detect and reads .name, which the observer has.
        out.append(score_episode(oracle, loaded, label=ORACLE_LABEL, t_on=t_on))  # type: ignore[arg-type]
    return out
