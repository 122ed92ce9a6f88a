"""The per-sample composition of ``catalogue-isolator``'s members: which faults are named
(:class:`Composition`; the rules are :mod:`diagnosers.isolation.catalogue_isolator`'s, steps 1-4).

Pure: it reads each member's alarm and name per sample, and holds what it needs to decide the
next one; the same code streams and runs a whole episode, so ``update`` equals ``detect``.
"""

from __future__ import annotations

from diagnosers.detection import NO_DIAGNOSIS, UNKNOWN

__all__ = ["Composition"]


class Composition:
    """The per-sample union of the members' confirmed names (module docstring of
    :mod:`diagnosers.isolation.catalogue_isolator`, steps 1-4).

    Args:
        claims: per member, the names it may say (others are no evidence).
        classes: the answers the isolator may give: each a name or ``a+b`` (its set counts).
        confirm: samples in a row a member must say a name before it is confirmed, ≥ 1.
        hold: keep a confirmed name after its member's alarm ends.
        several: per member, whether it may hold several names at once (default: none may).
        defers: per member, the members it defers to (their indexes; default: none).
        confirms: per member, its own confirmation run (``None``: ``confirm``).
        name_confirms: per member, the run some of its names need instead (a name that no
            other fault's first samples imitate may be confirmed sooner; default: none).
        precedes: per member, ``None`` (default) or a number of samples: a run of its name
            that began more than that many samples before the alarm of a member it defers to
            is not deferred, nor dropped as that member's echo (its fault came first).

    >>> c = Composition([("a",), ("b",)], ("a+b",), confirm=2, hold=True)
    >>> [c.step([True, False], ["a", ""]) for _ in range(2)]
    [(True, 'unknown'), (True, 'unknown')]
    >>> [c.step([False, True], ["", "b"]) for _ in range(2)]
    [(True, 'unknown'), (True, 'a+b')]
    """

    def __init__(
        self,
        claims: list[tuple[str, ...]],
        classes: tuple[str, ...],
        *,
        confirm: int,
        hold: bool,
        several: list[bool] | None = None,
        defers: list[tuple[int, ...]] | None = None,
        confirms: list[int | None] | None = None,
        name_confirms: list[dict[str, int]] | None = None,
        precedes: list[int | None] | None = None,
    ) -> None:
        self.claims = [frozenset(c) for c in claims]
        self.by_set = {frozenset(c.split("+")): c for c in classes}
        self.confirm = int(confirm)
        self.hold = bool(hold)
        self.several = list(several) if several is not None else [False] * len(claims)
        self.defers = [tuple(d) for d in defers] if defers is not None else [()] * len(claims)
        own = confirms if confirms is not None else [None] * len(claims)
        self.confirms = [int(confirm) if c is None else int(c) for c in own]
        by_name = name_confirms if name_confirms is not None else [{}] * len(claims)
        self.name_confirms = [{str(n): int(v) for n, v in d.items()} for d in by_name]
        first = precedes if precedes is not None else [None] * len(claims)
        self.precedes = [None if p is None else int(p) for p in first]
        self.reset()

    def reset(self) -> None:
        n = len(self.claims)
        self.run_name = [""] * n
        self.run_len = [0] * n
        #: per member, the sample its current run began
        self.run_start = [0] * n
        #: per member, its held names with the sample each was confirmed at
        self.held: list[dict[str, int]] = [{} for _ in range(n)]
        #: per member, its held names with the sample the confirmed run began
        self.held_run: list[dict[str, int]] = [{} for _ in range(n)]
        #: per member, the sample the alarm behind its held names began
        self.held_since = [0] * n
        #: per member, the sample its current alarm began (the next one while not alarmed)
        self.alarm_since = [0] * n
        self.k = 0

    def named(self) -> tuple[str, ...]:
        """The held names, first confirmed first (duplicates once)."""
        order = sorted((k, name) for held in self.held for name, k in held.items())
        return tuple(dict.fromkeys(name for _, name in order))

    def _explains(self, o: int, m: int, said: str, name: str) -> bool:
        """Whether member ``o`` (saying ``said``) explains member ``m``'s ``name`` now: it names
        or holds a fault of its own, and ``m``'s run did not begin before its alarm (by more
        than ``m``'s ``precedes``)."""
        own = said in self.claims[o]
        if not own and not self.held[o]:
            return False
        first = self.precedes[m]
        if first is None or not name or name != self.run_name[m] or not self.run_len[m]:
            return True
        since = min(
            self.held_since[o] if self.held[o] else self.k,
            self.alarm_since[o] if own else self.k,
        )
        return self.run_start[m] + first >= since

    def step(self, alarms: list[bool], names: list[str]) -> tuple[bool, str]:
        """One sample: each member's alarm and name → ``(alarm, diagnosis)``."""
        for m, (alarm, name) in enumerate(zip(alarms, names, strict=True)):
            if not alarm:
                self.alarm_since[m] = self.k + 1
            # deferred: another member names, or holds, a fault of its own, which explains this
            # one's alarm (a process fault makes every sensor look inconsistent with the model)
            if any(self._explains(o, m, names[o], name) for o in self.defers[m]):
                name = ""
            if name and name != UNKNOWN:
                same = name == self.run_name[m]
                self.run_len[m] = self.run_len[m] + 1 if same else 1
                self.run_start[m] = self.run_start[m] if same else self.k
                self.run_name[m] = name
            else:
                self.run_name[m], self.run_len[m] = "", 0
            held = self.held[m]
            need = self.name_confirms[m].get(name, self.confirms[m])
            if self.run_len[m] >= need and name not in held:
                if name not in self.claims[m]:
                    if not self.several[m]:
                        held.clear()  # its verdict is now a fault it does not name
                else:
                    if not self.several[m]:
                        held.clear()  # a member that names one fault replaces its own word
                    if not held:
                        self.held_since[m] = self.alarm_since[m]
                    held[name] = self.k
                    self.held_run[m][name] = self.run_start[m]
                    # what a deferring member named since this member's alarm began was this
                    # fault's echo: explained, dropped (a name it held before stays)
                    start = self.alarm_since[m]
                    for other, defers in enumerate(self.defers):
                        if m in defers:
                            first = self.precedes[other]
                            echo = [
                                n
                                for n, k in self.held[other].items()
                                if (k if first is None else self.held_run[other][n] + first)
                                >= start
                            ]
                            for n in echo:
                                del self.held[other][n]
            if not self.hold and not alarm:
                held.clear()
        self.k += 1
        named = self.named()
        alarm = any(alarms) or bool(named)
        if not alarm:
            return False, NO_DIAGNOSIS
        return True, self.by_set.get(frozenset(named), UNKNOWN)
