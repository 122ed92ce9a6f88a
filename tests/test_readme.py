"""The README's Python examples run, in order, in one namespace (as a reader would paste them).

Training diagnosers with their default hyperparameters takes minutes, so the default run
swaps in each class's ``fast_params()`` (small, fast settings) through ``diagnosers.make``; the
``slow`` run executes the examples exactly as written.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

import diagnosers

README = Path(__file__).resolve().parents[1] / "README.md"


def _python_blocks() -> list[str]:
    text = README.read_text()
    blocks = re.findall(r"```python\n(.*?)```", text, flags=re.S)
    assert len(blocks) >= 4, "the README lost its Python examples"
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


def test_readme_examples_run_with_fast_settings(tmp_path, monkeypatch) -> None:
    real_make = diagnosers.make

    def fast_make(name: str, **hyperparameters):
        fast = dict(diagnosers.diagnoser_class(name).fast_params())
        if name == "lrgf-lda":  # its detector must be good enough to alarm on paper-size faults
            fast["detector"] = {**fast["detector"], "max_epochs": 400}
        return real_make(name, **{**fast, **hyperparameters})

    monkeypatch.setattr(diagnosers, "make", fast_make)
    ns = _run_all(tmp_path, monkeypatch)
    assert ns["obs"].shape == (8,)
    assert ns["result"].alarm.shape == (ns["episode"].n_samples,)
    assert ns["decision"].alarm == bool(ns["result"].alarm[0])
    assert (tmp_path / "model_dir" / "config.json").is_file()
    assert isinstance(ns["det2"], diagnosers.Diagnoser) and ns["det2"].alpha == 0.01
    assert ns["iso"].isolates
    det = ns["det"]  # the isolation example's detection (the last block rebinds ``det``)
    assert det.diagnosis is not None and det.diagnosis.shape == det.alarm.shape


@pytest.mark.slow
def test_readme_examples_run_as_written(tmp_path, monkeypatch) -> None:
    ns = _run_all(tmp_path, monkeypatch)
    assert ns["result"].alarm.shape == (4000,)
