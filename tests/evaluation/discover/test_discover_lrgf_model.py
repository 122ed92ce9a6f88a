"""The modelling loop on the LRGF nominal model: missing measured inputs."""

from __future__ import annotations

import numpy as np
import pytest

import fcc_env
from evaluation import discover as d
from evaluation.discover.lrgf_model import LRGFModel


def synthetic(seed: int, gain: float, n: int = 2000) -> d.MeasuredData:
    """y = a nonlinear first-order response to u1, plus gain·u2(k − 2) at the output, plus noise."""
    rng = np.random.default_rng(seed)

    def steps() -> np.ndarray:
        return np.repeat(rng.uniform(-1, 1, n // 40 + 1), 40)[:n]

    u1, u2, u3 = steps(), steps(), steps()
    x = np.zeros(n)
    for k in range(1, n):
        x[k] = 0.8 * x[k - 1] + 0.2 * np.tanh(1.5 * u1[k - 1])
    u2d = np.concatenate([[u2[0]] * 2, u2[:-2]])
    y = x + gain * u2d + 0.02 * rng.standard_normal(n)
    return d.from_arrays({"y": y, "u1": u1, "u2": u2, "u3": u3}, sample_time_s=1.0)


def test_lrgf_adapter_finds_the_missing_input_and_its_delay():
    model = LRGFModel({"y": ["u1"]}, max_epochs=400, candidate_delays=(0, 1, 2, 3, 4))
    rep = d.discover(synthetic(0, gain=0.3), model=model, max_effects=2).to_json()
    assert rep["effects"][0]["id"] == "input:u2->y@2"
    assert rep["effects"][0]["params"]["gain"] == pytest.approx(0.3, rel=0.1)
    assert rep["rmse_after"]["y"] < 0.5 * rep["rmse_before"]["y"]
    assert not any(e["id"].startswith("input:u3") for e in rep["effects"])


def test_lrgf_adapter_on_fcc_data():
    """T_rx declared from T_fp alone misses the regenerated-catalyst temperature."""
    data = d.from_batch(fcc_env.simulate_episodes([0], 2000))
    rep = d.discover(
        data, model=LRGFModel({"T_rx": ["T_fp"]}, max_epochs=300), max_effects=1
    ).to_json()
    assert rep["effects"], "no missing input found"
    assert rep["effects"][0]["id"].split("@")[0] in {"input:T_rg2->T_rx", "input:T_rg1->T_rx"}
    assert rep["rmse_after"]["T_rx"] < 0.6 * rep["rmse_before"]["T_rx"]


def test_lrgf_adapter_bad_input():
    with pytest.raises(ValueError, match="at least one output channel"):
        LRGFModel({})
    with pytest.raises(
        ValueError, match=r"max_epochs=0 is outside the allowed range: an integer in \[1, 100000\]"
    ):
        LRGFModel({"y": ["u1"]}, max_epochs=0)
