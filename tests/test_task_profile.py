"""The task profile (bench.task_profile): list scheduling with dependencies and barriers, the
critical path, and the breakdown of a store's timings."""

from __future__ import annotations

import json
import time

import pytest

from bench.task_profile import (
    Block,
    blocks_from_records,
    critical_path,
    list_schedule,
    main,
    makespan,
    profile,
)
from evaluation.sweep.task_log import TIMINGS_FILE, TaskLog, read_timings


def test_list_schedule_by_hand() -> None:
    # LPT puts the long task first; FIFO (submission order) leaves it for last
    assert list_schedule({1: 1.0, 2: 1.0, 3: 4.0}, {}, 2, "lpt") == 4.0
    assert list_schedule({1: 1.0, 2: 1.0, 3: 4.0}, {}, 2, "fifo") == 5.0
    # LPT is not optimal: 3+3 | 2+2+2 would take 6
    assert list_schedule({1: 3.0, 2: 3.0, 3: 2.0, 4: 2.0, 5: 2.0}, {}, 2) == 7.0
    # a chain 1 -> 2 beside an independent 3
    cpu, after = {1: 1.0, 2: 2.0, 3: 5.0}, {2: (1,)}
    assert list_schedule(cpu, after, 2) == 5.0
    assert list_schedule(cpu, after, 1) == 8.0
    assert list_schedule({1: 1.0, 2: 2.0, 3: 1.5}, {2: (1,)}, 2) == 3.0
    assert critical_path(cpu, after) == 5.0
    assert critical_path({1: 1.0, 2: 2.0, 3: 1.0}, {2: (1,), 3: (2,)}) == 4.0
    # a dependency outside the block (an earlier stage) is done already
    assert list_schedule({5: 1.0}, {5: (1,)}, 1) == 1.0


def test_list_schedule_refuses_cycles_and_bad_counts() -> None:
    with pytest.raises(ValueError, match="cycle"):
        list_schedule({1: 1.0, 2: 1.0}, {1: (2,), 2: (1,)}, 2)
    with pytest.raises(ValueError, match="n=0"):
        list_schedule({1: 1.0}, {}, 0)


def test_makespan_adds_barriers_driver_and_startup() -> None:
    blocks = [
        Block("a", {1: 2.0, 2: 2.0}, {}, driver_s=0.5, startup_s=3.0),
        Block("b", {}, {}, driver_s=1.0),  # a driver stage without tasks
        Block("c", {3: 4.0, 4: 1.0}, {4: (3,)}, driver_s=0.25),
    ]
    assert makespan(blocks, 1) == 3.0 + 4.0 + 0.5 + 1.0 + 5.0 + 0.25
    assert makespan(blocks, 2) == 3.0 + 2.0 + 0.5 + 1.0 + 5.0 + 0.25
    assert makespan(blocks, None) == makespan(blocks, 16)


def _stats(cpu_s: float, startup_cpu_s: float | None = None) -> dict:
    now = time.time()
    return {
        "cpu_s": cpu_s,
        "wall_s": cpu_s,
        "start": now,
        "end": now,
        "pid": -1,
        "startup_cpu_s": startup_cpu_s,
        "parts": {},
    }


def _synthetic_log(path) -> None:
    """Two driver calls: a train stage (a chain), a score stage; then the reference rows."""
    log = TaskLog(path, "sweep", "local", 2)
    with log.stage("train"):
        log.task(1, "train", "d", [], _stats(1.0, startup_cpu_s=2.0))
        log.task(2, "relation", "r", [1], _stats(6.0))
        log.task(3, "train", "d", [2], _stats(1.0))
    with log.stage("score"):
        for i in range(4, 8):
            log.task(i, "episode", f"nominal/{i}", [], _stats(0.5))
    refs = TaskLog(path, "references", "local", 2)
    with refs.stage("references"):
        refs.task(1, "reference-fit", "x", [], _stats(3.0))


def test_profile_of_a_log(tmp_path, capsys) -> None:
    path = tmp_path / "store" / TIMINGS_FILE
    path.parent.mkdir()
    _synthetic_log(path)
    records = read_timings(path)
    blocks = blocks_from_records(records)
    assert [b.name for b in blocks] == ["sweep:train", "sweep:score", "references:references"]
    assert blocks[0].startup_s == 2.0 and blocks[1].startup_s == 0.0
    p = profile(records, (1, 2))
    assert p["n_tasks"] == 8 and p["task_cpu_s"] == pytest.approx(13.0)
    assert p["kinds"]["relation"] == {"n": 1, "cpu_s": 6.0, "mean_s": 6.0, "max_s": 6.0}
    assert p["longest_task"] == {"kind": "relation", "key": "r", "cpu_s": 6.0}
    driver = p["driver_cpu_s"]
    # one worker: every second of CPU one after the other; the chain bounds the train stage
    assert p["projection_s"]["lpt"][1] == pytest.approx(2.0 + 13.0 + driver)
    assert p["projection_s"]["lpt"][2] == pytest.approx(2.0 + 8.0 + 1.0 + 3.0 + driver)
    assert p["critical_path_s"] == pytest.approx(2.0 + 8.0 + 0.5 + 3.0 + driver)
    assert main([str(tmp_path), "--workers", "1,2", "--json", str(tmp_path / "p.json")]) == 0
    out = capsys.readouterr().out
    assert "| relation | 1 | 6.0 |" in out and "serial fraction" in out
    assert json.loads((tmp_path / "p.json").read_text())["n_tasks"] == 8


def test_profile_command_refuses_bad_input(tmp_path, capsys) -> None:
    for argv, why in (
        ([str(tmp_path / "nowhere")], "a timings.jsonl file or a directory"),
        ([str(tmp_path)], "paths holding a timings.jsonl"),
        ([str(tmp_path), "--workers", "2,4"], "1 among them"),
    ):
        with pytest.raises(SystemExit) as exit_:
            main(argv)
        assert exit_.value.code == 2 and why in capsys.readouterr().err
