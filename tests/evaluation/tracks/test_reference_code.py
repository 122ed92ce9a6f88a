"""The reference rows' code address: derived from the import graph, so no dependency is left
off, and any edit of a listed module changes it."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

from evaluation.tracks import reference_runs
from evaluation.tracks.reference_runs import REFERENCE_CODE, code_version, reference_code
from fcc_common.import_graph import import_closure, module_file


def test_the_reference_code_is_the_closure_of_the_rows_imports() -> None:
    assert REFERENCE_CODE == reference_code()
    # what the hand-written list named, and what it missed, are there
    for name in (
        "diagnosers.stages.innovation_stage",
        "evaluation.tracks.filter_bound",
        "evaluation.tracks.optimal",
        "diagnosers.filters.ukf_model",
        "diagnosers.lrgf.lrgf_glr",  # read by registry name: a root of its own
        "diagnosers.stages.alarm_stage",  # imported by the directional stage, never listed
    ):
        assert name in REFERENCE_CODE, name
    assert (
        module_file("diagnosers.stages.innovation_stage")
        == Path(reference_runs.__file__).parents[2]
        / "diagnosers"
        / "stages"
        / "innovation_stage.py"
    )
    # the simulator is named by its versions, and the scheduler computes no number
    assert not any(m.startswith("fcc_env") for m in REFERENCE_CODE)
    assert "evaluation.tracks.reference_runs" not in REFERENCE_CODE


def _package(root: Path, files: dict[str, str]) -> None:
    for rel, text in files.items():
        (root / rel).parent.mkdir(parents=True, exist_ok=True)
        (root / rel).write_text(text)


def test_an_edit_of_an_imported_module_changes_the_code_version(tmp_path, monkeypatch) -> None:
    _package(
        tmp_path,
        {
            "gpk/__init__.py": "",
            "gpk/rows.py": "from gpk.stage import limit\nimport numpy\n",
            "gpk/stage.py": "def limit():\n    from .deep import x\n    return x\n",
            "gpk/deep.py": "x = 1\n",
            "gpk/unused.py": "y = 2\n",
        },
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    module_file.cache_clear()
    try:
        mods = import_closure(["gpk.rows"], ["gpk"])
        # a relative import inside a function is followed; numpy and the unused module are not
        assert mods == ("gpk.deep", "gpk.rows", "gpk.stage")
        before = code_version(mods)
        (tmp_path / "gpk" / "deep.py").write_text("x = 2\n")  # two modules down, one byte
        code_version.cache_clear()
        assert code_version(mods) != before
    finally:
        code_version.cache_clear()
        module_file.cache_clear()
        for m in [m for m in sys.modules if m == "gpk" or m.startswith("gpk.")]:
            del sys.modules[m]


def test_a_root_outside_the_packages_is_refused() -> None:
    with pytest.raises(ValueError, match="'numpy'"):
        import_closure(["numpy"], ["diagnosers"])
    with pytest.raises(ValueError, match="excluded"):
        import_closure(["fcc_env.physics"], ["fcc_env"], exclude=("fcc_env",))
