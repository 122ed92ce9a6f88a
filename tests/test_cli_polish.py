"""The command lines as a new user meets them: named as invoked, with examples in every help
page, the leaderboard's legend on stdout, and a ``--help`` that imports nothing heavy."""

from __future__ import annotations

import importlib
import os
import subprocess
import sys
import tomllib
from collections.abc import Callable
from pathlib import Path

import pytest

from evaluation.leaderboard import arguments

ROOT = Path(__file__).resolve().parents[1]

#: Every command line with an argparse parser, by the module ``python -m`` runs.
COMMANDS = (
    "evaluation.leaderboard",
    "evaluation.discover",
    "bench.loop_speed",
    "evaluation.isolation.study",
    "evaluation.isolation.isolability",
    "fcc_env.generate",
    "fcc_env.demo",
    "fcc_env.closed_loop_report",
    "fcc_env.closed_loop_analysis",
    "bench.simulator_speed",
    "bench.control_speed",
    "bench.detector_speed",
    "bench.filter_speed",
    "bench.bank_speed",
    "bench.sweep_speed",
    "bench.vector_speed",
    "bench.scaling",
)


def _main(module: str) -> Callable[[list[str]], int | None]:
    return importlib.import_module(module).main


def _help(main: Callable[[list[str]], int | None], argv0: str, monkeypatch, capsys) -> str:
    monkeypatch.setattr(sys, "argv", [argv0])
    with pytest.raises(SystemExit) as e:
        main(["--help"])
    assert e.value.code == 0
    return capsys.readouterr().out


def _console_scripts() -> dict[str, str]:
    with (ROOT / "pyproject.toml").open("rb") as fh:
        return tomllib.load(fh)["project"]["scripts"]


@pytest.mark.parametrize("script", sorted(_console_scripts()))
def test_a_console_script_names_itself(script: str, monkeypatch, capsys) -> None:
    module, func = _console_scripts()[script].split(":")
    main = getattr(importlib.import_module(module), func)
    out = _help(main, f"/usr/local/bin/{script}", monkeypatch, capsys)
    assert out.startswith(f"usage: {script} ")
    assert f"\n  {script} " in out  # the examples, as the user invoked the command


@pytest.mark.parametrize("module", COMMANDS)
def test_python_m_says_python_m_and_shows_examples(module: str, monkeypatch, capsys) -> None:
    # ``python -m pkg`` sets argv[0] to pkg/__main__.py, ``python -m pkg.mod`` to pkg/mod.py
    path = ROOT.joinpath(*module.split("."))
    argv0 = str(path / "__main__.py") if path.is_dir() else str(path.with_suffix(".py"))
    out = _help(_main(module), argv0, monkeypatch, capsys)
    assert out.startswith(f"usage: python -m {module} ")
    examples = out.split("\nexamples:\n", 1)[1]
    assert examples.startswith(f"  python -m {module}"), examples
    assert "__main__.py" not in out and ".py " not in out.splitlines()[0]


def test_an_error_names_the_command_as_invoked(monkeypatch, capsys) -> None:
    monkeypatch.setattr(sys, "argv", ["/usr/local/bin/fcc-leaderboard"])
    with pytest.raises(SystemExit):
        _main("evaluation.leaderboard")(["--seeds", "0"])
    assert (
        "fcc-leaderboard: error: argument --seeds: must be >= 1, got 0" in capsys.readouterr().err
    )


def test_the_help_defaults_are_their_owners(monkeypatch) -> None:
    """The leaderboard's help quotes values owned by heavy modules: the mirrors stay equal."""
    for module, values in arguments.HELP_DEFAULTS.items():
        owner = importlib.import_module(module)
        for name, value in values.items():
            actual = getattr(owner, name)
            actual = tuple(actual) if isinstance(actual, dict) else actual
            assert actual == value, f"{module}.{name} is {actual!r}; the help says {value!r}"


def test_the_legend_follows_the_table_on_stdout(tmp_path, capsys) -> None:
    argv = ["--diagnosers", "limits", "--scenarios", "nominal,f1", "--seeds", "1"]
    argv += ["--train-episodes", "1", "--n-samples", "400", "--fault-time", "200"]
    argv += ["--workers", "0", "--no-figures", "--no-progress", "--out", str(tmp_path)]
    assert _main("evaluation.leaderboard")(argv) == 0
    printed = capsys.readouterr()
    table, legend = printed.out.split("\n\n")
    assert table.startswith("| diagnoser |") and legend.startswith("Legend: ")
    assert "cells computed" in printed.err and "Legend" not in printed.err


def test_leaderboard_help_imports_nothing_heavy() -> None:
    code = (
        "import runpy, sys\n"
        "sys.argv = ['fcc-leaderboard', '--help']\n"
        "try:\n"
        "    runpy.run_module('evaluation.leaderboard', run_name='__main__', alter_sys=True)\n"
        "except SystemExit as e:\n"
        "    assert e.code == 0, e.code\n"
        "heavy = ('torch', 'matplotlib', 'scipy', 'numba', 'diagnosers', 'gymnasium')\n"
        "print(sorted(m for m in heavy if m in sys.modules), file=sys.stderr)\n"
    )
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, env=env, capture_output=True, text=True, timeout=60
    )
    assert proc.returncode == 0, proc.stderr
    assert "examples:" in proc.stdout
    assert proc.stderr.strip().splitlines()[-1] == "[]", proc.stderr


def _recorded(folder: Path) -> Path:
    """A small recorded data set whose fault onset is assumed (manifest ``onset_assumed``)."""
    import json

    import numpy as np

    rng = np.random.default_rng(3)
    folder.mkdir()
    for name, n, step in (("healthy", 300, None), ("normal", 200, None), ("leak", 200, 120)):
        tr = 969.0 + rng.normal(0, 0.5, n)
        if step is not None:
            tr[step:] += 20.0
        data = np.column_stack([rng.normal(30, 0.2, n), tr])
        np.savetxt(folder / f"{name}.csv", data, delimiter=",", header="Frgc,Tr", comments="")
    manifest = {
        "inputs": ["Frgc"],
        "outputs": ["Tr"],
        "train_files": ["healthy.csv"],
        "test_files": [
            {"path": "normal.csv", "onset": None},
            {"path": "leak.csv", "onset": 120, "name": "leak", "onset_assumed": True},
        ],
        "sample_time_s": 60,
    }
    (folder / "dataset.json").write_text(json.dumps(manifest))
    return folder


def test_external_data_get_their_own_folder_and_the_printed_dagger(
    tmp_path, monkeypatch, capsys
) -> None:
    """``--external`` without ``--out`` once overwrote the ``--quick`` run's tables; and the
    terminal's table lacked the † of an assumed onset that the file has."""
    from evaluation.reports.tables import ASSUMED_MARK, ASSUMED_TEXT

    data = _recorded(tmp_path / "rec")
    monkeypatch.chdir(tmp_path)
    argv = ["--external", str(data), "--diagnosers", "limits", "--workers", "0"]
    assert _main("evaluation.leaderboard")([*argv, "--no-figures", "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert (tmp_path / "results" / "external" / "leaderboard.md").is_file()
    assert not (tmp_path / "results" / "leaderboard").exists()
    assert f"leak{ASSUMED_MARK} r_td" in out and ASSUMED_TEXT in out
    md = (tmp_path / "results" / "external" / "leaderboard.md").read_text()
    assert f"leak{ASSUMED_MARK} r_td" in md
