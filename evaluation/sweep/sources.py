"""Data sources of a sweep: where training and test episodes come from.

A data source implements :class:`DataSource` (it travels to worker processes, so it must be
picklable). :class:`SimulatedData` simulates ``FCC-v0`` episodes with
:func:`fcc_env.simulate_episodes`: training uses healthy (``nominal``) episodes of
``train_seeds``; testing uses ``scenarios`` × ``test_seeds``. The two seed sets must be disjoint
(checked): by default test seeds are ``0..N-1`` and training seeds ``1000..``, so a diagnoser
never sees a test episode's excitation or noise. :class:`evaluation.sweep.external_data.ExternalData`
reads a directory of CSV/Parquet records; :class:`evaluation.tracks.track_data.TrackData` simulates
the episodes of a benchmark track.

An episode that the simulator terminated early (the envelope was left, e.g. the afterburn
ignited) keeps its samples before ``terminated_at`` only; :class:`LoadedEpisode` carries the
planned onset, the termination sample and its reason to the records.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable

import fcc_env
from diagnosers.episode.record import Episode
from fcc_common.validation import IntegerSequence, OptionSequence, check, invalid
from fcc_env.plant import PlantConfig
from fcc_env.scenarios import (
    DEFAULT_N_SAMPLES,
    DEFAULT_RAMP_SAMPLES,
    NOMINAL,
    FaultProfile,
    FaultSpec,
    scenario_names,
)
from fcc_env.simulation import N_SAMPLES_RANGE
from fcc_env.uncertainty import PlantUncertainty

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
        scenarios: test scenarios, registered ones (:func:`fcc_env.scenario_names`); default:
            every scenario registered when the source is built.
        test_seeds: seeds of the test episodes (the same seeds for every scenario, so the
            scenarios share excitation programs: a paired design).
        train_seeds: seeds of the healthy training episodes; disjoint from ``test_seeds``.
        n_samples: samples per episode (4000 = the paper's horizon).
        fault: the fault of the test episodes, a :class:`fcc_env.scenarios.FaultSpec` whose
            ``scenario`` is replaced by each test scenario (default: the paper's onsets and
            magnitudes, abrupt). ``magnitude_scale=0.7`` gives the smaller faults of the
            validation protocol (:mod:`evaluation.leaderboard` ``--validation``).
        plant: the plant and its operation (a :class:`fcc_env.PlantConfig`, default the
            paper's), passed whole to :func:`fcc_env.simulate_episodes` for training and test
            episodes alike (:meth:`fcc_env.PlantConfig.to_json` is in the store key).
    """

    scenarios: tuple[str, ...] = field(default_factory=scenario_names)
    test_seeds: tuple[int, ...] = tuple(range(10))
    train_seeds: tuple[int, ...] = tuple(range(TRAIN_SEED_BASE, TRAIN_SEED_BASE + 5))
    n_samples: int = DEFAULT_N_SAMPLES
    fault: FaultSpec | None = None
    plant: PlantConfig = field(default_factory=PlantConfig)

    @property
    def fault_spec(self) -> FaultSpec:
        """The test episodes' :class:`FaultSpec` (``fault``, or the paper's faults)."""
        return FaultSpec() if self.fault is None else self.fault

    def validate(self) -> None:
        check("scenarios", self.scenarios, OptionSequence(scenario_names()))
        test = check("test_seeds", self.test_seeds, SEEDS)
        train = check("train_seeds", self.train_seeds, SEEDS)
        common = sorted(set(test) & set(train))
        if common:
            raise ValueError(
                f"train_seeds and test_seeds must be disjoint (a diagnoser must not be tested on "
                f"the episodes it was trained on); both hold {common}"
            )
        n = check("n_samples", self.n_samples, N_SAMPLES_RANGE)
        if not isinstance(self.plant, PlantConfig):
            raise invalid("plant", self.plant, "an fcc_env.PlantConfig")
        spec = self.fault_spec
        for sc in self.scenarios:
            try:
                spec.replace(scenario=sc).resolve(horizon=n)
            except ValueError as e:
                raise ValueError(
                    f"scenario {sc!r} with n_samples={n}: {e}; with short episodes pass "
                    "fault=FaultSpec(onset=<sample below n_samples>)"
                ) from e

    def store_key(self) -> dict[str, Any]:
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
            "plant": self.plant.to_json(),
        }

    def describe(self) -> DataDescription:
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
            and self.plant.noise_scale == 1.0
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
            plant=self.plant,
        )

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
            if sc == NOMINAL:
                continue
            for le in self._simulate(self.train_seeds, sc):
                ep = le.episode
                if ep.fault_onset is not None and ep.n_samples - ep.fault_onset >= 2:
                    out.append(ep)
        return out

    def load_test(self, scenario: str, seed: int) -> LoadedEpisode:
        return self._simulate([seed], scenario)[0]


def simulate_loaded(
    seeds: Sequence[int],
    n_samples: int,
    spec: FaultSpec,
    *,
    plant: PlantConfig | None = None,
    plant_uncertainty: PlantUncertainty | None = None,
) -> list[LoadedEpisode]:
    """Simulate ``seeds`` with the fault ``spec`` on ``plant`` (default: the paper's; with a
    :class:`fcc_env.RegulatoryLayer`, closed loop) and cut each at its termination sample."""
    res = fcc_env.simulate_episodes(
        list(seeds), int(n_samples), fault=spec, plant=plant, plant_uncertainty=plant_uncertainty
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
