"""Records of a sweep: one :class:`CellResult` per (diagnoser, scenario, seed), and summaries.

Episode scoring (:func:`score_episode`) uses :func:`evaluation.metrics.detection_metrics.episode_scores`. An episode
that the simulator terminated early is scored on its samples before ``terminated_at`` only; the
record keeps ``terminated_at`` and the reason. If it terminated before the fault onset, no faulty
sample remains: ``r_td`` and ``t_dt`` are then ``nan`` and the episode is not counted as a miss.
:func:`summarize` turns records into mean ± standard deviation across seeds (pure, no I/O).
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Collection, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from diagnosers.detection import Detection
from diagnosers.diagnoser import Diagnoser
from diagnosers.episode.record import Episode
from evaluation.metrics.detection_metrics import episode_scores
from evaluation.metrics.isolation_metrics import UNKNOWN, isolation_scores
from evaluation.sweep.sources import LoadedEpisode
from fcc_env.faults import isolation_outcome

#: Python types a stored cell field may hold, by the annotation of :class:`CellResult`.
_FIELD_KINDS: dict[str, type | tuple[type, ...]] = {
    "str": str,
    "int": int,
    "float": (int, float),
    "bool": bool,
}


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
    # isolating diagnosers only (evaluation.metrics.isolation_metrics); "" / nan otherwise and when healthy
    diagnosis: str = ""  # episode label: majority diagnosis of the alarmed post-onset samples
    t_it: float = math.nan  # isolation time [samples] (right label held for 100 samples)
    r_ti: float = math.nan  # true isolation rate
    r_fi: float = math.nan  # false isolation rate
    cdr: float = math.nan  # correct diagnosis rate among the alarmed post-onset samples
    # the fault onset is assumed, not stated by the data (r_td/t_dt count from an assumption);
    # set from the data source when results are presented (:func:`mark_assumed_onsets`)
    onset_assumed: bool = False
    # share of the fault-free window the diagnoser flagged novel (outside its training range,
    # Detection.novelty; those samples are not in r_fd); nan when it flags no novelty at all
    novelty: float = math.nan

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
            if f.name not in obj and f.default is not dataclasses.MISSING:
                continue  # a field added later (isolation scores): its default
            if f.name not in obj:
                raise ValueError(f"cell record lacks the field {f.name!r}")
            v = obj[f.name]
            if f.type == "float" and v is None:
                v = float("nan")
            kind = _FIELD_KINDS.get(f.type.replace(" | None", ""))
            ok = kind is None or (isinstance(v, kind) and (kind is bool or not isinstance(v, bool)))
            if not ok and not (v is None and "None" in f.type):
                raise ValueError(
                    f"cell record field {f.name}={v!r} has the wrong type (expected {f.type})"
                )
            kwargs[f.name] = float(v) if f.type == "float" else v
        return cls(**kwargs)


def mark_assumed_onsets(
    records: Sequence[CellResult], assumed: Collection[str]
) -> list[CellResult]:
    """``records`` with ``onset_assumed`` set for the faulty cells of the ``assumed`` scenarios
    (a data source's ``assumed_onsets``) and cleared elsewhere.

    The flag describes the data, not a result: it is applied when results are presented, so
    cells stored before it existed, or before a manifest marked its onsets, are labelled by
    what the data source says now.
    """
    out = []
    for r in records:
        flag = r.faulty and r.scenario in assumed
        out.append(r if r.onset_assumed == flag else dataclasses.replace(r, onset_assumed=flag))
    return out


def column_label(label: str, column: str) -> str:
    """``label`` as ``column`` where both name the same faults: a concurrent column ``a+b``
    (its faults, :meth:`evaluation.tracks.Track.labels`, joined by ``+``) named ``b+a``, in
    :func:`fcc_env.faults.isolation_outcome`'s convention (both names, any order; one of the
    two is wrong, ``unknown`` abstains). Other labels are returned as they are.

    >>> column_label("valve-stiction+sensor-bias", "sensor-bias+valve-stiction")
    'sensor-bias+valve-stiction'
    >>> column_label("sensor-bias", "sensor-bias+valve-stiction")
    'sensor-bias'
    """
    if label == column or "+" not in column or "+" not in label:
        return label
    same = isolation_outcome(label.split("+"), column.split("+")) == "correct"
    return column if same else label


def column_labels(diagnosis: np.ndarray, column: str) -> np.ndarray:
    """:func:`column_label` of every sample's diagnosis (each distinct label once)."""
    if "+" not in column:
        return diagnosis
    names, inverse = np.unique(diagnosis, return_inverse=True)
    mapped = np.array([column_label(str(n), column) for n in names], dtype=object)
    return mapped[inverse].astype(str)


def score_episode(
    diagnoser: Diagnoser, loaded: LoadedEpisode, *, label: str | None = None, t_on: int = 0
) -> CellResult:
    """Run ``diagnoser.detect`` on one episode and compute its indexes (no I/O)."""
    return detect_and_score(diagnoser, loaded, label=label, t_on=t_on)[0]


def detect_and_score(
    diagnoser: Diagnoser,
    loaded: LoadedEpisode,
    *,
    label: str | None = None,
    t_on: int = 0,
    detect: Callable[[Episode], Detection] | None = None,
) -> tuple[CellResult, Detection]:
    """:func:`score_episode` that also returns the :class:`Detection` it scored (no I/O).

    ``detect``: what gives the diagnoser's detection of the episode, if not
    ``diagnoser.detect`` (an isolator that reuses its inner detector's stored detection); the
    record's ``detect_wall_s`` is its wall time."""
    ep = loaded.episode
    nan = float("nan")
    t0 = time.perf_counter()
    det = (diagnoser.detect if detect is None else detect)(ep)
    wall = time.perf_counter() - t0
    n = ep.n_samples
    onset = ep.fault_onset  # None also when the episode ended before the planned onset
    if n > t_on:
        scores = episode_scores(det.alarm, onset, t_on=t_on, novelty=det.novelty)
    else:  # too short to score anything
        scores = {"r_fd": nan, "r_td": nan, "t_dt": nan}
    if loaded.fault_onset is not None and onset is None:
        # Terminated before the fault: r_fd over the fault-free samples, nothing to detect.
        scores["r_td"] = scores["t_dt"] = nan
    iso: dict[str, Any] = {}
    if det.diagnosis is not None and onset is not None:
        # a fault the diagnoser was not trained on is rightly called "unknown"
        classes = {column_label(c, ep.scenario) for c in det.class_names}
        truth = ep.scenario if ep.scenario in classes else UNKNOWN
        iso = isolation_scores(column_labels(det.diagnosis, ep.scenario), truth, onset)
        iso["diagnosis"] = iso.pop("label")
    record = CellResult(
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
        novelty=float(scores.get("novelty", nan)),
        **iso,
    )
    return record, det


#: Prefixes of the arrays of a kept detection: the diagnoser's decisions, and its band view.
_VIEWS = ("det", "bands")
_DET_FIELDS = ("alarm", "signal", "lower", "upper", "residual")


def pack_detection(
    loaded: LoadedEpisode, detection: Detection, bands: Detection | None = None
) -> dict[str, np.ndarray]:
    """The arrays a figure needs, as a flat dict of plain numpy arrays (no pickles).

    :func:`unpack_detection` is its inverse. The episode travels as its measurements, channel
    names, sample time and onsets, so the figure needs neither the simulator nor the model.
    """
    ep = loaded.episode
    out: dict[str, np.ndarray] = {
        "y": ep.y,
        "channels": np.array(ep.channels, dtype=str),
        **({} if ep.units is None else {"units": np.array(ep.units, dtype=str)}),
        "sample_time_s": np.array(ep.sample_time_s),
        "scenario": np.array(ep.scenario),
        "seed": np.array(-1 if ep.seed is None else ep.seed),
        "fault_onset": np.array(-1 if ep.fault_onset is None else ep.fault_onset),
        "planned_onset": np.array(-1 if loaded.fault_onset is None else loaded.fault_onset),
    }
    for view, det in zip(_VIEWS, (detection, bands), strict=True):
        if det is not None:
            out.update(detection_arrays(det, f"{view}_"))
    return out


def detection_arrays(det: Detection, prefix: str = "") -> dict[str, np.ndarray]:
    """A :class:`Detection` as plain arrays named ``<prefix><field>`` (no pickles), exactly:
    :func:`detection_from_arrays` gives it back to the bit. An isolator's inner detection is
    stored this way (:mod:`evaluation.sweep.runner`)."""
    out = {f"{prefix}{f}": np.asarray(getattr(det, f)) for f in _DET_FIELDS}
    out[f"{prefix}signal_names"] = np.array(det.signal_names, dtype=str)
    if det.diagnosis is not None:  # isolating diagnosers: the diagnosis per sample
        out[f"{prefix}diagnosis"] = np.asarray(det.diagnosis, dtype=str)
    if det.posterior is not None:  # probabilistic diagnosers: the posterior per sample
        out[f"{prefix}posterior"] = det.posterior
        out[f"{prefix}hypothesis_names"] = np.array(det.hypothesis_names, dtype=str)
    if det.novelty is not None:  # samples flagged outside the training range
        out[f"{prefix}novelty"] = det.novelty
    return out


def detection_from_arrays(arrays: Mapping[str, np.ndarray], prefix: str = "") -> Detection:
    """Inverse of :func:`detection_arrays`."""
    return Detection(
        **{f: arrays[f"{prefix}{f}"] for f in _DET_FIELDS},
        signal_names=tuple(str(n) for n in arrays[f"{prefix}signal_names"]),
        diagnosis=arrays.get(f"{prefix}diagnosis"),
        posterior=arrays.get(f"{prefix}posterior"),
        hypothesis_names=tuple(
            str(n) for n in arrays.get(f"{prefix}hypothesis_names", np.array([], str))
        ),
        novelty=arrays.get(f"{prefix}novelty"),
    )


def unpack_detection(
    arrays: Mapping[str, np.ndarray],
) -> tuple[Episode, int | None, Detection, Detection | None]:
    """Inverse of :func:`pack_detection`: ``(episode, planned onset, detection, bands)``."""
    onset = int(arrays["fault_onset"])
    planned = int(arrays["planned_onset"])
    seed = int(arrays["seed"])
    units = arrays.get("units")  # absent in arrays stored before episodes carried units
    ep = Episode(
        y=arrays["y"],
        channels=tuple(str(c) for c in arrays["channels"]),
        sample_time_s=float(arrays["sample_time_s"]),
        fault_onset=None if onset < 0 else onset,
        scenario=str(arrays["scenario"]),
        seed=None if seed < 0 else seed,
        units=None if units is None else tuple(str(u) for u in units),
    )
    views: list[Detection | None] = [
        detection_from_arrays(arrays, f"{view}_") if f"{view}_alarm" in arrays else None
        for view in _VIEWS
    ]
    det, bands = views
    assert det is not None, "a kept detection always holds the diagnoser's decisions"
    return ep, None if planned < 0 else planned, det, bands


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
    onset_assumed: bool = False  # the scenario's onset is assumed, not stated by the data
    novelty: float = float("nan")  # mean novel share (CellResult.novelty), nan when none flagged

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
                onset_assumed=any(r.onset_assumed for r in rs),
                novelty=_mean_std([r.novelty for r in rs])[0],
            )
        )
    return out
