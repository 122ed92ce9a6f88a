"""Every task of a leaderboard run, counted without running the long ones, and its projected
time: ``python -m bench.task_plan --track all``.

A from-scratch ``--track all`` with every registered detector takes hours on a two-core
machine; this plans it instead, with the driver's own rules, and measures a sample:

1. **Trainings and relation jobs, exactly.** Each track's applicable diagnosers (as the
   leaderboard picks them), one training per model-cache key (a track whose training set
   equals an earlier one's reuses its models, :func:`evaluation.tracks.board.run_track`). Each
   training task is run for real, in this process, timed (:func:`~evaluation.sweep.task_log.timed_call`):
   its banks name the relation jobs they need (:mod:`diagnosers.bank.relation_plan`), which
   get *stand-ins* (the same job trained for one epoch, filed under the real job's key) so
   that the fit goes on to its next round (``lrgf-glr``'s warm-started final bank) and ends.
   Job keys are counted once across the run, as the relation cache shares them.
2. **Relation jobs' CPU** from a sample of ``--relations`` jobs trained at their real
   settings: CPU seconds per unit of :attr:`~diagnosers.bank.parallel.RelationJob.cost`,
   applied to every job (their spread is reported).
3. **Scoring and reference rows** from a run of each track at sample sizes
   (``--healthy``/``--faulty`` test episodes) through the real drivers, in this process, with
   the trained (stand-in) models: the episode tasks' CPU by healthy/faulty episode, the
   reference rows' fits and per-cell scoring (on ``--reference-tracks``; the others take
   the figures of the measured track of the same loop kind), the driver's CPU per cell.
4. The plan as :class:`bench.task_profile.Block` s with the driver's barriers and
   dependencies, projected on 1, 2, 4, 8, 16 workers (:func:`bench.task_profile.makespan`).

The stand-in relations change the models, not the work of a fit or a detection (the networks
have the same sizes), except where a detector's work depends on its alarms. A worker's
start-up is measured once, on one pool worker.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys
import tempfile
import time
from collections import defaultdict
from collections.abc import Collection, Mapping, Sequence
from pathlib import Path
from typing import Any

from bench.amdahl import amdahl_fit
from bench.task_costs import sample_costs, sample_track, sampled, worker_startup
from bench.task_profile import Block, critical_path, makespan, parse_workers
from diagnosers.bank.parallel import train_relation
from diagnosers.registry import available
from evaluation.sweep.config import DiagnoserSpec, SweepConfig, default_specs
from evaluation.sweep.store import canonical_hash
from evaluation.sweep.task_log import (
    timed_call,
)
from evaluation.sweep.tasks import TrainOutcome, train_task
from evaluation.tracks.board import applicable, model_cache_dir, track_channels
from evaluation.tracks.catalogue import parse_tracks
from evaluation.tracks.filter_bound import SIGNATURE_SEEDS
from evaluation.tracks.oracle import DEFAULT_REFERENCES, OracleStage
from evaluation.tracks.reference_runs import (
    DIRECTIONAL_CHUNK,
    FILTER_CHUNK,
    sharing_groups,
)
from evaluation.tracks.track import Track
from evaluation.tracks.track_data import TrackData
from fcc_common.invocation import command_parser, run_command
from fcc_common.io import atomic_write
from fcc_common.validation import invalid

__all__ = ["main", "plan_trainings", "sample_costs"]


def _stand_in(job: Any) -> Any:
    """The job trained for one epoch (network and error model): a relation of the same sizes."""
    s = dataclasses.replace(job.settings, max_epochs=1, mem_max_epochs=1)
    return train_relation(dataclasses.replace(job, settings=s))


def plan_trainings(
    tracks: Sequence[Track], names: Sequence[str] | None, fit_tracks: Collection[str]
) -> tuple[list[dict[str, Any]], dict[str, Any]]:
    """Per track, its diagnosers and the trainings it runs (rounds: CPU and relation jobs);
    and every relation job met (key → job), each once.

    The trainings of ``fit_tracks`` are run (with stand-in relations); another track's
    training of a diagnoser copies the rounds of that diagnoser on a fitted track of the same
    loop kind (its relation jobs renamed for the track's training set, unless that set is the
    fitted track's own: then the relation cache shares them)."""
    fits: dict[str, dict[str, Any]] = {}  # model-cache key -> its training
    jobs: dict[str, Any] = {}
    plan: dict[str, dict[str, Any]] = {}
    fitted: list[dict[str, Any]] = []
    order = sorted(tracks, key=lambda t: t.name not in fit_tracks)  # the fitted tracks first
    for track in order:
        wanted = list(available()) if names is None else list(names)
        keep, _ = applicable(wanted, track_channels(track), f"on track {track.name}")
        config = SweepConfig(diagnosers=default_specs(keep), data=TrackData(track=track))
        keys = []
        for spec in config.diagnosers:
            key = str(model_cache_dir(config, spec, Path("/")))
            keys.append(key)
            if key in fits:  # the model cache: trained by an earlier track
                continue
            src = None if track.name in fit_tracks else _fitted_like(spec, track, fitted, fits)
            if src is None:
                fits[key] = _train(spec, config, jobs)
                print(f"  trained {spec.key}: {_cpu(fits[key]):.1f} s CPU", file=sys.stderr)
            else:
                fits[key] = _copied(track, *src, jobs)
        entry = {"track": track, "config": config, "keys": keys, "fits": fits}
        plan[track.name] = entry
        if track.name in fit_tracks or any(not fits[k].get("copied_from") for k in keys):
            fitted.append(entry)  # later tracks copy what was trained here
        print(f"planned {track.name}: {len(fits)} trainings, {len(jobs)} jobs", file=sys.stderr)
    return [plan[t.name] for t in tracks], jobs


def _cpu(fit: Mapping[str, Any]) -> float:
    return sum(r["cpu_s"] for r in fit["rounds"])


#: Suffixes of a variant whose training is its base's (a preset of other settings): a
#: variant no fitted track holds copies its base's training.
VARIANT_SUFFIXES = ("-closed-novelty", "-novelty", "-closed")


def _fitted_like(
    spec: DiagnoserSpec,
    track: Track,
    fitted: Sequence[Mapping[str, Any]],
    fits: Mapping[str, Mapping[str, Any]],
) -> tuple[Mapping[str, Any], Track] | None:
    """The training of ``spec`` (else of its base, :data:`VARIANT_SUFFIXES`) on a fitted
    track, the same loop kind first: ``(training, track)``, or None."""
    names = [spec.key] + [
        spec.key.removesuffix(x) for x in VARIANT_SUFFIXES if spec.key.endswith(x)
    ]
    same = [e for e in fitted if e["track"].closed_loop == track.closed_loop]
    for name in names:
        for e in [*same, *(e for e in fitted if e not in same)]:
            for key in e["keys"]:
                if fits[key]["spec"].key == name:
                    return fits[key], e["track"]
    return None


def _copied(
    track: Track, src: Mapping[str, Any], rep: Track, jobs: dict[str, Any]
) -> dict[str, Any]:
    """A training planned on the fitted track ``rep``, on ``track``: the same rounds, the
    relation jobs renamed for ``track``'s training set unless it is ``rep``'s."""
    own = canonical_hash(TrackData(track=track).training_key())[:12]
    shared = own == canonical_hash(TrackData(track=rep).training_key())[:12]
    rounds = []
    for rnd in src["rounds"]:
        renamed = [k if shared else f"{k}@{own}" for k in rnd["jobs"]]
        for k, new in zip(rnd["jobs"], renamed, strict=True):
            jobs.setdefault(new, jobs[k])
        rounds.append({**rnd, "jobs": renamed})
    return {**src, "rounds": rounds, "copied_from": rep.name}


def _train(spec: DiagnoserSpec, config: SweepConfig, jobs: dict[str, Any]) -> dict[str, Any]:
    """Run ``spec``'s training tasks as the sweep would, with stand-in relations; its rounds."""
    known: dict[str, Any] = {}
    rounds = []
    while True:
        outcome, stats = timed_call(train_task, spec, config.data, config.imports, dict(known))
        outcome = TrainOutcome(*outcome)
        rounds.append(
            {"cpu_s": stats["cpu_s"], "parts": stats["parts"], "jobs": list(outcome.needed)}
        )
        if not outcome.needed:
            return {"spec": spec, "rounds": rounds, "files": outcome.files, "info": outcome.info}
        if len(rounds) > 5:
            raise RuntimeError(f"training {spec.key}: more than 5 rounds of relation jobs")
        for rkey, job in outcome.needed.items():
            jobs.setdefault(rkey, job)
            known[rkey] = _stand_in(job)


def relation_rate(jobs: Mapping[str, Any], n: int) -> dict[str, Any]:
    """CPU seconds per unit of job cost, from ``n`` jobs trained at their real settings, picked
    at even quantiles of cost among the jobs that start from scratch."""
    # cold starts: a warm-started job's stand-in start is no trained bank (it would stop late)
    cold = [j for j in jobs.values() if j.init is None] or list(jobs.values())
    ordered = sorted(cold, key=lambda j: j.cost)
    picks = (
        [ordered[round(q * (len(ordered) - 1) / max(n - 1, 1))] for q in range(n)]
        if ordered
        else []
    )
    rows = []
    for job in picks:
        _, stats = timed_call(lambda j, _serial=False: train_relation(j), job)
        rows.append(
            {"cost": job.cost, "max_epochs": job.settings.max_epochs, "cpu_s": stats["cpu_s"]}
        )
        print(f"relation job cost {job.cost:.3g}: {stats['cpu_s']:.1f} s CPU", file=sys.stderr)
    rates = [r["cpu_s"] / r["cost"] for r in rows]
    return {
        "sample": rows,
        "rate": sum(r["cpu_s"] for r in rows) / sum(r["cost"] for r in rows) if rows else 0.0,
        "rate_min": min(rates, default=0.0),
        "rate_max": max(rates, default=0.0),
    }


class _Ids:
    def __init__(self) -> None:
        self.n = 0

    def __call__(self) -> int:
        self.n += 1
        return self.n


def build_blocks(
    entries: Sequence[Mapping[str, Any]],
    jobs: Mapping[str, Any],
    rate: float,
    costs: Mapping[str, Mapping[str, Any]],
) -> tuple[list[Block], dict[str, dict[str, float]]]:
    """The run of ``entries`` (tracks in order) from scratch as blocks; and per kind of task its
    count and CPU."""
    ids, blocks = _Ids(), []
    kinds: dict[str, dict[str, float]] = defaultdict(lambda: {"n": 0, "cpu_s": 0.0})
    trained_models: set[str] = set()
    relation_done: set[str] = set()

    def add(b: Block, kind: str, cpu: float, after: Sequence[int] = ()) -> int:
        i = ids()
        b.cpu_s[i], b.after[i] = cpu, tuple(after)
        kinds[kind]["n"] += 1
        kinds[kind]["cpu_s"] += cpu
        return i

    for e in entries:
        name, track = e["track"].name, e["track"]
        c = costs[name]
        train = Block(f"{name}:sweep:train")
        in_block: dict[str, int] = {}  # relation key -> its task in this block
        for key in e["keys"]:
            if key in trained_models:
                continue
            trained_models.add(key)
            deps: list[int] = []
            for rnd in e["fits"][key]["rounds"]:
                t = add(train, "train", rnd["cpu_s"], deps)
                deps = [t]
                for rkey in rnd["jobs"]:
                    if rkey not in relation_done:
                        relation_done.add(rkey)
                        in_block[rkey] = add(train, "relation", rate * jobs[rkey].cost, [t])
                    if rkey in in_block:
                        deps.append(in_block[rkey])
        blocks.append(train)
        cells = e["config"].data.cells()
        n_specs = len(e["keys"])
        score = Block(f"{name}:sweep:score", driver_s=c["sweep_driver_per_cell_s"] * len(cells))
        for sc, _ in cells:
            add(score, "episode", c["episode_healthy_s" if sc == "nominal" else "episode_faulty_s"])
        kinds["cells"]["n"] += len(cells) * n_specs
        blocks.append(score)
        blocks.append(_reference_block(name, track, cells, c, add))
    return blocks, dict(kinds)


def _reference_block(name: str, track: Track, cells: Any, c: Mapping[str, Any], add: Any) -> Block:
    """The reference rows' tasks of a track as :func:`~evaluation.tracks.reference_runs.run_references`
    submits them: the fits (the filter and directional rows split in parts), then per group
    of rows one task per seed, after the group's fits."""
    b = Block(f"{name}:references", driver_s=c["reference_driver_per_cell_s"] * len(cells))
    fit_s = c["reference_fit_s"]

    def parts(kind: str, n: int, after: Sequence[int] = ()) -> list[int]:
        return [add(b, kind, fit_s.get(kind, 0.0), after) for _ in range(n)]

    fit_of: dict[int, int] = {}
    for j, cfg in enumerate(DEFAULT_REFERENCES):
        n_cal = len(cfg.calibration_seeds(track))
        if cfg.stage == OracleStage.FILTER:
            sig = parts("filter-signature", len(track.train_fault_seeds[:SIGNATURE_SEEDS]))
            stat = parts("filter-statistics", math.ceil(n_cal / FILTER_CHUNK), sig)
            (fit_of[j],) = parts("filter-limits", 1, stat)
        elif cfg.stage == OracleStage.DIRECTIONAL:
            res = parts("directional-residuals", math.ceil(n_cal / DIRECTIONAL_CHUNK))
            (fit_of[j],) = parts("directional-fit", 1, res)
        else:
            key = f"fit:{cfg.inputs}+{cfg.stage}"
            fit_of[j] = add(b, "reference-fit", fit_s.get(key, 0.0))
    per_seed: dict[int, int] = defaultdict(int)
    for _, seed in cells:
        per_seed[seed] += 1
    for rows in sharing_groups(list(DEFAULT_REFERENCES)):
        group = "+".join(str(DEFAULT_REFERENCES[j].stage) for j in rows)
        per_cell = c["reference_seed_per_cell_s"].get(group, 0.0)
        for n in per_seed.values():
            add(b, "reference-seed", per_cell * n, [fit_of[j] for j in rows])
    return b


def with_startup(blocks: Sequence[Block], startup_s: float) -> list[Block]:
    """Each driver call starts a pool: the sweep (its training, else its scoring block) and the
    reference rows; its workers' start-up is added to the first of its blocks with tasks."""
    out, pending = [], False
    for b in blocks:
        kind = b.name.rsplit(":", 1)[-1]
        if kind == "train":
            pending = True
        if kind == "references":
            pending = True
        if pending and b.cpu_s:
            b = dataclasses.replace(b, startup_s=startup_s)
            pending = False
        if kind == "score":
            pending = False
        out.append(b)
    return out


def summary(
    blocks: Sequence[Block], kinds: Mapping[str, Mapping[str, float]], workers: Sequence[int]
) -> dict[str, Any]:
    """Total CPU, critical path, projected makespans and the serial fraction of a plan."""
    proj = {o: {n: makespan(blocks, n, o) for n in workers} for o in ("lpt", "fifo")}
    lpt = proj["lpt"]
    f = amdahl_fit(list(lpt), [lpt[1] / lpt[n] for n in lpt])
    task_cpu = sum(sum(b.cpu_s.values()) for b in blocks)
    driver = sum(b.driver_s for b in blocks)
    startup = sum(b.startup_s for b in blocks)
    longest = max((max(b.cpu_s.values()) for b in blocks if b.cpu_s), default=0.0)
    return {
        "kinds": {k: dict(v) for k, v in kinds.items()},
        "task_cpu_s": task_cpu,
        "driver_cpu_s": driver,
        "startup_per_pool_s": startup,
        "cpu_over_2_s": (task_cpu + driver) / 2,
        "critical_path_s": makespan(blocks, None),
        "longest_task_s": longest,
        "stage_critical_paths_s": {
            b.name: critical_path(b.cpu_s, b.after) for b in blocks if b.cpu_s
        },
        "projection_s": proj,
        "serial_fraction": f,
    }


def _print_summary(title: str, s: Mapping[str, Any], out: Any = None) -> None:
    w = (out or sys.stdout).write
    total = s["task_cpu_s"] + s["driver_cpu_s"]
    w(f"\n## {title}\n\n| part | tasks | CPU [s] | share |\n|---|---|---|---|\n")
    for k, v in sorted(s["kinds"].items(), key=lambda kv: -kv[1]["cpu_s"]):
        if k == "cells":
            continue
        w(f"| {k} | {v['n']:.0f} | {v['cpu_s']:.0f} | {v['cpu_s'] / total:.1%} |\n")
    w(f"| driver (serial) | | {s['driver_cpu_s']:.0f} | {s['driver_cpu_s'] / total:.1%} |\n")
    w(f"| total | | {total:.0f} | |\n\n")
    w(
        f"detector cells: {s['kinds'].get('cells', {}).get('n', 0):.0f}; pools' start-up (per worker, summed over pools): {s['startup_per_pool_s']:.0f} s\n"
    )
    w(f"sum of CPU / 2 (two cores, no overhead): {s['cpu_over_2_s'] / 60:.1f} min\n")
    w(
        f"critical path (unlimited workers): {s['critical_path_s'] / 60:.1f} min; longest task {s['longest_task_s']:.0f} s\n\n"
    )
    w("| workers | LPT [min] | FIFO [min] | speed-up (LPT) |\n|---|---|---|---|\n")
    lpt, fifo = s["projection_s"]["lpt"], s["projection_s"]["fifo"]
    for n in lpt:
        w(f"| {n} | {lpt[n] / 60:.1f} | {fifo[n] / 60:.1f} | {lpt[1] / lpt[n]:.2f} |\n")
    w(f"serial fraction (Amdahl fit of the LPT projection): {s['serial_fraction']:.3f}\n")


# ---- the command -------------------------------------------------------------------------------
def main(argv: list[str] | None = None) -> int:
    p = command_parser(
        "bench.task_plan",
        (__doc__ or "").split("\n\n")[0],
        (
            ("--track all", "every track, every registered detector, planned and projected"),
            ("--track small --relations 2 --json plan.json", "one track, as JSON"),
        ),
    )
    p.add_argument("--track", default="all", help="tracks, as the leaderboard's --track")
    p.add_argument("--diagnosers", default=None, help="comma-separated (default: every registered)")
    p.add_argument(
        "--relations",
        type=int,
        default=3,
        help="relation jobs trained in full (0: none, relation CPU unknown)",
    )
    p.add_argument("--healthy", type=int, default=2, help="healthy test episodes sampled per track")
    p.add_argument("--faulty", type=int, default=1, help="faulty test episodes per fault sampled")
    p.add_argument(
        "--fit-tracks",
        default="paper,closed",
        help="tracks whose trainings are run (with stand-in relations); the others copy a "
        "fitted track's trainings of the same loop kind",
    )
    p.add_argument(
        "--score-tracks",
        default="all",
        help="tracks whose scoring is sampled, among the fitted ones (the others take a sampled "
        "track's of the same loop kind)",
    )
    p.add_argument(
        "--reference-tracks", default="paper,closed", help="tracks whose reference rows are sampled"
    )
    p.add_argument("--goal-track", default="small", help="a track also planned alone, from scratch")
    p.add_argument("--workers", default="1,2,4,8,16", help="worker counts, 1 among them")
    p.add_argument(
        "--work", default=None, help="directory for the sample stores (default: temporary)"
    )
    p.add_argument("--json", default=None, metavar="PATH", help="write the plan's figures as JSON")
    return run_command(p, _report, argv)


def _report(args: argparse.Namespace) -> int:
    workers = parse_workers(args.workers)
    for flag, low in (("relations", 0), ("healthy", 1), ("faulty", 1)):
        if getattr(args, flag) < low:
            raise invalid(f"--{flag}", getattr(args, flag), f"an integer >= {low}")
    tracks = parse_tracks(args.track)
    names = None if args.diagnosers is None else args.diagnosers.split(",")
    ref_tracks = set(args.reference_tracks.split(","))
    fit_tracks = {t.name for t in parse_tracks(args.fit_tracks)}
    score_tracks = {t.name for t in parse_tracks(args.score_tracks)} & fit_tracks
    c0 = time.process_time()
    with tempfile.TemporaryDirectory(prefix="fcc-plan-") as tmp:
        work = Path(args.work or tmp)
        plan, jobs = plan_trainings(tracks, names, fit_tracks)
        rate = relation_rate(jobs, args.relations)
        startup = worker_startup()
        costs = {}
        for e in plan:
            t = e["track"]
            lines = sample_track(
                e, work, args.healthy, args.faulty, t.name in score_tracks, t.name in ref_tracks
            )
            small = sampled(t, args.healthy, args.faulty)
            costs[t.name] = sample_costs(lines, TrackData(track=small).cells())
            print(
                f"sampled {t.name}: {costs[t.name]['episode_healthy_s']:.2f} s per healthy episode task",
                file=sys.stderr,
            )
    _borrow(plan, costs, "has_scoring", SCORING_FIELDS)
    _borrow(plan, costs, "has_references", REFERENCE_FIELDS)
    out: dict[str, Any] = {
        "relation_rate": rate,
        "worker_startup_s": startup,
        "costs": costs,
        "n_jobs": len(jobs),
        "plan_cpu_s": time.process_time() - c0,
    }
    blocks, kinds = build_blocks(plan, jobs, rate["rate"], costs)
    out["all"] = summary(with_startup(blocks, startup), kinds, workers)
    _print_summary(f"{args.track}: {len(plan)} tracks", out["all"])
    goal = [e for e in plan if e["track"].name == args.goal_track]
    if goal:
        gb, gk = build_blocks(goal, jobs, rate["rate"], costs)
        out["goal"] = summary(with_startup(gb, startup), gk, workers)
        _print_summary(f"{args.goal_track} alone, from scratch", out["goal"])
    r = rate
    print(
        f"\nrelation jobs: {len(jobs)} distinct; CPU per unit cost {r['rate']:.3g} (sample {r['rate_min']:.3g}-{r['rate_max']:.3g}, {len(r['sample'])} jobs); worker start-up {startup:.1f} s; this plan took {out['plan_cpu_s']:.0f} s CPU"
    )
    if args.json is not None:
        atomic_write(args.json, json.dumps(out, indent=2, default=str) + "\n")
    return 0


SCORING_FIELDS = ("episode_healthy_s", "episode_faulty_s", "sweep_driver_per_cell_s")
REFERENCE_FIELDS = (
    "reference_driver_per_cell_s",
    "reference_seed_per_cell_s",
    "reference_fit_s",
)


def _borrow(
    plan: Sequence[Mapping[str, Any]],
    costs: dict[str, dict[str, Any]],
    flag: str,
    fields: Sequence[str],
) -> None:
    """A track whose part (``flag``) was not sampled takes the ``fields`` of a sampled track of
    the same loop kind (closed or open) and diagnoser count if there is one, else of the same
    loop kind, else of any sampled track."""
    done = [e for e in plan if costs[e["track"].name][flag]]
    for e in plan:
        c = costs[e["track"].name]
        if c[flag] or not done:
            continue
        loop = [d for d in done if d["track"].closed_loop == e["track"].closed_loop]
        same = [d for d in loop if len(d["keys"]) == len(e["keys"])] or loop or done
        src = same[0]["track"].name
        for f in fields:
            c[f] = costs[src][f]
        c[f"{flag}_from"] = src


if __name__ == "__main__":
    raise SystemExit(main())
