"""The isolation benchmark of one track: goal figures, confusion matrices, unknown faults.

``python -m evaluation.isolation.study --track paper --seeds test --out results/isolation``

1. The inner ``lrgf-mem`` is trained on the track's healthy training episodes (or loaded with
   ``--detector DIR``: a saved ``lrgf-mem`` trained on them), exactly as the leaderboard trains
   ``lrgf-mem``; the isolators that compose it (``lrgf-iso``, ``lrgf-lda``) share it, so their
   alarms are its alarms.
2. They learn the labelled training faults (:meth:`TrackData.train_fault_episodes`, training
   seeds 1000+); an isolator that stands alone (``mmae``, a bank of filters) is fitted on the
   healthy training episodes and the same labelled faults.
3. They are scored on faulty episodes of ``--seeds validation`` (5000+, for tuning) or
   ``test`` (the track's faulty test cells, seeds 0+; run once at the end), plus the unknown
   faults of :mod:`evaluation.isolation.unknown_faults` and ``--n-healthy`` healthy episodes
   on the same seeds.

Each lrgf-mem detection is computed once and shared by the isolators
(an isolator's ``diagnose_detection`` of the inner detection equals its ``detect``).

**Probabilities.** Beside t_it and CDR, each isolator's Brier score
(:mod:`evaluation.metrics.probability_metrics`): a probabilistic isolator's posterior, a hard
one's implied by its decision (nominal while not alarmed, its diagnosis when alarmed,
"unknown" uniform over the faults), and for ``lrgf-lda`` also its discriminants' softmax while
alarmed (LDA's own class posterior). Samples scored: every sample of a faulty episode from its
onset (truth: its fault) and every sample of a healthy episode (truth: nominal); unknown faults
are not scored (no hypothesis is true). The false-alarm rate r_fd on the healthy episodes too.

Outputs: ``<out>/<track>-<seeds>.md|json``, ``<out>/figures/<track>-<seeds>-<isolator>.png``
(confusion matrix) and ``<out>/figures/<track>-<seeds>-reliability.png`` (calibration).
Intervals: 95 % BCa bootstrap over episodes (:mod:`evaluation.metrics.intervals`).
"""

from __future__ import annotations

import argparse
import json
import math
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any, Protocol

import numpy as np
import torch

import diagnosers
from diagnosers.detection import Detection
from diagnosers.diagnoser import Diagnoser
from diagnosers.episode.record import Episode
from diagnosers.lrgf.lrgf_mem import LRGFMEM
from evaluation.isolation.probabilities import ProbabilityScores
from evaluation.isolation.unknown_faults import UNKNOWN_FAULTS, unknown_fault_episodes
from evaluation.metrics.detection_metrics import r_fd, r_td, t_dt
from evaluation.metrics.intervals import bootstrap_ci
from evaluation.metrics.isolation_metrics import UNKNOWN, confusion_matrix, isolation_scores
from evaluation.reports.plots import confusion_figure, reliability_figure
from evaluation.tracks.catalogue import TRACKS
from evaluation.tracks.track import Track
from evaluation.tracks.track_data import TrackData
from fcc_common.invocation import check_out_path, command_parser, out_path, run_command
from fcc_common.io import atomic_write
from fcc_common.validation import Integer, check, invalid
from fcc_env.scenarios import FaultSpec
from fcc_env.simulation import check_memory

__all__ = ["ISOLATORS", "Isolator", "check_counts", "episode_rows", "main", "summarise"]


class Isolator(Protocol):
    """What the study needs of an isolator that composes the inner detector: its classes,
    fitting on labelled faulty episodes with their inner detections, and a diagnosis of a
    detection. Any other isolating diagnoser is fitted and run through its contract
    (``fit``, ``detect``)."""

    isolates: bool
    classes_: tuple[str, ...]

    def fit_on_detector(
        self, detector: Diagnoser, faulty: list[Episode], detections: list[Detection]
    ) -> Any: ...

    def diagnose_detection(self, det: Detection) -> Detection: ...


#: the isolators scored, with their hyperparameters (defaults)
ISOLATORS: dict[str, dict[str, Any]] = {"lrgf-iso": {}, "lrgf-lda": {}, "mmae": {}}
#: the goal's allowance of isolation after detection [samples]
T_IT_ALLOWANCE = 30


def _ci(values: Sequence[float]) -> tuple[float, float, float]:
    v = [x for x in values if not math.isnan(x)]
    if not v:
        return (math.nan, math.nan, math.nan)
    if len(set(v)) == 1:
        return (v[0], v[0], v[0])
    iv = bootstrap_ci(v, rng=0)
    return (iv.estimate, iv.low, iv.high)


def episode_rows(
    classes: Sequence[str], episodes: Sequence[Episode], dets: Sequence[Detection]
) -> list[dict[str, Any]]:
    """One row of scores per faulty episode from the isolator's own detections ``dets``
    (truth: its class, or "unknown" if not one of ``classes``)."""
    rows = []
    for ep, det in zip(episodes, dets, strict=True):
        assert ep.fault_onset is not None
        assert det.diagnosis is not None
        truth = ep.scenario if ep.scenario in classes else UNKNOWN
        sc = isolation_scores(det.diagnosis, truth, ep.fault_onset)
        alarmed = det.diagnosis[ep.fault_onset :] != ""
        rows.append(
            {
                "scenario": ep.scenario,
                "seed": ep.seed,
                "truth": truth,
                "t_dt": t_dt(det.alarm, ep.fault_onset),
                "r_td": r_td(det.alarm, ep.fault_onset),
                "n_alarmed": int(np.count_nonzero(alarmed)),
                **sc,
            }
        )
    return rows


def summarise(rows: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per scenario: means with intervals, and the goal checks."""
    out = []
    for sc in dict.fromkeys(r["scenario"] for r in rows):
        rs = [r for r in rows if r["scenario"] == sc]
        gap = [r["t_it"] - r["t_dt"] for r in rs]
        within = [not math.isnan(g) and g <= T_IT_ALLOWANCE for g in gap]
        n_al = sum(r["n_alarmed"] for r in rs)
        pooled = sum(r["cdr"] * r["n_alarmed"] for r in rs if r["n_alarmed"]) / n_al if n_al else 0
        out.append(
            {
                "scenario": sc,
                "truth": rs[0]["truth"],
                "n": len(rs),
                "cdr": _ci([r["cdr"] for r in rs]),
                "cdr_pooled": pooled,
                "r_ti": _ci([r["r_ti"] for r in rs]),
                "r_fi": _ci([r["r_fi"] for r in rs]),
                "t_dt": _ci([r["t_dt"] for r in rs]),
                "t_it": _ci([r["t_it"] for r in rs]),
                "t_it_median": float(np.nanmedian([r["t_it"] for r in rs]))
                if any(not math.isnan(r["t_it"]) for r in rs)
                else math.nan,
                "t_it_minus_t_dt_median": float(np.nanmedian(gap))
                if any(not math.isnan(g) for g in gap)
                else math.nan,
                "share_t_it_within": float(np.mean(within)),
                "n_not_isolated": sum(math.isnan(r["t_it"]) for r in rs),
            }
        )
    return out


def _fmt(t: tuple[float, float, float], digits: int = 3) -> str:
    est, lo, hi = t
    if math.isnan(est):
        return "—"
    return f"{est:.{digits}f} [{lo:.{digits}f}, {hi:.{digits}f}]"


def _goal_rows(results: dict[str, Any]) -> list[str]:
    """One line per isolator: the issue's goal figures side by side."""
    lines = [
        "| isolator | CDR (mean over the faults) | mean t_it − mean t_dt [samples] | Brier after "
        "onset | Brier healthy | r_fd healthy | CPU s |",
        "|---|---|---|---|---|---|---|",
    ]
    for name, res in results["isolators"].items():
        known = [s for s in res["summary"] if s["truth"] != UNKNOWN]
        cdr_mean = float(np.nanmean([s["cdr"][0] for s in known])) if known else math.nan
        gap = [s["t_it"][0] - s["t_dt"][0] for s in known]
        brier = "; ".join(f"{v['faulty']:.3f} ({k})" for k, v in res["brier"].items()) or "—"
        healthy = "; ".join(f"{v['healthy']:.3f} ({k})" for k, v in res["brier"].items()) or "—"
        lines.append(
            f"| {name} | {cdr_mean:.3f} | {float(np.nanmean(gap)) if gap else math.nan:.1f} | "
            f"{brier} | {healthy} | {_fmt(res['r_fd_healthy'], 4)} | {res['cpu_s']:.0f} |"
        )
    return lines


def markdown(track: str, seeds: str, results: dict[str, Any]) -> str:
    lines = [f"## Isolation, track `{track}`, {seeds} seeds", ""]
    lines += [*_goal_rows(results), ""]
    lines += [
        "Brier: mean over the samples of the faulty episodes from their onset (known faults "
        "only) and of the healthy episodes; 'own' the isolator's posterior, 'decision' the "
        "one its decision implies, 'softmax' its discriminants' (module docstring).",
        "",
    ]
    for name, res in results["isolators"].items():
        lines += [
            f"### {name}",
            "",
            "| fault | n | CDR | r_ti | r_fi | t_dt | t_it | median t_it − t_dt | "
            f"t_it ≤ t_dt + {T_IT_ALLOWANCE} | not isolated |",
            "|---|---|---|---|---|---|---|---|---|---|",
        ]
        for s in res["summary"]:
            lines.append(
                f"| {s['scenario']} ({s['truth']}) | {s['n']} | {_fmt(s['cdr'])} | "
                f"{_fmt(s['r_ti'])} | {_fmt(s['r_fi'])} | {_fmt(s['t_dt'], 1)} | "
                f"{_fmt(s['t_it'], 1)} | {s['t_it_minus_t_dt_median']:.0f} | "
                f"{s['share_t_it_within']:.0%} | {s['n_not_isolated']} |"
            )
        rows, cols, m = res["confusion"]
        lines += ["", "Confusion (episodes; rows: true, columns: diagnosis):", ""]
        lines += ["| true \\ diagnosis | " + " | ".join(cols) + " |", "|---|" + "---|" * len(cols)]
        for r, counts in zip(rows, m, strict=True):
            lines.append(f"| {r} | " + " | ".join(str(c) for c in counts) + " |")
        u = res["unknown_share"]
        lines += [
            "",
            f"Unknown faults called 'unknown': {u:.1%} of their alarmed samples (pooled).",
            "",
        ]
    return "\n".join(lines)


def run(
    track: str,
    seeds: str,
    *,
    n_seeds: int = 20,
    n_unknown: int = 10,
    n_healthy: int = 10,
    detector: str | None = None,
    out: Path = Path("results/isolation"),
    isolators: dict[str, dict[str, Any]] | None = None,
) -> dict[str, Any]:
    """Train (or load) the inner detector, fit the isolators, score them; write the outputs."""
    torch.set_num_threads(1)
    if track not in TRACKS:
        raise ValueError(f"Unknown track {track!r}. Available: {sorted(TRACKS)}")
    if seeds not in ("validation", "test"):
        raise ValueError(f"seeds={seeds!r} must be 'validation' or 'test'")
    tr = TRACKS[track]
    start = _first_seed(tr, seeds)
    # before any training
    n_seeds, n_unknown = check_counts(tr, start, n_seeds, n_unknown, n_healthy)
    if isolators is not None and not (
        isinstance(isolators, dict) and all(isinstance(v, dict) for v in isolators.values())
    ):
        raise invalid("isolators", isolators, '{"label": {"name": registry name, params...}}')
    data = TrackData(track=tr)
    t0 = time.perf_counter()
    train_f = data.train_fault_episodes()
    seed_list = list(range(start, start + n_seeds))
    test = [
        data.simulate([s], tr.fault_spec(f, s))[0].episode for f in tr.faults for s in seed_list
    ]
    test = [ep for ep in test if ep.fault_onset is not None]
    test += [le.episode for le in unknown_fault_episodes(data, seed_list[:n_unknown])]
    healthy = [le.episode for le in data.simulate(seed_list[:n_healthy], FaultSpec())]
    shared = _SharedDetector(data, detector, train_f, test + healthy)
    results: dict[str, Any] = {"track": track, "seeds": seeds, "seed_list": seed_list}
    results["isolators"] = {}
    curves = {}
    for name, params in (isolators or ISOLATORS).items():
        params = dict(params)  # a label other than a registry name gives {"name": ..., ...}
        iso = diagnosers.make(params.pop("name", name), **params)
        assert iso.isolates, name
        c0 = time.process_time()
        if hasattr(iso, "fit_on_detector"):
            iso.fit_on_detector(shared.inner, train_f, shared.train_dets)
            own = [iso.diagnose_detection(d) for d in shared.dets]
        else:  # an isolator of its own: fitted and run through the contract
            iso.fit(data.train_episodes() + train_f)
            own = [iso.detect(ep) for ep in test + healthy]
        cpu_s = time.process_time() - c0
        rows = episode_rows(iso.classes_, test, own[: len(test)])
        truths = [r["truth"] for r in rows]
        conf = confusion_matrix(truths, [r["label"] for r in rows], iso.classes_)
        unk = [r for r in rows if r["truth"] == UNKNOWN]
        n_al = sum(r["n_alarmed"] for r in unk)
        share = sum(r["cdr"] * r["n_alarmed"] for r in unk if r["n_alarmed"]) / n_al if n_al else 0
        probs = ProbabilityScores(params.get("name", name))
        for ep, det in zip(test + healthy, own, strict=True):
            probs.add(ep, det, iso.classes_)
        results["isolators"][name] = {
            "params": iso.get_params(),
            "rows": rows,
            "summary": summarise(rows),
            "confusion": (conf[0], conf[1], conf[2].tolist()),
            "unknown_share": share,
            "r_fd_healthy": _ci([r_fd(d.alarm, len(d.alarm)) for d in own[len(test) :]]),
            "brier": {
                kind: {"faulty": probs.pooled(kind, False), "healthy": probs.pooled(kind, True)}
                for kind in probs.kinds()
            },
            "brier_rows": probs.rows,
            "cpu_s": cpu_s,
        }
        curves.update({f"{name} ({kind})": probs.curve(kind) for kind in probs.kinds()})
        confusion_figure(
            conf[0],
            conf[1],
            conf[2],
            f"{name}, track {track}, {seeds} seeds",
            out / "figures" / f"{track}-{seeds}-{name}.png",
        )
    reliability_figure(
        curves,
        f"Reliability of the isolators' probabilities, track {track}, {seeds} seeds",
        out / "figures" / f"{track}-{seeds}-reliability.png",
    )
    results["wall_s"] = time.perf_counter() - t0
    out.mkdir(parents=True, exist_ok=True)
    text = markdown(track, seeds, results)
    atomic_write(out / f"{track}-{seeds}.md", text)
    atomic_write(out / f"{track}-{seeds}.json", json.dumps(results, indent=1, default=float))
    print(text)
    return results


class _SharedDetector:
    """The inner ``lrgf-mem`` and its detections, made the first time an isolator asks."""

    def __init__(
        self, data: TrackData, path: str | None, train_f: list[Episode], scored: list[Episode]
    ) -> None:
        self.data, self.path, self.train_f, self.scored = data, path, train_f, scored
        self._inner: LRGFMEM | None = None

    @property
    def inner(self) -> LRGFMEM:
        if self._inner is None:
            if self.path is not None:
                inner = Diagnoser.load(self.path)
                if not isinstance(inner, LRGFMEM):
                    raise ValueError(f"{self.path} holds a {inner.name!r}, not an lrgf-mem")
                self._inner = inner
            else:
                self._inner = LRGFMEM().fit(self.data.train_episodes())
            self.train_dets = [self._inner.detect(ep) for ep in self.train_f]
            self.dets = [self._inner.detect(ep) for ep in self.scored]
        return self._inner


def _first_seed(track: Track, seeds: str) -> int:
    return track.validation_seed_start if seeds == "validation" else track.test_seed_start


def check_counts(
    track: Track, start: int, n_seeds: int, n_unknown: int, n_healthy: int = 0
) -> tuple[int, int]:
    """``n_seeds`` and ``n_unknown`` checked: the scored episodes fit the memory budget
    (:func:`fcc_env.simulation.check_memory`, as the leaderboard's counts) and test seeds from
    ``start`` stay below the training seeds; the unknown faults run on the first ``n_unknown``
    of the ``n_seeds`` seeds."""
    n_seeds = check("n_seeds", n_seeds, Integer(1))
    why = "the unknown faults run on the first n_seeds seeds"
    n_unknown = check("n_unknown", n_unknown, Integer(0, n_seeds, why=why))
    why = "the healthy episodes run on the first n_seeds seeds"
    n_healthy = check("n_healthy", n_healthy, Integer(0, n_seeds, why=why))
    train = track.train_seed_start
    if start < train < start + n_seeds:
        why = f"seeds from {start} would reach the training seeds {train}.."
        raise invalid("n_seeds", n_seeds, f"an integer in [1, {train - start}]", why)
    # every scored episode is held at once: each fault's and each unknown fault's
    try:
        n = len(track.faults) * n_seeds + len(UNKNOWN_FAULTS) * n_unknown + n_healthy
        check_memory(n, track.n_samples)
    except ValueError as e:
        raise ValueError(f"n_seeds={n_seeds}, n_unknown={n_unknown}: {e}") from None
    return n_seeds, n_unknown


def main(argv: Sequence[str] | None = None) -> int:
    p = command_parser(
        "evaluation.isolation.study",
        (__doc__ or "").split("\n")[0],
        (
            ("--track paper --seeds validation", "tune: the isolators on validation seeds 5000+"),
            (
                "--track paper --seeds test --out results/isolation",
                "the final score on the track's test seeds (run once, at the end)",
            ),
            (
                "--track small --detector models/lrgf-mem-small --n-seeds 5",
                "a saved lrgf-mem, trained on the track, and 5 faulty episodes per fault",
            ),
        ),
    )
    p.add_argument("--track", default="paper", help="comma-separated track names")
    p.add_argument("--seeds", default="validation", choices=["validation", "test"])
    p.add_argument("--n-seeds", type=int, default=20, help="faulty episodes per fault")
    p.add_argument("--n-unknown", type=int, default=10, help="episodes per unknown fault")
    p.add_argument(
        "--n-healthy", type=int, default=10, help="healthy episodes (Brier score, false alarms)"
    )
    p.add_argument("--detector", help="directory of a saved lrgf-mem (trained on the track)")
    p.add_argument("--out", type=out_path, default=Path("results/isolation"))
    p.add_argument(
        "--isolators",
        help='JSON {"label": {"name": registry name, params...}} (default: the registered two)',
    )
    return run_command(p, _study, argv)


def _study(a: argparse.Namespace) -> int:
    """The work of :func:`main`: its failures (and a Ctrl-C) are reported by :func:`run_command`."""
    try:
        isolators = json.loads(a.isolators) if a.isolators else None
    except json.JSONDecodeError as e:
        raise ValueError(f"--isolators {a.isolators!r} is not valid JSON: {e}") from None
    check_out_path("--out", a.out)
    tracks = [t.strip() for t in a.track.split(",")]
    for track in tracks:  # every track's counts before the first one trains
        if track not in TRACKS:
            raise ValueError(f"Unknown track {track!r}. Available: {sorted(TRACKS)}")
        start = _first_seed(TRACKS[track], a.seeds)
        check_counts(TRACKS[track], start, a.n_seeds, a.n_unknown, a.n_healthy)
    for track in tracks:
        run(
            track,
            a.seeds,
            n_seeds=a.n_seeds,
            n_unknown=a.n_unknown,
            n_healthy=a.n_healthy,
            detector=a.detector,
            out=a.out,
            isolators=isolators,
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
