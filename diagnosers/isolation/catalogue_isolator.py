"""``catalogue-isolator``: a union of specialised isolators that can name two faults, each
with its own onset (issue 43 item 3, the ``concurrent`` track).

A closed loop's faults are of kinds that no single method reads well: a sensor fault is seen
by analytical redundancy (``sensor-validation``), a sticking valve by the variance it puts in
the model's T_rx innovation (``stiction-ukf``), a blower short of air by its loop held off its
set point (``loop-offset``), a process fault or a valve bias by the model's innovations along
its direction (``ukf-glr``). This isolator runs such *members* side by side on every sample,
each with the fault names it may say (its ``classes``: a member's word on another kind is no
evidence), and keeps watching after the first alarm: every member confirms its own fault, so a
second fault is named when its member confirms it, whatever the first one did.

**The composition** (:class:`~diagnosers.isolation.composition.Composition`, a per-sample state
machine; the same code streams and runs a whole episode, so ``update`` equals ``detect``):

1. a member's name is *confirmed* once the member has said it ``confirm`` samples in a row (a
   member may have its own ``confirm``);
2. a confirmed name is *held* (``hold=True``, default): a fault in this benchmark persists, and a
   loop monitor's alarm comes and goes; a later confirmation by the same member replaces it (a
   sensor fault first read as a bias, later as a drift), and a confirmed verdict outside its
   classes clears it (the model first reads a T_rx bias as a valve bias), unless the member
   may name ``several`` faults (each confirmed name is added);
3. **deferral** (``defers_to``): a member's word is no evidence while a member it defers to
   names or holds a fault of its own, and what it named since that member's alarm began is
   dropped when that member confirms (an echo: a process fault makes every sensor look
   inconsistent with the model, and ``sensor-validation`` then names some sensor);
4. the diagnosis is the set of held names, as the training label that names exactly that set
   (``a+b`` for a concurrent column, in any order: :func:`fcc_env.faults.isolation_outcome`),
   and ``"unknown"`` when it matches none (more names than any training label, a combination
   never trained on, or an alarm with nothing confirmed yet): the isolator abstains rather than
   give half an answer, which the track scores as wrong.

Members are registered diagnosers given by name, hyperparameters and classes (presets change
them; the default is :data:`DEFAULT_MEMBERS`, the four above). An isolating member's own
diagnosis is read; a detector member's is the fault named by its most exceeded signal
(``glr[valve-bias,30]`` names ``valve-bias``). Each member is trained on the healthy episodes
and, if it isolates or learns from faults, on the labelled faulty episodes relabelled with the
one name of theirs it claims (a concurrent pair ``a+b`` becomes ``a`` for the member that
claims ``a``); a member that claims none of the training faults is not fitted and not run.
Figures: ``lab/catalogue-isolator.md``.
"""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from diagnosers.contract import Tier
from diagnosers.detection import NO_DIAGNOSIS, UNKNOWN, Decision, Detection, exceedance
from diagnosers.diagnoser import Diagnoser
from diagnosers.episode.record import Episode
from diagnosers.isolation.composition import Composition
from diagnosers.presets import keyword_init
from diagnosers.registry import diagnoser_class, make, register
from fcc_common.validation import Boolean, Integer, check, check_params, invalid
from fcc_env.faults import fault_names
from fcc_env.params import MEASUREMENT_NAMES

__all__ = ["DEFAULT_MEMBERS", "CatalogueIsolator", "signal_fault"]

#: The sensor-fault kinds ``sensor-validation`` names.
SENSOR_KINDS = ("sensor-bias", "sensor-drift", "sensor-stuck", "sensor-noise", "sensor-dropout")

#: The default members: which registered diagnoser, with which hyperparameters, may name which
#: faults. ``ukf-glr`` runs the nominal model (the closed-loop tracks' plant is the nominal
#: one) and tests the directions of the faults it claims plus those it must not confuse them
#: with (a T_rx bias and a sticking valve also move the riser's innovations).
DEFAULT_MEMBERS: list[dict[str, Any]] = [
    {
        "name": "sensor-validation",
        "params": {},
        "classes": list(SENSOR_KINDS),
        # a process or valve fault makes every sensor inconsistent with the model: while the
        # model's directions name such a fault, the sensor check's word is no evidence
        "defers_to": ["ukf-glr"],
    },
    {"name": "stiction-ukf", "params": {}, "classes": ["valve-stiction"]},
    {"name": "loop-offset", "params": {}, "classes": ["blower-capacity"]},
    {
        "name": "ukf-glr",
        "params": {
            "fit_method": "none",
            "estimate_noise": False,
            "online": "never",
            "faults": ["f1", "valve-bias", "sensor-bias"],
        },
        "classes": ["f1", "valve-bias"],
        # a sticking valve's cycle also fits a mean shift of some direction now and then
        "defers_to": ["stiction-ukf"],
        # a T_rx sensor bias first reads as a valve bias for ~550 samples (the loop moves the
        # valve either way), then as the sensor bias it is: the model's word needs longer
        "confirm": 700,
    },
]

_SIGNAL_FAULT = re.compile(r"\[([^,\]]+)[,\]]")


def signal_fault(signal_name: str) -> str | None:
    """The registered fault a detector's signal is named after (``glr[f1,30]`` → ``f1``), or
    ``None`` (``cusum[nis]``, ``T2``)."""
    m = _SIGNAL_FAULT.search(signal_name)
    name = m.group(1) if m else None
    return name if name in fault_names(include_path_faults=True) else None


@dataclasses.dataclass
class _Member:
    """A fitted member: the diagnoser, the names it may say, how its name is read."""

    diagnoser: Diagnoser
    claims: tuple[str, ...]
    #: it may name several faults at once, each confirmed on its own (a detector member)
    several: bool = False
    #: its own confirmation run (None: the isolator's ``confirm``)
    confirm: int | None = None
    #: a detector member: the fault each of its signals names (None: no fault)
    signal_faults: tuple[str | None, ...] = ()

    def name_of(self, d: Decision) -> str:
        if self.diagnoser.isolates:
            return d.diagnosis
        if not d.alarm:
            return NO_DIAGNOSIS
        e = exceedance(d.signal, d.lower, d.upper)
        best, name = 1.0, UNKNOWN
        for f, x in zip(self.signal_faults, e, strict=True):
            if f is not None and x > best:
                best, name = float(x), f
        return name

    def names_of(self, det: Detection) -> np.ndarray:
        if self.diagnoser.isolates:
            assert det.diagnosis is not None
            return det.diagnosis
        e = exceedance(det.signal, det.lower, det.upper)
        named = np.array([f is not None for f in self.signal_faults])
        e = np.where(named[None, :], e, -np.inf)
        j = np.argmax(e, axis=1) if e.shape[1] else np.zeros(len(e), dtype=int)
        best = e[np.arange(len(e)), j] if e.shape[1] else np.full(len(e), -np.inf)
        faults = np.array([f or UNKNOWN for f in self.signal_faults] or [UNKNOWN], dtype=object)
        out = np.where(best > 1.0, faults[j], UNKNOWN)
        return np.where(det.alarm, out, NO_DIAGNOSIS).astype(str)


_KEYS = {"name", "params", "classes"}
_OPTIONAL = {"several", "defers_to", "confirm"}


def _check_members(members: Any) -> list[dict[str, Any]]:
    if not isinstance(members, list | tuple) or not members:
        raise invalid("members", members, "a non-empty list of {name, params, classes} dicts")
    known = fault_names(include_path_faults=True)
    for i, m in enumerate(members):
        if not isinstance(m, dict) or not _KEYS <= set(m) <= {*_KEYS, *_OPTIONAL}:
            raise invalid(
                f"members[{i}]",
                m,
                "a dict with the keys name, params, classes (and several, defers_to, confirm)",
            )
        if not isinstance(m.get("several", False), bool):
            raise invalid(f"members[{i}].several", m["several"], "True or False")
        if "confirm" in m:
            check(f"members[{i}].confirm", m["confirm"], Integer(1, 100_000))
        names = [str(o["name"]) for o in members if isinstance(o, dict) and "name" in o]
        defers = m.get("defers_to", [])
        if not isinstance(defers, list | tuple) or any(
            d not in names or d == m["name"] for d in defers
        ):
            raise invalid(f"members[{i}].defers_to", defers, f"other members' names of {names}")
        cls = diagnoser_class(str(m["name"]))  # ValueError naming the registered ones
        if cls is CatalogueIsolator or issubclass(cls, CatalogueIsolator):
            raise invalid(
                f"members[{i}].name", m["name"], "a diagnoser other than an isolator union"
            )
        if not isinstance(m["params"], dict):
            raise invalid(f"members[{i}].params", m["params"], "a dict of hyperparameters")
        classes = m["classes"]
        if not isinstance(classes, list | tuple) or not classes:
            raise invalid(f"members[{i}].classes", classes, "a non-empty list of fault names")
        bad = [c for c in classes if c not in known]
        if bad:
            raise invalid(f"members[{i}].classes", bad, f"registered faults {list(known)}")
        make(str(m["name"]), **m["params"]).validate_params()
    return list(members)


@register("catalogue-isolator")
class CatalogueIsolator(Diagnoser):
    """A union of specialised isolators that names each fault its member confirms (module
    docstring), two at once included.

    Args:
        members: the members, each ``{"name": registered diagnoser, "params": its
            hyperparameters, "classes": the faults it may name}`` and optionally
            ``"several": True`` (it may name several at once, each held); default
            :data:`DEFAULT_MEMBERS`.
        confirm: samples in a row a member must say a name before it counts, in [1, 100000];
            default 30 (5 minutes at 10 s).
        hold: keep a confirmed name after its member's alarm ends; default True.

    Attributes:
        classes_: the training fault labels whose every name some member claims.
        member_names_: the members that were fitted (those claiming a training fault).
    """

    isolates: ClassVar[bool] = True
    #: grey box: its default members run the published model (``sensor-validation``,
    #: ``ukf-glr``); a union of black-box members is no more than they are
    tier: ClassVar[Tier] = Tier.GREY_BOX
    #: its classes are the registry's faults, which synthetic labels do not name
    physical_classes: ClassVar[bool] = True
    #: the default members' model reads every Table 1 channel
    REQUIRED_CHANNELS: ClassVar[tuple[str, ...]] = MEASUREMENT_NAMES
    CONSTRAINTS: ClassVar[dict[str, Any]] = {
        "confirm": Integer(1, 100_000),
        "hold": Boolean(),
    }
    DEFAULTS: ClassVar[dict[str, Any]] = {
        "members": DEFAULT_MEMBERS,
        "confirm": 30,
        "hold": True,
    }
    __init__ = keyword_init(DEFAULTS)

    members: list[dict[str, Any]]
    confirm: int
    hold: bool

    @classmethod
    def fast_params(cls) -> dict[str, Any]:
        ukf = {**diagnoser_class("ukf-glr").fast_params(), "faults": ["f1", "f2"]}
        return {"members": [{"name": "ukf-glr", "params": ukf, "classes": ["f1", "f2"]}]}

    def _validate_params(self) -> None:
        check_params(
            {k: v for k, v in self.get_params().items() if k in self.CONSTRAINTS}, self.CONSTRAINTS
        )
        _check_members(self.members)

    # ---- fitting -------------------------------------------------------------------------------
    def _fit(self, episodes: list[Episode]) -> None:
        healthy = [ep for ep in episodes if ep.fault_onset is None]
        faulty = [ep for ep in episodes if ep.fault_onset is not None]
        labels = sorted({ep.scenario for ep in faulty})
        parts = {p for label in labels for p in label.split("+")}
        self.members_: list[_Member] = []
        self.member_names_: tuple[str, ...] = ()
        claimed: set[str] = set()
        for spec in self.members:
            claims = tuple(c for c in spec["classes"] if c in parts)
            if not claims:
                continue
            d = make(spec["name"], **spec["params"])
            assert isinstance(d, Diagnoser)
            own = [
                dataclasses.replace(ep, scenario=mine[0])
                for ep in faulty
                if len(mine := [p for p in ep.scenario.split("+") if p in claims]) == 1
            ]
            d.fit(healthy + own if d.isolates or d.learns_from_faults else healthy)
            self.members_.append(
                self._member(d, claims, bool(spec.get("several", False)), spec.get("confirm"))
            )
            self.member_names_ += (spec["name"],)
            claimed.update(claims)
        fitted = list(self.member_names_)
        self.defers_ = [
            tuple(fitted.index(d) for d in spec.get("defers_to", []) if d in fitted)
            for spec in self.members
            if spec["name"] in fitted and any(c in parts for c in spec["classes"])
        ]
        self.classes_ = tuple(lab for lab in labels if set(lab.split("+")) <= claimed)
        if not self.classes_:
            raise ValueError(
                f"catalogue-isolator: no member claims every name of any training fault label "
                f"{labels}; the members claim {sorted({c for m in self.members for c in m['classes']})}"
            )
        self._finish()

    @staticmethod
    def _member(
        d: Diagnoser, claims: tuple[str, ...], several: bool, confirm: int | None
    ) -> _Member:
        faults = () if d.isolates else tuple(signal_fault(s) for s in d.signal_names_)
        return _Member(d, claims, several, confirm, faults)

    def _new_composition(self) -> Composition:
        """The members' composition in a fresh state (the fitted one, or a whole episode's)."""
        return Composition(
            [m.claims for m in self.members_],
            self.classes_,
            confirm=self.confirm,
            hold=self.hold,
            several=[m.several for m in self.members_],
            defers=self.defers_,
            confirms=[m.confirm for m in self.members_],
        )

    def _finish(self) -> None:
        self.signal_names_ = (
            *(
                f"{name}: {s}"
                for name, m in zip(self.member_names_, self.members_, strict=True)
                for s in m.diagnoser.signal_names_
            ),
            "faults named",
        )
        self.composition_ = self._new_composition()

    # ---- detection -----------------------------------------------------------------------------
    def _reset(self) -> None:
        for m in self.members_:
            m.diagnoser.reset()
        self.composition_.reset()

    def _decision(self, decisions: list[Decision], alarm: bool, diagnosis: str) -> Decision:
        n_named = float(len(self.composition_.named()))
        return Decision(
            alarm=alarm,
            signal=np.concatenate([*(d.signal for d in decisions), [n_named]]),
            lower=np.concatenate([*(d.lower for d in decisions), [-np.inf]]),
            upper=np.concatenate([*(d.upper for d in decisions), [0.5]]),
            residual=np.concatenate([*(np.atleast_1d(d.residual) for d in decisions), [n_named]]),
            diagnosis=diagnosis,
            class_scores=np.array([float(c == diagnosis) for c in self.classes_]),
        )

    def _update(self, y: np.ndarray) -> Decision:
        decisions = [m.diagnoser.update(y) for m in self.members_]
        alarm, diagnosis = self.composition_.step(
            [d.alarm for d in decisions],
            [m.name_of(d) for m, d in zip(self.members_, decisions, strict=True)],
        )
        return self._decision(decisions, alarm, diagnosis)

    def member_detections(self, episode: Episode) -> list[Detection]:
        """Each fitted member's detection of ``episode`` (:attr:`member_names_` order)."""
        self._check_episode(episode)
        return [m.diagnoser.detect(episode) for m in self.members_]

    def member_outputs(self, episode: Episode) -> list[tuple[np.ndarray, np.ndarray]]:
        """Each fitted member's ``(alarm (T,), name (T,))`` on ``episode``, as the composition
        reads them (a lab records them to try its settings offline)."""
        dets = self.member_detections(episode)
        return [(d.alarm, m.names_of(d)) for m, d in zip(self.members_, dets, strict=True)]

    def compose(
        self, outputs: list[tuple[np.ndarray, np.ndarray]]
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The composition of the members' :meth:`member_outputs` over a whole episode, from a
        fresh state: ``(alarm (T,), diagnosis (T,), names held (T,))``."""
        comp = self._new_composition()
        T = len(outputs[0][0])
        alarm, diagnosis, n_named = np.zeros(T, bool), np.empty(T, dtype=object), np.zeros(T)
        for k in range(T):
            alarm[k], diagnosis[k] = comp.step(
                [bool(a[k]) for a, _ in outputs], [str(n[k]) for _, n in outputs]
            )
            n_named[k] = len(comp.named())
        return alarm, diagnosis.astype(str), n_named

    def _detect(self, y: np.ndarray) -> Detection:
        ep = Episode(y, channels=self.channels_, sample_time_s=self.sample_time_s_)
        dets = [m.diagnoser.detect(ep) for m in self.members_]
        outputs = [(d.alarm, m.names_of(d)) for m, d in zip(self.members_, dets, strict=True)]
        alarm, diagnosis, n_named = self.compose(outputs)
        col = n_named[:, None]
        T = len(y)
        return Detection(
            alarm=alarm,
            signal=np.concatenate([*(d.signal for d in dets), col], axis=1),
            lower=np.concatenate([*(d.lower for d in dets), np.full((T, 1), -np.inf)], axis=1),
            upper=np.concatenate([*(d.upper for d in dets), np.full((T, 1), 0.5)], axis=1),
            residual=np.concatenate([*(d.residual.reshape(T, -1) for d in dets), col], axis=1),
            signal_names=self.signal_names_,
            diagnosis=diagnosis,
            class_scores=(diagnosis[:, None] == np.array(self.classes_)[None, :]).astype(float),
            class_names=self.classes_,
        )

    # ---- persistence ---------------------------------------------------------------------------
    def _get_state(self) -> dict[str, np.ndarray]:
        return {
            "classes": np.array(self.classes_, dtype=str),
            "member_names": np.array(self.member_names_, dtype=str),
            "claims": np.array(["|".join(m.claims) for m in self.members_], dtype=str),
            "several": np.array([m.several for m in self.members_], dtype=bool),
            "defers": np.array(["|".join(map(str, d)) for d in self.defers_], dtype=str),
            # float: the loader's finiteness check reads it (0: the isolator's ``confirm``)
            "confirms": np.array([m.confirm or 0 for m in self.members_], dtype=np.float64),
        }

    def _set_state(self, state: dict[str, np.ndarray]) -> None:
        self.classes_ = tuple(str(c) for c in state["classes"])
        self.member_names_ = tuple(str(n) for n in state["member_names"])
        self._claims = [tuple(str(c).split("|")) for c in state["claims"]]
        self._several = [bool(x) for x in np.asarray(state["several"]).reshape(-1)]
        self.defers_ = [
            tuple(int(i) for i in str(d).split("|") if i)
            for d in np.asarray(state["defers"]).reshape(-1)
        ]
        confirms = np.asarray(state["confirms"], dtype=np.float64).reshape(-1)
        if np.any(confirms < 0) or np.any(confirms != np.round(confirms)):
            raise ValueError(f"saved confirms must be whole numbers >= 0, got {confirms.tolist()}")
        self._confirms = [int(c) or None for c in confirms]
        if not len(self._claims) == len(self._several) == len(self.member_names_):
            raise ValueError("saved claims, several and member_names differ in length")

    def _save_extra(self, directory: Path) -> None:
        for i, m in enumerate(self.members_):
            m.diagnoser.save(directory / f"member{i}")

    def _load_extra(self, directory: Path) -> None:
        self.members_ = []
        saved = zip(self._claims, self._several, self._confirms, strict=True)
        for i, (claims, several, confirm) in enumerate(saved):
            d = Diagnoser.load(directory / f"member{i}")
            if d.name != self.member_names_[i]:
                raise ValueError(
                    f"{directory / f'member{i}'} holds a {d.name!r}, the saved isolator names "
                    f"{self.member_names_[i]!r}"
                )
            self.members_.append(self._member(d, claims, several, confirm))
        self._finish()
