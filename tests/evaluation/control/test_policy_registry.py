"""The control study's policy registry (issue 41): built-ins by name, a user's policy through
``python -m evaluation.control --import MODULE --policies ...``, and the refusals."""

from __future__ import annotations

import json
import re
import sys
import textwrap

import pytest

from evaluation.control import available_policies, make_policy, register_policy
from evaluation.control.policies import ProgramPolicy
from evaluation.control.policy_registry import policy_spec, unregister_policy
from evaluation.control.returns_command import main

MODULE = "fcc_test_policy_mod"
SOURCE = """
    import numpy as np

    from evaluation.control import register_policy


    @register_policy("half-up", summary="half a step up on both set points, always")
    class HalfUp:
        name = "half up (a user's policy)"

        def reset(self, info):
            pass

        def act(self, obs, info):
            return np.full(2, 0.5, dtype=np.float32)
"""


@pytest.fixture
def policy_module(tmp_path, monkeypatch):
    (tmp_path / f"{MODULE}.py").write_text(textwrap.dedent(SOURCE))
    monkeypatch.syspath_prepend(str(tmp_path))
    yield MODULE
    unregister_policy("half-up")
    sys.modules.pop(MODULE, None)


def test_the_builtins_are_registered_and_made_by_name() -> None:
    assert {"program", "fixed", "oracle", "supervisor", "ppo"} <= set(available_policies())
    program = make_policy("program")
    assert isinstance(program, ProgramPolicy) and program.name == "program (zero action)"
    assert policy_spec("supervisor").needs and not policy_spec("fixed").needs


def test_a_users_module_registers_a_policy_that_the_study_runs(policy_module, tmp_path, capsys):
    out = tmp_path / "study"
    argv = ["--import", policy_module, "--policies", "program,half-up", "--diagnosers", ""]
    assert main([*argv, "--seeds", "1", "--steps", "3", "--out", str(out)]) == 0
    assert "half-up" in available_policies()
    table = capsys.readouterr().out
    rows = [line.split(" | ")[0].lstrip("| ") for line in table.splitlines()[2:5]]
    assert rows == [
        "program (zero action)",
        "half up (a user's policy)",
        "oracle (knows the fault and its onset)",
    ]
    episodes = json.loads((out / "control.json").read_text())["episodes"]
    assert {e["policy"] for e in episodes} == set(rows) and len(episodes) == 3 * 5


def test_make_policy_refuses_what_is_not_a_policy() -> None:
    register_policy("not-a-policy")(lambda: object())
    try:
        with pytest.raises(ValueError, match=r"'not-a-policy' built .* not a policy"):
            make_policy("not-a-policy")
    finally:
        unregister_policy("not-a-policy")


def test_a_name_registered_twice_is_refused() -> None:
    with pytest.raises(ValueError, match="'program' is already registered"):
        register_policy("program")(lambda: ProgramPolicy())


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--policies", "nope"], r"--policies: unknown \['nope'\]; allowed: \["),
        (["--policies", "program,oracle"], "'oracle', which every study runs"),
        (["--policies", "supervisor"], r"\['supervisor'\] need arguments .*--diagnosers"),
        (["--policies", "program,program"], "repeats a name"),
        (["--import", "no_such_module_xyz"], "--import: cannot import module 'no_such_module_xyz'"),
        (["--import", ".relative"], "--import: .*absolute"),
    ],
)
def test_bad_policies_and_imports_are_refused_in_one_line(argv, message, capsys) -> None:
    with pytest.raises(SystemExit) as e:
        main([*argv, "--diagnosers", "", "--seeds", "1"])
    assert e.value.code == 2
    assert re.search(message, capsys.readouterr().err)


def test_two_policies_with_one_table_name_are_refused(capsys) -> None:
    register_policy("program-again")(lambda: ProgramPolicy())
    try:
        with pytest.raises(SystemExit) as e:
            main(["--policies", "program,program-again", "--diagnosers", "", "--seeds", "1"])
        assert e.value.code == 2
        assert "share a name in the table" in capsys.readouterr().err
    finally:
        unregister_policy("program-again")
