"""Leaderboard: pure table formatting, the CLI end to end on a small sweep, and bad input."""

from __future__ import annotations

import csv
import json
import os
import re
import subprocess
import sys
import time
from pathlib import Path

import pytest

from evaluation.leaderboard import main
from evaluation.leaderboard.arguments import build_parser
from evaluation.reports.tables import PAPER_TABLE2, markdown_table
from evaluation.sweep import CellSummary
from fcc_env.scenarios import FaultSpec

ROOT = Path(__file__).resolve().parents[3]  # the repository
NAN = float("nan")
SMALL = [
    "--diagnosers",
    "limits,arx-band",
    "--scenarios",
    "nominal,f1",
    "--seeds",
    "2",
    "--train-episodes",
    "2",
    "--n-samples",
    "600",
    "--fault-time",
    "300",
    "--workers",
    "0",
    "--no-progress",
]


def _summary(diag: str, sc: str, **kw) -> CellSummary:
    base = dict(
        diagnoser=diag,
        scenario=sc,
        faulty=sc != "nominal",
        n_seeds=3,
        r_fd=0.01,
        r_fd_std=0.002,
        r_td=0.5,
        r_td_std=0.1,
        t_dt=100.0,
        t_dt_std=20.0,
        t_dt_s=1000.0,
        t_dt_s_std=200.0,
        misses=0,
        n_detected=3,
        n_terminated=0,
    )
    return CellSummary(**{**base, **kw})


def test_markdown_table_layout_and_order() -> None:
    rows = [
        _summary("weak", "nominal", r_fd=0.2, r_td=NAN),
        _summary("weak", "f1", r_td=0.3, misses=1, n_detected=2),
        _summary("good", "nominal", r_fd=0.0123, r_fd_std=0.0045, r_td=NAN),
        _summary(
            "good", "f1", r_td=0.9, r_td_std=NAN, t_dt=NAN, t_dt_std=NAN, misses=3, n_detected=0
        ),
    ]
    md = markdown_table(rows, reference=PAPER_TABLE2).splitlines()
    assert md[0] == "| diagnoser | r_fd (nominal) | f1 r_td | f1 t_dt |"
    assert md[1] == "|---|---|---|---|"
    # sorted by r_td - r_fd: good (0.9 - 0.0123) before weak (0.3 - 0.2)
    assert md[2] == "| good | 0.0123 ± 0.0045 | 0.9000 | – (3/3 missed) |"
    assert md[3] == "| weak | 0.2000 ± 0.0020 | 0.3000 ± 0.1000 | 100 ± 20 (1/3 missed) |"
    assert md[4] == "| paper Table 2 (LRGF+MEM) | 0.0881 | 0.6978 | 250 |"
    assert len(md) == 5


def test_paper_reference_values() -> None:
    assert PAPER_TABLE2["r_fd"] == 0.0881
    assert PAPER_TABLE2["faults"] == {
        "f1": (0.6978, 250.0),
        "f2": (0.7184, 370.0),
        "f3": (0.6634, 80.0),
        "f4": (0.5294, 55.0),
    }


def _table_and_legend(out: str) -> tuple[str, str]:
    """The leaderboard's stdout: the Markdown table, a blank line, its one-paragraph legend."""
    table, legend = out.split("\n\n")
    assert legend.startswith("Legend: ") and legend.endswith("\n") and "\n" not in legend[:-1]
    return table + "\n", legend


def test_cli_end_to_end_and_resume(tmp_path, capsys) -> None:
    out = tmp_path / "lb"
    assert main([*SMALL, "--out", str(out)]) == 0
    printed = capsys.readouterr()
    table_text, legend = _table_and_legend(printed.out)
    table = table_text.splitlines()
    assert table[0] == "| diagnoser | r_fd (nominal) | f1 r_td | f1 t_dt |"
    assert {t.split(" | ")[0] for t in table[2:]} == {
        "| limits",
        "| arx-band",
        "| paper Table 2 (LRGF+MEM)",
    }
    assert "8 cells computed, 0 reused" in printed.err
    md = (out / "leaderboard.md").read_text()
    assert md.endswith(table_text) and legend in md  # stdout is the file's table and legend
    assert "Legend:" not in printed.err

    with (out / "leaderboard.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    assert [(r["diagnoser"], r["scenario"]) for r in rows] == [
        ("limits", "nominal"),
        ("limits", "f1"),
        ("arx-band", "nominal"),
        ("arx-band", "f1"),
    ]
    for col in ("n_seeds", "r_fd", "r_fd_std", "r_td", "r_td_std", "t_dt", "t_dt_std", "misses"):
        assert col in rows[0]
    assert all(r["n_seeds"] == "2" for r in rows) and rows[0]["r_td"] == ""  # nominal: no r_td
    assert rows[0]["data"].startswith("FCC-v0")

    raw = json.loads((out / "results.json").read_text())
    assert len(raw["records"]) == 8 and raw["data"]["train_seeds"] == [1000, 1001]
    with (out / "results.csv").open() as fh:
        per_seed = list(csv.DictReader(fh))
    assert {(r["diagnoser"], r["scenario"], r["seed"]) for r in per_seed} == {
        (d, s, str(k)) for d in ("limits", "arx-band") for s in ("nominal", "f1") for k in (0, 1)
    }
    # the CSV summary is the aggregate of the raw rows
    f1_arx = [
        float(r["r_td"]) for r in per_seed if (r["diagnoser"], r["scenario"]) == ("arx-band", "f1")
    ]
    arx_row = next(r for r in rows if (r["diagnoser"], r["scenario"]) == ("arx-band", "f1"))
    assert float(arx_row["r_td"]) == pytest.approx(sum(f1_arx) / 2)

    pngs = sorted((out / "figures").rglob("*.png"))
    assert [p.relative_to(out / "figures").as_posix() for p in pngs] == [
        "f1/arx-band.png",
        "f1/limits.png",
        "nominal/arx-band.png",
        "nominal/limits.png",
    ]
    assert all(p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" for p in pngs)

    assert main([*SMALL, "--out", str(out), "--no-figures"]) == 0
    again = capsys.readouterr()
    assert "0 cells computed, 8 reused, 0 diagnosers trained" in again.err
    assert again.out == printed.out


@pytest.mark.parametrize(
    ("args", "match"),
    [
        (["--seeds", "0"], "must be >= 1"),
        (["--seeds", "x"], "expected an integer"),
        (["--diagnosers", "limits,nope"], r"unknown diagnoser\(s\) \['nope'\]. Available"),
        (["--scenarios", "nominal,f7"], r"unknown scenario\(s\) \['f7'\]. Allowed"),
        (["--backend", "dask"], "invalid choice"),
        (["--workers", "-2"], "--workers must be >= 0"),
        (["--ray-address", "auto"], "needs --backend ray"),
        (["--external", "/no/such/dir"], "does not exist"),
        (["--n-samples", "600", "--scenarios", "f1"], "fault_time"),
        (["--validation", "--quick"], "--validation cannot be combined"),
        (["--ramp-samples", "100"], "--ramp-samples needs --fault-profile incipient"),
    ],
)
def test_cli_bad_input(tmp_path, capsys, args: list[str], match: str) -> None:
    with pytest.raises(SystemExit) as e:
        main([*args, "--out", str(tmp_path / "o"), "--no-progress", "--no-figures"])
    assert e.value.code == 2
    assert re.search(match, capsys.readouterr().err)
    assert not (tmp_path / "o").exists()


def test_validation_protocol_uses_its_own_seeds_and_smaller_faults(tmp_path, capsys) -> None:
    out = tmp_path / "val"
    argv = ["--validation", "--diagnosers", "limits", "--scenarios", "nominal,f3", "--seeds", "2"]
    assert main([*argv, "--train-episodes", "2", "--out", str(out), "--no-progress"]) == 0
    printed = capsys.readouterr().out
    assert "paper Table 2" not in printed  # the paper's row is for the paper's magnitudes
    raw = json.loads((out / "results.json").read_text())
    assert raw["data"]["fault"]["magnitude_scale"] == 0.7
    assert {r["seed"] for r in raw["records"]} == {5000, 5001}
    assert "0.7x the paper's" in (out / "leaderboard.md").read_text()


def test_incipient_faults_from_the_cli(tmp_path, capsys) -> None:
    out = tmp_path / "inc"
    argv = ["--diagnosers", "limits", "--scenarios", "f1", "--seeds", "1", "--train-episodes", "1"]
    argv += ["--fault-profile", "incipient", "--ramp-samples", "360", "--no-progress"]
    assert main([*argv, "--out", str(out), "--no-figures"]) == 0
    assert "paper Table 2" not in capsys.readouterr().out
    raw = json.loads((out / "results.json").read_text())
    assert (raw["data"]["fault"]["profile"], raw["data"]["fault"]["ramp_samples"]) == (
        "incipient",
        360,
    )
    assert "ramps to its full change over 360 samples" in (out / "leaderboard.md").read_text()


def test_fault_magnitude_scale_scales_every_fault() -> None:
    from evaluation.sweep import SimulatedData

    def magnitude(data: SimulatedData, scenario: str) -> float | None:
        fault = data.fault_spec.replace(scenario=scenario).resolve(horizon=4000)
        return None if scenario == "nominal" else fault.magnitude

    data = SimulatedData(fault=FaultSpec(magnitude_scale=0.7))
    assert magnitude(data, "f2") == pytest.approx(0.105)
    assert magnitude(data, "f4") == pytest.approx(0.035)
    assert magnitude(data, "nominal") is None
    half = SimulatedData(fault=FaultSpec(magnitude=0.2, magnitude_scale=0.5))
    assert magnitude(half, "f1") == 0.1
    # the default leaves the store key (and so earlier stores) as before the option existed
    assert SimulatedData().store_key()["fault"]["magnitude_scale"] == 1.0
    with pytest.raises(
        ValueError,
        match=r"magnitude_scale=0 is outside the allowed range: a number in \(0, 10\]",
    ):
        FaultSpec(magnitude_scale=0)


def test_help_documents_flags() -> None:
    text = build_parser().format_help()
    for flag in (
        "--quick",
        "--validation",
        "--diagnosers",
        "--scenarios",
        "--seeds",
        "--out",
        "--backend",
    ):
        assert flag in text


@pytest.mark.slow
def test_quick_under_two_minutes(tmp_path) -> None:
    """The README's main job: ``--quick`` in a fresh process, start-up included, under 2 min."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    t0 = time.perf_counter()
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "evaluation.leaderboard",
            "--quick",
            "--no-progress",
            "--out",
            str(tmp_path / "q"),
        ],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    wall = time.perf_counter() - t0
    assert proc.returncode == 0, proc.stderr
    assert wall < 120.0
    lines = _table_and_legend(proc.stdout)[0].splitlines()
    assert len(lines) == 2 + 3 + 1  # header, rule, three baselines, the paper row


SANTANDER = ROOT.parent / "shared" / "data" / "fccu-santander-mlpse"


@pytest.mark.skipif(not SANTANDER.is_dir(), reason=f"{SANTANDER} not present")
def test_cli_external_santander(tmp_path, capsys) -> None:
    args = [
        "--external",
        str(SANTANDER),
        "--diagnosers",
        "pca,arx-band",
        "--scenarios",
        "NOC_stableFeedFlow,deltaP_increase",
        "--workers",
        "0",
        "--no-progress",
        "--out",
        str(tmp_path),
    ]
    assert main(args) == 0
    lines = _table_and_legend(capsys.readouterr().out)[0].splitlines()
    assert lines[0] == (
        "| diagnoser | r_fd (NOC_stableFeedFlow) | deltaP_increase† r_td | deltaP_increase† t_dt |"
    )  # † : the recorded fault's onset is assumed, marked in the printed table as in the file
    assert len(lines) == 4  # two diagnosers, no paper row: the paper's plant is another one
    assert (tmp_path / "figures" / "deltaP_increase" / "arx-band.png").is_file()
    assert "\n\n| diagnoser |" in (tmp_path / "leaderboard.md").read_text()
    with pytest.raises(SystemExit):
        main([*args[:4], "--scenarios", "f1"])
    assert "Allowed: ['NOC_stableFeedFlow'" in capsys.readouterr().err


def test_training_failure_exits_cleanly(monkeypatch, capsys, tmp_path):
    from evaluation.leaderboard import paper

    def boom(opts):
        raise RuntimeError("training failed: lrgf-mem: ValueError: bad relation")

    monkeypatch.setattr(paper, "run", boom)
    with pytest.raises(SystemExit) as e:
        main(["--quick", "--out", str(tmp_path)])
    assert e.value.code == 1
    err = capsys.readouterr().err
    # a diagnoser that raised raises again: no advice to re-run (issue 32)
    assert "training failed: lrgf-mem" in err and "fails the same way" in err
    assert "re-run to resume" not in err


def test_track_options_train_episodes_and_quick() -> None:
    from evaluation.leaderboard.track_runs import track_options
    from evaluation.tracks import parse_tracks

    parser = build_parser()
    tracks = parse_tracks("paper,noisy")

    def n_train(*argv: str) -> list[int]:
        args = parser.parse_args(["--track", "paper,noisy", *argv])
        return [t.n_train for t in track_options(args, parser, tracks)]

    assert n_train() == [9, 9]
    assert n_train("--train-episodes", "20") == [20, 20]
    assert n_train("--quick") == [3, 3]
    assert n_train("--quick", "--train-episodes", "5") == [5, 5]  # the explicit flag wins
    quick = track_options(parser.parse_args(["--track", "paper", "--quick"]), parser, tracks)
    assert (quick[0].n_healthy, quick[0].n_faulty) == (6, 3)


def test_track_options_move_the_test_seeds_only() -> None:
    from evaluation.leaderboard.track_runs import track_options
    from evaluation.tracks import parse_tracks

    parser = build_parser()
    tracks = parse_tracks("paper,random")
    args = parser.parse_args(["--track", "paper,random", "--test-seed-start", "100000"])
    moved = track_options(args, parser, tracks)
    for before, after in zip(tracks, moved, strict=True):
        assert after.test_seeds.start == 100_000
        assert len(after.test_seeds) == len(before.test_seeds)
        assert (after.train_seeds, after.validation_seeds) == (
            before.train_seeds,
            before.validation_seeds,
        )
    assert moved[1].test_cells()[-1][1] >= 100_000


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--test-seed-start", "7"], "--test-seed-start 7 applies to --track"),
        (
            ["--track", "paper", "--test-seed-start", "900"],
            "--test-seed-start 900: train_seed_start=1000 is outside the allowed range",
        ),
        (
            ["--track", "paper", "--test-seed-start", "5050"],
            "calibration seeds 5000..5099 into the track's test seeds 5050..5249",
        ),
        (["--track", "paper", "--test-seed-start", "-1"], "must be >= 0, got -1"),
    ],
)
def test_test_seed_start_refused_by_value_and_range(tmp_path, capsys, argv, message) -> None:
    with pytest.raises(SystemExit) as e:
        main([*argv, "--diagnosers", "limits", "--out", str(tmp_path / "o"), "--no-progress"])
    assert e.value.code == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "o").exists()  # refused before any work


def test_track_refuses_a_bad_train_episodes_count(tmp_path, capsys) -> None:
    with pytest.raises(SystemExit) as e:
        main(["--track", "paper", "--train-episodes", "0", "--out", str(tmp_path / "o")])
    assert e.value.code == 2
    assert "--train-episodes: must be >= 1, got 0" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize(
    "flag",
    [
        ["--seeds", "5"],
        ["--scenarios", "f1"],
        ["--validation"],
        ["--n-samples", "3000"],
        ["--fault-time", "100"],
        ["--fault-profile", "incipient"],
        ["--external", "x"],
    ],
)
def test_track_refuses_paper_leaderboard_options(tmp_path, capsys, flag: list[str]) -> None:
    with pytest.raises(SystemExit) as e:
        main(["--track", "paper", *flag, "--out", str(tmp_path / "o"), "--no-progress"])
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert f"{flag[0]} applies to the paper leaderboard, not to --track" in err
    assert "allowed with --track: --quick, --train-episodes" in err
    assert not (tmp_path / "o").exists()
