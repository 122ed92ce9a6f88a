"""The FCC physics model as a :class:`~evaluation.discover.base.ModelAdapter`.

Candidates are the effects of :mod:`fcc_env.effects` plus any :class:`PhysicsCandidate` the user
adds. A first-order *sensor lag on a model input channel* (T_ar, T_fp) cannot be inverted
without differentiating noise, so those candidates are not offered (listed under
``skipped_candidates``).
"""

from __future__ import annotations

import math
from collections import OrderedDict
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import signal

from evaluation.discover.base import Candidate, ParamInfo
from evaluation.discover.corrected_sim import TermTable, simulate_corrected, term_values
from evaluation.discover.data import TABLE1, MeasuredData
from evaluation.discover.terms import FormCandidate, form_from_json
from fcc_env import effects as fx
from fcc_env.params import NOMINAL_INPUTS, PARAM_INDEX, FCCParams
from fcc_env.physics import steady_state
from fcc_env.plant import DEFAULT_SAMPLE_TIME_S
from fcc_env.simulation import simulate_inputs

__all__ = [
    "PHYSICS_INPUT_CHANNELS",
    "PHYSICS_OUTPUT_CHANNELS",
    "PhysicsCandidate",
    "PhysicsModel",
    "declared_from_report",
    "first_order_lag",
    "library_candidates",
]

#: Measured channels the physics model takes as inputs (u_F and R_ar come from the commands).
PHYSICS_INPUT_CHANNELS = ("T_ar", "T_fp")
_INPUT_SLOT = {"T_ar": 2, "T_fp": 3}  # position in fcc_env.INPUT_NAMES
PHYSICS_OUTPUT_CHANNELS = ("R_ar", "T_rx", "T_rg1", "T_rg2", "T_d1", "T_dg")
_NULL = {
    "extra_ua_kw_per_k": 0.0,
    "tau_s": 1.0,
    "bias": 0.0,
    "rate_per_h": 0.0,
    "loss_per_day": 0.0,
    "rise_per_day": 0.0,
    "factor": 1.0,
    "delta_alpha1": 0.0,
}
_GRID = {
    "extra_ua_kw_per_k": (0.0, 0.3, 1.0, 3.0, 10.0),
    "tau_s": (5.0, 20.0, 60.0, 180.0, 600.0),
    "bias": (-8.0, -2.0, -0.5, 0.0, 0.5, 2.0, 8.0),
    "rate_per_h": (-2.0, -0.5, -0.1, 0.0, 0.1, 0.5, 2.0),
    "loss_per_day": (0.0, 0.05, 0.2, 0.8),
    "rise_per_day": (-0.3, -0.1, -0.02, 0.0, 0.02, 0.1, 0.3),
    "factor": (0.5, 0.8, 1.0, 1.3, 2.0, 3.0),
    "delta_alpha1": (-0.05, -0.01, 0.0, 0.01, 0.05),
}
_SENSOR_KINDS = ("sensor_bias", "sensor_drift", "sensor_lag")


@dataclass(frozen=True)
class PhysicsCandidate:
    """A candidate for :class:`PhysicsModel`.

    ``factory(**params)`` returns an effect object with ``param_multipliers(t_s, base_params)``
    and/or ``transform_inputs(t_s, U)`` (the hooks of :mod:`fcc_env.effects` that the compiled
    simulator applies exactly). A user ``measure`` or ``d_state`` hook is not applied: a
    ``d_state`` effect would need the slow Python integration path, and is left for later.
    Library sensor effects are handled in closed form (``sensor`` set): on an output
    channel they transform the model output (no re-simulation); on an input channel (bias,
    drift) the measured input is corrected before simulation (the exact inverse).
    """

    id: str
    params: tuple[ParamInfo, ...]
    factory: Callable[..., Any] | None = None
    sensor: tuple[str, str] | None = None  # (kind, channel) for library sensor effects

    @property
    def needs_simulation(self) -> bool:
        if self.sensor is not None:
            return self.sensor[1] in PHYSICS_INPUT_CHANNELS
        return True  # user factories: decided per object in PhysicsModel (conservative)


def library_candidates() -> tuple[dict[str, PhysicsCandidate], dict[str, str]]:
    """Candidates for every library effect; sensor lags on input channels are skipped (reason)."""
    out: dict[str, PhysicsCandidate] = {}
    skipped: dict[str, str] = {}
    for eid, spec in fx.available().items():
        kind, _, target = eid.partition(":")
        if kind == "sensor_lag" and target in PHYSICS_INPUT_CHANNELS:
            skipped[eid] = "a lag on a model input cannot be inverted without differentiating noise"
            continue
        params = tuple(
            ParamInfo(
                name,
                float(s["default"]),
                float(s["range"][0]),
                float(s["range"][1]),
                _NULL.get(name, 0.0),
                s["unit"],
                tuple(v for v in _GRID.get(name, ()) if s["range"][0] <= v <= s["range"][1]),
            )
            for name, s in spec["params"].items()
        )
        sensor = (kind, target) if kind in _SENSOR_KINDS else None
        out[eid] = PhysicsCandidate(eid, params, (lambda _e=eid, **p: fx.make(_e, **p)), sensor)
    return out, skipped


def first_order_lag(y: np.ndarray, tau_s: float, dt: float) -> np.ndarray:
    """First-order lag along the last axis, started at equilibrium (as fcc_env's sensor_lag)."""
    a = math.exp(-dt / tau_s)
    zi = a * y[..., :1]
    out, _ = signal.lfilter([1.0 - a], [1.0, -a], y, axis=-1, zi=zi)
    return out


class PhysicsModel:
    """The declared FCC model (``fcc_env.simulation.simulate_inputs``) as a :class:`ModelAdapter`.

    Inputs: u_F = ``cmd_u_F`` and R_ar = ``cmd_R_ar`` (the commanded valve and air, which the
    regulatory layer delivers); T_ar, T_fp = the measured channels; F_feed = 61.111 kg/s and
    f_coke = 1 (declared nominal), or an estimated coking drift (:meth:`set_drift`). Outputs: R_ar (the air measurement against its command),
    T_rx, T_rg1, T_rg2, T_d1, T_dg. Taking the air from its command rather than from its noisy
    measurement matters: the 0.5 % air-flow noise, integrated by the slow coke balance, made the
    clean declared model's residual wander enough for a spurious drift to pass the held-out
    test on 2 of 20 clean seeds; with the command it does not (and an R_ar sensor effect becomes
    an output effect). Initial state: the
    declared steady state at the mean of the first ``init_samples`` (corrected) inputs of each
    episode.
    """

    name = "fcc-physics"
    output_channels = PHYSICS_OUTPUT_CHANNELS

    def __init__(
        self,
        init_samples: int = 20,
        cache_size: int = 8,
        declared: Sequence[tuple[Candidate, Sequence[float]]] = (),
    ):
        self.init_samples = init_samples
        self.cache_size = cache_size
        #: accepted effects that are now part of the declared model: (candidate, values)
        self.declared = tuple((c, np.asarray(v, np.float64)) for c, v in declared)
        self._cache: OrderedDict[Any, tuple[np.ndarray, np.ndarray | None]] = OrderedDict()
        self._cands, self._skipped = library_candidates()
        self._U: np.ndarray | None = None
        self._data_id: int | None = None
        self._drift: np.ndarray | None = None

    def set_drift(self, f_coke: np.ndarray | None) -> None:
        """Feed the prepared data's episodes an estimated feed coking factor ``f_coke``
        (n_episodes, n_samples; :mod:`evaluation.discover.drift`) instead of the declared 1;
        None restores the declared value. Kept until the next :meth:`prepare` on other data."""
        if self._U is None:
            raise RuntimeError("prepare() the model on the data before set_drift()")
        if f_coke is not None:
            f_coke = np.asarray(f_coke, np.float64)
            if f_coke.shape != self._U.shape[:2] or not np.isfinite(f_coke).all():
                raise ValueError(
                    f"f_coke of shape {f_coke.shape} must be finite and match the data's "
                    f"(n_episodes, n_samples) = {self._U.shape[:2]}"
                )
        self._drift = f_coke
        self._U[:, :, 5] = NOMINAL_INPUTS[5] if f_coke is None else f_coke
        self._cache.clear()

    def prepare(self, data: MeasuredData, n_train: int) -> None:
        data.require(
            ["cmd_u_F", "cmd_R_ar", *PHYSICS_INPUT_CHANNELS, *PHYSICS_OUTPUT_CHANNELS], self.name
        )
        E, T = data.n_episodes, data.n_samples
        U = np.empty((E, T, 6))
        U[:, :, 0] = data.channels["cmd_u_F"]
        U[:, :, 1] = data.channels["cmd_R_ar"]
        for c, j in _INPUT_SLOT.items():
            U[:, :, j] = data.channels[c]
        U[:, :, 4] = NOMINAL_INPUTS[4]
        U[:, :, 5] = NOMINAL_INPUTS[5]
        self._U = U
        if self._data_id == id(data) and self._drift is not None:
            U[:, :, 5] = self._drift  # re-prepared on the same data: the drift stays
        else:
            self._drift = None
        self._data_id = id(data)
        self._cache.clear()

    def candidates(self) -> dict[str, Candidate]:
        return dict(self._cands)

    def skipped_candidates(self) -> dict[str, str]:
        return dict(self._skipped)

    def other_signals(self, data: MeasuredData) -> list[str]:
        return ["cmd_u_F", "cmd_R_ar", *PHYSICS_INPUT_CHANNELS]

    # -- simulation ------------------------------------------------------------------------------
    def _needs_sim(self, eff: Candidate) -> bool:
        if isinstance(eff, PhysicsCandidate):
            return eff.needs_simulation
        if isinstance(eff, FormCandidate):
            return not eff.is_measurement
        return True

    def form_table(self, effects: Sequence[Candidate]) -> TermTable | None:
        """The terms of every form among ``effects``, packed for the kernel (None: no form)."""
        forms = [e for e in effects if isinstance(e, FormCandidate)]
        if not forms:
            return None
        terms = [t for f in forms for t in f.terms]
        targets = [None if f.is_measurement else f.target for f in forms for _ in f.terms]
        return TermTable(terms, targets)

    def _simulate(
        self,
        settings: list[list[tuple[Candidate, np.ndarray]]],
        n: int,
        table: TermTable | None = None,
        forms: Sequence[FormCandidate] = (),
        keep_signals: bool = False,
        x0_shift: np.ndarray | None = None,
    ) -> tuple[np.ndarray, np.ndarray | None]:
        """Simulate each setting (a list of simulation effects with values): outputs
        (R, E, n, 8) and, with forms, the signals their terms read (R, E, n, n_z)."""
        assert self._U is not None, "prepare() first"
        base = FCCParams()
        t = np.arange(n) * self._dt
        E = self._U.shape[0]
        Us, x0s, mults = [], [], []
        for setting in settings:
            U = self._U[:, :n].copy()
            mult: dict[str, np.ndarray] = {}
            for eff, th in setting:
                if isinstance(eff, FormCandidate):
                    continue
                values = {p.name: float(v) for p, v in zip(eff.params, th, strict=True)}
                sensor = getattr(eff, "sensor", None)
                if sensor is not None:
                    kind, ch = sensor
                    j = _INPUT_SLOT[ch]
                    if kind == "sensor_bias":
                        U[:, :, j] -= values["bias"]
                    else:  # sensor_drift (lags on inputs are not offered)
                        U[:, :, j] -= values["rate_per_h"] * t / 3600.0
                    continue
                obj = eff.factory(**values)
                if callable(getattr(obj, "transform_inputs", None)):
                    U = np.asarray(obj.transform_inputs(t, U), np.float64)
                if callable(getattr(obj, "param_multipliers", None)):
                    for f, v in obj.param_multipliers(t, base).items():
                        mult[f] = mult.get(f, 1.0) * np.broadcast_to(np.asarray(v, float), (n,))
            Us.append(U)
            m0 = min(self.init_samples, n)
            x0 = np.stack([steady_state(base, U[e, :m0].mean(axis=0)) for e in range(E)])
            x0s.append(x0 if x0_shift is None else x0 + x0_shift)
            mults.append(mult)
        R = len(settings)
        fields_ = sorted({f for m in mults for f in m})
        pm = {
            f: np.stack([np.broadcast_to(m.get(f, np.ones(n)), (E, n)) for m in mults]).reshape(
                R * E, n
            )
            for f in fields_
        }
        if table is None and not keep_signals:
            with np.errstate(all="ignore"):
                sim = simulate_inputs(
                    np.concatenate(Us).reshape(R * E, n, 6),
                    param_multipliers=pm or None,
                    x0=np.concatenate(x0s),
                    sample_time_s=self._dt,
                )
            return sim.y_clean.reshape(R, E, n, -1), None
        table = table if table is not None else TermTable([], [])
        theta = np.zeros((R, table.target.size))
        for r, setting in enumerate(settings):
            values = {id(e): th for e, th in setting if isinstance(e, FormCandidate)}
            k = 0
            for f in forms:
                if id(f) in values:
                    theta[r, k : k + len(f.terms)] = values[id(f)]
                k += len(f.terms)
        names = sorted(pm)
        pidx = np.array([[PARAM_INDEX[f] for f in names] or [-1]] * (R * E), np.int64)
        PM = np.ones((R * E, n, max(1, len(names))))
        for j, f in enumerate(names):
            PM[:, :, j] = pm[f]
        Y, Z = simulate_corrected(
            np.concatenate(Us).reshape(R * E, n, 6),
            np.concatenate(x0s),
            np.tile(base.as_array(), (R * E, 1)),
            table,
            np.repeat(theta, E, axis=0),
            sample_time_s=self._dt,
            pidx=pidx,
            PM=PM,
            keep_signals=keep_signals or any(f.is_measurement for f in forms),
        )
        return Y.reshape(R, E, n, -1), None if Z is None else Z.reshape(R, E, n, -1)

    def signals(
        self,
        data: MeasuredData,
        effects: Sequence[Candidate],
        theta: np.ndarray,
        n_samples: int,
        x0_shift: np.ndarray | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Outputs (E, n, 8, Table 1 order) and signals (E, n, n_z) of one parameter row: what
        a form's terms read (:data:`~evaluation.discover.terms.SIGNALS`), from the state
        ``x0_shift`` away from the usual initial state (a stability probe)."""
        if self._data_id != id(data):
            self.prepare(data, n_samples)
        self._dt = data.sample_time_s
        if self.declared:
            effects = [*(c for c, _ in self.declared), *effects]
            theta = np.concatenate([*(v for _, v in self.declared), np.ravel(theta)])
        forms = [e for e in effects if isinstance(e, FormCandidate)]
        table = self.form_table(forms)
        setting, k = [], 0
        for e in effects:
            setting.append((e, np.ravel(theta)[k : k + len(e.params)]))
            k += len(e.params)
        sim = [(e, th) for e, th in setting if self._needs_sim(e)]
        Y, Z = self._simulate([sim], int(n_samples), table, forms, True, x0_shift)
        assert Z is not None
        return Y[0], Z[0]

    def predict(
        self, data: MeasuredData, effects: Sequence[Candidate], thetas: np.ndarray, n_samples: int
    ) -> np.ndarray:
        if self._data_id != id(data):
            self.prepare(data, n_samples)
        self._dt = data.sample_time_s
        thetas = np.atleast_2d(np.asarray(thetas, np.float64))
        B = thetas.shape[0]
        if self.declared:  # accepted effects: part of the model, ahead of the candidates
            effects = [*(c for c, _ in self.declared), *effects]
            fixed = np.concatenate([v for _, v in self.declared])
            thetas = np.hstack([np.tile(fixed, (B, 1)), thetas])
        n = int(n_samples)
        slices, k = [], 0
        for e in effects:
            slices.append(slice(k, k + len(e.params)))
            k += len(e.params)
        sim_idx = [i for i, e in enumerate(effects) if self._needs_sim(e)]
        forms = [e for e in effects if isinstance(e, FormCandidate)]
        table = self.form_table(forms)
        keys = []
        for b in range(B):
            keys.append(
                (
                    n,
                    tuple(
                        (effects[i].id, tuple(np.round(thetas[b, slices[i]], 12))) for i in sim_idx
                    ),
                    tuple(f.id for f in forms),
                )
            )
        sims = {k_: self._cache[k_] for k_ in keys if k_ in self._cache}
        todo = list(dict.fromkeys(k_ for k_ in keys if k_ not in sims))
        if todo:
            key_to_row = {k_: keys.index(k_) for k_ in todo}
            settings = [
                [(effects[i], thetas[key_to_row[k_], slices[i]]) for i in sim_idx] for k_ in todo
            ]
            Y, Z = self._simulate(settings, n, table, forms)
            for j, k_ in enumerate(todo):
                sims[k_] = (Y[j], None if Z is None else Z[j])
                self._cache[k_] = sims[k_]
                while len(self._cache) > self.cache_size:
                    self._cache.popitem(last=False)
        out_idx = [TABLE1.index(c) for c in self.output_channels]
        t = np.arange(n) * self._dt
        result = np.empty((B, self._U.shape[0], n, len(out_idx)))
        for b in range(B):
            Y, Z = sims[keys[b]]
            Y = Y.copy()
            col = 0
            for i, e in enumerate(effects):
                if isinstance(e, FormCandidate):
                    if e.is_measurement:
                        assert table is not None and Z is not None
                        cols = slice(col, col + len(e.terms))
                        vals = term_values(table, Z)[..., cols]
                        Y[..., TABLE1.index(e.channel)] += vals @ thetas[b, slices[i]]
                    col += len(e.terms)
                elif i not in sim_idx:
                    Y = self._apply_output_effect(e, thetas[b, slices[i]], t, Y)
            result[b] = Y[..., out_idx]
        return result

    def _apply_output_effect(
        self, eff: Candidate, th: np.ndarray, t: np.ndarray, Y: np.ndarray
    ) -> np.ndarray:
        values = {p.name: float(v) for p, v in zip(eff.params, th, strict=True)}
        kind, ch = eff.sensor  # type: ignore[attr-defined]
        j = TABLE1.index(ch)
        if kind == "sensor_bias":
            Y[..., j] += values["bias"]
        elif kind == "sensor_drift":
            Y[..., j] += values["rate_per_h"] * t / 3600.0
        else:
            Y[..., j] = first_order_lag(Y[..., j], values["tau_s"], self._dt)
        return Y

    _dt: float = DEFAULT_SAMPLE_TIME_S


def declared_from_report(report: Mapping[str, Any]) -> list[tuple[Candidate, np.ndarray]]:
    """The effects of a loop report (``report.json``'s dict), library ones and forms, with their
    fitted values: what ``PhysicsModel(declared=...)`` takes to accept them into the model."""
    lib, _ = library_candidates()
    out: list[tuple[Candidate, np.ndarray]] = []
    for e in report.get("effects", []):
        if e.get("form") is not None:
            cand: Candidate = form_from_json(e["form"], str(e["id"]))
        elif e.get("id") in lib:
            cand = lib[e["id"]]
        else:
            raise ValueError(
                f"effect {e.get('id')!r} of the report is neither a form nor a library effect "
                f"({sorted(lib)})"
            )
        try:
            values = np.array([float(e["params"][p.name]) for p in cand.params])
        except (KeyError, TypeError) as err:
            raise ValueError(f"effect {e.get('id')!r} lacks parameter {err}") from err
        out.append((cand, values))
    return out
