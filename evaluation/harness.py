"""Evaluation harness: diagnosers × scenarios × seeds, in parallel, with a resumable result store.

A sweep is described by a frozen :class:`SweepConfig`: the diagnosers (:class:`DiagnoserSpec`,
registry name + hyperparameters + label), a data source and the start-up time ``t_on``. Two data
sources exist:

* :class:`SimulatedData` - ``FCC-v0`` episodes from :func:`fcc_env.simulate_episodes`. Training
  uses healthy (``nominal``) episodes of ``train_seeds``; testing uses ``scenarios`` × ``test_seeds``.
  The two seed sets must be disjoint (checked): by default test seeds are ``0..N-1`` and training
  seeds ``1000..``, so a diagnoser never sees a test episode's excitation or noise.
* :class:`evaluation.external.ExternalData` - a directory of CSV/Parquet records (healthy training
  files, test files with their fault onsets).

:func:`run_sweep` does three things, keeping recording, metrics and presentation apart:

1. **Train** every diagnoser once per sweep on the healthy training episodes (one parallel task per
   diagnoser). The fitted diagnoser is stored with :meth:`Diagnoser.save` under the store's
   ``models/<label>`` directory, so workers load it and a resumed sweep reuses it.
2. **Score** every test episode: one parallel task per ``(scenario, seed)`` episode runs every
   diagnoser whose cell is missing on it. One task per episode, not per cell, because simulating
   the episode costs far more than a baseline's ``detect`` (≈ 45 ms versus < 1 ms for 4000
   samples), so the work grows linearly with the number of seeds and spreads over all workers.
   Each finished cell (diagnoser, scenario, seed) is written to the store at once
   (:mod:`evaluation.store`), so an interrupted sweep loses nothing finished.
3. **Collect** the cell records of the sweep into :class:`SweepResults`; :func:`summarize` turns
   them into mean ± standard deviation across seeds (pure function, no I/O).

Episode scoring (:func:`score_episode`) uses :func:`evaluation.metrics.episode_scores`. An episode
that the simulator terminated early (the envelope was left, e.g. the afterburn ignited) is scored
on its samples before ``terminated_at`` only; the record keeps ``terminated_at`` and the reason. If
it terminated before the fault onset, no faulty sample remains: ``r_td`` and ``t_dt`` are then
``nan`` and the episode is not counted as a miss.

Backends: ``"local"`` runs tasks in a :class:`~concurrent.futures.ProcessPoolExecutor` with the
``spawn`` start method (numba and torch thread pools do not survive ``fork`` reliably); each worker
limits numba and torch to one thread, since parallelism comes from the processes. ``"ray"`` runs
the same task functions as Ray tasks (``ray.init(address=...)`` when an address is given, else a
local instance with one CPU per worker). Results always travel back to the driver, which alone
writes the store, so remote Ray nodes need no shared file system.
"""

from __future__ import annotations

import dataclasses
import math
import os
import sys
import tempfile
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol, runtime_checkable

import numpy as np

from diagnosers.base import Detection, Diagnoser, Episode
from diagnosers.registry import available, make
from evaluation.metrics import episode_scores
from evaluation.store import ResultStore, canonical_hash, check_name

__all__ = [
    "BACKENDS",
    "BASELINES",
    "CellResult",
    "CellSummary",
    "DataSource",
    "DiagnoserSpec",
    "LoadedEpisode",
    "SimulatedData",
    "SweepConfig",
    "SweepResults",
    "default_specs",
    "detect_episode",
    "load_cell",
    "ray_runtime_env",
    "run_sweep",
    "score_episode",
    "summarize",
]

#: Execution backends accepted by :func:`run_sweep`.
BACKENDS: tuple[str, ...] = ("local", "ray")
#: The classical baselines of :mod:`diagnosers.baselines` (the ``--quick`` leaderboard set).
BASELINES: tuple[str, ...] = ("limits", "pca", "arx-band")
#: Bumped when the meaning of a stored cell record changes (part of every cell hash).
HARNESS_VERSION = 1
#: Default first training seed: far from the test seeds 0..N-1 of any realistic sweep.
TRAIN_SEED_BASE = 1000


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
        test: use each class's ``_test_params()`` classmethod where it has one (small, fast
            hyperparameters meant for tests), else the defaults.
    """
    from diagnosers.registry import _REGISTRY  # the class is needed for _test_params

    names = available() if names is None else list(names)
    specs = []
    for n in names:
        if n not in _REGISTRY:
            raise ValueError(f"Unknown diagnoser {n!r}. Available: {available()}")
        params: dict[str, Any] = {}
        hook = getattr(_REGISTRY[n], "_test_params", None)
        if test and callable(hook):
            params = dict(hook())
        specs.append(DiagnoserSpec(n, params))
    return tuple(specs)


@dataclass(frozen=True)
class LoadedEpisode:
    """A test episode ready for scoring, with what the harness records about it.

    Attributes:
        episode: the usable samples (cut at ``terminated_at``); its ``fault_onset`` is ``None``
            when no faulty sample remains.
        fault_onset: the scenario's onset sample as planned (``None`` for a healthy episode).
        n_samples_planned: samples the episode was meant to have.
        terminated_at: first sample outside the plant envelope, ``None`` if it ran to the end.
        termination_reason: why it terminated, ``None`` if it did not.
    """

    episode: Episode
    fault_onset: int | None
    n_samples_planned: int
    terminated_at: int | None = None
    termination_reason: str | None = None


@runtime_checkable
class DataSource(Protocol):
    """What :func:`run_sweep` needs from a data source (picklable: it travels to workers)."""

    def validate(self) -> None:
        """Raise ``ValueError`` naming a bad option and the allowed values."""

    def store_key(self) -> dict[str, Any]:
        """JSON description of everything that defines training and test data, except which
        test cells are run (hashed into the store manifest)."""

    def cells(self) -> list[tuple[str, int]]:
        """The test episodes as ``(scenario, seed)`` pairs, in presentation order."""

    def train_episodes(self) -> list[Episode]:
        """Healthy training episodes."""

    def load_test(self, scenario: str, seed: int) -> LoadedEpisode:
        """One test episode."""


def _check_seeds(name: str, seeds: object) -> tuple[int, ...]:
    if isinstance(seeds, str | bytes) or not isinstance(seeds, Sequence) or len(seeds) == 0:
        raise ValueError(f"{name}={seeds!r} must be a non-empty sequence of integers >= 0")
    out = []
    for s in seeds:
        if isinstance(s, bool) or not isinstance(s, int | np.integer) or s < 0:
            raise ValueError(f"{name} must hold integers >= 0, got {s!r}")
        out.append(int(s))
    if len(set(out)) != len(out):
        raise ValueError(f"{name}={out} holds duplicates")
    return tuple(out)


@dataclass(frozen=True, kw_only=True)
class SimulatedData:
    """``FCC-v0`` episodes simulated on demand (deterministic in the seed and options).

    Args:
        scenarios: test scenarios, a subset of ``fcc_env.SCENARIOS``.
        test_seeds: seeds of the test episodes (the same seeds for every scenario, so the
            scenarios share excitation programs: a paired design).
        train_seeds: seeds of the healthy training episodes; disjoint from ``test_seeds``.
        n_samples: samples per episode (4000 = the paper's horizon).
        fault_time: onset sample for every fault, or ``None`` for the paper's onsets
            (f1, f2: 1900; f3: 2020; f4: 2000). Must be below ``n_samples``.
        fault_magnitude, fault_profile, ramp_samples, excitation, noise_scale, sample_time_s:
            passed to :func:`fcc_env.simulate_episodes` (its defaults are the paper's set-up).
        fault_magnitude_scale: multiplies the magnitude of every fault f1–f4 (``fault_magnitude``
            or each fault's own default): 0.7 gives the smaller faults of the validation protocol
            (:mod:`evaluation.leaderboard` ``--validation``), on which hyperparameters may be chosen.
    """

    scenarios: tuple[str, ...] = ("nominal", "f1", "f2", "f3", "f4")
    test_seeds: tuple[int, ...] = tuple(range(10))
    train_seeds: tuple[int, ...] = tuple(range(TRAIN_SEED_BASE, TRAIN_SEED_BASE + 5))
    n_samples: int = 4000
    fault_time: int | None = None
    fault_magnitude: float | None = None
    fault_profile: str = "abrupt"
    ramp_samples: int | None = None
    excitation: bool = True
    noise_scale: float = 1.0
    sample_time_s: float = 10.0
    fault_magnitude_scale: float = 1.0

    def validate(self) -> None:
        import fcc_env
        from fcc_env.scenarios import resolve_fault

        if isinstance(self.scenarios, str) or not self.scenarios:
            raise ValueError(
                f"scenarios={self.scenarios!r} must be a non-empty sequence of names from "
                f"{list(fcc_env.SCENARIOS)}"
            )
        for sc in self.scenarios:
            if sc not in fcc_env.SCENARIOS:
                raise ValueError(f"Unknown scenario {sc!r}. Available: {list(fcc_env.SCENARIOS)}")
        if len(set(self.scenarios)) != len(self.scenarios):
            raise ValueError(f"scenarios={list(self.scenarios)} holds duplicates")
        test = _check_seeds("test_seeds", self.test_seeds)
        train = _check_seeds("train_seeds", self.train_seeds)
        common = sorted(set(test) & set(train))
        if common:
            raise ValueError(
                f"train_seeds and test_seeds must be disjoint (a diagnoser must not be tested on "
                f"the episodes it was trained on); both hold {common}"
            )
        n = self.n_samples
        if isinstance(n, bool) or not isinstance(n, int | np.integer) or n < 2:
            raise ValueError(f"n_samples={n!r} must be an integer >= 2")
        if not isinstance(self.excitation, bool):
            raise ValueError(f"excitation={self.excitation!r} must be True or False")
        for name in ("noise_scale", "sample_time_s", "fault_magnitude_scale"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
                raise ValueError(f"{name}={v!r} must be a finite number")
        if not 0 < self.fault_magnitude_scale <= 10:
            raise ValueError(
                f"fault_magnitude_scale={self.fault_magnitude_scale!r} outside the allowed range "
                "(0, 10]"
            )
        if self.noise_scale < 0 or self.sample_time_s <= 0:
            raise ValueError(
                f"noise_scale={self.noise_scale!r} must be >= 0 and "
                f"sample_time_s={self.sample_time_s!r} > 0"
            )
        for sc in self.scenarios:
            try:
                resolve_fault(
                    sc,
                    self.fault_time,
                    self._magnitude(sc),
                    self.fault_profile,
                    self.ramp_samples,
                    horizon=int(n),
                )
            except ValueError as e:
                raise ValueError(
                    f"scenario {sc!r} with n_samples={n}: {e}; with short episodes pass "
                    "fault_time=<sample below n_samples>"
                ) from e

    def store_key(self) -> dict[str, Any]:
        import fcc_env

        key = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        # Which test cells run does not change any single cell's result: leave them out so that
        # a sweep extended with more seeds or scenarios reuses the stored cells.
        del key["scenarios"], key["test_seeds"]
        key["train_seeds"] = list(self.train_seeds)
        if self.fault_magnitude_scale == 1.0:  # keeps the keys of stores written before the option
            del key["fault_magnitude_scale"]
        key["kind"] = "simulated"
        key["model_version"] = fcc_env.MODEL_VERSION
        return key

    def cells(self) -> list[tuple[str, int]]:
        return [(sc, int(s)) for sc in self.scenarios for s in self.test_seeds]

    def _simulate(self, seeds: Sequence[int], scenario: str) -> Any:
        import fcc_env

        return fcc_env.simulate_episodes(
            list(seeds),
            int(self.n_samples),
            scenario=scenario,
            fault_time=self.fault_time,
            fault_magnitude=self._magnitude(scenario),
            fault_profile=self.fault_profile,
            ramp_samples=self.ramp_samples,
            excitation=self.excitation,
            noise_scale=self.noise_scale,
            sample_time_s=self.sample_time_s,
        )

    def _magnitude(self, scenario: str) -> float | None:
        """The fault magnitude passed to the simulator for ``scenario`` (scale applied)."""
        from fcc_env.scenarios import FAULTS, Scenario

        sc = Scenario(scenario)
        if self.fault_magnitude_scale == 1.0 or sc not in FAULTS:
            return self.fault_magnitude
        base = (
            FAULTS[sc].default_magnitude if self.fault_magnitude is None else self.fault_magnitude
        )
        return base * self.fault_magnitude_scale

    def _loaded(self, res: Any, b: int) -> LoadedEpisode:
        import fcc_env

        term = int(res.terminated_at[b])
        n_used = term if term >= 0 else int(self.n_samples)
        onset = res.fault_onsets[b]
        onset = None if onset is None else int(onset)
        episode = Episode(
            y=np.asarray(res.observations[b, :n_used], dtype=np.float64),
            channels=tuple(fcc_env.MEASUREMENT_NAMES),
            sample_time_s=float(res.sample_time_s),
            fault_onset=onset if onset is not None and onset < n_used else None,
            scenario=str(res.scenarios[b]),
            seed=int(res.seeds[b]),
            y_clean=np.asarray(res.y_clean[b, :n_used]),
        )
        return LoadedEpisode(
            episode=episode,
            fault_onset=onset,
            n_samples_planned=int(self.n_samples),
            terminated_at=term if term >= 0 else None,
            termination_reason=res.termination_reasons[b] if term >= 0 else None,
        )

    def train_episodes(self) -> list[Episode]:
        res = self._simulate(self.train_seeds, "nominal")
        # A training episode that left the envelope keeps its samples before termination; one
        # with fewer than 2 samples has nothing to learn from and is dropped.
        eps = [self._loaded(res, b).episode for b in range(len(self.train_seeds))]
        return [ep for ep in eps if ep.n_samples >= 2]

    def load_test(self, scenario: str, seed: int) -> LoadedEpisode:
        return self._loaded(self._simulate([seed], scenario), 0)


@dataclass(frozen=True, kw_only=True)
class SweepConfig:
    """A whole sweep: which diagnosers, on which data, scored from sample ``t_on`` on.

    Args:
        diagnosers: the diagnosers to train and score (labels must be unique).
        data: a :class:`DataSource` (:class:`SimulatedData` or
            :class:`evaluation.external.ExternalData`).
        t_on: start-up samples not scored for false alarms (the paper's ``t_on``; 0 scores all).
    """

    diagnosers: tuple[DiagnoserSpec, ...]
    data: DataSource = field(default_factory=SimulatedData)
    t_on: int = 0

    def validate(self) -> None:
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
            spec.build()  # unknown name or hyperparameter -> ValueError naming the allowed set
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
        cells: the store then says so instead of mixing old and new results.
        """
        from fcc_env import MODEL_VERSION, __version__

        return canonical_hash(
            {
                "v": HARNESS_VERSION,
                "package": f"{__version__} ({MODEL_VERSION})",
                "data": data_hash,
                "name": spec.name,
                "params": spec.build().get_params(),
            }
        )

    def cell_hash(self, spec: DiagnoserSpec, data_hash: str) -> str:
        """Hash of what a cell's result depends on: the model and ``t_on``."""
        return canonical_hash({"model": self.model_hash(spec, data_hash), "t_on": self.t_on})


# ---- records -----------------------------------------------------------------------------------
@dataclass(frozen=True)
class CellResult:
    """Scores of one diagnoser on one test episode (one cell of the sweep).

    Times are in samples unless the name ends in ``_s``. ``nan`` marks an undefined score
    (``r_td``/``t_dt`` on healthy episodes, ``t_dt`` when the fault was missed).
    """

    diagnoser: str  # label
    diagnoser_name: str  # registry name
    scenario: str
    seed: int
    fault_onset: int | None  # planned onset sample, None when healthy
    n_samples: int  # samples scored (cut at terminated_at)
    n_samples_planned: int
    n_fault_samples: int  # samples from the onset on (0 when healthy or terminated before it)
    terminated_at: int | None
    termination_reason: str | None
    r_fd: float  # false detection rate over [t_on, onset) or the whole healthy episode
    r_td: float  # true detection rate over [onset, end)
    t_dt: float  # detection time [samples], nan when missed
    t_dt_s: float  # detection time [s]
    n_alarms: int  # alarmed samples in the episode
    sample_time_s: float
    detect_wall_s: float  # wall time of Diagnoser.detect on this episode

    @property
    def faulty(self) -> bool:
        return self.fault_onset is not None

    @property
    def missed(self) -> bool:
        """A fault with scored faulty samples and no alarm from its onset on."""
        return self.n_fault_samples > 0 and math.isnan(self.t_dt)

    def to_json(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_json(cls, obj: Mapping[str, Any]) -> CellResult:
        """Inverse of :meth:`to_json`; JSON ``null`` scores become ``nan``."""
        kwargs = {}
        for f in dataclasses.fields(cls):
            if f.name not in obj:
                raise ValueError(f"cell record lacks the field {f.name!r}")
            v = obj[f.name]
            if f.type == "float" and v is None:
                v = float("nan")
            kwargs[f.name] = v
        return cls(**kwargs)


def score_episode(
    diagnoser: Diagnoser, loaded: LoadedEpisode, *, label: str | None = None, t_on: int = 0
) -> CellResult:
    """Run ``diagnoser.detect`` on one episode and compute its indexes (no I/O)."""
    ep = loaded.episode
    nan = float("nan")
    t0 = time.perf_counter()
    det = diagnoser.detect(ep)
    wall = time.perf_counter() - t0
    n = ep.n_samples
    onset = ep.fault_onset  # None also when the episode ended before the planned onset
    if n > t_on:
        scores = episode_scores(det.alarm, onset, t_on=t_on)
    else:  # too short to score anything
        scores = {"r_fd": nan, "r_td": nan, "t_dt": nan}
    if loaded.fault_onset is not None and onset is None:
        # Terminated before the fault: r_fd over the fault-free samples, nothing to detect.
        scores["r_td"] = scores["t_dt"] = nan
    return CellResult(
        diagnoser=label or diagnoser.name,
        diagnoser_name=diagnoser.name,
        scenario=ep.scenario,
        seed=int(ep.seed) if ep.seed is not None else 0,
        fault_onset=loaded.fault_onset,
        n_samples=n,
        n_samples_planned=loaded.n_samples_planned,
        n_fault_samples=n - onset if onset is not None else 0,
        terminated_at=loaded.terminated_at,
        termination_reason=loaded.termination_reason,
        r_fd=float(scores["r_fd"]),
        r_td=float(scores["r_td"]),
        t_dt=float(scores["t_dt"]),
        t_dt_s=float(scores["t_dt"]) * ep.sample_time_s,
        n_alarms=int(np.count_nonzero(det.alarm)),
        sample_time_s=float(ep.sample_time_s),
        detect_wall_s=wall,
    )


@dataclass(frozen=True)
class CellSummary:
    """One diagnoser on one scenario, aggregated over seeds.

    Means and standard deviations (``ddof=1``; ``nan`` with fewer than two values) are over the
    seeds where the score is defined: ``r_fd`` over all episodes, ``r_td`` over episodes with
    faulty samples, ``t_dt`` over *detected* faults only (a missed fault has no detection time;
    ``misses`` counts them).
    """

    diagnoser: str
    scenario: str
    faulty: bool
    n_seeds: int
    r_fd: float
    r_fd_std: float
    r_td: float
    r_td_std: float
    t_dt: float
    t_dt_std: float
    t_dt_s: float
    t_dt_s_std: float
    misses: int
    n_detected: int
    n_terminated: int

    def to_json(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


def _mean_std(values: Sequence[float]) -> tuple[float, float]:
    v = np.asarray([x for x in values if math.isfinite(x)], dtype=np.float64)
    if v.size == 0:
        return float("nan"), float("nan")
    return float(v.mean()), float(v.std(ddof=1)) if v.size > 1 else float("nan")


def summarize(records: Sequence[CellResult]) -> list[CellSummary]:
    """Aggregate cells per (diagnoser, scenario), in order of first appearance (pure)."""
    groups: dict[tuple[str, str], list[CellResult]] = {}
    for r in records:
        groups.setdefault((r.diagnoser, r.scenario), []).append(r)
    out = []
    for (diag, sc), rs in groups.items():
        faulty = any(r.faulty for r in rs)
        r_fd = _mean_std([r.r_fd for r in rs])
        r_td = _mean_std([r.r_td for r in rs if r.n_fault_samples > 0])
        detected = [r for r in rs if r.n_fault_samples > 0 and not math.isnan(r.t_dt)]
        t_dt = _mean_std([r.t_dt for r in detected])
        t_dt_s = _mean_std([r.t_dt_s for r in detected])
        out.append(
            CellSummary(
                diagnoser=diag,
                scenario=sc,
                faulty=faulty,
                n_seeds=len(rs),
                r_fd=r_fd[0],
                r_fd_std=r_fd[1],
                r_td=r_td[0],
                r_td_std=r_td[1],
                t_dt=t_dt[0],
                t_dt_std=t_dt[1],
                t_dt_s=t_dt_s[0],
                t_dt_s_std=t_dt_s[1],
                misses=sum(r.missed for r in rs),
                n_detected=len(detected),
                n_terminated=sum(r.terminated_at is not None for r in rs),
            )
        )
    return out


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


# ---- worker side -------------------------------------------------------------------------------
def _limit_threads() -> None:
    """One compute thread per worker: the parallelism comes from the worker processes."""
    if "torch" in sys.modules:
        sys.modules["torch"].set_num_threads(1)
    if "numba" in sys.modules:
        sys.modules["numba"].set_num_threads(1)


def _init_worker() -> None:
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    import numba

    numba.set_num_threads(1)
    _limit_threads()


_MODEL_CACHE: dict[str, Diagnoser] = {}
_MODEL_CACHE_SIZE = 8


def _dir_files(path: Path) -> dict[str, bytes]:
    return {
        p.relative_to(path).as_posix(): p.read_bytes()
        for p in sorted(path.rglob("*"))
        if p.is_file()
    }


def _load_model(model_hash: str, source: str | Mapping[str, bytes]) -> Diagnoser:
    """Load a stored model (a directory path, or its files as bytes), cached per process.

    The cache is keyed by the model hash, so a worker that scores many episodes loads each model
    once. ``Diagnoser.detect`` resets the diagnoser before and after, so reuse is safe.
    """
    diag = _MODEL_CACHE.get(model_hash)
    if diag is not None:
        return diag
    if isinstance(source, str):
        diag = Diagnoser.load(source)
    else:
        with tempfile.TemporaryDirectory(prefix="fcc-model-") as d:
            for rel, data in source.items():
                target = Path(d) / rel
                target.parent.mkdir(parents=True, exist_ok=True)
                target.write_bytes(data)
            diag = Diagnoser.load(d)
    if len(_MODEL_CACHE) >= _MODEL_CACHE_SIZE:
        _MODEL_CACHE.pop(next(iter(_MODEL_CACHE)))
    _MODEL_CACHE[model_hash] = diag
    return diag


def _train_task(
    spec: DiagnoserSpec, data: DataSource, _serial: bool = False
) -> tuple[dict[str, bytes], dict[str, Any]]:
    """Fit one diagnoser on the healthy training episodes; return its saved files and facts."""
    if not _serial:
        _limit_threads()
    t0 = time.perf_counter()
    episodes = data.train_episodes()
    try:
        diag = spec.build().fit(episodes)
    except Exception as e:
        raise RuntimeError(f"training {spec.key}: {type(e).__name__}: {e}") from e
    wall = time.perf_counter() - t0
    with tempfile.TemporaryDirectory(prefix="fcc-train-") as d:
        diag.save(d)
        files = _dir_files(Path(d))
    info = {
        "train_wall_s": wall,
        "n_train_episodes": len(episodes),
        "n_train_samples": int(sum(ep.n_samples for ep in episodes)),
    }
    return files, info


@dataclass(frozen=True)
class _EpisodeTask:
    """Score the diagnosers ``labels`` on episode ``(scenario, seed)`` of ``data``."""

    data: DataSource
    scenario: str
    seed: int
    t_on: int
    labels: tuple[str, ...]
    model_hashes: tuple[str, ...]
    model_paths: tuple[str, ...] | None  # local backend; None when models come as bytes


def _episode_task(
    task: _EpisodeTask, *model_files: Mapping[str, bytes], _serial: bool = False
) -> list[dict[str, Any]]:
    if not _serial:
        _limit_threads()
    loaded = task.data.load_test(task.scenario, task.seed)
    out = []
    for i, (label, mhash) in enumerate(zip(task.labels, task.model_hashes, strict=True)):
        source = task.model_paths[i] if task.model_paths is not None else model_files[i]
        try:
            diag = _load_model(mhash, source)
            rec = score_episode(diag, loaded, label=label, t_on=task.t_on)
        except Exception as e:
            # Name the cell: the traceback of a worker process does not reach the user.
            raise RuntimeError(
                f"{label} on {task.scenario}, seed {task.seed}: {type(e).__name__}: {e}"
            ) from e
        # External data name the episode by file; keep the sweep's cell key as given.
        rec = dataclasses.replace(rec, scenario=task.scenario, seed=task.seed)
        out.append(rec.to_json())
    return out


# ---- backends ----------------------------------------------------------------------------------
class _Backend(Protocol):
    passes_paths: bool

    def put(self, obj: Any) -> Any: ...

    def submit(self, fn: Callable[..., Any], *args: Any) -> Any: ...

    def completed(self, handles: list[Any]) -> Iterator[tuple[Any, Any]]: ...

    def close(self, cancel: bool) -> None: ...


class _LocalBackend:
    passes_paths = True

    def __init__(self, n_workers: int) -> None:
        import multiprocessing

        self._pool = ProcessPoolExecutor(
            max_workers=n_workers,
            mp_context=multiprocessing.get_context("spawn"),
            initializer=_init_worker,
        )

    def put(self, obj: Any) -> Any:
        return obj

    def submit(self, fn: Callable[..., Any], *args: Any) -> Future:
        return self._pool.submit(fn, *args)

    def completed(self, handles: list[Future]) -> Iterator[tuple[Future, Any]]:
        pending = set(handles)
        while pending:
            done, pending = wait(pending, return_when=FIRST_COMPLETED)
            for fut in done:
                yield fut, fut.result()

    def close(self, cancel: bool) -> None:
        self._pool.shutdown(wait=not cancel, cancel_futures=cancel)


def ray_runtime_env() -> dict[str, Any]:
    """Runtime environment that lets local Ray workers import this repository's packages."""
    root = str(Path(__file__).resolve().parents[1])
    path = os.pathsep.join([root, *filter(None, [os.environ.get("PYTHONPATH", "")])])
    return {"env_vars": {"PYTHONPATH": path, "OMP_NUM_THREADS": "1"}}


class _RayBackend:
    passes_paths = False

    def __init__(self, n_workers: int, address: str | None) -> None:
        try:
            import ray
        except ImportError as e:
            raise ImportError(
                "backend='ray' needs Ray: pip install 'fcc-fault-diagnosis[ray]'"
            ) from e
        self._ray = ray
        self._owned = False
        if not ray.is_initialized():
            if address is not None:
                ray.init(address=address)
            else:
                ray.init(
                    num_cpus=n_workers,
                    include_dashboard=False,
                    runtime_env=ray_runtime_env(),
                    log_to_driver=False,
                )
            self._owned = True
        self._remote: dict[Callable[..., Any], Any] = {}

    def put(self, obj: Any) -> Any:
        return self._ray.put(obj)

    def submit(self, fn: Callable[..., Any], *args: Any) -> Any:
        if fn not in self._remote:
            self._remote[fn] = self._ray.remote(num_cpus=1)(fn)
        return self._remote[fn].remote(*args)

    def completed(self, handles: list[Any]) -> Iterator[tuple[Any, Any]]:
        pending = list(handles)
        while pending:
            done, pending = self._ray.wait(pending, num_returns=1)
            for ref in done:
                yield ref, self._ray.get(ref)

    def close(self, cancel: bool) -> None:
        if self._owned:
            self._ray.shutdown()


class _SerialBackend:
    """Runs each task in the calling process when its result is collected (``n_workers=0``).

    For debugging and fast tests: no process start-up, exceptions with their full traceback. The
    caller's thread settings are left alone (``_limit_threads`` is a worker-only measure).
    """

    passes_paths = True

    def put(self, obj: Any) -> Any:
        return obj

    class _Deferred:
        """A task not run yet (hashable by identity, like a Future)."""

        def __init__(self, fn: Callable[..., Any], args: tuple) -> None:
            self.fn, self.args = fn, args

    def submit(self, fn: Callable[..., Any], *args: Any) -> _SerialBackend._Deferred:
        return self._Deferred(fn, args)

    def completed(self, handles: list[Any]) -> Iterator[tuple[Any, Any]]:
        for h in handles:
            yield h, h.fn(*h.args, _serial=True)

    def close(self, cancel: bool) -> None:
        pass


def _cpu_count() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


# ---- the sweep ---------------------------------------------------------------------------------
def run_sweep(
    config: SweepConfig,
    store_dir: str | os.PathLike,
    backend: str = "local",
    n_workers: int | None = None,
    ray_address: str | None = None,
    progress: bool = True,
) -> SweepResults:
    """Train and score every diagnoser of ``config``, resuming from ``store_dir``.

    Args:
        config: the sweep.
        store_dir: result store directory (created if missing; see :mod:`evaluation.store`).
        backend: ``"local"`` (process pool) or ``"ray"``.
        n_workers: worker processes / Ray CPUs for a local Ray instance; default: all cores of
            this machine, capped at the number of tasks. ``0`` (local backend only) runs every
            task in this process, for debugging and fast tests.
        ray_address: address of a running Ray cluster (``backend="ray"`` only). Its workers
            must be able to import this package (install it there, or start the cluster with a
            ``runtime_env``); a local instance started here gets :func:`ray_runtime_env`. If
            Ray is already initialised in this process, that instance is used and left running.
        progress: show a tqdm progress bar over cells (on stderr).

    Returns:
        :class:`SweepResults` with every cell of the sweep.

    Raises:
        ValueError: bad configuration (message names the value and the allowed set).
        evaluation.store.StoreError: the store is corrupted, foreign or of another sweep.
        RuntimeError: a training or scoring task failed (cells finished before stay stored).
    """
    t_start = time.perf_counter()
    if backend not in BACKENDS:
        raise ValueError(f"Unknown backend {backend!r}. Available: {list(BACKENDS)}")
    if ray_address is not None and backend != "ray":
        raise ValueError("ray_address is only used with backend='ray'")
    if n_workers is not None and (
        isinstance(n_workers, bool) or not isinstance(n_workers, int) or n_workers < 0
    ):
        raise ValueError(f"n_workers={n_workers!r} must be an integer >= 0 or None")
    if n_workers == 0 and backend != "local":
        raise ValueError("n_workers=0 (run in this process) needs backend='local'")
    config.validate()
    store = ResultStore.open(store_dir, config.data.store_key())
    specs = list(config.diagnosers)
    mhash = {s.key: config.model_hash(s, store.data_hash) for s in specs}
    chash = {s.key: config.cell_hash(s, store.data_hash) for s in specs}

    # Which work is left: models to train, and per episode the diagnosers still missing.
    to_train = [s for s in specs if not store.has_model(s.key, mhash[s.key])]
    cells = config.data.cells()
    missing: dict[tuple[str, int], list[DiagnoserSpec]] = {}
    for sc, seed in cells:
        for s in specs:
            if store.read_cell(s.key, sc, seed, chash[s.key]) is None:
                missing.setdefault((sc, seed), []).append(s)
    n_missing = sum(len(v) for v in missing.values())

    if to_train or missing:
        n_tasks = max(len(to_train), len(missing))
        workers = min(n_workers or _cpu_count(), max(n_tasks, 1))
        runner: _Backend
        if n_workers == 0:
            runner = _SerialBackend()
        elif backend == "local":
            runner = _LocalBackend(workers)
        else:
            runner = _RayBackend(workers, ray_address)
        cancel = True
        try:
            _train_all(runner, store, config, to_train, mhash, progress)
            _score_all(runner, store, config, missing, mhash, chash, n_missing, progress)
            cancel = False
        finally:
            runner.close(cancel=cancel)

    records = []
    for s in specs:
        for sc, seed in cells:
            rec = store.read_cell(s.key, sc, seed, chash[s.key])
            if rec is None:  # only if a file vanished while we ran
                raise RuntimeError(f"cell {s.key}/{sc}/seed {seed} is missing after the sweep")
            try:
                records.append(CellResult.from_json(rec))
            except (ValueError, TypeError) as e:
                path = store.cell_path(s.key, sc, seed)
                raise ValueError(f"{path}: {e}; delete it to recompute this cell") from e
    return SweepResults(
        config=config,
        store_dir=store.root,
        records=tuple(records),
        n_computed=n_missing,
        n_reused=len(records) - n_missing,
        n_trained=len(to_train),
        wall_s=time.perf_counter() - t_start,
    )


def _progress_bar(total: int, desc: str, enabled: bool) -> Any:
    from tqdm.auto import tqdm

    return tqdm(total=total, desc=desc, unit="cell", disable=not enabled or total == 0, leave=False)


def _train_all(
    runner: _Backend,
    store: ResultStore,
    config: SweepConfig,
    to_train: list[DiagnoserSpec],
    mhash: Mapping[str, str],
    progress: bool,
) -> None:
    if not to_train:
        return
    handles = {runner.submit(_train_task, s, config.data): s for s in to_train}
    with _progress_bar(len(to_train), "training", progress) as bar:
        it = runner.completed(list(handles))
        while True:
            try:
                handle, (files, info) = next(it)
            except StopIteration:
                break
            except Exception as e:  # a worker's exception, re-raised with the cell's name
                raise RuntimeError(f"training failed: {type(e).__name__}: {e}") from e
            spec = handles[handle]
            store.write_model(spec.key, mhash[spec.key], files, {**spec.to_json(), **info})
            bar.update(1)


def _score_all(
    runner: _Backend,
    store: ResultStore,
    config: SweepConfig,
    missing: Mapping[tuple[str, int], list[DiagnoserSpec]],
    mhash: Mapping[str, str],
    chash: Mapping[str, str],
    n_missing: int,
    progress: bool,
) -> None:
    if not missing:
        return
    labels_needed = {s.key for ss in missing.values() for s in ss}
    refs: dict[str, Any] = {}
    if not runner.passes_paths:
        # Ship each model's files once (Ray's object store), not once per task.
        refs = {lab: runner.put(_dir_files(store.model_dir(lab))) for lab in labels_needed}
    handles: dict[Any, tuple[str, int]] = {}
    for (sc, seed), ss in missing.items():
        labels = tuple(s.key for s in ss)
        task = _EpisodeTask(
            data=config.data,
            scenario=sc,
            seed=seed,
            t_on=config.t_on,
            labels=labels,
            model_hashes=tuple(mhash[lab] for lab in labels),
            model_paths=(
                tuple(str(store.model_dir(lab).resolve()) for lab in labels)
                if runner.passes_paths
                else None
            ),
        )
        args = [] if runner.passes_paths else [refs[lab] for lab in labels]
        handles[runner.submit(_episode_task, task, *args)] = (sc, seed)
    with _progress_bar(n_missing, "cells", progress) as bar:
        it = runner.completed(list(handles))
        while True:
            try:
                handle, recs = next(it)
            except StopIteration:
                break
            except Exception as e:
                raise RuntimeError(f"scoring failed: {type(e).__name__}: {e}") from e
            sc, seed = handles[handle]
            for rec in recs:
                store.write_cell(rec["diagnoser"], sc, seed, chash[rec["diagnoser"]], rec)
                bar.update(1)


def detect_episode(
    config: SweepConfig, store_dir: str | os.PathLike, label: str, scenario: str, seed: int
) -> tuple[LoadedEpisode, Detection]:
    """Re-run one cell in this process and return the episode and the full :class:`Detection`.

    For figures and inspection after :func:`run_sweep` (which stores only scores): the model is
    loaded from the store and the episode regenerated, so the arrays match the stored cell.
    """
    loaded, diag = load_cell(config, store_dir, label, scenario, seed)
    return loaded, diag.detect(loaded.episode)


def load_cell(
    config: SweepConfig, store_dir: str | os.PathLike, label: str, scenario: str, seed: int
) -> tuple[LoadedEpisode, Diagnoser]:
    """The episode of one cell and the trained diagnoser ``label`` loaded from the store."""
    store = ResultStore.open(store_dir, config.data.store_key())
    specs = {s.key: s for s in config.diagnosers}
    if label not in specs:
        raise ValueError(f"Unknown diagnoser label {label!r}. In this sweep: {sorted(specs)}")
    if not store.has_model(label, config.model_hash(specs[label], store.data_hash)):
        raise ValueError(f"{label!r} has no trained model in {store.root}; run run_sweep first")
    diag = Diagnoser.load(store.model_dir(label))
    return config.data.load_test(scenario, seed), diag
