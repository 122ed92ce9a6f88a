"""The README's Python examples run, in order, in one namespace (as a reader would paste them),
and what the README promises a reader about itself holds.

Training diagnosers with their default hyperparameters takes minutes, so the default run
swaps in each class's ``fast_params()`` (small, fast settings) through ``diagnosers.make``; the
``slow`` run executes the examples exactly as written.
"""

from __future__ import annotations

import importlib
import re
from pathlib import Path

import numpy as np
import pytest

import diagnosers

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
QUICKSTART = (
    "pip install torch==2.13.0 -e . && python -m evaluation.leaderboard --quick\n"
    'pip install torch==2.13.0 -e ".[test,ray]" && python -m pytest -n 2 --dist loadfile\n'
)


def _python_blocks() -> list[str]:
    text = README.read_text()
    blocks = re.findall(r"```python\n(.*?)```", text, flags=re.S)
    assert len(blocks) >= 2, "the README lost its Python examples"
    return blocks


def _run_all(tmp_path, monkeypatch) -> dict:
    monkeypatch.chdir(tmp_path)  # the examples write model_dir/
    namespace: dict = {}
    for i, block in enumerate(_python_blocks()):
        try:
            exec(compile(block, f"README.md python block {i + 1}", "exec"), namespace)
        except Exception as e:  # name the block: the traceback alone points at <string>
            raise AssertionError(f"README python block {i + 1} failed: {e!r}\n{block}") from e
    return namespace


def _check_namespace(ns: dict, tmp_path: Path) -> None:
    assert ns["obs"].shape == (8,)
    assert ns["result"].alarm.shape == (ns["episode"].n_samples,)
    assert ns["decision"].alarm == bool(ns["result"].alarm[0])
    assert (tmp_path / "model_dir" / "config.json").is_file()
    loaded = ns["det2"]
    assert isinstance(loaded, diagnosers.Diagnoser) and type(loaded) is type(ns["det"])
    # the saved model is the fitted one: it raises the same alarms
    np.testing.assert_array_equal(loaded.detect(ns["episode"]).alarm, ns["result"].alarm)


def test_readme_examples_run_with_fast_settings(tmp_path, monkeypatch) -> None:
    real_make = diagnosers.make

    def fast_make(name: str, **hyperparameters):
        fast = dict(diagnosers.diagnoser_class(name).fast_params())
        if "n_jobs" in hyperparameters:  # worker processes change no model; on small fits
            hyperparameters = {**hyperparameters, "n_jobs": 1}  # they only add start-up time
        return real_make(name, **{**fast, **hyperparameters})

    monkeypatch.setattr(diagnosers, "make", fast_make)
    _check_namespace(_run_all(tmp_path, monkeypatch), tmp_path)


@pytest.mark.slow
def test_readme_examples_run_as_written(tmp_path, monkeypatch) -> None:
    ns = _run_all(tmp_path, monkeypatch)
    _check_namespace(ns, tmp_path)
    assert ns["result"].alarm.shape == (4000,)


def test_quickstart_is_the_two_commands_ci_runs() -> None:
    """The Quickstart's commands are the contract with a newcomer: the first installs and runs a
    quick leaderboard, the second is the test command that CI (``.ci/run``) runs verbatim."""
    text = README.read_text()
    section = text.split("## Quickstart", 1)[1]
    block = re.search(r"```bash\n(.*?)```", section, flags=re.S)
    assert block is not None and block[1] == QUICKSTART
    ci = (ROOT / ".ci" / "run").read_text().splitlines()
    assert QUICKSTART.splitlines()[1] in ci


def test_readme_is_short_and_self_contained() -> None:
    """At most 250 lines, no path a clone does not have, and every local link resolves."""
    text = README.read_text()
    assert len(text.splitlines()) <= 250
    assert "shared/" not in text
    for target in re.findall(r"\]\(([^)#]+)(?:#[^)]*)?\)", text):
        if not re.match(r"[a-z]+://", target):
            assert (ROOT / target).exists(), f"README links to a missing file: {target}"


def test_documentation_examples_import_what_exists() -> None:
    """The docs site's Python examples import only names that exist (modules move; the README's
    own examples run in full above)."""
    pages = sorted((ROOT / "docs").glob("*.md"))
    imports = [
        line.strip()
        for page in pages
        for block in re.findall(r"```python\n(.*?)```", page.read_text(), flags=re.S)
        for line in block.splitlines()
        if re.match(r"\s*(import|from) \w", line)
    ]
    assert imports, "the docs lost their Python examples"
    for line in imports:
        exec(line, {})


def _resolves(dotted: str) -> bool:
    """Whether ``a.b.c`` names a module, or an attribute reached from the longest module prefix."""
    parts = dotted.split(".")
    for i in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:i]))
        except ImportError:
            continue
        try:
            for name in parts[i:]:
                obj = getattr(obj, name)
        except AttributeError:
            return False
        return True
    return False


def test_names_in_the_readme_and_docs_exist() -> None:
    """Every ``package.module.name`` the README and the docs pages mention exists, so a moved
    module fails here rather than on a reader."""
    pages = [README, *sorted((ROOT / "docs").rglob("*.md"))]
    pattern = r"\b((?:fcc_env|fcc_common|diagnosers|evaluation)(?:\.[A-Za-z_]\w*)+)"
    names = {n for page in pages for n in re.findall(pattern, page.read_text())}
    missing = sorted(n for n in names if not n.endswith(".md") and not _resolves(n))
    assert not missing, f"the README or the docs name what does not exist: {missing}"
