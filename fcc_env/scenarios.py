"""Scenarios (healthy and faults f1–f4), fault profiles and the operating program (excitation).

Faults follow the paper (Section 5.3, after Sotomayor et al. 2004) and enter through the parameters
named in the specification's §3:

=========  ====================================  ================  ================
scenario   parameter change                       default onset     magnitude
=========  ====================================  ================  ================
nominal    none                                   –                 –
f1         catalyst density ρ_b × (1 + m)          1900              m = 0.10
f2         weir constants K_w1, K_w2 × (1 − m)     1900              m = 0.15
f3         CO2/CO ratio constant k_σ × (1 − m)     2020              m = 0.10
f4         reactor holdup set point × (1 + m)      2000              m = 0.05
=========  ====================================  ================  ================

``fault_magnitude`` is the size of the relative change and is never negative; its direction is
the paper's (density and holdup up, weir and ratio constants down).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from enum import StrEnum
from typing import Any

import numpy as np

from fcc_env.params import NOMINAL_INPUTS, PARAM_INDEX


class Scenario(StrEnum):
    NOMINAL = "nominal"
    F1 = "f1"
    F2 = "f2"
    F3 = "f3"
    F4 = "f4"


class FaultProfile(StrEnum):
    ABRUPT = "abrupt"
    INCIPIENT = "incipient"


@dataclass(frozen=True)
class FaultDefinition:
    parameters: tuple[str, ...]  # FCCParams fields scaled by the fault
    direction: int  # +1: parameter grows, -1: parameter shrinks
    default_magnitude: float
    default_onset: int
    description: str


FAULTS: dict[Scenario, FaultDefinition] = {
    Scenario.F1: FaultDefinition(("rho_b",), +1, 0.10, 1900, "catalyst density +10 %"),
    Scenario.F2: FaultDefinition(
        ("K_w1", "K_w2"), -1, 0.15, 1900, "weir constant of stages 1 and 2 −15 %"
    ),
    Scenario.F3: FaultDefinition(("k_sigma",), -1, 0.10, 2020, "CO2/CO ratio constant −10 %"),
    Scenario.F4: FaultDefinition(("V_rx_sp_m3",), +1, 0.05, 2000, "catalyst reactor holdup +5 %"),
}

SCENARIOS: tuple[str, ...] = tuple(s.value for s in Scenario)
#: Upper bound on fault magnitudes: beyond it the plant leaves the hot state (f2 at 100 % stops flow).
MAX_FAULT_MAGNITUDE = 0.9


def parse_scenario(value: Any) -> Scenario:
    try:
        return Scenario(value)
    except ValueError:
        raise ValueError(
            f"Unknown scenario {value!r}. Allowed: {list(SCENARIOS)} or 'random'"
        ) from None


def parse_profile(value: Any) -> FaultProfile:
    try:
        return FaultProfile(value)
    except ValueError:
        allowed = [p.value for p in FaultProfile]
        raise ValueError(f"Unknown fault_profile {value!r}. Allowed: {allowed}") from None


@dataclass(frozen=True)
class FaultConfig:
    """A resolved fault for one episode (``scenario == nominal`` means none)."""

    scenario: Scenario
    onset: int = -1  # sample index at which the parameter switches; -1 = never
    magnitude: float = 0.0  # relative change, ≥ 0
    profile: FaultProfile = FaultProfile.ABRUPT
    ramp_samples: int = 0  # incipient: samples to reach the full magnitude

    @property
    def param_indices(self) -> np.ndarray:
        idx = np.full(2, -1, dtype=np.int64)
        if self.scenario is not Scenario.NOMINAL:
            for j, name in enumerate(FAULTS[self.scenario].parameters):
                idx[j] = PARAM_INDEX[name]
        return idx

    @property
    def final_multiplier(self) -> float:
        if self.scenario is Scenario.NOMINAL:
            return 1.0
        return 1.0 + FAULTS[self.scenario].direction * self.magnitude

    @property
    def ramp(self) -> int:
        return self.ramp_samples if self.profile is FaultProfile.INCIPIENT else 0

    def multipliers(self, k: np.ndarray) -> np.ndarray:
        """Multipliers of the two fault-parameter slots over samples ``k``: shape (n, 2).

        1 before the onset; afterwards the final multiplier, reached linearly over
        ``ramp_samples`` for an incipient fault (at sample ``onset + ramp_samples − 1``).
        """
        k = np.asarray(k)
        m = np.ones(k.shape[0])
        if self.scenario is not Scenario.NOMINAL:
            after = k >= self.onset
            frac = np.minimum(1.0, (k - self.onset + 1) / self.ramp) if self.ramp > 0 else 1.0
            m = np.where(after, 1.0 + (self.final_multiplier - 1.0) * frac, 1.0)
        return np.column_stack([m, m])

    def active(self, k: int) -> bool:
        return self.scenario is not Scenario.NOMINAL and 0 <= self.onset <= k


def resolve_fault(
    scenario: Any,
    fault_time: Any = None,
    fault_magnitude: Any = None,
    fault_profile: Any = "abrupt",
    ramp_samples: Any = None,
    horizon: int | None = None,
) -> FaultConfig:
    """Validate fault options and fill the paper's defaults; errors name the value and the range."""
    sc = parse_scenario(scenario)
    profile = parse_profile(fault_profile)
    if sc is Scenario.NOMINAL:
        return FaultConfig(Scenario.NOMINAL)
    definition = FAULTS[sc]
    onset = definition.default_onset if fault_time is None else fault_time
    if isinstance(onset, bool) or not isinstance(onset, int | np.integer):
        raise ValueError(f"fault_time must be an integer sample index, got {onset!r}")
    onset = int(onset)
    upper = horizon if horizon is not None else math.inf
    if not 0 <= onset < upper:
        raise ValueError(
            f"fault_time={onset} is outside the episode: allowed 0 <= fault_time < {upper}"
        )
    mag = definition.default_magnitude if fault_magnitude is None else fault_magnitude
    if isinstance(mag, bool) or not isinstance(mag, int | float | np.number):
        raise ValueError(f"fault_magnitude must be a number, got {mag!r}")
    mag = float(mag)
    if not (math.isfinite(mag) and 0.0 <= mag <= MAX_FAULT_MAGNITUDE):
        raise ValueError(
            f"fault_magnitude={mag!r} is outside the allowed range [0, {MAX_FAULT_MAGNITUDE}] "
            "(a relative change; its sign is fixed by the fault)"
        )
    ramp = 0
    if profile is FaultProfile.INCIPIENT:
        ramp = 500 if ramp_samples is None else ramp_samples
        if isinstance(ramp, bool) or not isinstance(ramp, int | np.integer) or ramp < 1:
            raise ValueError(
                f"ramp_samples must be an integer >= 1 for an incipient fault, got {ramp!r}"
            )
        ramp = int(ramp)
    elif ramp_samples not in (None, 0):
        raise ValueError(f"ramp_samples={ramp_samples!r} only applies to fault_profile='incipient'")
    return FaultConfig(sc, onset, mag, profile, ramp)


# ---- operating program (spec §7.5) -------------------------------------------------------------
@dataclass(frozen=True)
class Excitation:
    """Amplitude-modulated pseudo-random steps (APRBS) on T_fp, T_ar and R_ar (spec §7.5).

    Each new level is uniform in nominal ± half-range and is held for an integer number of samples
    drawn uniformly from ``[hold_min, hold_max]``; the first ``warmup_samples`` stay at nominal.
    The catalyst valve is held (exciting it would make the T_rx relation unidentifiable, spec §5).
    """

    T_fp_halfrange_C: float = 10.0
    T_ar_halfrange_C: float = 10.0
    R_ar_halfrange_rel: float = 0.05
    hold_min: int = 20
    hold_max: int = 200
    warmup_samples: int = 100

    @classmethod
    def from_option(cls, value: Any) -> Excitation | None:
        """``True``/``None`` → defaults, ``False`` → no excitation, a mapping → overrides."""
        if value is None or value is True:
            return cls()
        if value is False:
            return None
        if isinstance(value, Excitation):
            return value
        if isinstance(value, Mapping):
            allowed = set(cls.__dataclass_fields__)
            unknown = sorted(set(value) - allowed)
            if unknown:
                raise ValueError(
                    f"Unknown excitation option(s) {unknown}. Allowed: {sorted(allowed)}"
                )
            exc = cls(**value)
            exc.validate()
            return exc
        raise ValueError(f"excitation must be True, False or a mapping of options, got {value!r}")

    def validate(self) -> None:
        for name in ("T_fp_halfrange_C", "T_ar_halfrange_C"):
            v = getattr(self, name)
            if not (math.isfinite(v) and 0 <= v <= 50):
                raise ValueError(f"excitation {name}={v!r} outside the allowed range [0, 50] °C")
        if not (math.isfinite(self.R_ar_halfrange_rel) and 0 <= self.R_ar_halfrange_rel <= 0.07):
            raise ValueError(
                f"excitation R_ar_halfrange_rel={self.R_ar_halfrange_rel!r} outside [0, 0.07] "
                "(larger air moves leave the hot-state envelope, spec §4)"
            )
        if not (1 <= self.hold_min <= self.hold_max):
            raise ValueError(
                f"excitation hold range [{self.hold_min}, {self.hold_max}] must satisfy "
                "1 <= hold_min <= hold_max"
            )
        if self.warmup_samples < 0:
            raise ValueError(f"excitation warmup_samples={self.warmup_samples} must be >= 0")


class ProgramGenerator:
    """Streams the operating program: inputs ``(n, 6)`` per sample, chunk by chunk.

    Each excited channel draws from its own generator, in blocks of ``_BLOCK`` levels and hold
    times (one numpy call each instead of two per segment), so the program does not depend on
    how it is chunked, and a seed gives the same program whatever the scenario.
    """

    _CHANNELS = (3, 2, 1)  # T_fp, T_ar, R_ar columns of the input vector
    _BLOCK = 64

    def __init__(self, excitation: Excitation | None, rngs: list[np.random.Generator]):
        self.excitation = excitation
        self.rngs = rngs
        self.k = 0
        self._level = NOMINAL_INPUTS[list(self._CHANNELS)].copy()
        self._left = np.zeros(3, dtype=np.int64)
        self._draws: list[tuple[np.ndarray, np.ndarray]] = [(np.empty(0), np.empty(0))] * 3
        self._next = [0, 0, 0]

    def _segment(self, c: int) -> tuple[float, int]:
        """Next (offset in [-1, 1), hold samples) of channel c."""
        ex = self.excitation
        assert ex is not None
        if self._next[c] >= self._draws[c][0].shape[0]:
            rng = self.rngs[c]
            offsets = rng.uniform(-1.0, 1.0, size=self._BLOCK)
            holds = rng.integers(ex.hold_min, ex.hold_max, size=self._BLOCK, endpoint=True)
            self._draws[c] = (offsets, holds)
            self._next[c] = 0
        j = self._next[c]
        self._next[c] += 1
        return float(self._draws[c][0][j]), int(self._draws[c][1][j])

    def take(self, n: int) -> np.ndarray:
        out = np.empty((n, NOMINAL_INPUTS.shape[0]))
        out[:] = NOMINAL_INPUTS
        ex = self.excitation
        if ex is None:
            self.k += n
            return out
        half = (
            ex.T_fp_halfrange_C,
            ex.T_ar_halfrange_C,
            ex.R_ar_halfrange_rel * NOMINAL_INPUTS[1],
        )
        for c, col in enumerate(self._CHANNELS):
            centre = NOMINAL_INPUTS[col]
            i = max(0, min(n, ex.warmup_samples - self.k))  # warm-up samples stay at nominal
            while i < n:
                if self._left[c] == 0:
                    offset, hold = self._segment(c)
                    self._level[c] = centre + half[c] * offset
                    self._left[c] = hold
                m = int(min(self._left[c], n - i))
                out[i : i + m, col] = self._level[c]
                self._left[c] -= m
                i += m
        self.k += n
        return out


def episode_generators(rng: np.random.Generator) -> dict[str, Any]:
    """Split an episode's generator into independent streams (program, noise, random fault)."""
    children = rng.spawn(5)
    return {"program": children[:3], "noise": children[3], "fault": children[4]}
