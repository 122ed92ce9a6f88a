"""Novelty for any detector: the same alarms, plus the samples outside its training regime.

A black-box detector knows the plant only where its healthy training history went. When the
operators move a set point beyond that history, its relations and limits extrapolate and its
alarms say "new regime", not "fault" (``lab/regimes-lab.md``: on the ``regimes`` track the
baselines and ``lrgf-glr-closed`` put 30-50 % of the healthy samples in alarm, almost all of
them while a set point is outside its training range). :class:`RangeGuard` gives a detector
the outcome "outside the training range" (:attr:`~diagnosers.detection.Detection.novelty`):
``fit`` records the range of the set points on the healthy training episodes
(:class:`~diagnosers.stages.operating_range.OperatingRange`), and ``detect`` flags a sample
while a set point is outside it and for ``novelty_hold`` samples after (the plant settles
slowly: the regenerator's loop has a time constant of about 1600 s). Every decision of the
detector is unchanged; the scoring counts no novel sample as a false alarm and reports the novel
share beside r_fd. On open-loop episodes (no set points) nothing is flagged.

One mechanism, many detectors: :func:`novelty_variant` registers ``<name>-novelty`` for a
registered detector class, the class with the guard mixed in and one hyperparameter more
(``novelty_hold``). A variant rather than a new hyperparameter of the base: the base's
:meth:`~diagnosers.contract.DiagnoserContract.result_params`, and so every stored result of it,
stay as they are.

Streaming :meth:`update` returns the base's :class:`~diagnosers.detection.Decision`, which has
no novelty: the flag belongs to the episode's :meth:`detect`.
"""

from __future__ import annotations

import dataclasses
import inspect
from typing import Any, TypeVar

import numpy as np

from diagnosers.detection import Detection
from diagnosers.diagnoser import Diagnoser
from diagnosers.episode.record import Episode
from diagnosers.presets import keyword_init
from diagnosers.registry import register
from diagnosers.stages.operating_range import OperatingRange
from fcc_common.validation import Integer, check, invalid

__all__ = ["NOVELTY_HOLD", "RangeGuard", "novelty_variant"]

D = TypeVar("D", bound=Diagnoser)

#: Samples a novelty flag lasts after the set points return inside their training range:
#: 300 (5 h at 60 s) brought the alarms flagged novel from 0.98 (limits) and 0.96 (pca) at 0 to
#: 0.99 on the wider program's validation episodes, and r_fd outside novelty below 0.01
#: (``lab/regimes_lab.py``).
NOVELTY_HOLD = 300


class RangeGuard:
    """The mixin: fit the training range of the set points, flag the samples outside it.

    It comes first among a variant's bases, so its methods wrap the detector's (``super()`` is
    the detector). The range is fitted on the healthy training episodes only (a detector that
    learns from faults also receives labelled faulty ones; they run the same program).
    """

    novelty_hold: int
    channels_: tuple[str, ...]
    sample_time_s_: float
    range_: OperatingRange

    def _validate_params(self) -> None:
        super()._validate_params()  # type: ignore[misc]
        check("novelty_hold", self.novelty_hold, Integer(0))

    def _fit(self, episodes: list[Episode]) -> None:
        super()._fit(episodes)  # type: ignore[misc]
        healthy = [ep for ep in episodes if ep.fault_onset is None] or episodes
        self.range_ = OperatingRange(hold=int(self.novelty_hold)).fit(healthy)

    def _detect(self, y: np.ndarray) -> Detection:
        det = super()._detect(y)  # type: ignore[misc]
        ep = Episode(y=y, channels=self.channels_, sample_time_s=self.sample_time_s_)
        return dataclasses.replace(det, novelty=self.range_.flag(ep))

    def _get_state(self) -> dict[str, np.ndarray]:
        used = [self.channels_.index(c) for c in self.range_.used]
        return {
            **super()._get_state(),  # type: ignore[misc]
            "range_channels": np.array(used, dtype=np.int64),
            "range_low": self.range_.low,
            "range_high": self.range_.high,
        }

    def _set_state(self, state: dict[str, np.ndarray]) -> None:
        super()._set_state(state)  # type: ignore[misc]
        idx = np.asarray(state["range_channels"]).astype(np.int64).ravel()
        low = np.asarray(state["range_low"], dtype=np.float64).ravel()
        high = np.asarray(state["range_high"], dtype=np.float64).ravel()
        if not (idx.size == low.size == high.size) or np.any(
            (idx < 0) | (idx >= len(self.channels_))
        ):
            raise invalid(
                "range_channels",
                idx.tolist(),
                f"indices in [0, {len(self.channels_)}) with one low and one high each",
            )
        rng = OperatingRange(hold=int(self.novelty_hold))
        rng.used = tuple(self.channels_[int(i)] for i in idx)
        rng.low, rng.high = low, high
        self.range_ = rng


#: parts of a registered name written in capitals in its class name
_ACRONYMS = frozenset({"lrgf", "mem", "glr", "pca", "cva", "dpca", "arx", "n4sid"})


def variant_class_name(name: str) -> str:
    """The class name :func:`novelty_variant` gives ``name`` (``"n4sid-glr-novelty"`` ->
    ``"N4SIDGLRNovelty"``): the module-level name the caller assigns it to, so it pickles."""
    return "".join(p.upper() if p in _ACRONYMS else p.title() for p in name.split("-"))


def _defaults(base: type[Diagnoser]) -> dict[str, Any]:
    """The base's hyperparameters and defaults (its ``__init__``'s keyword-only parameters)."""
    sig = inspect.signature(base.__init__)
    return {
        p.name: p.default
        for p in sig.parameters.values()
        if p.kind is p.KEYWORD_ONLY and p.default is not p.empty
    }


def novelty_variant(base: type[D], *, module: str, hold: int = NOVELTY_HOLD) -> type[D]:
    """Register ``<base.name>-novelty``: ``base`` with :class:`RangeGuard` mixed in.

    The variant keeps every hyperparameter of ``base`` (same defaults, same meaning) and adds
    ``novelty_hold`` (≥ 0 samples, default ``hold``). Assign the result to a module-level name
    of ``module`` (the caller's ``__name__``) equal to :func:`variant_class_name` of its name, so
    that saved models find their class.
    """
    if not base.name:
        raise invalid("base", base.__qualname__, "a registered diagnoser class")
    name = f"{base.name}-novelty"
    defaults = {**_defaults(base), "novelty_hold": hold}
    qualname = variant_class_name(name)
    kept = ", ".join(f"``{k}``" for k in defaults if k != "novelty_hold")
    doc = (
        f"``{base.name}`` that flags the samples outside its training set-point range as novel "
        f"(:class:`~diagnosers.range_guard.RangeGuard`).\n\nHyperparameters: those of "
        f":class:`~{base.__module__}.{base.__qualname__}`, each documented there ({kept}), "
        f"plus ``novelty_hold``: samples a novelty flag lasts after the set points return "
        f"inside their training range (≥ 0, default {hold})."
    )
    cls = type(
        qualname,
        (RangeGuard, base),
        {
            "DEFAULTS": defaults,
            "__init__": keyword_init(defaults),
            "__doc__": doc,
            "__module__": module,
            "__qualname__": qualname,
        },
    )
    return register(name)(cls)  # type: ignore[return-value]
