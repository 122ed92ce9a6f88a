"""The alarm stage's protocol: what every stage does, whatever its statistics.

A detector's alarm stage turns the *normalised remaining error* ``e`` of its models (one column
per relation, ``(T, k)`` for a record, ``(k,)`` for a sample) into decisions. Every stage here
(:class:`~diagnosers.stages.ewma_stage.EWMAStage`, :class:`~diagnosers.stages.directional_stage.
DirectionalStage`) follows :class:`AlarmStage`, so a detector runs any of them with one
streaming and persistence skeleton (:class:`diagnosers.lrgf.bank_detector.BankDetector`) and a
reference row runs them on a perfect model (:mod:`evaluation.tracks.oracle`).

The conventions:

* **warm-up**: while ``warm`` (the first ``warm_up`` samples of a record) a stage reads a zero
  error whatever ``e`` holds, and sets no limit (no alarm): its filters start after it;
* **batch = stream**: :meth:`AlarmStage.detect` on a record equals :meth:`~AlarmStage.reset`
  then :meth:`~AlarmStage.step` on every sample (alarms and limits exactly, statistics up to
  rounding where the batch path computes them vectorised);
* **what a sample carries besides ``e``**: ``residual`` (what the decision reports, usually
  ``output − centre``), ``output`` and ``centre`` (a band rule draws its band around the
  centre), ``phi`` (regressors of a regression baseline); a stage ignores what it does not use;
* **hyperparameters**: the class attribute ``DEFAULTS`` (name → default, in signature order)
  and ``CONSTRAINTS`` (name → :mod:`fcc_common.validation` constraint) are written once, on the
  stage; a detector takes them into its own tables under the same names.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, ClassVar, Protocol, runtime_checkable

import numpy as np

from diagnosers.detection import Decision, Detection
from diagnosers.stages.alarm import LimitMethod
from fcc_common.validation import Options, Real

__all__ = ["SHARED_CONSTRAINTS", "AlarmStage", "stage_constraints"]


@runtime_checkable
class AlarmStage(Protocol):
    """From normalised remaining errors to decisions (module docstring)."""

    #: the stage's hyperparameters and their defaults, in signature order
    DEFAULTS: ClassVar[Mapping[str, Any]]
    #: their constraints (:func:`fcc_common.validation.check_params`)
    CONSTRAINTS: ClassVar[Mapping[str, Any]]

    def fit(self, norm: Sequence[np.ndarray], *args: Any, **kwargs: Any) -> AlarmStage:
        """Learn the limits from healthy normalised error records ``norm`` (``(T, k)`` each,
        past their warm-up); a stage may take more (fault directions, regressors)."""
        ...

    def reset(self) -> None:
        """Fresh streaming state (filters, counters) before a record."""

    def step(
        self,
        e: np.ndarray,
        *,
        warm: bool,
        residual: np.ndarray,
        output: np.ndarray | None = None,
        centre: np.ndarray | None = None,
        phi: np.ndarray | None = None,
    ) -> Decision:
        """The decision of one sample with normalised error ``e`` ``(k,)``."""
        ...

    def detect(
        self,
        e: np.ndarray,
        *,
        warm_up: int,
        residual: np.ndarray,
        names: Sequence[str],
        output: np.ndarray | None = None,
        centre: np.ndarray | None = None,
        phi: np.ndarray | None = None,
    ) -> Detection:
        """The decisions of a whole record ``e`` ``(T, k)`` (the other arrays row by row) as one
        :class:`~diagnosers.detection.Detection` whose signals are called ``names``, from a
        fresh :meth:`reset`; equal to :meth:`step` on every row."""
        ...

    def signal_names(self, names: Sequence[str]) -> tuple[str, ...]:
        """The names of the signals, given the names the stage labels them by (the relations'
        outputs, or the fault directions')."""
        ...

    def get_state(self) -> dict[str, np.ndarray]:
        """The learned numeric state as named arrays (what a saved detector stores)."""
        ...

    def set_state(self, state: Mapping[str, np.ndarray]) -> None:
        """Inverse of :meth:`get_state`; a missing array raises ``ValueError`` naming it."""


#: constraints of the hyperparameters that several stages have, each written once
SHARED_CONSTRAINTS: dict[str, Any] = {
    "false_alarm_target": Real(0, 0.5, closed="neither"),
    "ewma_lambda": Real(0, 1, closed="right"),
    "limit_method": Options(LimitMethod),
    "threshold_margin": Real(0.5, 10),
}


def stage_constraints(defaults: Mapping[str, Any], own: Mapping[str, Any]) -> dict[str, Any]:
    """A stage's ``CONSTRAINTS``: for each hyperparameter of ``defaults``, in their order, its
    own constraint in ``own`` or the shared one (:data:`SHARED_CONSTRAINTS`).

    >>> list(stage_constraints({"ewma_lambda": 0.3, "n": 1}, {"n": Real(0)}))
    ['ewma_lambda', 'n']
    """
    table = {**SHARED_CONSTRAINTS, **own}
    return {name: table[name] for name in defaults}
