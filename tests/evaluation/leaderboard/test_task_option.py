"""``python -m evaluation.leaderboard --task control``: the control task's leaderboard."""

from __future__ import annotations

import pytest

from evaluation.leaderboard.command import main


@pytest.mark.parametrize("task", [["--task", "control"], ["--task=control"]])
def test_task_control_is_the_control_commands(task, capsys) -> None:
    with pytest.raises(SystemExit) as exit_:
        main([*task, "--help"])
    assert exit_.value.code == 0
    assert "--diagnoser-params" in capsys.readouterr().out  # the control command's own option


def test_task_control_refuses_the_control_commands_bad_values(capsys) -> None:
    with pytest.raises(SystemExit) as exit_:
        main(["--task", "control", "--seeds", "0", "--diagnosers", ""])
    assert exit_.value.code == 2
    assert "--seeds" in capsys.readouterr().err


def test_an_unknown_task_is_refused_with_the_allowed_ones(capsys) -> None:
    with pytest.raises(SystemExit) as exit_:
        main(["--task", "plan"])
    assert exit_.value.code == 2
    err = capsys.readouterr().err
    assert "'plan'" in err and "detection" in err and "control" in err


def test_task_detection_is_the_default_leaderboard(capsys) -> None:
    with pytest.raises(SystemExit) as exit_:
        main(["--task", "detection", "--help"])
    assert exit_.value.code == 0
    assert "--track" in capsys.readouterr().out


def test_task_is_read_wherever_it_stands_and_only_spelled_out(capsys) -> None:
    # --task read first by its own parser: the words around it go to the control command
    with pytest.raises(SystemExit) as exit_:
        main(["--seeds", "0", "--task=control", "--diagnosers", ""])
    assert exit_.value.code == 2
    assert "evaluation.control: error: --seeds 0" in capsys.readouterr().err
    # an abbreviation would otherwise run the detection leaderboard under the control task's name
    with pytest.raises(SystemExit) as exit_:
        main(["--tas", "control", "--quick"])
    assert exit_.value.code == 2
    # refused by name: no parser reads an abbreviated flag (allow_abbrev=False everywhere)
    err = capsys.readouterr().err
    assert "--tas" in err and ("spell --task out" in err or "unrecognized arguments" in err)
