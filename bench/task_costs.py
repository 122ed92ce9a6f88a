"""The measured part of :mod:`bench.task_plan`: a track at sample sizes run through the real
drivers, timed, and a pool worker's start-up (the plan prices every task with these)."""

from __future__ import annotations

import dataclasses
import tempfile
from collections import defaultdict
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from evaluation.sweep.backends import LocalBackend
from evaluation.sweep.runner import run_sweep
from evaluation.sweep.store import ResultStore
from evaluation.sweep.task_log import (
    TIMINGS_FILE,
    ProfiledBackend,
    TaskLog,
    read_timings,
)
from evaluation.tracks.board import model_cache_dir
from evaluation.tracks.oracle import DEFAULT_REFERENCES
from evaluation.tracks.reference_runs import (
    run_references,
)
from evaluation.tracks.track import Track
from evaluation.tracks.track_data import TrackData

__all__ = ["SAMPLE_SEED_START", "sample_costs", "sample_track", "sampled", "worker_startup"]


#: First test seed of the sampled episodes: validation seeds (5000+), never test seeds, and
#: clear of the reference rows' calibration seeds (5000 + at most a few hundred).
SAMPLE_SEED_START = 9000


def sampled(track: Track, healthy: int, faulty: int) -> Track:
    """The track at sample sizes, its test episodes moved to :data:`SAMPLE_SEED_START`."""
    return track.replace(n_healthy=healthy, n_faulty=faulty).with_seeds(test=SAMPLE_SEED_START)


def sample_track(
    entry: Mapping[str, Any], work: Path, healthy: int, faulty: int, score: bool, references: bool
) -> list[dict[str, Any]]:
    """Score the track at sample sizes with its trained models (``score``), and
    (``references``) its reference rows, in this process; the timing lines."""
    if not (score or references):
        return []
    track = sampled(entry["track"], healthy, faulty)
    config = dataclasses.replace(entry["config"], data=TrackData(track=track))
    store_dir = work / track.name
    store = ResultStore.open(store_dir, config.data.store_key())
    for spec in config.diagnosers:
        fit = entry["fits"][str(model_cache_dir(entry["config"], spec, Path("/")))]
        mhash = config.model_hash(spec, store.data_hash)
        store.write_model(spec.key, mhash, fit["files"], {**spec.to_json(), **fit["info"]})
    if score:
        run_sweep(config, store_dir, n_workers=0, progress=False)
    if references:
        run_references(config.data, DEFAULT_REFERENCES, store_dir, n_workers=0, progress=False)
    return read_timings(store_dir / TIMINGS_FILE)


def worker_startup() -> float:
    """The start-up CPU of one local pool worker (imports), from its first task's line."""
    with tempfile.TemporaryDirectory(prefix="fcc-plan-") as d:
        log = TaskLog(Path(d) / TIMINGS_FILE, "startup", "local", 1)
        runner = ProfiledBackend(LocalBackend(1), log)
        try:
            handle = runner.submit_as("probe", "", _probe)
            list(runner.completed([handle]))
        finally:
            runner.close(cancel=False)
        return float(read_timings(Path(d) / TIMINGS_FILE)[0]["startup_cpu_s"] or 0.0)


def _probe(_serial: bool = False) -> int:
    return 0


# ---- the plan as blocks ------------------------------------------------------------------------
def _mean(values: Sequence[float]) -> float:
    return sum(values) / len(values) if values else 0.0


def sample_costs(
    lines: Sequence[Mapping[str, Any]], cells: Sequence[tuple[str, int]]
) -> dict[str, Any]:
    """Per-task CPU figures of a sample run (its timing lines; ``cells``: its test cells)."""
    ep = [r for r in lines if r["kind"] == "episode"]
    healthy = [r["cpu_s"] for r in ep if r["key"].startswith("nominal/")]
    faulty = [r["cpu_s"] for r in ep if not r["key"].startswith("nominal/")]
    driver = defaultdict(float)
    for r in lines:
        if r["kind"] == "driver":
            driver[f"{r['scope']}:{r['stage']}"] += r["cpu_s"]
    per_seed = defaultdict(int)
    for _, seed in cells:
        per_seed[seed] += 1
    seed_cpu, seed_cells = defaultdict(float), defaultdict(int)
    for r in lines:
        if r["kind"] == "reference-seed":
            group, seed = r["key"].rsplit("/seed-", 1)
            seed_cpu[group] += r["cpu_s"]
            seed_cells[group] += per_seed[int(seed)]
    fits = defaultdict(list)
    for r in lines:
        if r["kind"] == "reference-fit" or r["kind"].startswith(("filter-", "directional-")):
            fits[r["kind"] if r["kind"] != "reference-fit" else f"fit:{r['key']}"].append(
                r["cpu_s"]
            )
    n = len(cells)
    return {
        "episode_healthy_s": _mean(healthy),
        "episode_faulty_s": _mean(faulty),
        "sweep_driver_per_cell_s": (
            driver["sweep:plan"] + driver["sweep:score"] + driver["sweep:collect"]
        )
        / n,
        "reference_driver_per_cell_s": sum(
            v for k, v in driver.items() if k.startswith("references:")
        )
        / n,
        "reference_seed_per_cell_s": {
            g: seed_cpu[g] / seed_cells[g] for g in seed_cpu if seed_cells[g]
        },
        "reference_fit_s": {k: _mean(v) for k, v in fits.items()},
        "has_references": bool(fits),
        "has_scoring": bool(ep),
    }
