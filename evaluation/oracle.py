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

**A second reference row**, ``perfect model (measured inputs)`` (``OracleConfig(inputs=
"measured")``): the same observer, but its reference is the healthy plant driven sample by sample
by the episode's *measured* inputs (R_ar with 0.5 % noise, T_ar and T_fp with 0.3 °C;
:meth:`evaluation.sources.TrackData.reference`), which is all a simulation-residual detector can
read. The gap between the two rows is what knowing the true inputs is worth; the gap between a
diagnoser and the second row is its model error (and its alarm stage). On `paper` (validation
seeds) the measured inputs add an independent 0.17 °C to the T_rg1 residual and move f3 from 12
to 20 samples. Both rows use the same stage, which is not the best possible one: a detector
with a better stage can beat either on slow or small faults (it is a reference, not a bound).

>>> OracleConfig().channels
('T_rx', 'T_rg1', 'T_rg2', 'T_d1', 'T_dg')
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from enum import StrEnum

import numpy as np

from diagnosers.alarm import EWMA, HotellingT2, LimitMethod, calibrate_limit
from diagnosers.base import Detection, Episode
from evaluation.records import CellResult, score_episode
from evaluation.sources import LoadedEpisode, TrackData
from fcc_env.params import MEASUREMENT_NAMES, MEASUREMENTS
from fcc_env.validation import Options, Real, check

__all__ = [
    "MEASURED_INPUTS_LABEL",
    "ORACLE_LABEL",
    "REFERENCE_LABELS",
    "OracleConfig",
    "OracleInputs",
    "PhysicalLimit",
    "oracle_records",
    "reference_records",
]

#: The row's label in tables (never a registry name).
ORACLE_LABEL = "oracle (physical limit)"
#: The label of the perfect model driven by the measured inputs.
MEASURED_INPUTS_LABEL = "perfect model (measured inputs)"


class OracleInputs(StrEnum):
    """Which inputs drive the observer's healthy reference (see the module docstring)."""

    TRUE = "true"
    MEASURED = "measured"


#: every reference row's label, by the inputs that drive it
REFERENCE_LABELS = {OracleInputs.TRUE: ORACLE_LABEL, OracleInputs.MEASURED: MEASURED_INPUTS_LABEL}


@dataclass(frozen=True, kw_only=True)
class OracleConfig:
    """Settings of the physical-limit observer (see the module docstring)."""

    channels: tuple[str, ...] = ("T_rx", "T_rg1", "T_rg2", "T_d1", "T_dg")
    ewma_lambda: float = 0.3
    target: float = 0.002
    inputs: str = "true"

    def __post_init__(self) -> None:
        check("ewma_lambda", self.ewma_lambda, Real(0.0, 1.0, closed="right"))
        check("target", self.target, Real(0.0, 0.5, closed="neither"))
        check("inputs", self.inputs, Options(OracleInputs))

    @property
    def label(self) -> str:
        """The row's label in tables."""
        return REFERENCE_LABELS[OracleInputs(self.inputs)]


class PhysicalLimit:
    """The observer of one track: :meth:`fit` calibrates on validation seeds, then scores.

    It follows the detection contract only as far as scoring needs (``detect`` returns a
    :class:`Detection`), but it is built from references, not trained on episodes.
    """

    name = ORACLE_LABEL

    def __init__(self, data: TrackData, config: OracleConfig | None = None) -> None:
        self.data = data
        self.config = config or OracleConfig()
        self.name = self.config.label
        idx = [MEASUREMENT_NAMES.index(c) for c in self.config.channels]
        self._idx = np.array(idx)
        noise = np.array([MEASUREMENTS[i].noise_std for i in idx])
        #: noise std [channel unit] of each monitored channel on this track
        self.noise_std = noise * data.track.noise_scale

    def _statistic(self, y: np.ndarray, seed: int) -> tuple[np.ndarray, np.ndarray]:
        measured = y if self.config.inputs == OracleInputs.MEASURED else None
        y_ref = self.data.reference(seed, measured)
        r = (y[:, self._idx] - y_ref[: y.shape[0], self._idx]) / self.noise_std
        return r, EWMA(self.config.ewma_lambda).filter(r)

    def fit(self, seeds: Sequence[int] | None = None) -> PhysicalLimit:
        """Calibrate T² and its limit on healthy episodes of ``seeds`` (default: the track's
        validation seeds)."""
        seeds = list(self.data.track.validation_seeds if seeds is None else seeds)
        zs = []
        for s in seeds:
            le = self.data.load_test("nominal", s)
            zs.append(self._statistic(le.episode.y, s)[1])
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
        r, z = self._statistic(episode.y, episode.seed)
        stat = np.asarray(self.t2_.score(z)).reshape(-1, 1)
        upper = np.full_like(stat, self.limit_)
        return Detection(
            alarm=stat[:, 0] > self.limit_,
            signal=stat,
            lower=np.full_like(stat, -np.inf),
            upper=upper,
            residual=np.linalg.norm(r, axis=1, keepdims=True),
            signal_names=("T2[oracle]" if self.name == ORACLE_LABEL else "T2[measured inputs]",),
        )


def oracle_records(
    data: TrackData, config: OracleConfig | None = None, *, t_on: int = 0
) -> list[CellResult]:
    """A reference row's records on every test cell of ``data`` (pure computation): the
    physical limit's, or with ``config.inputs="measured"`` the perfect model's on measured
    inputs."""
    return reference_records(data, [config or OracleConfig()], t_on=t_on)


def reference_records(
    data: TrackData, configs: Sequence[OracleConfig], *, t_on: int = 0
) -> list[CellResult]:
    """The records of several reference rows (one per config), each test cell simulated once."""
    observers = [PhysicalLimit(data, c).fit() for c in configs]
    out = []
    for sc, seed in data.cells():
        loaded: LoadedEpisode = data.load_test(sc, seed)
        for obs in observers:
            # score_episode only calls .detect and reads .name, which the observer has.
            out.append(score_episode(obs, loaded, label=obs.name, t_on=t_on))  # type: ignore[arg-type]
    return out
