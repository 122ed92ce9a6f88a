"""The report object of the modelling loop, the package layout, and the fitting back end."""

from __future__ import annotations

import dataclasses
import json
import pathlib

import numpy as np
import pytest

from evaluation import discover as d

EXPECTED_KEYS = [
    "tool", "model", "data", "n_episodes", "n_samples", "n_train", "channels", "effects",
    "rmse_before", "rmse_after", "rmse_train_before", "rmse_train_after", "noise_std_estimate",
    "unexplained", "unexplained_channels", "structure_before", "structure_after",
    "structure_limits", "tests_before", "tests_after", "rounds", "skipped_candidates",
    "settings", "elapsed_s",
]  # fmt: skip


def arx_case(gain: float = 0.1, n: int = 1500) -> d.MeasuredData:
    rng = np.random.default_rng(0)

    def steps() -> np.ndarray:
        return np.repeat(rng.uniform(-1, 1, n // 30 + 1), 30)[:n]

    u1, u2 = steps(), steps()
    w = 0.05 * rng.standard_normal(n)
    y = np.zeros(n)
    for k in range(2, n):
        y[k] = 1.5 * y[k - 1] - 0.6 * y[k - 2] + 0.3 * u1[k - 1] + gain * u2[k - 2] + w[k]
    return d.from_arrays({"y": y, "u1": u1, "u2": u2}, sample_time_s=1.0)


def test_report_is_frozen_typed_and_its_json_is_the_written_file(tmp_path):
    model = d.ARXModel({"y": ["u1"]}, na=2, nb=2)
    rep = d.discover(arx_case(), model=model, out_dir=tmp_path, plots=False)
    assert isinstance(rep, d.DiscoveryReport)
    assert rep.effects[0].id == "input:u2->y@2"
    assert rep.channels == ("y",) and rep.plots is None
    with pytest.raises(dataclasses.FrozenInstanceError):
        rep.unexplained = True  # type: ignore[misc]
    js = rep.to_json()
    note = ["note"] if rep.note is not None else []
    assert list(js) == EXPECTED_KEYS[:-1] + note + ["elapsed_s"]
    assert js["effects"][0]["id"] == "input:u2->y@2"
    written = (tmp_path / "report.json").read_text()
    assert json.loads(written) == json.loads(json.dumps(js))
    js["effects"].clear()  # to_json hands out a copy
    assert rep.to_json()["effects"]


def test_fit_effects_is_bounded_and_counts_batched_evaluations():
    """least_squares sees the bounds; every evaluation is one batched (1 + n_free)-row predict."""
    calls = []

    class Quadratic:
        name = "toy"
        output_channels = ("y",)

        def predict(self, data, effects, thetas, n):
            calls.append(thetas.shape[0])
            t = np.linspace(0, 1, n)
            return (thetas[:, 0, None] * t + thetas[:, 1, None] * t**2)[:, None, :, None]

    data = d.from_arrays({"y": np.linspace(0, 1, 200) * 2.0})
    cand = d.MissingInput("a", "y", 0, id="c", params=(
        d.ParamInfo("a", 1.0, -10.0, 1.5, 0.0, "-", ()),
        d.ParamInfo("b", 1.0, -10.0, 10.0, 0.0, "-", ()),
    ))  # fmt: skip
    Y = data.stack(["y"])
    fit = d.fit_effects(
        Quadratic(), data, [cand], np.zeros(2), np.ones(2, bool), Y, 200, np.ones(1), grid=False
    )
    assert fit.theta[0] == pytest.approx(1.5)  # the bound holds (the free optimum is a = 2, b = 0)
    # b fits the rest, 0.5·t, by b·t²: b = 0.5·∫t³/∫t⁴ = 0.625 (continuous limit)
    assert fit.theta[1] == pytest.approx(0.625, rel=0.01)
    assert set(calls) == {3} and fit.n_evals == 3 * len(calls)
    assert np.all(np.isfinite(fit.stderr))


def test_no_module_of_the_package_is_too_long_or_imports_private_names():
    root = pathlib.Path(d.__file__).parent
    for path in root.glob("*.py"):
        text = path.read_text()
        assert len(text.splitlines()) <= 700, path.name
        for line in text.splitlines():
            if line.startswith("from evaluation") and " import " in line:
                names = line.split(" import ", 1)[1]
                assert not names.lstrip("(").strip().startswith("_"), (path.name, line)
