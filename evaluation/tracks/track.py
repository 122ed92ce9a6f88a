"""Benchmark tracks: typed, validated definitions of what a leaderboard column is scored on.

A :class:`Track` fixes everything that defines the test episodes of one benchmark question: which
faults, how large, when, how they develop (abrupt step or incipient ramp), the measurement noise,
whether the plant parameters vary per episode, how many episodes and which seeds. The harness
asks the track for its cells (:meth:`Track.test_cells`) and, per cell, for the fault to simulate
(:meth:`Track.fault_spec`, a :class:`fcc_env.scenarios.FaultSpec` with every field explicit). The
draw of plant parameters (``plant_variation``) and the noise itself are implemented by the env.

Seeds (module constants; one range per use so no episode serves two purposes):

* test: ``TEST_SEED_START`` + 0, 1, ... (healthy seeds 0..n_healthy−1 and faulty seeds
  0..n_faulty−1 of every fault: the paired design of the paper leaderboard, where the healthy
  and the faulty episode of a seed share excitation and noise);
* training (healthy, for fitting): ``TRAIN_SEED_START`` = 1000 + 0, 1, ...;
* validation (for tuning thresholds and hyperparameters): ``VALIDATION_SEED_START`` = 5000 + ....

The three ranges may not overlap. To keep a test range of your own that no tuning loop has seen,
move it: ``TRACKS["paper"].with_seeds(test=100_000)`` (or ``dataclasses.replace``); the seeds are
part of :meth:`Track.to_json`, so results on the private range are stored apart.

The distributions a track draws from live in :mod:`evaluation.tracks.distributions`, the
published tracks in :mod:`evaluation.tracks.catalogue`.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import re
import zlib
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from evaluation.tracks.distributions import (
    Choice,
    Distribution,
    Fixed,
    Uniform,
    check_distribution,
)
from evaluation.tracks.fault_templates import FaultTemplate
from fcc_common.validation import Boolean, Integer, Options, Real, check, invalid
from fcc_env.plant import PlantConfig
from fcc_env.scenarios import (
    DEFAULT_N_SAMPLES,
    MAX_FAULT_MAGNITUDE,
    NOMINAL,
    PAPER_FAULTS,
    FaultProfile,
    FaultSpec,
    fault_definition,
    fault_names,
)
from fcc_env.uncertainty import PlantMismatch, PlantUncertainty

__all__ = [
    "MIN_HEALTHY",
    "RAMP_LENGTHS",
    "RAMP_MARGIN",
    "TEST_SEED_START",
    "TRACKS_VERSION",
    "TRAIN_SEED_START",
    "VALIDATION_SEED_START",
    "Track",
    "stable_hash",
]

#: First test seed: healthy and faulty test episodes use seeds 0, 1, ... (paired design).
TEST_SEED_START = 0
#: First healthy training seed (far from any realistic test range; the harness's default too).
TRAIN_SEED_START = 1000
#: First validation seed (threshold and hyperparameter tuning).
VALIDATION_SEED_START = 5000
#: Ramp lengths [samples] an incipient fault is drawn among (up to half the 4000-sample episode).
RAMP_LENGTHS: tuple[int, ...] = (500, 1000, 1500, 2000)
#: Samples that must remain after a ramp completes (and after an abrupt onset), so that the full
#: fault is seen long enough for r_td and t_dt to mean something: onset + ramp <= n_samples − 200.
RAMP_MARGIN = 200
#: Bumped when the meaning of a track's fields changes (part of :meth:`Track.to_json`).
TRACKS_VERSION = 1
#: The healthy-episode count of the published tracks. A small r_fd needs many episodes: an
#: episode's alarms come in streaks, so the per-episode rates are heavy-tailed. On 400 healthy
#: validation episodes of ``lrgf-glr`` (realised rate 0.0054), the upper end of the 95 % interval
#: over blocks of 50 episodes ranged 0.0054-0.0113, over blocks of 200 0.0059-0.0071: with 50, an
#: interval cannot tell a detector at 0.005 from one at 0.01 (``lab/fd_tail_lab.py``).
MIN_HEALTHY = 200

_NAME = re.compile(r"[a-z][a-z0-9_-]*\Z")


def stable_hash(text: str) -> int:
    """A 32-bit hash of ``text`` that is the same in every process (unlike :func:`hash`).

    >>> stable_hash("paper")
    1310351382
    """
    return zlib.crc32(text.encode("utf-8"))


# ---- the track ---------------------------------------------------------------------------------
@dataclass(frozen=True, kw_only=True)
class Track:
    """One benchmark track (keyword-only, validated on construction; errors name value and range).

    Attributes:
        name: lowercase identifier (letters, digits, ``-``, ``_``).
        description: what the track tests and why (feeds the documentation's track catalogue).
        faults: fault scenarios of the track, registered faults (:func:`fcc_env.fault_names`,
            read when the track is built); default the paper's f1–f4
            (:data:`fcc_env.PAPER_FAULTS`).
        magnitudes: per fault, the distribution of the magnitude as an absolute relative change
            (0.1 = 10 %); ``None`` takes each fault's default magnitude (the paper's for f1–f4,
            :data:`fcc_env.FAULTS`).
            Stored as sorted ``(fault, distribution)`` pairs (hashable); read with
            :meth:`magnitude`.
        onset: onset sample distribution; ``None`` takes each fault's default onset.
        profiles: the profiles an episode is drawn among (one: fixed).
        ramp: ramp-length distribution [samples] of incipient faults (:class:`Fixed` or
            :class:`Choice`); ``None`` means :data:`RAMP_LENGTHS` when a profile is incipient.
            Per episode the ramp is drawn among the lengths that complete by
            ``n_samples − RAMP_MARGIN`` after the drawn onset (at least one always does).
        draw_fault: the fault type of each faulty test episode is drawn per seed (``random``).
        noise_scale: multiplier on the measurement noise, for training and test alike.
        plant_variation: each episode draws its plant parameters (drawn by the env).
        plant_mismatch: each episode's plant carries undeclared effects of the library
            (:class:`fcc_env.uncertainty.PlantMismatch`: heat losses, a thermocouple lag,
            catalyst deactivation), drawn by the env; not together with ``plant_variation``.
        closed_loop: the plant runs under its regulatory layer (``FCC-closedloop-v0``,
            :class:`fcc_env.RegulatoryLayer`): episodes have 11 channels (Table 1, the valve
            command, the set points). Not together with ``plant_variation`` (the closed-loop
            reference rows replay a declared plant).
        n_samples: episode length [samples].
        n_healthy: healthy test episodes (the published tracks use at least :data:`MIN_HEALTHY`).
        n_faulty: faulty test episodes per fault.
        n_train: healthy training episodes (default 9: the protocol on which ``lrgf-mem`` and
            ``lrgf-glr`` were validated, 6 to train and 3 to calibrate, or 3 cross-fitted folds;
            it also keeps a run of every track within the benchmark's time budget).
        n_train_faults: labelled faulty training episodes per fault, for diagnosers that isolate
            (seeds from ``train_seed_start``; 20: the setting the isolators were validated on).
        n_validation: validation episodes (per scenario, healthy and each fault).
        test_setpoint_halfranges: closed loop only: the half-ranges ``(T_rx, T_rg1)`` [°C] of
            the set-point program of the *test* episodes, where they differ from the training
            program's (:class:`fcc_env.regulatory.SetpointProgram`); ``None`` (default): the
            test episodes run the training program. Training (and validation) episodes always
            run :attr:`plant`'s program: an operator moves set points wider than any history a
            detector learned from (:attr:`test_plant`).
        test_seed_start, train_seed_start, validation_seed_start: first seed of each range.
        fault_templates: the track's faults as spec templates
            (:class:`~evaluation.tracks.fault_templates.FaultTemplate`: scenario, size, onset and
            channel distributions, or two faults at once), for faults that ``faults`` and
            ``magnitudes`` cannot say (a channel, a size in a unit of its own, a pair). When
            given, ``faults`` becomes their names and ``magnitudes`` stays ``None``; a
            template's onset ``None`` takes ``onset``. Empty (the default) for the paper-fault
            tracks, whose definitions and store keys it leaves as they were.
    """

    name: str
    description: str
    faults: tuple[str, ...] = PAPER_FAULTS
    magnitudes: Mapping[str, Distribution] | tuple[tuple[str, Distribution], ...] | None = None
    onset: Distribution | None = None
    profiles: tuple[FaultProfile, ...] = (FaultProfile.ABRUPT,)
    ramp: Fixed | Choice | None = None
    draw_fault: bool = False
    noise_scale: float = 1.0
    plant_variation: bool = False
    plant_mismatch: bool = False
    closed_loop: bool = False
    n_samples: int = DEFAULT_N_SAMPLES
    n_healthy: int = MIN_HEALTHY
    n_faulty: int = 20
    n_train: int = 9
    n_train_faults: int = 20
    n_validation: int = 20
    test_seed_start: int = TEST_SEED_START
    train_seed_start: int = TRAIN_SEED_START
    validation_seed_start: int = VALIDATION_SEED_START
    test_setpoint_halfranges: tuple[float, float] | None = None
    fault_templates: tuple[FaultTemplate, ...] = ()

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        if not isinstance(self.name, str) or not _NAME.match(self.name):
            raise invalid("name", self.name, "a lowercase name of letters, digits, '-' or '_'")
        if not isinstance(self.description, str) or not self.description.strip():
            raise invalid("description", self.description, "a non-empty string")
        if self.fault_templates:
            _set_templates(self)
        faults, registered = self.faults, fault_names()
        if self.fault_templates:
            registered = faults
        if isinstance(faults, str) or not isinstance(faults, tuple | list) or not faults:
            raise invalid("faults", faults, f"a non-empty tuple of {list(registered)}")
        faults = tuple(str(check("faults", f, Options(registered))) for f in faults)
        if len(set(faults)) != len(faults):
            raise invalid("faults", faults, f"distinct faults of {list(registered)}")
        set_(self, "faults", faults)
        for int_field, low in [
            ("n_samples", 2 * RAMP_MARGIN),
            ("n_healthy", 1),
            ("n_faulty", 1),
            ("n_train", 1),
            ("n_train_faults", 1),
            ("n_validation", 1),
            ("test_seed_start", 0),
            ("train_seed_start", 0),
            ("validation_seed_start", 0),
        ]:
            set_(self, int_field, check(int_field, getattr(self, int_field), Integer(low)))
        set_(
            self,
            "noise_scale",
            check("noise_scale", self.noise_scale, Real(0.0, 100.0, closed="right")),
        )
        set_(self, "plant_variation", check("plant_variation", self.plant_variation, Boolean()))
        set_(self, "plant_mismatch", check("plant_mismatch", self.plant_mismatch, Boolean()))
        if self.plant_mismatch and (self.plant_variation or self.closed_loop):
            raise invalid(
                "plant_mismatch",
                True,
                "False with plant_variation or closed_loop",
                "a plant draws either its parameters or undeclared effects, in open loop",
            )
        set_(self, "draw_fault", check("draw_fault", self.draw_fault, Boolean()))
        set_(self, "closed_loop", check("closed_loop", self.closed_loop, Boolean()))
        if self.closed_loop and self.plant_variation:
            raise invalid(
                "plant_variation",
                True,
                "False on a closed-loop track",
                "the closed-loop reference rows replay the declared plant; drawn plants are "
                "not built for closed loop",
            )
        if not self.fault_templates:
            set_(self, "magnitudes", _checked_magnitudes(self.magnitudes, self.faults))
        _check_test_program(self)
        last_onset = self.n_samples - RAMP_MARGIN
        if self.onset is not None:
            check_distribution(
                "onset", self.onset, 1, last_onset, f"{RAMP_MARGIN} samples must follow"
            )
            if isinstance(self.onset, Uniform) and math.ceil(self.onset.low) > self.onset.high:
                raise invalid("onset", self.onset, "a range holding an integer sample")
        if self.fault_templates and self._latest_onset() > last_onset:
            raise invalid(
                "fault_templates onset",
                self._latest_onset(),
                f"at most {last_onset}",
                f"{RAMP_MARGIN} samples must follow",
            )
        profiles = self.profiles
        if isinstance(profiles, str) or not isinstance(profiles, tuple | list) or not profiles:
            raise invalid("profiles", profiles, f"a non-empty tuple of {list(FaultProfile)}")
        profiles = tuple(check("profiles", p, Options(FaultProfile)) for p in profiles)
        if len(set(profiles)) != len(profiles):
            raise invalid("profiles", profiles, "distinct profiles")
        set_(self, "profiles", profiles)
        self._check_ramp()
        _check_seed_ranges(self)

    def template(self, fault: str) -> FaultTemplate:
        """The template of column ``fault`` of a track with ``fault_templates``."""
        by_name = {t.name: t for t in self.fault_templates}
        return by_name[str(check("fault", fault, Options(list(by_name))))]

    def labels(self, fault: str) -> tuple[str, ...]:
        """The fault names an isolator must give for an episode of column ``fault`` (two
        for a concurrent column: :func:`fcc_env.faults.isolation_outcome`)."""
        if self.fault_templates:
            return self.template(fault).labels
        return (str(check("fault", fault, Options(self.faults))),)

    def _check_ramp(self) -> None:
        incipient = FaultProfile.INCIPIENT in self.profiles
        if not incipient:
            if self.ramp is not None:
                raise invalid(
                    "ramp", self.ramp, "None", "a ramp needs 'incipient' among the profiles"
                )
            return
        ramp = Choice(RAMP_LENGTHS) if self.ramp is None else self.ramp
        if not isinstance(ramp, Fixed | Choice):
            raise invalid("ramp", ramp, "a Fixed or Choice distribution of sample counts")
        for v in (ramp.low, ramp.high) if isinstance(ramp, Fixed) else ramp.values:
            check("ramp", v, Integer(1))
        latest = self._latest_onset()
        room = self.n_samples - RAMP_MARGIN - latest
        if ramp.low > room:
            raise invalid(
                "ramp",
                ramp,
                f"a length <= {room} samples",
                f"the latest onset {latest} plus the ramp must end by "
                f"n_samples - {RAMP_MARGIN} = {self.n_samples - RAMP_MARGIN}",
            )
        object.__setattr__(self, "ramp", ramp)

    def _latest_onset(self) -> int:
        if self.fault_templates:
            return max(t.latest_onset(self.onset) for t in self.fault_templates)
        if self.onset is not None:
            return math.floor(self.onset.high)
        return max(fault_definition(f).default_onset for f in self.faults)

    # ---- seeds ---------------------------------------------------------------------------------
    @property
    def n_faulty_total(self) -> int:
        """Faulty test episodes over all faults."""
        return self.n_faulty * len(self.faults)

    @property
    def test_seeds(self) -> range:
        """Test seeds: healthy episodes use the first ``n_healthy``, each fault the first
        ``n_faulty`` (with ``draw_fault``, the first ``n_faulty_total``)."""
        n = max(self.n_healthy, self.n_faulty_total if self.draw_fault else self.n_faulty)
        return range(self.test_seed_start, self.test_seed_start + n)

    @property
    def train_seeds(self) -> range:
        return range(self.train_seed_start, self.train_seed_start + self.n_train)

    @property
    def plant(self) -> PlantConfig:
        """The track's plant, whole: the paper's, with the track's noise scale, under the
        default regulatory layer on a closed-loop track (what every episode of the track runs
        on; :meth:`fcc_env.PlantConfig.to_json` is in its store keys)."""
        return PlantConfig.build(
            noise_scale=self.noise_scale, regulatory=True if self.closed_loop else None
        )

    @property
    def test_plant(self) -> PlantConfig:
        """The plant of the test episodes: :attr:`plant`, its set-point program widened to
        ``test_setpoint_halfranges`` where that is set (equal to it otherwise)."""
        plant = self.plant
        if self.test_setpoint_halfranges is None:
            return plant
        layer = plant.regulatory
        assert layer is not None and layer.program is not None  # closed loop (checked)
        t_rx, t_rg1 = self.test_setpoint_halfranges
        program = dataclasses.replace(
            layer.program, T_rx_sp_halfrange_C=t_rx, T_rg1_sp_halfrange_C=t_rg1
        )
        return dataclasses.replace(plant, regulatory=layer.replace(program=program))

    @property
    def plant_draw(self) -> PlantUncertainty | PlantMismatch | None:
        """Each episode's plant drawn by its seed (``plant_variation``, ``plant_mismatch``), or
        ``None``."""
        if self.plant_mismatch:
            return PlantMismatch()
        return PlantUncertainty() if self.plant_variation else None

    @property
    def train_fault_seeds(self) -> range:
        """Seeds of the labelled faulty training episodes (training seeds too)."""
        return range(self.train_seed_start, self.train_seed_start + self.n_train_faults)

    @property
    def validation_seeds(self) -> range:
        n = self.n_validation * (len(self.faults) if self.draw_fault else 1)
        return range(self.validation_seed_start, self.validation_seed_start + n)

    def with_seeds(
        self, *, test: int | None = None, train: int | None = None, validation: int | None = None
    ) -> Track:
        """A copy whose seed ranges start elsewhere, e.g. a private test range held out from
        every tuning loop: ``track.with_seeds(test=100_000)``."""
        changes = {
            f"{k}_seed_start": v
            for k, v in (("test", test), ("train", train), ("validation", validation))
            if v is not None
        }
        return dataclasses.replace(self, **changes)

    def replace(self, **changes: Any) -> Track:
        """A validated copy with ``changes`` (e.g. ``n_healthy=2`` for a smoke run)."""
        return dataclasses.replace(self, **changes)

    # ---- draws ---------------------------------------------------------------------------------
    def magnitude(self, fault: str) -> Distribution:
        """The magnitude distribution of ``fault`` (a template's: :meth:`template`)."""
        fault = check("fault", fault, Options(self.faults))
        if self.fault_templates:
            raise invalid(
                "fault",
                fault,
                "a fault of a track without fault_templates",
                "read template(fault).magnitude",
            )
        return dict(self.magnitudes)[fault]  # type: ignore[arg-type]

    def _streams(self, seed: int, key: str, n: int) -> list[np.random.Generator]:
        # One generator per (seed, track, key), independent of the episode's own seed use
        # (excitation, noise) and split into one child stream per drawn field, so that changing
        # how one field is drawn never shifts the draws of the others.
        root = np.random.SeedSequence([seed, stable_hash(self.name), stable_hash(key)])
        return [np.random.default_rng(s) for s in root.spawn(n)]

    def fault_spec(self, scenario: str, seed: int) -> FaultSpec:
        """The fault of test (or validation) episode ``(scenario, seed)``, every field explicit.

        Deterministic in (track name, scenario, seed) and independent of call order. ``nominal``
        gives the healthy spec.
        """
        scenario = str(check("scenario", scenario, Options([NOMINAL, *self.faults])))
        seed = check("seed", seed, Integer(0))
        if scenario == NOMINAL:
            return FaultSpec(scenario=scenario)
        if self.fault_templates:
            return self.template(scenario).draw(
                lambda key, n: self._streams(seed, key, n), self._profile_and_ramp, self.onset
            )
        g_mag, g_onset, g_profile, g_ramp = self._streams(seed, scenario, 4)
        magnitude = self.magnitude(scenario).sample(g_mag)
        onset = (
            fault_definition(scenario).default_onset
            if self.onset is None
            else self.onset.sample_int(g_onset)
        )
        profile = self.profiles[int(g_profile.integers(len(self.profiles)))]
        ramp = None
        if profile is FaultProfile.INCIPIENT:
            room = self.n_samples - RAMP_MARGIN - onset
            dist = self.ramp.at_most(room) if isinstance(self.ramp, Choice) else self.ramp
            assert dist is not None  # _check_ramp set it
            ramp = dist.sample_int(g_ramp)
        return FaultSpec(
            scenario=scenario,
            onset=onset,
            magnitude=magnitude,
            profile=profile,
            ramp_samples=ramp,
        )

    def _profile_and_ramp(
        self, g_profile: np.random.Generator, g_ramp: np.random.Generator, onset: int
    ) -> tuple[FaultProfile, int | None]:
        """A template fault's profile and ramp, drawn as :meth:`fault_spec` draws them."""
        profile = self.profiles[int(g_profile.integers(len(self.profiles)))]
        if profile is not FaultProfile.INCIPIENT:
            return profile, None
        room = self.n_samples - RAMP_MARGIN - onset
        dist = self.ramp.at_most(room) if isinstance(self.ramp, Choice) else self.ramp
        assert dist is not None  # _check_ramp set it
        return profile, dist.sample_int(g_ramp)

    def drawn_fault(self, seed: int) -> str:
        """The fault type of faulty episode ``seed`` of a ``draw_fault`` track (uniform)."""
        seed = check("seed", seed, Integer(0))
        (g,) = self._streams(seed, "fault-type", 1)
        return self.faults[int(g.integers(len(self.faults)))]

    def test_cells(self) -> list[tuple[str, int]]:
        """Test episodes as ``(scenario, seed)``: healthy first, then faulty, fault by fault.

        With ``draw_fault`` the faulty seeds are ``0..n_faulty_total − 1`` (offset by
        ``test_seed_start``) and each cell names the fault drawn for its seed.
        """
        s0 = self.test_seed_start
        cells = [(NOMINAL, s0 + i) for i in range(self.n_healthy)]
        if self.draw_fault:
            seeds = range(s0, s0 + self.n_faulty_total)
            return cells + [(self.drawn_fault(s), s) for s in seeds]
        for f in self.faults:
            cells += [(f, s0 + i) for i in range(self.n_faulty)]
        return cells

    # ---- serialisation -------------------------------------------------------------------------
    def to_json(self) -> dict[str, Any]:
        """Everything that defines the track's data (hashed into the result store)."""
        return {
            "version": TRACKS_VERSION,
            "name": self.name,
            "description": self.description,
            "faults": list(self.faults),
            "magnitudes": {f: d.to_json() for f, d in self.magnitudes},  # type: ignore[union-attr]
            "onset": "paper" if self.onset is None else self.onset.to_json(),
            "profiles": [p.value for p in self.profiles],
            "ramp": None if self.ramp is None else self.ramp.to_json(),
            "draw_fault": self.draw_fault,
            "noise_scale": self.noise_scale,
            "plant_variation": self.plant_variation,
            **({"plant_mismatch": True} if self.plant_mismatch else {}),
            # only when set, so that the open-loop tracks' store keys stay as they were
            **({"closed_loop": True} if self.closed_loop else {}),
            "n_samples": self.n_samples,
            "n_healthy": self.n_healthy,
            "n_faulty": self.n_faulty,
            "n_train": self.n_train,
            "n_train_faults": self.n_train_faults,
            "n_validation": self.n_validation,
            "test_seed_start": self.test_seed_start,
            "train_seed_start": self.train_seed_start,
            "validation_seed_start": self.validation_seed_start,
            # only when set, so that every other track's store keys stay as they were
            **(
                {"test_setpoint_halfranges": list(self.test_setpoint_halfranges)}
                if self.test_setpoint_halfranges is not None
                else {}
            ),
            # only when set, so that the paper-fault tracks' store keys stay as they were
            **(
                {"fault_templates": [t.to_json() for t in self.fault_templates]}
                if self.fault_templates
                else {}
            ),
        }

    def digest(self) -> str:
        """SHA-256 of the canonical JSON of :meth:`to_json`."""
        text = json.dumps(self.to_json(), sort_keys=True, separators=(",", ":"))
        return hashlib.sha256(text.encode()).hexdigest()


def _checked_magnitudes(
    given: Any, faults: tuple[str, ...]
) -> tuple[tuple[str, Distribution], ...]:
    """``magnitudes`` of a track as sorted ``(fault, distribution)`` pairs, one per fault."""
    if given is None:
        given = {f: Fixed(fault_definition(f).default_magnitude) for f in faults}
    if isinstance(given, tuple):
        given = dict(given)
    if not isinstance(given, Mapping):
        raise invalid("magnitudes", given, "a mapping fault -> distribution, or None")
    if set(given) != set(faults):
        raise invalid(
            "magnitudes",
            sorted(given),
            f"one distribution for each fault of the track {sorted(faults)}",
        )
    return tuple(
        (
            f,
            check_distribution(
                f"magnitudes[{f!r}]", given[f], 0.0, MAX_FAULT_MAGNITUDE, "a relative change"
            ),
        )
        for f in sorted(given)
    )


def _check_test_program(track: Track) -> None:
    given = track.test_setpoint_halfranges
    if given is None:
        return
    if not track.closed_loop:
        raise invalid(
            "test_setpoint_halfranges", given, "None on an open-loop track", "no set points"
        )
    if isinstance(given, str) or not isinstance(given, tuple | list) or len(given) != 2:
        raise invalid("test_setpoint_halfranges", given, "a pair (T_rx, T_rg1) of °C")
    limits = (("T_rx_sp_halfrange_C", 10.0), ("T_rg1_sp_halfrange_C", 15.0))
    pair = tuple(
        float(check(name, v, Real(0.0, high, unit="°C")))
        for (name, high), v in zip(limits, given, strict=True)
    )
    object.__setattr__(track, "test_setpoint_halfranges", pair)


def _set_templates(track: Track) -> None:
    """``fault_templates`` checked; ``faults`` their names (module docstring)."""
    given = track.fault_templates
    if not isinstance(given, tuple | list) or not all(isinstance(t, FaultTemplate) for t in given):
        raise invalid("fault_templates", given, "a tuple of FaultTemplate")
    names = tuple(t.name for t in given)
    if track.faults not in (PAPER_FAULTS, names):
        raise invalid("faults", track.faults, f"{names}: the templates' names, or unset")
    if track.magnitudes not in (None, ()):
        raise invalid("magnitudes", track.magnitudes, "None", "the templates carry the sizes")
    needs_loop = sorted({s for t in given for s in t.definitions_needing_loop})
    if needs_loop and not track.closed_loop:
        raise invalid(
            "closed_loop",
            False,
            "True",
            f"{needs_loop} only act while a controller moves the valve",
        )
    object.__setattr__(track, "fault_templates", tuple(given))
    object.__setattr__(track, "faults", names)
    object.__setattr__(track, "magnitudes", ())


def _check_seed_ranges(track: Track) -> None:
    """``ValueError`` unless the track's test, training and validation seeds are disjoint."""
    ranges = {
        "test": track.test_seeds,
        "train": range(
            track.train_seed_start,
            track.train_seed_start + max(track.n_train, track.n_train_faults),
        ),
        "validation": track.validation_seeds,
    }
    names = list(ranges)
    for i, a in enumerate(names):
        for b in names[i + 1 :]:
            ra, rb = ranges[a], ranges[b]
            lo, hi = max(ra.start, rb.start), min(ra.stop, rb.stop)
            if lo < hi:
                raise invalid(
                    f"{b}_seed_start",
                    getattr(track, f"{b}_seed_start"),
                    f"a start whose seeds {rb.start}..{rb.stop - 1} avoid the {a} seeds "
                    f"{ra.start}..{ra.stop - 1}",
                    f"seeds {lo}..{hi - 1} would be both {a} and {b} seeds",
                )
