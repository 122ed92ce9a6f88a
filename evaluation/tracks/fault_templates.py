"""A track's fault as a :class:`~fcc_env.scenarios.FaultSpec` template (:class:`FaultTemplate`).

The paper's tracks name catalogue faults and bound their sizes as relative parameter changes
(:attr:`Track.faults <evaluation.tracks.track.Track.faults>`, ``magnitudes``). The closed-loop
faults of issue 43 need more: a sensor fault has a channel, an actuator fault's size has a unit
of its own, and a concurrent fault is two faults, each with its own onset. A
:class:`FaultTemplate` is the spec of one column of a track with a distribution in place of
each value the seed draws: the scenario, the size, the onset and (for a channel fault) the
channel, or, for ``scenario="concurrent"``, two part templates. The column's name is the
scenario (``sensor-bias``), or ``a+b`` for two faults at once (``sensor-bias+valve-stiction``),
unless given.

Sizes are checked against the registered fault's own range (its ``max_magnitude``, in its own
unit: :func:`fcc_env.faults.has_own_unit`) when the template is built, so a track can never ask
for a size the plant does not carry. A template's ``onset`` may be left ``None``: the track's
``onset``, else the fault's default onset.

Labels for isolation: a concurrent column's episode carries both names
(:attr:`FaultTemplate.labels`), scored by :func:`fcc_env.faults.isolation_outcome` (both names
correct, one of the two wrong, ``"unknown"`` abstains).

>>> from evaluation.tracks.distributions import Uniform
>>> t = FaultTemplate(scenario="sensor-bias", magnitude=Uniform(2, 10), channel=("T_rx", "T_rg1"))
>>> t.name, t.labels, t.to_json()["channel"]
('sensor-bias', ('sensor-bias',), ['T_rx', 'T_rg1'])
>>> FaultTemplate(scenario="concurrent", parts=(t, FaultTemplate(scenario="valve-bias"))).name
'sensor-bias+valve-bias'
>>> FaultTemplate(scenario="valve-bias", magnitude=Uniform(0.1, 0.5))
Traceback (most recent call last):
...
ValueError: magnitude of valve-bias=Uniform(low=0.1, high=0.5) is outside the allowed range: ...
"""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from evaluation.tracks.distributions import Distribution, Fixed, check_distribution
from fcc_common.validation import Options, check, invalid
from fcc_env.faults import CONCURRENT_SCENARIO, fault_definition, fault_names, has_own_unit
from fcc_env.scenarios import FaultProfile, FaultSpec

__all__ = ["FaultTemplate", "StreamsFor"]

_NAME = re.compile(r"[a-z][a-z0-9_+-]*\Z")

#: ``streams(key, n)``: ``n`` independent generators for the draws of ``key`` (the track's
#: per-(seed, track, key) streams, :meth:`evaluation.tracks.track.Track.fault_spec`).
StreamsFor = Callable[[str, int], list[np.random.Generator]]
#: ``profile_and_ramp(g_profile, g_ramp, onset) -> (profile, ramp or None)``: the track's draw.
ProfileDraw = Callable[[np.random.Generator, np.random.Generator, int], tuple[FaultProfile, Any]]


@dataclass(frozen=True, kw_only=True)
class FaultTemplate:
    """One column of a track: a fault spec whose size, onset and channel the seed draws.

    Attributes:
        scenario: a registered fault (:func:`fcc_env.fault_names` ``(include_path_faults=True)``:
            the paper's, the sensor and the actuator faults) or ``"concurrent"``.
        magnitude: the size's distribution, in the fault's own unit (its
            ``magnitude_unit``), within ``[0, max_magnitude]``; ``None``: its default size.
        onset: the onset sample's distribution; ``None``: the track's ``onset``, else the
            fault's default onset (checked against the horizon by the track).
        channel: a channel fault's measured channel, or a tuple of them drawn uniformly per
            episode; ``None``: the fault's default channel. Refused for other faults.
        parts: ``scenario="concurrent"``'s two templates of different registered faults (each
            with its own onset, size and channel); empty otherwise.
        name: the column's name (``None``: the scenario, or ``"a+b"`` for two faults).
    """

    scenario: str
    magnitude: Distribution | None = None
    onset: Distribution | None = None
    channel: str | tuple[str, ...] | None = None
    parts: tuple[FaultTemplate, ...] = ()
    name: str | None = None

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        options = Options([*fault_names(include_path_faults=True), CONCURRENT_SCENARIO])
        set_(self, "scenario", str(check("scenario", self.scenario, options)))
        if self.scenario == CONCURRENT_SCENARIO:
            self._check_concurrent()
        else:
            if self.parts:
                raise invalid("parts", self.parts, "()", f"only {CONCURRENT_SCENARIO!r} has parts")
            d = fault_definition(self.scenario)
            mag = Fixed(d.default_magnitude) if self.magnitude is None else self.magnitude
            unit = d.magnitude_unit if has_own_unit(self.scenario) else "a relative change"
            check_distribution(
                f"magnitude of {self.scenario}",
                mag,
                0.0,
                d.max_magnitude,
                f"{unit}: {d.max_reason}",
            )
            set_(self, "magnitude", mag)
            set_(self, "channel", self._checked_channel(d.channels))
        if self.onset is not None:
            check_distribution(f"onset of {self.scenario}", self.onset, 1, np.inf, "a sample")
        name = self.name
        if name is None:
            name = "+".join(p.name for p in self.parts) if self.parts else self.scenario
        if not isinstance(name, str) or not _NAME.match(name):
            raise invalid("name", name, "a lowercase name of letters, digits, '-', '_' or '+'")
        set_(self, "name", name)

    def _check_concurrent(self) -> None:
        parts = self.parts
        if isinstance(parts, FaultTemplate) or not isinstance(parts, tuple | list):
            raise invalid("parts", parts, "a tuple of two FaultTemplate")
        parts = tuple(parts)
        if len(parts) != 2 or not all(isinstance(p, FaultTemplate) for p in parts):
            raise invalid("parts", parts, "a tuple of two FaultTemplate")
        if any(p.scenario == CONCURRENT_SCENARIO for p in parts):
            raise invalid("parts", [p.scenario for p in parts], "two registered faults")
        if parts[0].scenario == parts[1].scenario:
            raise invalid(
                "parts",
                [p.scenario for p in parts],
                "two different faults",
                "an isolator names both, so two faults of one kind would be one label",
            )
        given = [k for k in ("magnitude", "onset", "channel") if getattr(self, k) is not None]
        if given:
            raise invalid("concurrent template", given, "none of them", "each part carries its own")
        object.__setattr__(self, "parts", parts)

    def _checked_channel(self, channels: tuple[str, ...]) -> tuple[str, ...] | None:
        ch = self.channel
        if ch is None:
            return None
        if not channels:
            raise invalid(
                "channel", ch, "None", f"{self.scenario} acts on no measured channel of its own"
            )
        many = (ch,) if isinstance(ch, str) else ch
        if not isinstance(many, tuple | list) or not many:
            raise invalid("channel", ch, f"a channel or a non-empty tuple of {list(channels)}")
        many = tuple(str(check("channel", c, Options(channels))) for c in many)
        if len(set(many)) != len(many):
            raise invalid("channel", ch, "distinct channels")
        return many

    @property
    def labels(self) -> tuple[str, ...]:
        """The fault names an isolator must give for an episode of this column."""
        return tuple(p.scenario for p in self.parts) if self.parts else (self.scenario,)

    @property
    def definitions_needing_loop(self) -> tuple[str, ...]:
        """The faults of the column that only act while a controller moves the actuator."""
        return tuple(s for s in self.labels if fault_definition(s).needs_loop)

    def latest_onset(self, default: Distribution | None) -> int:
        """The latest onset the column can draw (``default``: the track's onset)."""
        if self.parts:
            return max(p.latest_onset(default) for p in self.parts)
        dist = self.onset or default
        return int(dist.high) if dist is not None else fault_definition(self.scenario).default_onset

    def draw(
        self, streams: StreamsFor, profile_and_ramp: ProfileDraw, default_onset: Distribution | None
    ) -> FaultSpec:
        """The spec of one episode: every field explicit, drawn from ``streams`` (one key per
        part, so the draws of one part never shift the other's)."""
        if self.parts:
            specs = tuple(
                p._draw_single(streams(f"{self.name}/{j}", 5), profile_and_ramp, default_onset)
                for j, p in enumerate(self.parts)
            )
            return FaultSpec(scenario=CONCURRENT_SCENARIO, parts=specs)
        return self._draw_single(streams(self.name, 5), profile_and_ramp, default_onset)

    def _draw_single(
        self,
        gens: list[np.random.Generator],
        profile_and_ramp: ProfileDraw,
        default_onset: Distribution | None,
    ) -> FaultSpec:
        g_mag, g_onset, g_profile, g_ramp, g_channel = gens
        assert self.magnitude is not None  # set on construction
        magnitude = self.magnitude.sample(g_mag)
        dist = self.onset or default_onset
        d = fault_definition(self.scenario)
        onset = d.default_onset if dist is None else dist.sample_int(g_onset)
        profile, ramp = profile_and_ramp(g_profile, g_ramp, onset)
        channel = d.default_channel  # explicit: None but for a channel fault
        if isinstance(self.channel, tuple):
            channel = self.channel[int(g_channel.integers(len(self.channel)))]
        return FaultSpec(
            scenario=self.scenario,
            onset=onset,
            magnitude=magnitude,
            profile=profile,
            ramp_samples=ramp,
            channel=channel,
        )

    def to_json(self) -> dict[str, Any]:
        """Everything that defines the column (part of the track's store key)."""
        out: dict[str, Any] = {"name": self.name, "scenario": self.scenario}
        if self.parts:
            out["parts"] = [p.to_json() for p in self.parts]
            return out
        assert self.magnitude is not None
        out["magnitude"] = self.magnitude.to_json()
        out["onset"] = None if self.onset is None else self.onset.to_json()
        out["channel"] = None if self.channel is None else list(self.channel)
        return out
