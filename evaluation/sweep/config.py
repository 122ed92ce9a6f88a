"""What a sweep is: the diagnosers (:class:`DiagnoserSpec`), the data and the start-up time
(:class:`SweepConfig`, frozen and validated), and what it returns (:class:`SweepResults`).

:meth:`SweepConfig.model_hash` and :meth:`SweepConfig.cell_hash` name a sweep's models and cells
in the store: they change whenever anything a stored result depends on changes.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from diagnosers.diagnoser import Diagnoser
from diagnosers.registry import available, diagnoser_class, import_modules, make
from evaluation.sweep.records import (
    CellResult,
    CellSummary,
    summarize,
)
from evaluation.sweep.sources import DataSource, SimulatedData
from evaluation.sweep.store import canonical_hash, check_name
from fcc_env import MODEL_VERSION, __version__

__all__ = [
    "BASELINES",
    "HARNESS_VERSION",
    "DiagnoserSpec",
    "SweepConfig",
    "SweepResults",
    "default_specs",
]

BASELINES: tuple[str, ...] = ("limits", "pca", "arx-band")
#: Bumped when the meaning of a stored cell record changes (part of every cell hash).
HARNESS_VERSION = 1


# ---- configuration -----------------------------------------------------------------------------
@dataclass(frozen=True)
class DiagnoserSpec:
    """One diagnoser of a sweep: registry ``name``, hyperparameters and a unique ``label``.

    ``params`` must be JSON-serialisable (they are hashed into the store). ``label`` defaults to
    ``name``; give two specs of the same diagnoser different labels to compare hyperparameters.
    """

    name: str
    params: Mapping[str, Any] = field(default_factory=dict)
    label: str | None = None

    @property
    def key(self) -> str:
        """The label used in the store, tables and figures."""
        return self.label if self.label is not None else self.name

    def build(self) -> Diagnoser:
        return make(self.name, **dict(self.params))

    def to_json(self) -> dict[str, Any]:
        return {"name": self.name, "params": dict(self.params), "label": self.key}


def default_specs(
    names: Sequence[str] | None = None, *, test: bool = False
) -> tuple[DiagnoserSpec, ...]:
    """Specs for registered diagnosers with default hyperparameters.

    Args:
        names: registry names (all of :func:`diagnosers.available` when ``None``).
        test: use each class's :meth:`~diagnosers.contract.DiagnoserContract.fast_params`
            (small, fast hyperparameters for smoke runs and tests) instead of the defaults.
    """
    names = available() if names is None else list(names)
    classes = [diagnoser_class(n) for n in names]  # unknown names: the registry's message
    return tuple(
        DiagnoserSpec(n, dict(cls.fast_params()) if test else {})
        for n, cls in zip(names, classes, strict=True)
    )


@dataclass(frozen=True, kw_only=True)
class SweepConfig:
    """A whole sweep: which diagnosers, on which data, scored from sample ``t_on`` on.

    Args:
        diagnosers: the diagnosers to train and score (labels must be unique).
        data: a :class:`DataSource` (:class:`SimulatedData` or
            :class:`evaluation.sweep.external_data.ExternalData`).
        t_on: start-up samples not scored for false alarms (the paper's ``t_on``; 0 scores all).
        imports: modules that register diagnosers of your own (``@diagnosers.register``),
            imported before the names are resolved, in this process and in every worker (a
            ``spawn`` worker or a Ray worker starts from a fresh interpreter). They must be
            importable there: from the installed packages, or from a directory on ``sys.path``
            (local workers inherit the driver's). Not part of any hash: they say where the code
            is, not what it computes.
    """

    diagnosers: tuple[DiagnoserSpec, ...]
    data: DataSource = field(default_factory=SimulatedData)
    t_on: int = 0
    imports: tuple[str, ...] = ()

    def validate(self) -> None:
        if isinstance(self.imports, str) or not all(isinstance(m, str) for m in self.imports):
            raise ValueError(
                f"imports={self.imports!r} is outside the allowed range: a tuple of module names"
            )
        import_modules(self.imports)
        if not self.diagnosers:
            raise ValueError(f"a sweep needs at least one diagnoser. Available: {available()}")
        labels = [d.key for d in self.diagnosers]
        dup = sorted({lab for lab in labels if labels.count(lab) > 1})
        if dup:
            raise ValueError(
                f"diagnoser labels must be unique, {dup} repeat; give DiagnoserSpec(label=...)"
            )
        for spec in self.diagnosers:
            if not isinstance(spec, DiagnoserSpec):
                raise ValueError(f"diagnosers must be DiagnoserSpec objects, got {spec!r}")
            check_name("diagnoser label", spec.key)
            try:
                # unknown name or hyperparameter, or a bad value: fail before any training
                spec.build().validate_params()
            except (ValueError, TypeError) as e:
                raise ValueError(f"diagnoser {spec.key!r}: {e}") from e
            canonical_hash(spec.to_json())  # params must be JSON-serialisable
        if not isinstance(self.data, DataSource):
            raise ValueError(f"data={self.data!r} does not implement the DataSource protocol")
        self.data.validate()
        for sc, _ in self.data.cells():
            check_name("scenario", sc)
        if isinstance(self.t_on, bool) or not isinstance(self.t_on, int) or self.t_on < 0:
            raise ValueError(f"t_on={self.t_on!r} must be an integer >= 0")

    def model_hash(self, spec: DiagnoserSpec, data_hash: str) -> str:
        """Hash of what a trained model depends on: the diagnoser and the data.

        The hyperparameters are the *resolved* ones (defaults included) and the package version
        is part of the hash, so a changed default or a new release never reuses stale models or
        cells: the store then says so instead of mixing old and new results. Hyperparameters
        that do not change the fit (:attr:`Diagnoser.execution_params`: ``progress``,
        ``n_jobs``) are left out, so changing them reuses the stored model.
        """
        return canonical_hash(
            {
                "v": HARNESS_VERSION,
                "package": f"{__version__} ({MODEL_VERSION})",
                "data": data_hash,
                "name": spec.name,
                "params": spec.build().result_params(),
            }
        )

    def cell_hash(self, spec: DiagnoserSpec, data_hash: str) -> str:
        """Hash of what a cell's result depends on: the model and ``t_on``."""
        return canonical_hash({"model": self.model_hash(spec, data_hash), "t_on": self.t_on})


@dataclass(frozen=True)
class SweepResults:
    """What :func:`run_sweep` returns: every cell of the sweep plus bookkeeping.

    Attributes:
        records: one :class:`CellResult` per (diagnoser, scenario, seed), diagnosers in config
            order, then cells in the data source's order.
        n_computed / n_reused: cells computed in this call / found in the store.
        n_trained: diagnosers trained in this call (the others were loaded from the store).
        wall_s: wall time of the call.
    """

    config: SweepConfig
    store_dir: Path
    records: tuple[CellResult, ...]
    n_computed: int
    n_reused: int
    n_trained: int
    wall_s: float

    def summary(self) -> list[CellSummary]:
        return summarize(self.records)
