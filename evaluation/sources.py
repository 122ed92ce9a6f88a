"""Data sources of a sweep: where training and test episodes come from.

A data source implements :class:`DataSource` (it travels to worker processes, so it must be
picklable). :class:`SimulatedData` simulates ``FCC-v0`` episodes with
:func:`fcc_env.simulate_episodes`: training uses healthy (``nominal``) episodes of
``train_seeds``; testing uses ``scenarios`` × ``test_seeds``. The two seed sets must be disjoint
(checked): by default test seeds are ``0..N-1`` and training seeds ``1000..``, so a diagnoser
never sees a test episode's excitation or noise. :class:`evaluation.external.ExternalData` reads
a directory of CSV/Parquet records.

An episode that the simulator terminated early (the envelope was left, e.g. the afterburn
ignited) keeps its samples before ``terminated_at`` only; :class:`LoadedEpisode` carries the
planned onset, the termination sample and its reason to the records.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Protocol, runtime_checkable

import numpy as np

from diagnosers.base import Episode
from evaluation.tracks import Track
from fcc_env.params import INPUT_NAMES, MEASUREMENT_NAMES
from fcc_env.scenarios import (
    DEFAULT_N_SAMPLES,
    DEFAULT_RAMP_SAMPLES,
    FaultProfile,
    FaultSpec,
    Scenario,
)
from fcc_env.simulation import N_SAMPLES_RANGE, NOISE_SCALE_RANGE, SAMPLE_TIME_RANGE
from fcc_env.uncertainty import PlantUncertainty
from fcc_env.validation import Boolean, IntegerSequence, OptionSequence, check, invalid

#: Default first training seed: far from the test seeds 0..N-1 of any realistic sweep.
TRAIN_SEED_BASE = 1000
#: Seeds of a sweep: distinct non-negative integers.
SEEDS = IntegerSequence(0)


@dataclass(frozen=True)
class LoadedEpisode:
    """A test episode ready for scoring, with what the harness records about it.

    Attributes:
        episode: the usable samples (cut at ``terminated_at``); its ``fault_onset`` is ``None``
            when no faulty sample remains.
        fault_onset: the scenario's onset sample as planned (``None`` for a healthy episode).
        n_samples_planned: samples the episode was meant to have.
        terminated_at: first sample outside the plant envelope, ``None`` if it ran to the end.
        termination_reason: why it terminated, ``None`` if it did not.
    """

    episode: Episode
    fault_onset: int | None
    n_samples_planned: int
    terminated_at: int | None = None
    termination_reason: str | None = None


@runtime_checkable
class DataSource(Protocol):
    """What :func:`run_sweep` needs from a data source (picklable: it travels to workers)."""

    def validate(self) -> None:
        """Raise ``ValueError`` naming a bad option and the allowed values."""

    def store_key(self) -> dict[str, Any]:
        """JSON description of everything that defines training and test data, except which
        test cells are run (hashed into the store manifest)."""

    def cells(self) -> list[tuple[str, int]]:
        """The test episodes as ``(scenario, seed)`` pairs, in presentation order."""

    def train_episodes(self) -> list[Episode]:
        """Healthy training episodes."""

    def load_test(self, scenario: str, seed: int) -> LoadedEpisode:
        """One test episode."""

    def describe(self) -> DataDescription:
        """What the data are, for table headers (see :class:`DataDescription`)."""


@dataclass(frozen=True)
class DataDescription:
    """What a data source says about itself for tables and headers (no branching on its type).

    Attributes:
        label: short name of the data (the env id and model version, or ``external:<dir>``).
        lines: sentences for the table header (seeds, set-up, what differs from the paper).
        paper_setup: the paper's own set-up (abrupt faults at the paper's sizes and onsets),
            beside which the paper's Table 2 is a fair reference row.
    """

    label: str
    lines: tuple[str, ...]
    paper_setup: bool = False


@dataclass(frozen=True, kw_only=True)
class SimulatedData:
    """``FCC-v0`` episodes simulated on demand (deterministic in the seed and options).

    Args:
        scenarios: test scenarios, a subset of ``fcc_env.SCENARIOS``.
        test_seeds: seeds of the test episodes (the same seeds for every scenario, so the
            scenarios share excitation programs: a paired design).
        train_seeds: seeds of the healthy training episodes; disjoint from ``test_seeds``.
        n_samples: samples per episode (4000 = the paper's horizon).
        fault: the fault of the test episodes, a :class:`fcc_env.scenarios.FaultSpec` whose
            ``scenario`` is replaced by each test scenario (default: the paper's onsets and
            magnitudes, abrupt). ``magnitude_scale=0.7`` gives the smaller faults of the
            validation protocol (:mod:`evaluation.leaderboard` ``--validation``).
        excitation, noise_scale, sample_time_s: the plant's operation, passed to
            :func:`fcc_env.simulate_episodes` for training and test episodes alike.
        fault_time, fault_magnitude, fault_profile, ramp_samples, fault_magnitude_scale: the
            fields of ``fault`` under their former names (kept for one release; give either
            these or ``fault``).
    """

    scenarios: tuple[str, ...] = ("nominal", "f1", "f2", "f3", "f4")
    test_seeds: tuple[int, ...] = tuple(range(10))
    train_seeds: tuple[int, ...] = tuple(range(TRAIN_SEED_BASE, TRAIN_SEED_BASE + 5))
    n_samples: int = DEFAULT_N_SAMPLES
    fault: FaultSpec | None = None
    excitation: bool = True
    noise_scale: float = 1.0
    sample_time_s: float = 10.0
    fault_time: int | None = None
    fault_magnitude: float | None = None
    fault_profile: str = "abrupt"
    ramp_samples: int | None = None
    fault_magnitude_scale: float = 1.0

    @property
    def fault_spec(self) -> FaultSpec:
        """The test episodes' :class:`FaultSpec` (from ``fault`` or the former field names)."""
        legacy = {
            "onset": self.fault_time,
            "magnitude": self.fault_magnitude,
            "profile": self.fault_profile,
            "ramp_samples": self.ramp_samples,
            "magnitude_scale": self.fault_magnitude_scale,
        }
        if self.fault is None:
            try:
                return FaultSpec(**legacy)
            except ValueError as e:  # name the field as the caller wrote it
                msg = str(e).replace("magnitude_scale=", "fault_magnitude_scale=", 1)
                raise ValueError(msg) from None
        default = FaultSpec()
        changed = [k for k, v in legacy.items() if v != getattr(default, k)]
        if changed:
            raise ValueError(
                f"SimulatedData got fault={self.fault!r} and the former fault fields "
                f"{changed}; give the fault once, as a FaultSpec"
            )
        return self.fault

    def validate(self) -> None:
        import fcc_env

        check("scenarios", self.scenarios, OptionSequence(fcc_env.SCENARIOS))
        test = check("test_seeds", self.test_seeds, SEEDS)
        train = check("train_seeds", self.train_seeds, SEEDS)
        common = sorted(set(test) & set(train))
        if common:
            raise ValueError(
                f"train_seeds and test_seeds must be disjoint (a diagnoser must not be tested on "
                f"the episodes it was trained on); both hold {common}"
            )
        n = check("n_samples", self.n_samples, N_SAMPLES_RANGE)
        check("excitation", self.excitation, Boolean())
        check("noise_scale", self.noise_scale, NOISE_SCALE_RANGE)
        check("sample_time_s", self.sample_time_s, SAMPLE_TIME_RANGE)
        spec = self.fault_spec
        for sc in self.scenarios:
            try:
                spec.replace(scenario=sc).resolve(horizon=n)
            except ValueError as e:
                raise ValueError(
                    f"scenario {sc!r} with n_samples={n}: {e}; with short episodes pass "
                    "fault_time=<sample below n_samples>"
                ) from e

    def store_key(self) -> dict[str, Any]:
        import fcc_env

        # Which test cells run does not change any single cell's result: leave them out so that
        # a sweep extended with more seeds or scenarios reuses the stored cells.
        fault = self.fault_spec.to_json()
        del fault["scenario"]
        return {
            "kind": "simulated",
            "model_version": fcc_env.MODEL_VERSION,
            "n_samples": self.n_samples,
            "train_seeds": list(self.train_seeds),
            "fault": fault,
            "excitation": self.excitation,
            "noise_scale": self.noise_scale,
            "sample_time_s": self.sample_time_s,
        }

    def describe(self) -> DataDescription:
        import fcc_env

        spec = self.fault_spec
        lines = [
            f"Test seeds {self.test_seeds[0]}..{self.test_seeds[-1]} ({len(self.test_seeds)} per "
            f"scenario), training on {len(self.train_seeds)} healthy episodes (seeds "
            f"{self.train_seeds[0]}..{self.train_seeds[-1]}), {self.n_samples} samples each."
        ]
        if spec.profile is not FaultProfile.ABRUPT:
            ramp = DEFAULT_RAMP_SAMPLES if spec.ramp_samples is None else spec.ramp_samples
            lines.append(
                f"Incipient faults: each parameter ramps to its full change over {ramp} samples "
                "from the onset; t_dt counts from the onset. The paper's row (abrupt faults) does "
                "not apply."
            )
        if spec.magnitude_scale != 1.0:
            lines.append(
                f"Fault magnitudes {spec.magnitude_scale:g}x the paper's (validation "
                "protocol): the paper's row does not apply."
            )
        paper = (
            spec.magnitude_scale == 1.0
            and spec.profile is FaultProfile.ABRUPT
            and spec.magnitude is None
            and self.noise_scale == 1.0
        )
        return DataDescription(
            label=f"{fcc_env.ENV_ID} ({fcc_env.MODEL_VERSION})",
            lines=tuple(lines),
            paper_setup=paper,
        )

    def cells(self) -> list[tuple[str, int]]:
        return [(sc, int(s)) for sc in self.scenarios for s in self.test_seeds]

    def _simulate(self, seeds: Sequence[int], scenario: str) -> list[LoadedEpisode]:
        return simulate_loaded(
            seeds,
            self.n_samples,
            self.fault_spec.replace(scenario=scenario),
            excitation=self.excitation,
            noise_scale=self.noise_scale,
            sample_time_s=self.sample_time_s,
        )

    def _magnitude(self, scenario: str) -> float | None:
        """The fault magnitude passed to the simulator for ``scenario`` (scale applied)."""
        return self.fault_spec.magnitude_for(Scenario(scenario))

    def train_episodes(self) -> list[Episode]:
        # A training episode that left the envelope keeps its samples before termination; one
        # with fewer than 2 samples has nothing to learn from and is dropped.
        loaded = self._simulate(self.train_seeds, "nominal")
        return [le.episode for le in loaded if le.episode.n_samples >= 2]

    def train_fault_episodes(self) -> list[Episode]:
        """Labelled faulty training episodes for diagnosers that isolate: every fault scenario
        of ``scenarios`` on every training seed, with the test episodes' fault settings."""
        out = []
        for sc in self.scenarios:
            if sc == "nominal":
                continue
            for le in self._simulate(self.train_seeds, sc):
                ep = le.episode
                if ep.fault_onset is not None and ep.n_samples - ep.fault_onset >= 2:
                    out.append(ep)
        return out

    def load_test(self, scenario: str, seed: int) -> LoadedEpisode:
        return self._simulate([seed], scenario)[0]


#: the tracks' sample time [s] (the env's default)
TRACK_SAMPLE_TIME_S = 10.0

#: the plant inputs that are also measured (Table 1), as (input index, measurement index)
_MEASURED_INPUTS = tuple(
    (INPUT_NAMES.index(c), MEASUREMENT_NAMES.index(c))
    for c in INPUT_NAMES
    if c in MEASUREMENT_NAMES
)


class MeasuredInputs:
    """Plant effect (``transform_inputs``): the process sees the measured inputs of ``y``.

    ``y`` holds an episode's measurements ``(T, 8)``; at sample ``k`` the inputs that Table 1
    measures (R_ar, T_ar, T_fp) are replaced by ``y[k]``'s values, the others are left alone.
    Replaying an episode's noise-free measurements reproduces it exactly (tested).
    """

    def __init__(self, y: np.ndarray, sample_time_s: float) -> None:
        y = np.asarray(y, dtype=np.float64)
        n_meas = len(MEASUREMENT_NAMES)
        if y.ndim != 2 or y.shape[0] < 1 or y.shape[1] != n_meas:
            raise ValueError(
                f"measured has shape {y.shape}; allowed: (T, {n_meas}) with T >= 1, the columns "
                f"{', '.join(MEASUREMENT_NAMES)}"
            )
        if not np.isfinite(y).all():
            raise ValueError("measured contains NaN or inf; allowed: finite values")
        self.y = y
        self.sample_time_s = float(sample_time_s)

    def transform_inputs(self, t_s: np.ndarray, u: np.ndarray) -> np.ndarray:
        k = np.rint(np.asarray(t_s) / self.sample_time_s).astype(np.int64)
        k = np.clip(k, 0, self.y.shape[0] - 1)
        out = np.array(u, dtype=np.float64, copy=True)
        for i_in, i_meas in _MEASURED_INPUTS:
            out[..., i_in] = self.y[k, i_meas]
        return out


def simulate_loaded(
    seeds: Sequence[int],
    n_samples: int,
    spec: FaultSpec,
    *,
    excitation: bool = True,
    noise_scale: float = 1.0,
    sample_time_s: float = TRACK_SAMPLE_TIME_S,
    plant_uncertainty: PlantUncertainty | None = None,
) -> list[LoadedEpisode]:
    """Simulate ``seeds`` with the fault ``spec`` and cut each at its termination sample."""
    import fcc_env

    sc = Scenario(spec.scenario)
    res = fcc_env.simulate_episodes(
        list(seeds),
        int(n_samples),
        scenario=spec.scenario,
        fault_time=spec.onset,
        fault_magnitude=spec.magnitude_for(sc),
        fault_profile=spec.profile.value,
        ramp_samples=spec.ramp_samples,
        excitation=excitation,
        noise_scale=noise_scale,
        sample_time_s=sample_time_s,
        plant_uncertainty=plant_uncertainty,
    )
    out = []
    # Episode.from_batch cuts each episode at its termination and drops an onset it never reached
    for b, episode in enumerate(Episode.from_batch(res)):
        term = int(res.terminated_at[b])
        onset = res.fault_onsets[b]
        out.append(
            LoadedEpisode(
                episode=episode,
                fault_onset=None if onset is None else int(onset),
                n_samples_planned=int(n_samples),
                terminated_at=term if term >= 0 else None,
                termination_reason=res.termination_reasons[b] if term >= 0 else None,
            )
        )
    return out


@dataclass(frozen=True, kw_only=True)
class TrackData:
    """The episodes of a benchmark track (:mod:`evaluation.tracks`) as a sweep's data source.

    Training: ``track.n_train`` healthy episodes from the track's training seeds, with the
    track's noise scale. Test: :meth:`Track.test_cells`, each with its own
    :meth:`Track.fault_spec` (every field explicit, drawn from the seed). The store key is the
    track's definition without its test counts, so a sweep extended with more test episodes
    reuses the stored cells and models.
    """

    track: Track

    def validate(self) -> None:
        if not isinstance(self.track, Track):
            raise invalid("track", self.track, "an evaluation.tracks.Track")

    def store_key(self) -> dict[str, Any]:
        import fcc_env

        key = self.track.to_json()
        del key["n_healthy"], key["n_faulty"], key["description"]
        return {"kind": "track", "model_version": fcc_env.MODEL_VERSION, "track": key}

    def cells(self) -> list[tuple[str, int]]:
        return self.track.test_cells()

    def training_key(self) -> dict[str, Any]:
        """What the training episodes depend on: tracks with equal keys train equal models."""
        import fcc_env

        t = self.track
        return {
            "model_version": fcc_env.MODEL_VERSION,
            "n_samples": t.n_samples,
            "noise_scale": t.noise_scale,
            "plant_variation": t.plant_variation,
            "train_seeds": [t.train_seeds.start, t.train_seeds.stop],
        }

    def _simulate(self, seeds: Sequence[int], spec: FaultSpec) -> list[LoadedEpisode]:
        return simulate_loaded(
            seeds,
            self.track.n_samples,
            spec,
            noise_scale=self.track.noise_scale,
            plant_uncertainty=PlantUncertainty() if self.track.plant_variation else None,
        )

    def train_episodes(self) -> list[Episode]:
        loaded = self._simulate(list(self.track.train_seeds), FaultSpec())
        return [le.episode for le in loaded if le.episode.n_samples >= 2]

    def train_fault_episodes(self) -> list[Episode]:
        """Labelled faulty training episodes, for diagnosers that isolate (``isolates``).

        Every fault of the track on every training seed, its size, onset and profile drawn from
        the track's distributions with that training seed (:meth:`Track.fault_spec`): the same
        seeds as the healthy training episodes, never a test or validation seed. An episode that
        ended before its onset has no faulty sample and is dropped.
        """
        out = []
        for fault in self.track.faults:
            for seed in self.track.train_fault_seeds:
                ep = self._simulate([seed], self.track.fault_spec(fault, seed))[0].episode
                if ep.fault_onset is not None and ep.n_samples - ep.fault_onset >= 2:
                    out.append(ep)
        return out

    def fault_training_key(self) -> dict[str, Any]:
        """What the labelled training faults depend on besides :meth:`training_key`: the
        track's fault distributions (tracks sharing healthy training may differ here)."""
        key = self.track.to_json()
        for k in ("n_healthy", "n_faulty", "description", "test_seed_start"):
            key.pop(k, None)
        return key

    def load_test(self, scenario: str, seed: int) -> LoadedEpisode:
        return self._simulate([seed], self.track.fault_spec(scenario, seed))[0]

    def reference(self, seed: int, measured: np.ndarray | None = None) -> np.ndarray:
        """The healthy plant's noise-free measurements of ``seed`` (same plant): what the
        physical-limit rows compare with (no diagnoser may read it).

        Without ``measured`` the plant sees its true inputs. With ``measured`` (an episode's
        measurements, ``(T, 8)``) it sees, sample by sample, the *measured* values of the
        inputs that are measured (R_ar, T_ar, T_fp; noise included) in place of the true ones:
        the output of a perfect model driven by what a detector reads. Returns ``(T', 8)``.
        """
        if measured is None:
            ep = self._simulate([seed], FaultSpec())[0].episode
            assert ep.y_clean is not None
            return ep.y_clean
        import fcc_env

        replay = MeasuredInputs(measured, TRACK_SAMPLE_TIME_S)  # checks the shape and values
        res = fcc_env.simulate_episodes(
            [seed],
            replay.y.shape[0],
            plant_effects=[replay],
            noise_scale=self.track.noise_scale,
            sample_time_s=TRACK_SAMPLE_TIME_S,
            plant_uncertainty=PlantUncertainty() if self.track.plant_variation else None,
        )
        return np.asarray(res.y_clean[0], dtype=np.float64)

    def describe(self) -> DataDescription:
        import fcc_env

        t = self.track
        return DataDescription(
            label=f"{fcc_env.ENV_ID} ({fcc_env.MODEL_VERSION}), track {t.name}",
            lines=(
                t.description,
                f"{t.n_healthy} healthy and {t.n_faulty_total} faulty test episodes (seeds from "
                f"{t.test_seed_start}), training on {t.n_train} healthy episodes (seeds from "
                f"{t.train_seed_start}), {t.n_samples} samples each.",
            ),
            paper_setup=t.name == "paper",
        )
