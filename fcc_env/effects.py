"""Undeclared plant effects: things a real unit does that the declared model does not.

An effect changes the simulated plant without appearing in observations, ``info`` or the env's
spec, so data generated with it is "measured data with an undeclared effect". Pass effects as
``gymnasium.make("FCC-v0", plant_effects=[...])`` (or the reset option of that name), to
:func:`fcc_env.simulate_episodes` or to ``python -m fcc_env.generate --plant-effect ID,k=v``.

**User effects** are any object with one or both of these methods (and optionally ``reset()``,
called at the start of every episode):

* ``d_state(t, x, u, params) -> array`` added to the state derivative. ``t`` in seconds, ``x`` the
  state ordered as :data:`fcc_env.STATE_NAMES` (kg, kg/kg, °C; derivatives per second), ``u`` the
  inputs ordered as :data:`fcc_env.INPUT_NAMES`, ``params`` the plant's :class:`FCCParams`
  (faults not applied). In batch simulation ``x`` and ``u`` have a leading episode axis.
* ``measure(t, y) -> array``: the eight noise-free Table 1 measurements (shape ``(8,)``, or
  ``(n_episodes, 8)`` in batch simulation) transformed, before measurement noise. Called once per
  sample in time order, so it may keep state (a sensor lag does).

**Library effects** (:func:`make` / :func:`available`) are physically named and parametrised;
their string ids are used everywhere (env, generator, the modelling loop, reports). Effects that
change the process act through the model's own parameters or inputs (``param_multipliers`` and
``transform_inputs``), which the compiled simulator applies exactly; sensor effects implement
``measure``. Each has a realistic default size for a plant, stated below.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from fcc_common.validation import Real, check
from fcc_env.params import INPUT_NAMES, MEASUREMENT_NAMES

SECONDS_PER_DAY = 86_400.0
SECONDS_PER_HOUR = 3_600.0

_HEAT_LOSS_UNITS = {
    "stage1": "UA_1",
    "stage2": "UA_2",
    "dilute1": "UA_d1",
    "dilute_general": "UA_dg",
}
_AFTERBURN_UNITS = {"dilute1": "eta1", "dilute_general": "eta_g"}


@dataclass(frozen=True)
class ParamSpec:
    name: str
    default: float
    low: float
    high: float
    unit: str
    description: str


@dataclass
class LibraryEffect:
    """A library effect: an id (``kind`` or ``kind:target``) and its parameter values."""

    effect_id: str
    params: dict[str, float]
    _state: np.ndarray | None = field(default=None, repr=False)
    _t_prev: float | None = field(default=None, repr=False)

    @property
    def kind(self) -> str:
        return self.effect_id.split(":", 1)[0]

    @property
    def target(self) -> str | None:
        parts = self.effect_id.split(":", 1)
        return parts[1] if len(parts) == 2 else None

    def describe(self) -> dict[str, Any]:
        return {"id": self.effect_id, "params": dict(self.params)}

    def reset(self) -> None:
        self._state = None
        self._t_prev = None

    # ---- process effects: schedules applied by the compiled simulator --------------------------
    def param_multipliers(self, t_s: np.ndarray, base: Any) -> dict[str, np.ndarray]:
        """Multipliers of :class:`FCCParams` fields over samples at times ``t_s`` (seconds)."""
        kind, p = self.kind, self.params
        ones = np.ones_like(t_s, dtype=np.float64)
        if kind == "heat_loss":
            field_name = _HEAT_LOSS_UNITS[self.target]
            ua = getattr(base, field_name)
            return {field_name: ones * ((ua + p["extra_ua_kw_per_k"]) / ua)}
        if kind == "afterburn":
            return {_AFTERBURN_UNITS[self.target]: ones * p["factor"]}
        if kind == "air_split":
            return {"alpha1": ones * ((base.alpha1 + p["delta_alpha1"]) / base.alpha1)}
        if kind == "catalyst_deactivation":
            return {"A_cr": np.maximum(0.05, 1.0 - p["loss_per_day"] * t_s / SECONDS_PER_DAY)}
        return {}

    def transform_inputs(self, t_s: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Inputs the process really sees (``u``: (..., n, 6) over samples at ``t_s``)."""
        if self.kind == "feed_coking_drift":
            u = u.copy()
            u[..., INPUT_NAMES.index("f_coke")] *= 1.0 + self.params["rise_per_day"] * (
                t_s / SECONDS_PER_DAY
            )
        return u

    # ---- sensor effects ------------------------------------------------------------------------
    def measure(self, t: float, y: np.ndarray) -> np.ndarray:
        kind = self.kind
        if kind not in ("sensor_bias", "sensor_drift", "sensor_lag"):
            return y
        i = MEASUREMENT_NAMES.index(self.target)
        out = np.array(y, dtype=np.float64, copy=True)
        if kind == "sensor_bias":
            out[..., i] = out[..., i] + self.params["bias"]
        elif kind == "sensor_drift":
            out[..., i] = out[..., i] + self.params["rate_per_h"] * (t / SECONDS_PER_HOUR)
        else:  # sensor_lag: exact discretisation of a first-order lag, started at equilibrium
            if self._state is None or self._t_prev is None:
                self._state = np.array(out[..., i], dtype=np.float64, copy=True)
            else:
                a = math.exp(-(t - self._t_prev) / self.params["tau_s"])
                self._state = (1.0 - a) * out[..., i] + a * self._state
            self._t_prev = t
            out[..., i] = self._state
        return out

    @property
    def hooks(self) -> frozenset[str]:
        """The hooks this effect really uses (the others are no-ops for its kind)."""
        return _KIND_HOOKS.get(self.kind, frozenset())


def _kinds() -> dict[str, tuple[list[str | None], list[ParamSpec], str]]:
    temps = list(MEASUREMENT_NAMES)
    return {
        "heat_loss": (
            list(_HEAT_LOSS_UNITS),
            [
                ParamSpec(
                    "extra_ua_kw_per_k",
                    1.0,
                    0.0,
                    50.0,
                    "kW/K",
                    "extra heat loss coefficient to ambient (modelled UA: 2 kW/K for the beds, "
                    "1–1.5 for the dilute phases). The spec's §5 suggests UA × 3–5; here that "
                    "moves the dilute phases by tens of °C and can end the episode, so the "
                    "default is +1 kW/K (UA × 1.5–2)",
                ),
            ],
            "heat loss to ambient larger than modelled: extra loss ∝ (T − T_amb)",
        ),
        "sensor_lag": (
            temps,
            [ParamSpec("tau_s", 60.0, 1.0, 1800.0, "s", "thermocouple time constant (30–90 s)")],
            "first-order lag on a Table 1 channel",
        ),
        "sensor_bias": (
            temps,
            [ParamSpec("bias", 4.0, -50.0, 50.0, "channel unit", "constant offset (3–5 °C)")],
            "constant offset on a Table 1 channel",
        ),
        "sensor_drift": (
            temps,
            [ParamSpec("rate_per_h", 0.5, -10.0, 10.0, "unit/h", "linear drift rate")],
            "linear ramp on a Table 1 channel",
        ),
        "catalyst_deactivation": (
            [None],
            [
                ParamSpec(
                    "loss_per_day",
                    0.2,
                    0.0,
                    2.0,
                    "1/day",
                    "fractional loss of cracking activity A_cr per day (τ_d of days)",
                )
            ],
            "cracking activity decaying over time: A_cr·(1 − loss·t)",
        ),
        "feed_coking_drift": (
            [None],
            [
                ParamSpec(
                    "rise_per_day",
                    0.15,
                    -1.0,
                    1.0,
                    "1/day",
                    "relative rise of the feed coking factor per day (spec §5: 1 → 1.05–1.10)",
                )
            ],
            "feed coking tendency drifting: f_coke·(1 + rise·t)",
        ),
        "afterburn": (
            list(_AFTERBURN_UNITS),
            [ParamSpec("factor", 2.0, 0.1, 5.0, "-", "afterburn efficiency multiplier (1.5–3)")],
            "dilute-phase CO combustion stronger or weaker (η × factor)",
        ),
        "air_split": (
            [None],
            [ParamSpec("delta_alpha1", 0.02, -0.1, 0.1, "-", "shift of the stage-1 air share")],
            "share of air to stage 1 shifted (nozzle erosion)",
        ),
    }


def available() -> dict[str, dict[str, Any]]:
    """Library effect ids with their description and parameters (default, range, unit)."""
    out: dict[str, dict[str, Any]] = {}
    for kind, (targets, params, description) in _kinds().items():
        for target in targets:
            eid = kind if target is None else f"{kind}:{target}"
            out[eid] = {
                "description": description,
                "params": {
                    p.name: {
                        "default": p.default,
                        "range": [p.low, p.high],
                        "unit": p.unit,
                        "description": p.description,
                    }
                    for p in params
                },
            }
    return out


def make(effect_id: str, **params: float) -> LibraryEffect:
    """Build library effect ``effect_id`` (e.g. ``"heat_loss:stage1"``), defaults for params."""
    lib = available()
    if effect_id not in lib:
        raise ValueError(f"Unknown plant effect {effect_id!r}. Available: {sorted(lib)}")
    spec = lib[effect_id]["params"]
    unknown = sorted(set(params) - set(spec))
    if unknown:
        raise ValueError(
            f"Unknown parameter(s) {unknown} for effect {effect_id!r}. Allowed: {sorted(spec)}"
        )
    values = {
        name: check(name, params.get(name, s["default"]), param_range(s, effect_id))
        for name, s in spec.items()
    }
    return LibraryEffect(effect_id, values)


def param_range(spec: Mapping[str, Any], effect_id: str) -> Real:
    """The constraint of one effect parameter, from its entry in :func:`available`."""
    lo, hi = spec["range"]
    return Real(lo, hi, unit=spec["unit"], why=f"parameter of {effect_id}")


def parse(text: str) -> LibraryEffect:
    """``"heat_loss:stage1,extra_ua_kw_per_k=6"`` → the library effect (CLI syntax)."""
    eid, *assignments = [part.strip() for part in text.split(",")]
    params: dict[str, float] = {}
    for a in assignments:
        name, sep, value = a.partition("=")
        if not sep:
            raise ValueError(f"bad effect parameter {a!r} in {text!r}: use name=value")
        try:
            params[name.strip()] = float(value)
        except ValueError:
            raise ValueError(f"effect parameter {name!r}={value!r} is not a number") from None
    return make(eid, **params)


def resolve(effects: Iterable[Any] | None) -> list[Any]:
    """Normalise a ``plant_effects`` value: ids, ``(id, params)`` pairs, mappings or objects."""
    if effects is None:
        return []
    if isinstance(effects, str | Mapping) or not isinstance(effects, Iterable):
        effects = [effects]
    out: list[Any] = []
    for e in effects:
        if isinstance(e, str):
            out.append(parse(e))
        elif isinstance(e, tuple) and len(e) == 2 and isinstance(e[0], str):
            out.append(make(e[0], **dict(e[1])))
        elif isinstance(e, Mapping) and "id" in e:
            out.append(make(e["id"], **dict(e.get("params", {}))))
        elif any(callable(getattr(e, m, None)) for m in _HOOKS):
            out.append(e)
        else:
            raise ValueError(
                f"plant effect {e!r} is neither a library id ({sorted(available())}) nor an "
                "object with a d_state(t, x, u, params) or measure(t, y) method"
            )
    return out


_HOOKS = ("d_state", "measure", "param_multipliers", "transform_inputs")


#: The one hook each library effect kind acts through (how the simulator files it).
_KIND_HOOKS: dict[str, frozenset[str]] = {
    "heat_loss": frozenset({"param_multipliers"}),
    "afterburn": frozenset({"param_multipliers"}),
    "air_split": frozenset({"param_multipliers"}),
    "catalyst_deactivation": frozenset({"param_multipliers"}),
    "feed_coking_drift": frozenset({"transform_inputs"}),
    "sensor_bias": frozenset({"measure"}),
    "sensor_drift": frozenset({"measure"}),
    "sensor_lag": frozenset({"measure"}),
}


def has_hook(effect: Any, name: str) -> bool:
    """Whether ``effect`` acts through hook ``name``.

    An effect that declares ``hooks`` (a library effect: one class serves every kind, so it has
    every method) acts through those only, so e.g. a heat loss does not take the slower
    measurement path; any other object acts through the hooks it has.
    """
    hooks = getattr(effect, "hooks", None)
    if hooks is not None:
        return name in hooks
    return callable(getattr(effect, name, None))


def reset_all(effects: Iterable[Any]) -> None:
    for e in effects:
        if callable(getattr(e, "reset", None)):
            e.reset()
