"""The members of ``catalogue-isolator``: how a member's word is read (:class:`Member`), what
a member spec may hold (:func:`check_members`), the saved per-name runs (:func:`name_runs`).
"""

from __future__ import annotations

import dataclasses
import re
from typing import Any

import numpy as np

from diagnosers.detection import NO_DIAGNOSIS, UNKNOWN, Decision, Detection, exceedance
from diagnosers.diagnoser import Diagnoser
from diagnosers.registry import diagnoser_class, make
from fcc_common.validation import Integer, check, invalid
from fcc_env.faults import fault_names

__all__ = ["Member", "check_members", "name_runs", "signal_fault"]

_SIGNAL_FAULT = re.compile(r"\[([^,\]]+)[,\]]")


def signal_fault(signal_name: str) -> str | None:
    """The registered fault a detector's signal is named after (``glr[f1,30]`` → ``f1``), or
    ``None`` (``cusum[nis]``, ``T2``)."""
    m = _SIGNAL_FAULT.search(signal_name)
    name = m.group(1) if m else None
    return name if name in fault_names(include_path_faults=True) else None


@dataclasses.dataclass
class Member:
    """A fitted member: the diagnoser, the names it may say, how its name is read."""

    diagnoser: Diagnoser
    claims: tuple[str, ...]
    #: it may name several faults at once, each confirmed on its own (a detector member)
    several: bool = False
    #: its own confirmation run (None: the isolator's ``confirm``)
    confirm: int | None = None
    #: a detector member: the fault each of its signals names (None: no fault)
    signal_faults: tuple[str | None, ...] = ()
    #: the run some of its names need instead of ``confirm``
    name_confirms: dict[str, int] = dataclasses.field(default_factory=dict)
    #: a run begun this many samples before the alarm of a member it defers to is no echo
    #: (None: every run is deferred)
    precedes: int | None = None

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
_OPTIONAL = {"several", "defers_to", "confirm", "confirm_names", "precedes"}


def check_members(members: Any, union: type) -> list[dict[str, Any]]:
    """``members`` checked (each a ``{name, params, classes, ...}`` dict of a registered
    diagnoser other than ``union`` or its subclasses); a clear error names the bad entry."""
    if not isinstance(members, list | tuple) or not members:
        raise invalid("members", members, "a non-empty list of {name, params, classes} dicts")
    known = fault_names(include_path_faults=True)
    for i, m in enumerate(members):
        if not isinstance(m, dict) or not _KEYS <= set(m) <= {*_KEYS, *_OPTIONAL}:
            raise invalid(
                f"members[{i}]",
                m,
                "a dict with the keys name, params, classes (and several, defers_to, confirm, "
                "confirm_names, precedes)",
            )
        if not isinstance(m.get("several", False), bool):
            raise invalid(f"members[{i}].several", m["several"], "True or False")
        if "confirm" in m:
            check(f"members[{i}].confirm", m["confirm"], Integer(1, 100_000))
        if m.get("precedes") is not None:
            check(f"members[{i}].precedes", m["precedes"], Integer(0, 100_000))
        by_name = m.get("confirm_names", {})
        if not isinstance(by_name, dict) or any(n not in m.get("classes", ()) for n in by_name):
            raise invalid(
                f"members[{i}].confirm_names", by_name, "a dict of the member's classes to runs"
            )
        for n, v in by_name.items():
            check(f"members[{i}].confirm_names[{n!r}]", v, Integer(1, 100_000))
        names = [str(o["name"]) for o in members if isinstance(o, dict) and "name" in o]
        defers = m.get("defers_to", [])
        if not isinstance(defers, list | tuple) or any(
            d not in names or d == m["name"] for d in defers
        ):
            raise invalid(f"members[{i}].defers_to", defers, f"other members' names of {names}")
        cls = diagnoser_class(str(m["name"]))  # ValueError naming the registered ones
        if issubclass(cls, union):
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


def name_runs(text: str) -> dict[str, int]:
    """``"f1=150;valve-bias=700"`` → ``{"f1": 150, "valve-bias": 700}`` (a saved member's)."""
    out: dict[str, int] = {}
    for item in filter(None, text.split(";")):
        name, _, run = item.partition("=")
        if not run.isdigit() or int(run) < 1:
            raise ValueError(f"saved name_confirms item {item!r} is not name=run with run >= 1")
        out[name] = int(run)
    return out
