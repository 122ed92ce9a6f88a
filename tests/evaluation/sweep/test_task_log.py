"""Per-task accounting (evaluation.sweep.task_log): every task of a sweep is timed and logged in
the store, with its kind, key, dependencies and parts, and the driver's own time per stage."""

from __future__ import annotations

import json
import os
import time

import pytest

from evaluation.sweep import SimulatedData, SweepConfig, default_specs, run_sweep
from evaluation.sweep.backends import SerialBackend
from evaluation.sweep.task_log import (
    TIMINGS_FILE,
    ProfiledBackend,
    TaskLog,
    read_timings,
    task_part,
    timed_call,
)
from fcc_env.scenarios import FaultSpec

DATA = SimulatedData(
    scenarios=("nominal", "f1"),
    test_seeds=(0, 1),
    train_seeds=(100, 101),
    n_samples=600,
    fault=FaultSpec(onset=300),
)


def _spin(seconds: float, part: str | None = None, _serial: bool = False) -> float:
    """Busy CPU for ``seconds`` (inside part ``part`` when given)."""

    def burn() -> None:
        t0 = time.process_time()
        while time.process_time() - t0 < seconds:
            pass

    if part is None:
        burn()
    else:
        with task_part(part):
            burn()
    return seconds


def test_timed_call_measures_cpu_and_parts() -> None:
    result, stats = timed_call(_spin, 0.05, "inner")
    assert result == 0.05
    assert 0.05 <= stats["cpu_s"] < 1.0 and stats["wall_s"] >= 0.05
    assert 0.05 <= stats["parts"]["inner"] <= stats["cpu_s"]
    assert stats["pid"] == os.getpid() and stats["end"] >= stats["start"]
    with task_part("outside"):  # outside a timed task nothing is recorded, nothing fails
        pass


def test_profiled_backend_logs_kinds_keys_dependencies_and_driver(tmp_path) -> None:
    log = TaskLog(tmp_path / TIMINGS_FILE, "sweep", "local", 0)
    runner = ProfiledBackend(SerialBackend(), log)
    with log.stage("train"):
        a = runner.submit_as("train", "d1", _spin, 0.01)
        results = dict(runner.completed([a]))
        # by default a task waits for the one whose result the driver took last
        b = runner.submit_as("relation", "r1", _spin, 0.02, info={"cost": 7})
        c = runner.submit_as("relation", "r2", _spin, 0.01, after=[a])
        results.update(runner.completed([b, c]))
        d = runner.submit_as("train", "d1", _spin, 0.01, after=[b, c])
        results.update(runner.completed([d]))
    assert results == {a: 0.01, b: 0.02, c: 0.01, d: 0.01}  # the tasks' own results
    lines = read_timings(tmp_path / TIMINGS_FILE)
    tasks = [r for r in lines if r["kind"] != "driver"]
    assert [(r["id"], r["kind"], r["key"], r["after"]) for r in tasks] == [
        (1, "train", "d1", []),
        (2, "relation", "r1", [1]),
        (3, "relation", "r2", [1]),
        (4, "train", "d1", [2, 3]),
    ]
    assert tasks[1]["info"] == {"cost": 7} and all(r["stage"] == "train" for r in lines)
    assert all(r["cpu_s"] >= s for r, s in zip(tasks, (0.01, 0.02, 0.01, 0.01), strict=True))
    (driver,) = [r for r in lines if r["kind"] == "driver"]
    # the tasks ran in this process: their CPU is not the driver's
    assert driver["key"] == "train" and driver["cpu_s"] < 0.05 + 0.01
    assert len({r["run"] for r in lines}) == 1


def test_a_sweep_logs_every_task_and_the_driver(tmp_path) -> None:
    config = SweepConfig(diagnosers=default_specs(("limits", "arx-band")), data=DATA)
    run_sweep(config, tmp_path / "s", n_workers=0, progress=False)
    lines = read_timings(tmp_path / "s" / TIMINGS_FILE)
    tasks = [r for r in lines if r["kind"] != "driver"]
    assert sorted((r["kind"], r["key"]) for r in tasks) == sorted(
        [("train", "limits"), ("train", "arx-band")]
        + [("episode", f"{sc}/{seed}") for sc in ("nominal", "f1") for seed in (0, 1)]
    )
    episode = next(r for r in tasks if r["kind"] == "episode")
    assert {"simulate", "detect:limits", "detect:arx-band"} <= set(episode["parts"])
    assert sum(episode["parts"].values()) <= episode["cpu_s"] + 1e-6
    train = next(r for r in tasks if r["kind"] == "train")
    assert {"data", "fit"} <= set(train["parts"])
    stages = [r["key"] for r in lines if r["kind"] == "driver"]
    assert stages == ["plan", "train", "score", "collect"]
    # a re-run of the finished sweep computes nothing: only the driver's stages are added
    run_sweep(config, tmp_path / "s", n_workers=0, progress=False)
    again = read_timings(tmp_path / "s" / TIMINGS_FILE)[len(lines) :]
    assert [r["key"] for r in again] == ["plan", "collect"]


def test_a_cut_line_is_skipped_and_a_foreign_version_refused(tmp_path) -> None:
    path = tmp_path / TIMINGS_FILE
    log = TaskLog(path, "sweep", "local", 1)
    with log.stage("plan"):
        pass
    with path.open("a") as fh:
        fh.write('{"format": "fcc-task-timing", "ver')  # a killed writer's last line
    assert len(read_timings(path)) == 1
    with path.open("a") as fh:
        fh.write("\n" + json.dumps({"format": "fcc-task-timing", "version": 99}) + "\n")
    with pytest.raises(ValueError, match="timings version 99"):
        read_timings(path)
    with pytest.raises(ValueError, match="not a regular timings file"):
        read_timings(tmp_path / "missing.jsonl")
