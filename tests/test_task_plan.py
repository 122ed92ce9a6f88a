"""The plan of a leaderboard run (bench.task_plan): its blocks follow the driver's rules (a
model trained once across tracks, a relation job once, the reference rows' dependencies)."""

from __future__ import annotations

import math
from types import SimpleNamespace

import pytest

from bench.task_plan import build_blocks, sample_costs, summary, with_startup
from bench.task_profile import list_schedule
from evaluation.tracks.catalogue import parse_tracks
from evaluation.tracks.filter_bound import SIGNATURE_SEEDS
from evaluation.tracks.reference_runs import DIRECTIONAL_CHUNK, FILTER_CHUNK
from evaluation.tracks.track_data import TrackData

COSTS = {
    "episode_healthy_s": 1.0,
    "episode_faulty_s": 2.0,
    "sweep_driver_per_cell_s": 0.01,
    "reference_driver_per_cell_s": 0.02,
    "reference_seed_per_cell_s": {"oracle": 0.5},
    "reference_fit_s": {"filter-statistics": 3.0, "directional-residuals": 1.0},
    "has_references": True,
}


def _entry(name: str, keys: list[str], fits: dict) -> dict:
    track = parse_tracks(name)[0].replace(n_healthy=4, n_faulty=2)
    config = SimpleNamespace(data=TrackData(track=track))
    return {"track": track, "config": config, "keys": keys, "fits": fits}


def test_blocks_follow_the_drivers_rules() -> None:
    job = SimpleNamespace(cost=10.0)
    jobs = {"r1": job, "r2": job, "r3": job}
    fits = {
        "a": {"rounds": [{"cpu_s": 1.0, "jobs": ["r1", "r2"]}, {"cpu_s": 2.0, "jobs": []}]},
        # a second diagnoser on the same relations, then a warm-started round
        "b": {
            "rounds": [
                {"cpu_s": 1.0, "jobs": ["r1", "r2"]},
                {"cpu_s": 1.0, "jobs": ["r3"]},
                {"cpu_s": 4.0, "jobs": []},
            ]
        },
        "c": {"rounds": [{"cpu_s": 0.5, "jobs": []}]},
    }
    entries = [_entry("paper", ["a", "b", "c"], fits), _entry("small", ["a", "b", "c"], fits)]
    blocks, kinds = build_blocks(entries, jobs, 0.5, {"paper": COSTS, "small": COSTS})
    assert [b.name for b in blocks] == [
        f"{t}:{s}" for t in ("paper", "small") for s in ("sweep:train", "sweep:score", "references")
    ]
    # each relation job once (rate 0.5 s per unit cost), each model once across the tracks
    assert kinds["relation"] == {"n": 3, "cpu_s": 15.0}
    assert kinds["train"] == {"n": 6, "cpu_s": 9.5}
    assert not blocks[3].cpu_s  # small reuses paper's models
    train = blocks[0]
    # b's second round waits for its first and for both shared jobs; its third for r3
    assert list_schedule(train.cpu_s, train.after, 100) == 1.0 + 5.0 + 1.0 + 5.0 + 4.0
    n_cells = len(entries[0]["config"].data.cells())
    assert kinds["episode"]["n"] == 2 * n_cells and kinds["cells"]["n"] == 2 * 3 * n_cells
    track = entries[0]["track"]
    n_stat = math.ceil(100 / FILTER_CHUNK)
    assert kinds["filter-statistics"] == {"n": 2 * n_stat, "cpu_s": 2 * 3.0 * n_stat}
    assert kinds["directional-residuals"] == {
        "n": 2 * 100 // DIRECTIONAL_CHUNK,
        "cpu_s": 2 * 100 // DIRECTIONAL_CHUNK,
    }
    assert kinds["directional-fit"]["n"] == 2
    assert kinds["filter-signature"]["n"] == 2 * len(track.train_fault_seeds[:SIGNATURE_SEEDS])
    assert kinds["reference-seed"]["n"] == 2 * 2 * len({s for _, s in track.test_cells()})
    started = with_startup(blocks, 3.0)
    assert [b.startup_s for b in started] == [3.0, 0.0, 3.0, 0.0, 3.0, 3.0]
    s = summary(started, kinds, (1, 2))
    total = s["task_cpu_s"] + s["driver_cpu_s"] + 4 * 3.0
    assert s["projection_s"]["lpt"][1] == pytest.approx(total)
    assert s["critical_path_s"] <= s["projection_s"]["lpt"][2] <= total


def test_sample_costs_per_kind() -> None:
    cells = [("nominal", 9000), ("nominal", 9001), ("f1", 9000)]
    line = {"scope": "sweep", "stage": "score", "key": ""}
    lines = [
        {**line, "kind": "episode", "key": "nominal/9000", "cpu_s": 1.0},
        {**line, "kind": "episode", "key": "nominal/9001", "cpu_s": 3.0},
        {**line, "kind": "episode", "key": "f1/9000", "cpu_s": 5.0},
        {**line, "kind": "driver", "stage": "score", "cpu_s": 0.3},
        {
            **line,
            "scope": "references",
            "kind": "reference-seed",
            "key": "a+b/seed-9000",
            "cpu_s": 4.0,
        },
        {**line, "scope": "references", "kind": "reference-fit", "key": "true+t2", "cpu_s": 7.0},
    ]
    c = sample_costs(lines, cells)
    assert (c["episode_healthy_s"], c["episode_faulty_s"]) == (2.0, 5.0)
    assert c["sweep_driver_per_cell_s"] == pytest.approx(0.1)
    assert c["reference_seed_per_cell_s"] == {"a+b": 2.0}  # seed 9000 holds two cells
    assert c["reference_fit_s"] == {"fit:true+t2": 7.0} and c["has_references"]
