"""Issue 45 item 7: progress bars on the long commands (``fcc_common.progress``).

Each command takes ``--progress`` / ``--no-progress``; a bar goes to standard error only (asked
for, or when it is a terminal) and never changes what the command writes: the files of a run
with a bar are the same as without one (timings apart).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import fcc_env
from fcc_common.progress import add_progress_flag, auto_progress, progress_bar
from fcc_env.generate import PROGRESS_CHUNK, simulate_in_chunks, write_dataset

MODES = {"on": ["--progress"], "off": ["--no-progress"], "auto": []}


def _files(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir()) if p.is_file()}


def _json_without(path: Path, *keys: str) -> dict:
    data = json.loads(path.read_text())
    for key in keys:
        data.pop(key, None)
    return data


def test_the_flag_and_the_auto_default(capsys) -> None:
    import argparse

    parser = argparse.ArgumentParser()
    add_progress_flag(parser)
    assert [parser.parse_args(a).progress for a in MODES.values()] == [True, False, None]
    # captured standard error is not a terminal: "auto" draws nothing, True draws on stderr
    assert auto_progress(None) is False
    for enabled in (None, True):
        for _ in progress_bar(range(3), desc="work", unit="step", progress=enabled):
            pass
    out = capsys.readouterr()
    assert out.out == "" and out.err.count("work") >= 1


def test_generate_writes_the_same_bytes_with_and_without_bars(tmp_path, capsys) -> None:
    n_seeds = PROGRESS_CHUNK + 5  # a bar simulates in chunks: more than one here
    base = ["--scenario", "random", "--seeds", f"0-{n_seeds - 1}", "--samples", "300"]
    base += ["--closed-loop", "--plant-effect", "sensor_bias:T_rg2,bias=2"]
    err = {}
    for mode, flag in MODES.items():
        out = tmp_path / mode
        assert fcc_env.generate.main([*base, "--out", str(out / "d.csv"), *flag]) == 0
        err[mode] = capsys.readouterr().err
    assert _files(tmp_path / "on") == _files(tmp_path / "off") == _files(tmp_path / "auto")
    assert "simulating" in err["on"] and "writing d.csv" in err["on"]
    assert err["off"] == err["auto"] == ""


def test_chunked_simulation_equals_one_batch() -> None:
    seeds = list(range(3, 3 + 2 * PROGRESS_CHUNK + 1))
    faults = [fcc_env.FaultSpec(scenario=f"f{1 + s % 4}", onset=150) for s in seeds]
    plant = fcc_env.PlantConfig.build(regulatory=True)
    whole = fcc_env.simulate_episodes(seeds, 300, fault=faults, plant=plant)
    chunked = simulate_in_chunks(seeds, 300, progress=True, fault=faults, plant=plant)
    for name, value in vars(whole).items():
        other = getattr(chunked, name)
        if isinstance(value, np.ndarray):
            np.testing.assert_array_equal(value, other, err_msg=name)
        else:
            assert value == other, name
    with pytest.raises(ValueError, match="episodes x 300 samples need about"):
        simulate_in_chunks(seeds, 300, progress=True, memory_budget_bytes=1e6)


def test_write_dataset_by_episode_is_one_savetxt(tmp_path) -> None:
    # the CSV is written an episode at a time: the same text as np.savetxt of the whole table
    path = write_dataset(tmp_path / "d.csv", seeds=[0, 1], n_samples=50, progress=True)
    rows = np.loadtxt(path, delimiter=",", skiprows=1)
    header = path.read_text().splitlines()[0]
    assert rows.shape == (100, len(header.split(",")))
    assert path.read_text().count("\n") == 101


def test_control_study_writes_the_same_files_with_and_without_bars(
    tmp_path, capsys, monkeypatch
) -> None:
    from evaluation.control import policies
    from evaluation.control.returns_command import main

    # the best set points are a seeded search that takes no progress flag (the same result in
    # every mode): computed once here, not twice per mode, the test's largest cost
    found: dict[str, object] = {}
    real = policies.best_setpoints

    def best_setpoints_once(*args, **kwargs):
        key = repr((args, sorted(kwargs.items())))
        if key not in found:
            found[key] = real(*args, **kwargs)
        return found[key]

    monkeypatch.setattr(policies, "best_setpoints", best_setpoints_once)
    err = {}
    for mode, flag in MODES.items():
        argv = ["--seeds", "1", "--steps", "12", "--diagnosers", "", "--out", str(tmp_path / mode)]
        assert main([*argv, *flag]) == 0
        err[mode] = capsys.readouterr().err
    on, off, auto = (_files(tmp_path / m) for m in MODES)
    assert on == off == auto and {"control.csv", "control.json"} <= set(on)
    assert "control study" in err["on"] and "fault traces" in err["on"]
    assert err["off"] == err["auto"] == ""


def test_rl_train_takes_the_flag_and_trains_the_same_policy(tmp_path, capsys) -> None:
    pytest.importorskip("stable_baselines3")
    from evaluation.control.rl import main

    small = ["--minutes", "5", "--envs", "4", "--n-steps", "16", "--batch-size", "32"]
    small += ["--n-epochs", "1", "--hidden", "8,8", "--max-env-steps", "64", "--val-seeds", "0"]
    err = {}
    for mode in ("on", "off"):
        assert main(["train", *small, "--out", str(tmp_path / mode), *MODES[mode]]) == 0
        err[mode] = capsys.readouterr().err
    for name in ("policy.npz", "policy.json"):
        assert (tmp_path / "on" / name).read_bytes() == (tmp_path / "off" / name).read_bytes()
    logs = [_json_without(tmp_path / m / "training.json", "seconds", "env_steps_per_s", "rollouts")
            for m in ("on", "off")]  # fmt: skip
    assert logs[0] == logs[1]
    assert "PPO (5 min budget)" in err["on"] and "step" in err["on"]
    assert err["off"] == ""


def test_rl_evaluate_passes_the_flag_to_the_study(monkeypatch) -> None:
    from evaluation.control import rl_command

    seen = []
    monkeypatch.setattr(rl_command, "make_policy", lambda *a, **k: object())
    monkeypatch.setattr(rl_command.returns_command, "main", lambda argv, **k: seen.append(argv))
    for flag in MODES.values():
        rl_command.main(["evaluate", "--policy", "p", "--seeds", "1", *flag])
    flags = [[w for w in argv if w.endswith("progress")] for argv in seen]
    assert flags == [["--progress"], ["--no-progress"], []]


def test_discover_reports_the_same_with_and_without_bars(tmp_path, capsys) -> None:
    from evaluation.discover.cli import main

    data = write_dataset(tmp_path / "h.csv", seeds=[0], n_samples=400,
                         plant_effects=["sensor_bias:T_rg2,bias=2"])  # fmt: skip
    err = {}
    for mode, flag in MODES.items():
        argv = ["--data", str(data), "--out", str(tmp_path / mode), "--no-plots"]
        argv += ["--max-effects", "1", "--candidates", "sensor_bias:T_rg2,sensor_bias:T_rx"]
        assert main([*argv, *flag]) == 0
        err[mode] = capsys.readouterr().err
    reports = [_json_without(tmp_path / m / "report.json", "elapsed_s") for m in MODES]
    assert reports[0] == reports[1] == reports[2]
    assert "round 1/1" in err["on"] and "candidate" in err["on"]
    assert err["off"] == err["auto"] == ""
