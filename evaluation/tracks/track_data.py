"""A benchmark track's episodes as a sweep's data source (:class:`TrackData`).

The physical-limit rows also need the healthy plant's output driven by what a detector reads:
:class:`MeasuredInputs` replays an episode's measured inputs into the simulator.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

import fcc_env
from diagnosers.episode.record import Episode
from evaluation.sweep.sources import DataDescription, LoadedEpisode, simulate_loaded
from evaluation.tracks.track import Track
from fcc_common.validation import invalid
from fcc_env.closed_loop import CLOSED_LOOP_CHANNELS
from fcc_env.params import INPUT_NAMES, MEASUREMENT_NAMES
from fcc_env.plant import PlantConfig
from fcc_env.scenarios import FaultSpec
from fcc_env.simulation import operating_program, simulate_inputs

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
        key = self.track.to_json()
        del key["n_healthy"], key["n_faulty"], key["description"]
        return {
            "kind": "track",
            "model_version": fcc_env.MODEL_VERSION,
            "track": key,
            "plant": self.track.plant.to_json(),
        }

    def cells(self) -> list[tuple[str, int]]:
        return self.track.test_cells()

    def training_key(self) -> dict[str, Any]:
        """What the training episodes depend on: tracks with equal keys train equal models."""
        t = self.track
        return {
            "model_version": fcc_env.MODEL_VERSION,
            "n_samples": t.n_samples,
            "plant": t.plant.to_json(),
            "plant_variation": t.plant_variation,
            **({"plant_mismatch": True} if t.plant_mismatch else {}),
            "train_seeds": [t.train_seeds.start, t.train_seeds.stop],
        }

    def simulate(
        self, seeds: Sequence[int], spec: FaultSpec, *, test: bool = False
    ) -> list[LoadedEpisode]:
        """Episodes of ``seeds`` with the fault ``spec``, under the track's noise and plant
        (``test``: the test episodes' plant, :attr:`Track.test_plant`, whose set-point program
        may be wider than the training one)."""
        track = self.track
        plant = track.test_plant if test else track.plant
        return simulate_loaded(
            seeds, track.n_samples, spec, plant=plant, plant_uncertainty=track.plant_draw
        )

    def train_episodes(self) -> list[Episode]:
        loaded = self.simulate(list(self.track.train_seeds), FaultSpec())
        return [le.episode for le in loaded if le.episode.n_samples >= 2]

    def train_fault_episodes(self, seeds: Sequence[int] | None = None) -> list[Episode]:
        """Labelled faulty training episodes, for diagnosers that isolate (``isolates``) or
        learn from faults (``learns_from_faults``).

        Every fault of the track on every training fault seed (:attr:`Track.train_fault_seeds`;
        ``seeds``: only those of them, in that order), its size, onset and profile drawn from
        the track's distributions with that training seed (:meth:`Track.fault_spec`), on the
        track's plant and noise: training seeds, never a test or validation seed. An episode
        that ended before its onset has no faulty sample and is dropped.
        """
        own = self.track.train_fault_seeds
        out = []
        for fault in self.track.faults:
            for seed in own if seeds is None else [s for s in seeds if s in own]:
                ep = self.load_test(fault, seed).episode
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
        """Episode ``(scenario, seed)`` of the track (``scenario`` a column of the track).

        A column whose name is not its episodes' scenario (a concurrent pair's ``a+b``, whose
        episodes say ``concurrent``) labels them with its name, so that what learns per label
        (an isolator, the reference rows' fault directions) learns one per column, and an
        isolator's answer is scored against the pair (:meth:`Track.labels`).
        """
        le = self.simulate([seed], self.track.fault_spec(scenario, seed), test=True)[0]
        if le.episode.scenario == scenario or scenario not in self.track.faults:
            return le
        return dataclasses.replace(le, episode=dataclasses.replace(le.episode, scenario=scenario))

    def reference(self, seed: int, measured: np.ndarray | None = None) -> np.ndarray:
        """The healthy plant's noise-free measurements of ``seed`` (same plant): what the
        physical-limit rows compare with (no diagnoser may read it).

        Without ``measured`` the plant sees its true inputs. With ``measured`` (an episode's
        measurements, ``(T, 8)``) it sees, sample by sample, the *measured* values of the
        inputs that are measured (R_ar, T_ar, T_fp; noise included) in place of the true ones:
        the output of a perfect model driven by what a detector reads. Returns ``(T', 8)``.
        """
        if self.track.closed_loop:
            return self._closed_loop_reference(seed, measured)
        if measured is None:
            ep = self.simulate([seed], FaultSpec())[0].episode
            assert ep.y_clean is not None
            return ep.y_clean
        plant = self.track.plant
        replay = MeasuredInputs(measured, plant.sample_time_s)  # checks the shape and values
        res = fcc_env.simulate_episodes(
            [seed],
            replay.y.shape[0],
            plant=plant,
            plant_effects=[replay],
            plant_uncertainty=self.track.plant_draw,
        )
        return np.asarray(res.y_clean[0], dtype=np.float64)

    def _closed_loop_reference(self, seed: int, record: np.ndarray | None) -> np.ndarray:
        """Closed loop: the healthy plant, in open loop, driven by an episode's own record of
        the manipulated variables and the measured inputs.

        A twin that ran its own controllers would share the episode's noise through them and
        match its valve to the last bit until the fault, then differ by exactly the fault:
        no detector can read that, and it is no limit. The healthy model fed the episode's
        valve command, air, air and feed temperatures instead is what "the same inputs" means
        under control: before the fault its temperatures differ from the episode's by the
        measurement noise, after it by what the fault does at the inputs the controllers
        chose. ``record`` (``(T, 11)``) is the episode's noise-free observation (true
        inputs) or its observation (measured inputs: R_ar with 0.5 % noise, T_ar and T_fp
        with 0.3 °C; the valve command is exact in both). The feed rate and the coking factor,
        which nobody measures, are the seed's program (the same in the healthy twin). So the
        measured-input rows of a closed-loop track read one thing no detector may: the
        program's feed-quality (coking-factor) drift. With the declared coking factor instead,
        the perfect model's residual spread on T_rg1 is 1.29 °C against 0.36 °C
        (``lab/closed_f3_limit.py``); a row at what the measured channels allow would estimate
        the drift (an observer), which is not built. Returns ``(T', 8)``, the Table 1 channels,
        ``T' < T`` where the healthy model left its domain (non-finite output) at sample ``T'``.
        """
        plant = self.track.test_plant
        if record is None:
            twin = fcc_env.simulate_episodes([seed], self.track.n_samples, plant=plant)
            record = twin.y_clean[0]
        record = np.asarray(record, dtype=np.float64)
        if record.ndim != 2 or record.shape[1] != len(CLOSED_LOOP_CHANNELS):
            raise ValueError(
                f"record has shape {record.shape}; allowed: (T, {len(CLOSED_LOOP_CHANNELS)}) "
                f"with the columns {', '.join(CLOSED_LOOP_CHANNELS)}"
            )
        T = record.shape[0]
        u, _ = operating_program(seed, T, plant)
        for name in ("u_F", "R_ar", "T_ar", "T_fp"):
            u[:, INPUT_NAMES.index(name)] = record[:, CLOSED_LOOP_CHANNELS.index(name)]
        x0 = PlantConfig().initial_state()
        sim = simulate_inputs(u, x0=x0, sample_time_s=self.track.plant.sample_time_s)
        y = np.asarray(sim.y_clean, dtype=np.float64)
        # The healthy model driven by a faulty record can leave its domain where the faulty
        # plant, under its controllers, did not (actuator seed 5018, valve-stuck: NaN from
        # sample 2537): the reference ends there, as a tripped twin's does, and the rows read
        # no healthy alternative past it (reference_over, FaultSignatures.of). A NaN left in
        # would make every statistic NaN and a limit calibrated on it never alarm.
        finite = np.isfinite(y).all(axis=1)
        return y if finite.all() else y[: int(np.argmin(finite))]

    def describe(self) -> DataDescription:
        t = self.track
        return DataDescription(
            label=(
                f"{fcc_env.CLOSED_LOOP_ENV_ID if t.closed_loop else fcc_env.ENV_ID} "
                f"({fcc_env.MODEL_VERSION}), track {t.name}"
            ),
            lines=(
                t.description,
                f"{t.n_healthy} healthy and {t.n_faulty_total} faulty test episodes (seeds from "
                f"{t.test_seed_start}), training on {t.n_train} healthy episodes (seeds from "
                f"{t.train_seed_start}), {t.n_samples} samples each.",
            ),
            paper_setup=t.name == "paper",
        )
