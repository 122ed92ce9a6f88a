"""The common protocol of the model adapters: candidates, their parameters, fit results.

A declared model plugs into the loop as a :class:`ModelAdapter`; a candidate missing effect is
any object with an ``id`` and a tuple of :class:`ParamInfo` (:class:`Candidate`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

from evaluation.discover.data import MeasuredData

__all__ = ["Candidate", "FitResult", "ModelAdapter", "ParamInfo"]


@dataclass(frozen=True)
class ParamInfo:
    """One parameter of a candidate: bounds, the value meaning "no effect", a start grid."""

    name: str
    typical: float  # a realistic size; sets the finite-difference step
    low: float
    high: float
    null: float = 0.0
    unit: str = ""
    grid: tuple[float, ...] = ()


@runtime_checkable
class Candidate(Protocol):
    """A candidate missing effect: an id and its parameters (the model adapter knows the rest)."""

    id: str
    params: tuple[ParamInfo, ...]


@runtime_checkable
class ModelAdapter(Protocol):
    """A declared model the loop can simulate with candidate effects added.

    ``predict`` returns outputs (B, n_episodes, n_samples, n_outputs) for B parameter rows
    ``thetas`` (B, Σ n_params of ``effects``, concatenated in ``effects`` order), simulating the
    first ``n_samples`` samples. An adapter may also define ``fit(data, effects, theta0, free,
    n_train, sqrt_w) -> FitResult`` to replace the generic simulation-error least squares (e.g.
    a closed-form linear fit).
    """

    name: str
    output_channels: tuple[str, ...]

    def prepare(self, data: MeasuredData, n_train: int) -> None: ...

    def candidates(self) -> dict[str, Candidate]: ...

    def skipped_candidates(self) -> dict[str, str]: ...

    def predict(
        self, data: MeasuredData, effects: Sequence[Candidate], thetas: np.ndarray, n_samples: int
    ) -> np.ndarray: ...

    def other_signals(self, data: MeasuredData) -> list[str]: ...


@dataclass
class FitResult:
    """Fitted parameters ``theta`` (all, fixed ones unchanged), their covariance, fit diagnostics."""

    theta: np.ndarray
    cov: np.ndarray
    n_evals: int
    cost: float
    converged: bool

    @property
    def stderr(self) -> np.ndarray:
        return np.sqrt(np.clip(np.diag(self.cov), 0.0, None))
