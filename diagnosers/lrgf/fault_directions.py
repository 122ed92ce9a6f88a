"""Where each fault moves a bank's remaining error: ``lrgf-glr``'s fault directions.

A directional test needs, per fault, the direction the fault takes in the normalised
remaining-error space of the relations. It is learned from the labelled faulty episodes passed
to ``fit`` (``Episode.fault_onset``, ``Episode.scenario``, ``Episode.seed``; the harness passes
its training faults, :attr:`diagnosers.Diagnoser.learns_from_faults`): each faulty episode is
paired with the healthy episode of the same seed among those passed, its *noise twin* (the same
seed draws the same noise and operating program), and the difference of the two episodes'
normalised remaining errors over ``window`` samples from the onset is the fault's signature
without the noise. The mean signature over the seeds, made a unit vector, is the direction.

``fault_scenarios`` and ``fault_seeds`` filter which of the episodes passed give directions.
What is a warning and what an error (both raised or logged before anything is trained):

* no labelled faulty episode at all (whatever ``fault_scenarios`` names): no directions, the
  detector runs its omnibus T² alone and says so once per ``fit`` in the log (a warning):
  recorded data without labelled faults are a normal case, not an error;
* with ``fault_scenarios=None`` (every fault passed), a fault none of whose episodes is on
  ``fault_seeds``: no direction for it, a warning (``fault_seeds`` is a filter: data on other
  seeds, e.g. a user's synthetic records, simply give none);
* a fault that ``fault_scenarios`` names but no episode on ``fault_seeds`` carries, a selected
  episode without its noise twin (the training fault seeds must be among the healthy training
  seeds), or a fault whose every selected episode ended inside the window: an error naming it.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence

import numpy as np

from diagnosers.episode.record import Episode
from fcc_common.validation import IntegerSequence, check, invalid

__all__ = [
    "DEFAULT_FAULT_SEEDS",
    "PAPER_FAULTS",
    "FaultDirections",
    "Pairs",
    "Signature",
    "paired_difference",
]

logger = logging.getLogger(__name__)

#: the faults of a model saved before its directions' names were saved with it (it learned these,
#: in this order, unless ``fault_scenarios`` said otherwise); never a list of the faults to learn
PAPER_FAULTS = ("f1", "f2", "f3", "f4")

#: ``lrgf-glr``'s default ``fault_seeds``: the first three training seeds of the benchmark
#: tracks (``evaluation.tracks.TRAIN_SEED_START`` + 0, 1, 2; a test there keeps them equal),
#: the seeds the directions have always been learned on
DEFAULT_FAULT_SEEDS = (1000, 1001, 1002)


#: per fault, its labelled faulty training episodes, each with its healthy noise twin
Pairs = dict[str, list[tuple[Episode, Episode]]]

#: ``signature(faulty, healthy, end)``: the normalised remaining error of a labelled faulty
#: episode minus that of its healthy twin, over their first ``end`` samples
Signature = Callable[[Episode, Episode, int], np.ndarray]


def paired_difference(normalised: Callable[[np.ndarray], np.ndarray]) -> Signature:
    """The signature of a detector whose normalised remaining error of a record is
    ``normalised(y)``: that of the faulty episode minus that of its healthy twin."""

    def signature(faulty: Episode, healthy: Episode, end: int) -> np.ndarray:
        d = normalised(faulty.y[:end])
        d -= normalised(healthy.y[:end])
        return d

    return signature


class FaultDirections:
    """Learns where each fault moves a detector's normalised remaining error.

    The optional part of ``lrgf-glr``'s directional tests. Args (the hyperparameters
    ``fault_scenarios``, ``fault_seeds``, ``direction_window``): the faults that give directions
    (None: every labelled fault passed, in the order first passed), the seeds whose faulty
    episodes give them (None: every seed passed) and the samples after the onset averaged.
    """

    def __init__(
        self,
        scenarios: Sequence[str] | None = None,
        seeds: Sequence[int] | None = None,
        window: int = 300,
    ) -> None:
        self.scenarios = None if scenarios is None else tuple(scenarios)
        self.seeds = None if seeds is None else list(seeds)
        self.window = window

    def check(self) -> None:
        """Raise ValueError for a fault name that no labelled episode can carry or a seed that
        is not a seed."""
        if self.scenarios is not None:
            for f in self.scenarios:
                if not isinstance(f, str) or f in ("", "nominal", "unknown"):
                    raise invalid(
                        "fault_scenarios",
                        list(self.scenarios),
                        "None or fault names (labels "
                        "of faulty training episodes, not '', 'nominal' or 'unknown')",
                    )
            if len(set(self.scenarios)) != len(self.scenarios):
                raise invalid("fault_scenarios", list(self.scenarios), "distinct fault names")
        if self.seeds is not None:
            check("fault_seeds", self.seeds, IntegerSequence(0, why="seeds of training faults"))

    def saved_faults(self) -> tuple[str, ...]:
        """The faults of a model saved without its directions' names (before they were saved):
        ``fault_scenarios``, or the paper's four it then always learned."""
        return PAPER_FAULTS if self.scenarios is None else self.scenarios

    def pairs(self, episodes: Sequence[Episode]) -> Pairs:
        """Per fault to learn, its selected labelled faulty episodes of ``episodes`` (those with
        a ``fault_onset``), each with its healthy twin there, in the order of ``fault_seeds``
        (else as passed); those that end inside the window are left out. Checked here, before
        anything is trained (module docstring: what is an error, what a warning).
        """
        faulty = [ep for ep in episodes if ep.fault_onset is not None]
        if not faulty:
            logger.warning(
                "no labelled faulty training episode was passed to fit: no fault directions, "
                "the omnibus T² alone (pass the training faults, e.g. the harness's "
                "train_fault_episodes, to learn them)"
            )
            return {}
        twins: dict[int, Episode] = {}
        for ep in episodes:
            if ep.fault_onset is None and ep.seed is not None:
                twins.setdefault(ep.seed, ep)
        given = list(dict.fromkeys(ep.scenario for ep in faulty))
        out: Pairs = {}
        for f in given if self.scenarios is None else self.scenarios:
            selected = self._select([ep for ep in faulty if ep.scenario == f], f, given)
            if selected:  # empty only for a fault passed off fault_seeds (fault_scenarios=None)
                out[f] = self._paired(f, selected, twins)
        if self.scenarios is None and len(out) < len(given):
            left = [f for f in given if f not in out]
            logger.warning(
                "no training episode of fault(s) %s is on fault_seeds=%s: no direction for "
                "them (directions for %s)",
                left,
                self.seeds,
                list(out),
            )
        return out

    def _paired(
        self, fault: str, selected: list[Episode], twins: dict[int, Episode]
    ) -> list[tuple[Episode, Episode]]:
        """``selected`` episodes of ``fault`` with their twins, but those ending in the window."""
        kept = []
        for ep in selected:
            twin = None if ep.seed is None else twins.get(ep.seed)
            if twin is None:
                raise ValueError(
                    f"the training fault {fault} of seed {ep.seed} has no healthy episode of "
                    f"that seed among the training episodes (its noise twin; healthy seeds: "
                    f"{sorted(twins)}): pass the healthy episode of every faulty seed, or "
                    "choose fault_seeds among the healthy ones"
                )
            end = ep.fault_onset + self.window  # type: ignore[operator]
            if ep.n_samples >= end and twin.n_samples >= end:
                kept.append((ep, twin))
        if not kept:
            raise ValueError(f"no training episode of fault {fault} lasted through its window")
        return kept

    def learn(
        self, pairs: Pairs, n_relations: int, signature: Signature
    ) -> tuple[np.ndarray, tuple[str, ...]]:
        """Unit fault directions ``(m, n_relations)`` and the names of their faults, from the
        :meth:`pairs`: the mean of ``signature`` over ``window`` samples from the onset."""
        out = []
        for ps in pairs.values():
            diffs = [self._window(signature, ep, twin) for ep, twin in ps]
            mean = np.mean([d.mean(axis=0) for d in diffs], axis=0)
            out.append(mean / np.linalg.norm(mean))
        return np.array(out).reshape(len(out), n_relations), tuple(pairs)

    def _window(self, signature: Signature, faulty: Episode, twin: Episode) -> np.ndarray:
        """``signature`` of one pair over the ``window`` samples from the onset ``(window, k)``."""
        onset = faulty.fault_onset
        assert onset is not None  # a pair's faulty episode has one
        return signature(faulty, twin, onset + self.window)[onset:]

    def _select(self, of_fault: list[Episode], fault: str, given: list[str]) -> list[Episode]:
        """The episodes of ``fault`` on ``fault_seeds`` (in their order; None: all); a fault
        that ``fault_scenarios`` names must have some."""
        if not of_fault:
            raise ValueError(
                f"fault_scenarios names {fault!r}, but no labelled faulty training episode has "
                f"that scenario (given: {given})"
            )
        if self.seeds is None:
            return of_fault
        selected = [ep for s in self.seeds for ep in of_fault if ep.seed == s]
        if not selected and self.scenarios is not None:
            raise ValueError(
                f"no training episode of fault {fault} has a seed of fault_seeds={self.seeds} "
                f"(its seeds: {sorted({ep.seed for ep in of_fault}, key=str)}): choose "
                "fault_seeds among them, or None for every one"
            )
        return selected
