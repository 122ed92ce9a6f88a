"""Fault requests and resolved faults: :class:`FaultSpec` and :class:`EpisodeFault`.

The faults themselves (the paper's f1–f4 and any registered since) live in the registry of
:mod:`fcc_env.faults` (:data:`FAULTS`, :func:`register_fault`); the names below are re-exported
from there. ``fault_magnitude`` is the size of the relative change and is never negative; its
direction is the fault's (for the paper's: density and holdup up, weir and ratio constants
down).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass
from enum import StrEnum
from typing import Any

import numpy as np

from fcc_common.validation import Integer, Options, Real, check, invalid
from fcc_env.faults import (
    CONCURRENT_SCENARIO,
    FAULTS,
    MAX_FAULT_MAGNITUDE,
    NOMINAL,
    PAPER_FAULTS,
    RANDOM_SCENARIO,
    FaultDefinition,
    Scenario,
    fault_definition,
    fault_names,
    fault_width,
    has_own_unit,
    is_channel_fault,
    register_fault,
    scenario_names,
    unregister_fault,
)
from fcc_env.params import MEASUREMENT_NAMES, PARAM_INDEX, FCCParams

__all__ = [
    "DEFAULT_N_SAMPLES",
    "DEFAULT_RAMP_SAMPLES",
    "ENV_FAULT_KEYWORDS",
    "FAULTS",
    "FAULT_MAGNITUDE_RANGE",
    "MAGNITUDE_SCALE_RANGE",
    "MAX_FAULT_MAGNITUDE",
    "NOMINAL",
    "PAPER_FAULTS",
    "RAMP_SAMPLES_RANGE",
    "RANDOM_SCENARIO",
    "EpisodeFault",
    "FaultDefinition",
    "FaultProfile",
    "FaultSpec",
    "Scenario",
    "fault_channel_options",
    "fault_definition",
    "fault_from_request",
    "fault_names",
    "fault_time_range",
    "fault_width",
    "register_fault",
    "scenario_names",
    "scenario_options",
    "unregister_fault",
]


class FaultProfile(StrEnum):
    ABRUPT = "abrupt"
    INCIPIENT = "incipient"


#: Samples an incipient fault takes to reach its magnitude when ``ramp_samples`` is not given.
DEFAULT_RAMP_SAMPLES = 500
#: Episode length of the paper (4000 samples of 10 s); the env's and the harness's default.
DEFAULT_N_SAMPLES = 4000
#: Allowed ``magnitude_scale`` of :class:`FaultSpec` (a multiplier on the paper's magnitudes).
MAGNITUDE_SCALE_RANGE = Real(0.0, 10.0, closed="right")


#: Allowed ``fault_magnitude`` (the size of the relative change).
FAULT_MAGNITUDE_RANGE = Real(
    0.0, MAX_FAULT_MAGNITUDE, why="a relative change; its sign is fixed by the fault"
)
#: Allowed ``ramp_samples`` of an incipient fault.
RAMP_SAMPLES_RANGE = Integer(1, why="samples an incipient fault takes to reach its magnitude")


def scenario_options() -> Options:
    """Allowed scenario names now: every registered one, ``"random"`` (draws one per
    episode) and ``"concurrent"`` (two of them, :attr:`FaultSpec.parts`)."""
    return Options(
        [*scenario_names(include_path_faults=True), RANDOM_SCENARIO, CONCURRENT_SCENARIO]
    )


def fault_channel_options(scenario: str) -> Options:
    """Allowed ``fault_channel`` of channel fault ``scenario``: its channels (the plant's
    measured ones, :data:`fcc_env.MEASUREMENT_NAMES`)."""
    return Options(FAULTS[scenario].channels, why=f"the measured channels {scenario} acts on")


def _checked_channel(scenario: str, channel: Any) -> str | None:
    """``channel`` of a request for ``scenario``: a channel fault's (``None``: its default),
    refused for any other scenario (the one check)."""
    if is_channel_fault(scenario):
        return check("fault_channel", channel, fault_channel_options(scenario), None)
    if channel is not None:
        channel_faults = [n for n in FAULTS if is_channel_fault(n)]
        raise invalid(
            "fault_channel",
            channel,
            "None",
            f"scenario {scenario!r} acts on no chosen channel; the faults that take one: "
            f"{channel_faults}",
        )
    return None


def fault_time_range(horizon: int | None) -> Integer:
    """Allowed ``fault_time`` for an episode of ``horizon`` samples (``None``: unbounded)."""
    high = math.inf if horizon is None else horizon
    return Integer(0, high, closed="left", why="a sample index inside the episode")


@dataclass(frozen=True)
class EpisodeFault:
    """The fault of one episode, resolved by :meth:`FaultSpec.resolve` (``nominal``: none).

    What the physics reads: which parameter slots the fault scales and by how much per sample,
    and the fault's hooks on the measurement and actuator paths (:mod:`fcc_env.faults`).
    ``scenario`` is the registered name (a ``str``).
    """

    scenario: str
    onset: int = -1  # sample index at which the parameter switches; -1 = never
    magnitude: float = 0.0  # relative change, ≥ 0
    profile: FaultProfile = FaultProfile.ABRUPT
    ramp_samples: int = 0  # incipient: samples to reach the full magnitude
    channel: str | None = None  # a channel fault's measured channel (MEASUREMENT_NAMES)
    #: a concurrent fault's two faults, in onset order (onset and magnitude: the first's)
    parts: tuple[EpisodeFault, ...] = ()

    @property
    def components(self) -> tuple[EpisodeFault, ...]:
        """The single faults acting in the episode: none when nominal, the parts of a
        concurrent fault, else this fault."""
        return () if self.nominal else self.parts or (self,)

    @property
    def labels(self) -> tuple[str, ...]:
        """The names an isolator must give: the scenario, or a concurrent fault's two (in
        onset order; :func:`fcc_env.faults.isolation_outcome`)."""
        return tuple(c.scenario for c in self.components)

    @property
    def channel_index(self) -> int:
        """The position of :attr:`channel` in the Table 1 measurements (a channel fault)."""
        return MEASUREMENT_NAMES.index(str(self.channel))

    @property
    def nominal(self) -> bool:
        return self.scenario == NOMINAL

    @property
    def definition(self) -> FaultDefinition | None:
        """The registered definition (None when nominal or concurrent: see :attr:`parts`)."""
        return None if self.nominal or self.parts else fault_definition(self.scenario)

    @property
    def param_indices(self) -> np.ndarray:
        """The parameter slots the fault scales, ``-1`` where unused: :func:`fault_width` of
        them (the widest registered fault's), so every episode of a batch has as many."""
        if self.parts:  # each part's slots, one after the other
            return np.concatenate([p.param_indices for p in self.parts])
        idx = np.full(fault_width(), -1, dtype=np.int64)
        d = self.definition
        if d is not None:
            for j, name in enumerate(d.parameters):
                idx[j] = PARAM_INDEX[name]
        return idx

    @property
    def final_multiplier(self) -> float:
        d = self.definition
        return 1.0 if d is None else 1.0 + d.direction * self.magnitude

    def faulty_params(self, params: FCCParams) -> FCCParams:
        """``params`` with the fault at its full size (the plant long after the onset)."""
        for p in self.parts:
            params = p.faulty_params(params)
        d = self.definition
        if d is None:
            return params
        m = self.final_multiplier
        return params.replace(**{n: getattr(params, n) * m for n in d.parameters})

    @property
    def ramp(self) -> int:
        return self.ramp_samples if self.profile is FaultProfile.INCIPIENT else 0

    def fraction(self, k: np.ndarray) -> np.ndarray:
        """How far the fault has developed over samples ``k``: 0 before the onset (and when
        nominal), 1 at its full size, reached linearly over ``ramp_samples`` for an incipient
        fault (at sample ``onset + ramp_samples − 1``). What a hook scales its effect by."""
        k = np.asarray(k)
        if self.nominal:
            return np.zeros(k.shape)
        frac = np.minimum(1.0, (k - self.onset + 1) / self.ramp) if self.ramp > 0 else 1.0
        return np.where(k >= self.onset, frac, 0.0)

    def multipliers(self, k: np.ndarray) -> np.ndarray:
        """Multipliers of the fault's parameter slots over samples ``k``: shape
        ``(n, fault_width())``, every slot the same.

        1 before the onset; afterwards the final multiplier, reached as :meth:`fraction`.
        """
        k = np.asarray(k)
        if self.parts:
            return np.concatenate([p.multipliers(k) for p in self.parts], axis=1)
        m = np.ones(k.shape[0])
        if not self.nominal:
            after = k >= self.onset
            m = np.where(after, 1.0 + (self.final_multiplier - 1.0) * self.fraction(k), 1.0)
        return np.repeat(m[:, None], fault_width(), axis=1)

    def active(self, k: int) -> bool:
        return not self.nominal and 0 <= self.onset <= k


#: The env's keyword names for the :class:`FaultSpec` fields (``gym.make`` kwargs, ``reset``
#: options, :func:`fcc_env.simulate_episodes`, the ``generate`` CLI): ``{keyword: field}``.
ENV_FAULT_KEYWORDS: dict[str, str] = {
    "scenario": "scenario",
    "fault_time": "onset",
    "fault_magnitude": "magnitude",
    "fault_profile": "profile",
    "ramp_samples": "ramp_samples",
    "fault_channel": "channel",
}


def _checked_magnitude(scenario: str, magnitude: float) -> float:
    """``magnitude`` of fault ``scenario``, within what the plant carries (the one check)."""
    d = fault_definition(scenario)
    unit = f" ({d.magnitude_unit})" if has_own_unit(scenario) else ""
    why = f"for {scenario}{unit}: {d.max_reason}"
    return check("fault_magnitude", magnitude, Real(0.0, d.max_magnitude, why=why))


@dataclass(frozen=True, kw_only=True)
class FaultSpec:
    """The fault an episode is asked for, before the horizon and any random draw resolve it.

    The one typed fault that the env, :func:`fcc_env.simulate_episodes`, the harness's data
    sources, the tracks and the ``generate`` CLI pass whole; it is validated once, here, on
    construction, and :meth:`resolve` turns it into the :class:`EpisodeFault` of one episode
    (what the physics reads). ``None`` means the fault's own default (the table above, the
    paper's set-up). The env's keywords (``fault_time``, ``fault_magnitude``, ``fault_profile``)
    name the fields ``onset``, ``magnitude``, ``profile`` (:data:`ENV_FAULT_KEYWORDS`); errors use
    the env's names.

    Attributes:
        scenario: ``"nominal"``, a registered fault (:func:`fault_names`: ``"f1"``–``"f4"``
            and any added by :func:`register_fault`) or ``"random"`` (scenario uniform over
            ``nominal`` and the registered faults, onset uniform in the middle half of the
            horizon, magnitude uniform in [0.5, 1.5] × the fault's default; explicit
            ``onset``/``magnitude`` override the draws; the draw leaves out the sensor and
            actuator faults, which ``FCC-control-v0``'s ``catalogue="all"`` draws:
            :mod:`fcc_env.control_draws`), or ``"concurrent"`` (two faults: :attr:`parts`).
        onset: sample at which the fault starts (default: the fault's paper onset).
        magnitude: relative size of the change, ≥ 0 (default: the fault's paper magnitude).
        profile: ``"abrupt"`` (a step) or ``"incipient"`` (a linear ramp).
        ramp_samples: samples an incipient fault takes to reach its magnitude
            (default :data:`DEFAULT_RAMP_SAMPLES`); only with ``profile="incipient"``.
        magnitude_scale: multiplies the magnitude (given or default) of any fault, e.g. 0.7 for
            the validation protocol's smaller faults.
        channel: the measured channel a channel fault acts on (``sensor-bias`` and the other
            sensor faults of :mod:`fcc_env.sensor_faults`: one of
            :data:`fcc_env.MEASUREMENT_NAMES`; ``None``: the fault's default, ``T_rx``); the
            env keyword is ``fault_channel``. Other faults refuse a channel. A channel fault's
            ``magnitude`` is in its own unit (°C for a bias; the definition's
            ``magnitude_unit``).
        parts: ``scenario="concurrent"``'s two faults, each a whole :class:`FaultSpec` of a
            registered fault with its own onset, size, profile and channel (two different
            scenarios); the concurrent spec's own onset, magnitude, profile and ramp stay
            unset, and its ``magnitude_scale`` multiplies both parts'. The episode's
            :class:`EpisodeFault` has the parts in onset order, its onset (and
            ``fault_active``) the first's; its labels for isolation are both names
            (:attr:`EpisodeFault.labels`, :func:`fcc_env.faults.isolation_outcome`). Passed
            whole (``fault=``): the env's keywords have no parts.

    >>> FaultSpec(scenario="f1").resolve(horizon=4000).magnitude
    0.1
    >>> FaultSpec(scenario="f3", magnitude_scale=0.5).resolve(horizon=4000).magnitude
    0.05
    >>> FaultSpec(scenario="f1", magnitude=0.5)
    Traceback (most recent call last):
    ...
    ValueError: fault_magnitude=0.5 is outside the allowed range: a number in [0, 0.13] (for f1: ...)
    """

    scenario: str = NOMINAL
    onset: int | None = None
    magnitude: float | None = None
    profile: FaultProfile = FaultProfile.ABRUPT
    ramp_samples: int | None = None
    magnitude_scale: float = 1.0
    channel: str | None = None
    parts: tuple[FaultSpec, ...] = ()

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        set_(self, "scenario", str(check("scenario", self.scenario, scenario_options())))
        set_(self, "onset", check("fault_time", self.onset, fault_time_range(None), None))
        # a channel fault's magnitude has its own unit and range (checked below)
        size_range = Real(0.0) if has_own_unit(self.scenario) else FAULT_MAGNITUDE_RANGE
        set_(self, "magnitude", check("fault_magnitude", self.magnitude, size_range, None))
        set_(self, "channel", _checked_channel(self.scenario, self.channel))
        set_(self, "profile", check("fault_profile", self.profile, Options(FaultProfile)))
        set_(
            self, "ramp_samples", check("ramp_samples", self.ramp_samples, RAMP_SAMPLES_RANGE, None)
        )
        if self.ramp_samples is not None and self.profile is not FaultProfile.INCIPIENT:
            raise ValueError(
                f"ramp_samples={self.ramp_samples!r} only applies to fault_profile='incipient'"
            )
        set_(
            self,
            "magnitude_scale",
            check("magnitude_scale", self.magnitude_scale, MAGNITUDE_SCALE_RANGE),
        )
        if self.scenario in FAULTS:  # a fixed fault: its size is known now (a drawn one later)
            _checked_magnitude(self.scenario, self._scaled(self.scenario, self.magnitude))
        set_(self, "parts", _checked_parts(self))

    def with_env_options(self, options: Mapping[str, Any]) -> FaultSpec:
        """This spec with the env's keywords (:data:`ENV_FAULT_KEYWORDS`) applied; ``None``
        gives a field its default. The one bridge from the env's keyword surface:
        ``FaultSpec().with_env_options(make_kwargs)``, and ``reset(options=...)`` over the
        ``make`` fault.

        >>> FaultSpec().with_env_options({"scenario": "f2", "fault_time": 100}).onset
        100
        """
        unknown = sorted(set(options) - set(ENV_FAULT_KEYWORDS))
        if unknown:
            raise ValueError(
                f"Unknown fault option(s) {unknown}. Allowed: {list(ENV_FAULT_KEYWORDS)}"
            )
        if not options:
            return self
        defaults = {f.name: f.default for f in dataclasses.fields(self)}
        changes = {}
        for opt, value in options.items():
            name = ENV_FAULT_KEYWORDS[opt]
            changes[name] = defaults[name] if value is None else value
        scenario = changes.get("scenario", self.scenario)
        if not is_channel_fault(scenario):
            changes["channel"] = None  # a channel stays with the channel fault it was given for
        if scenario != CONCURRENT_SCENARIO:
            changes["parts"] = ()  # and the parts with the concurrent fault
        return self.replace(**changes)

    def replace(self, **changes: Any) -> FaultSpec:
        return dataclasses.replace(self, **changes)

    def to_json(self) -> dict[str, Any]:
        out = {
            "scenario": self.scenario,
            "onset": self.onset,
            "magnitude": self.magnitude,
            "profile": self.profile.value,
            "ramp_samples": self.ramp_samples,
            "magnitude_scale": self.magnitude_scale,
        }
        if self.channel is not None:  # only then: the store keys of the other faults stay
            out["channel"] = self.channel
        if self.parts:
            out["parts"] = [p.to_json() for p in self.parts]
        return out

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> FaultSpec:
        """The spec :meth:`to_json` wrote."""
        parts = tuple(cls.from_json(p) for p in data.get("parts", ()))
        return cls(
            **{**data, "profile": FaultProfile(data.get("profile", "abrupt")), "parts": parts}
        )

    def _scaled_part(self, part: FaultSpec) -> FaultSpec:
        """A concurrent fault's ``part`` with this spec's ``magnitude_scale`` applied too."""
        if self.magnitude_scale == 1.0:
            return part
        return part.replace(magnitude_scale=part.magnitude_scale * self.magnitude_scale)

    def _scaled(self, scenario: str, magnitude: float | None) -> float:
        """The magnitude of fault ``scenario`` (``None``: its default) × ``magnitude_scale``."""
        base = fault_definition(scenario).default_magnitude if magnitude is None else magnitude
        # unscaled values pass untouched, so a magnitude given is the magnitude simulated
        return base if self.magnitude_scale == 1.0 else base * self.magnitude_scale

    def resolve(self, horizon: int, rng: np.random.Generator | None = None) -> EpisodeFault:
        """The fault of one episode of ``horizon`` samples; ``rng`` draws a random scenario.

        The random draws always consume the same numbers of ``rng``, so the rest of the episode
        does not depend on them. Only what depends on the horizon or the draw is checked here
        (the onset inside the episode, a drawn fault's size); errors name the value and the range.
        """
        sc, onset, magnitude = self.scenario, self.onset, self.magnitude
        if sc == CONCURRENT_SCENARIO:
            parts = sorted(
                (self._scaled_part(p).resolve(horizon, rng) for p in self.parts),
                key=lambda f: f.onset,
            )
            first = parts[0]
            return EpisodeFault(sc, first.onset, first.magnitude, parts=tuple(parts))
        drawn = sc == RANDOM_SCENARIO
        if drawn:
            if rng is None:
                raise ValueError("scenario='random' needs a random generator to draw from")
            names = scenario_names()  # read now: a fault registered since is drawn too
            sc = names[int(rng.integers(len(names)))]
            drawn_onset = int(rng.integers(horizon // 4, max(horizon // 4 + 1, 3 * horizon // 4)))
            scale = float(rng.uniform(0.5, 1.5))
            if sc != NOMINAL:
                onset = drawn_onset if onset is None else onset
                if magnitude is None:
                    # clipped at what the plant carries (f1 above +13 % empties the well)
                    d = fault_definition(sc)
                    magnitude = min(d.default_magnitude * scale, d.max_magnitude)
        if sc == NOMINAL:
            return EpisodeFault(NOMINAL)
        onset = fault_definition(sc).default_onset if onset is None else onset
        onset = check("fault_time", onset, fault_time_range(horizon))
        magnitude = self._scaled(sc, magnitude)
        if drawn:
            magnitude = _checked_magnitude(sc, magnitude)
        ramp = 0
        if self.profile is FaultProfile.INCIPIENT:
            ramp = DEFAULT_RAMP_SAMPLES if self.ramp_samples is None else self.ramp_samples
        channel = None
        if is_channel_fault(sc):
            channel = self.channel or fault_definition(sc).default_channel
        return EpisodeFault(sc, onset, magnitude, self.profile, ramp, channel)


def _checked_parts(spec: FaultSpec) -> tuple[FaultSpec, ...]:
    """The parts of ``spec``: two distinct registered faults for ``concurrent`` (whose own
    fields stay at their defaults: each part carries its onset and size), none otherwise."""
    parts = spec.parts
    if spec.scenario != CONCURRENT_SCENARIO:
        if parts:
            raise invalid(
                "parts", parts, "() (empty)", f"only scenario={CONCURRENT_SCENARIO!r} has parts"
            )
        return ()
    example = (
        "e.g. FaultSpec(scenario='concurrent', parts=(FaultSpec(scenario='sensor-bias', "
        "onset=1500), FaultSpec(scenario='valve-stiction', onset=2500)))"
    )
    if isinstance(parts, FaultSpec) or not isinstance(parts, tuple | list) or len(parts) != 2:
        raise invalid("parts", parts, "a tuple of two FaultSpec of registered faults", example)
    names = fault_names(include_path_faults=True)
    for p in parts:
        if not isinstance(p, FaultSpec):
            raise invalid("parts", p, "a FaultSpec of a registered fault", example)
        check("parts scenario", p.scenario, Options(names, why="a concurrent fault's part"))
    if parts[0].scenario == parts[1].scenario:
        raise invalid(
            "parts",
            [p.scenario for p in parts],
            "two different faults",
            "an isolator names both, so two faults of one kind would be one label",
        )
    given = [
        name
        for name, value in (
            ("fault_time", spec.onset),
            ("fault_magnitude", spec.magnitude),
            ("ramp_samples", spec.ramp_samples),
        )
        if value is not None
    ]
    if spec.profile is not FaultProfile.ABRUPT:
        given.append("fault_profile")
    if given:
        raise ValueError(
            f"scenario='concurrent' takes {given} from its parts: set them on each part's "
            f"FaultSpec ({example})"
        )
    for p in parts:
        spec._scaled_part(p)  # magnitude_scale applies to each part: checked there
    return tuple(parts)


def fault_from_request(fault: FaultSpec | None, keywords: Mapping[str, Any]) -> FaultSpec:
    """``fault``, or the fault of the env's ``keywords`` (:data:`ENV_FAULT_KEYWORDS`; ``None`` =
    not given); both at once raise, so a stale keyword never silently loses or wins."""
    given = {k: v for k, v in keywords.items() if v is not None}
    if fault is None:
        return FaultSpec().with_env_options(given)
    if not isinstance(fault, FaultSpec):
        raise invalid("fault", fault, "a FaultSpec or None")
    if given:
        raise ValueError(
            f"fault={fault!r} and the fault keyword(s) {sorted(given)} were both given: pass the "
            f"fault either as fault=FaultSpec(...) or as the keywords {list(ENV_FAULT_KEYWORDS)}, "
            "not both"
        )
    return fault
