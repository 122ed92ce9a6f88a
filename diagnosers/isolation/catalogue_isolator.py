"""``catalogue-isolator``: a union of specialised isolators that can name two faults, each
with its own onset (issue 43 item 3, the ``concurrent`` track).

A closed loop's faults are of kinds that no single method reads well: a sensor fault is seen
by analytical redundancy (``sensor-validation``), a sticking valve by the variance it puts in
the model's T_rx innovation (``stiction-ukf``), a blower short of air by the metered air
falling short of the air loop's command (``air-deficit``), a process fault or a valve bias by the model's innovations along
its direction (``ukf-glr``). This isolator runs such *members* side by side on every sample,
each with the fault names it may say (its ``classes``: a member's word on another kind is no
evidence), and keeps watching after the first alarm: every member confirms its own fault, so a
second fault is named when its member confirms it, whatever the first one did.

**The composition** (:class:`~diagnosers.isolation.composition.Composition`, a per-sample state
machine; the same code streams and runs a whole episode, so ``update`` equals ``detect``):

1. a member's name is *confirmed* once the member has said it ``confirm`` samples in a row (a
   member may have its own ``confirm``, and a run per name, ``confirm_names``);
2. a confirmed name is *held* (``hold=True``, default): a fault in this benchmark persists, and a
   loop monitor's alarm comes and goes; a later confirmation by the same member replaces it (a
   sensor fault first read as a bias, later as a drift), and a confirmed verdict outside its
   classes clears it (the model first reads a T_rx bias as a valve bias), unless the member
   may name ``several`` faults (each confirmed name is added);
3. **deferral** (``defers_to``): a member's word is no evidence while a member it defers to
   names or holds a fault of its own, and what it named since that member's alarm began is
   dropped when that member confirms (an echo: a process fault makes every sensor look
   inconsistent with the model, and ``sensor-validation`` then names some sensor); with
   ``precedes`` = N, a run of the member's name that began more than N samples before that
   member's alarm is neither deferred nor dropped: its fault came first (an f1 that a sticking
   valve follows before the model's 700 samples are up);
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
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from diagnosers.contract import Tier
from diagnosers.detection import Decision, Detection
from diagnosers.diagnoser import Diagnoser
from diagnosers.episode.record import Episode
from diagnosers.isolation.catalogue_members import Member, check_members, name_runs, signal_fault
from diagnosers.isolation.composition import Composition
from diagnosers.presets import keyword_init
from diagnosers.registry import diagnoser_class, make, register
from fcc_common.validation import Boolean, Integer, check_params
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
    # the air loop's command against the metered air: a capped blower shows while the loop
    # asks for more than the cap, whatever the set points do (``loop-offset``, the control
    # error held off its set point, named 7 of 12 dev episodes' blowers against 11 of 12)
    {"name": "air-deficit", "params": {}, "classes": ["blower-capacity"]},
    {
        "name": "ukf-glr",
        "params": {
            "fit_method": "none",
            "estimate_noise": False,
            "online": "never",
            "faults": ["f1", "valve-bias", "sensor-bias"],
        },
        "classes": ["f1", "valve-bias"],
        # a sticking valve's cycle also fits a mean shift of some direction now and then, and
        # a capped blower's colder bed reads as f1 after a while
        "defers_to": ["stiction-ukf", "air-deficit"],
        # a T_rx sensor bias first reads as a valve bias for ~550 samples (the loop moves the
        # valve either way), then as the sensor bias it is: the model's word needs longer
        "confirm": 700,
        # ... so its f1 or valve bias may still be running when a second fault's member
        # alarms: a run begun 300 samples before that alarm is its own (dev seeds: 150-400
        # name every f1 and no f1 on a sticking valve alone; 0-100 named one)
        "precedes": 300,
    },
]


@register("catalogue-isolator")
class CatalogueIsolator(Diagnoser):
    """A union of specialised isolators that names each fault its member confirms (module
    docstring), two at once included.

    Args:
        members: the members, each ``{"name": registered diagnoser, "params": its
            hyperparameters, "classes": the faults it may name}`` and optionally
            ``"several": True`` (it may name several at once, each held), ``"defers_to"``
            (other members' names), ``"confirm"`` (its own run, in [1, 100000]),
            ``"confirm_names"`` (``{name: run}`` for some of its classes), ``"precedes"``
            (samples in [0, 100000], module docstring step 3); default
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
        check_members(self.members, CatalogueIsolator)

    # ---- fitting -------------------------------------------------------------------------------
    def _fit(self, episodes: list[Episode]) -> None:
        healthy = [ep for ep in episodes if ep.fault_onset is None]
        faulty = [ep for ep in episodes if ep.fault_onset is not None]
        labels = sorted({ep.scenario for ep in faulty})
        parts = {p for label in labels for p in label.split("+")}
        self.members_: list[Member] = []
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
            by_name = {n: int(v) for n, v in spec.get("confirm_names", {}).items() if n in claims}
            self.members_.append(
                self._member(
                    d,
                    claims,
                    bool(spec.get("several", False)),
                    spec.get("confirm"),
                    by_name,
                    spec.get("precedes"),
                )
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
        d: Diagnoser,
        claims: tuple[str, ...],
        several: bool,
        confirm: int | None,
        name_confirms: dict[str, int] | None = None,
        precedes: int | None = None,
    ) -> Member:
        faults = () if d.isolates else tuple(signal_fault(s) for s in d.signal_names_)
        return Member(d, claims, several, confirm, faults, dict(name_confirms or {}), precedes)

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
            name_confirms=[m.name_confirms for m in self.members_],
            precedes=[m.precedes for m in self.members_],
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
            "name_confirms": np.array(
                [";".join(f"{n}={v}" for n, v in m.name_confirms.items()) for m in self.members_],
                dtype=str,
            ),
            # float: the loader's finiteness check reads it (-1: every run deferred)
            "precedes": np.array(
                [-1 if m.precedes is None else m.precedes for m in self.members_],
                dtype=np.float64,
            ),
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
        # absent from an isolator saved before per-name runs existed
        saved = state.get("name_confirms", np.array([""] * len(confirms)))
        self._name_confirms = [name_runs(str(x)) for x in np.asarray(saved).reshape(-1)]
        first = np.asarray(state.get("precedes", -np.ones(len(confirms))), dtype=np.float64)
        if np.any(first < -1) or np.any(first != np.round(first)):
            raise ValueError(f"saved precedes must be whole numbers >= -1, got {first.tolist()}")
        self._precedes = [None if p < 0 else int(p) for p in first.reshape(-1)]
        if not len(self._claims) == len(self._several) == len(self.member_names_):
            raise ValueError("saved claims, several and member_names differ in length")

    def _save_extra(self, directory: Path) -> None:
        for i, m in enumerate(self.members_):
            m.diagnoser.save(directory / f"member{i}")

    def _load_extra(self, directory: Path) -> None:
        self.members_ = []
        saved = zip(
            self._claims,
            self._several,
            self._confirms,
            self._name_confirms,
            self._precedes,
            strict=True,
        )
        for i, (claims, several, confirm, by_name, first) in enumerate(saved):
            d = Diagnoser.load(directory / f"member{i}")
            if d.name != self.member_names_[i]:
                raise ValueError(
                    f"{directory / f'member{i}'} holds a {d.name!r}, the saved isolator names "
                    f"{self.member_names_[i]!r}"
                )
            self.members_.append(self._member(d, claims, several, confirm, by_name, first))
        self._finish()
