"""The residual → missing-effect loop on data with undeclared effects (evaluation.discover).

Detection sizes are realistic for a plant (stated per case, all smaller than the library defaults)
on healthy 4000-sample (11.1 h) excited records. Criteria per case: the right effect is named
first, its parameter is within ``rel_tol`` of the truth, and the held-out RMSE of the most
affected channel drops by at least 80 % of the gap to the noise floor, where the floor is the
held-out RMSE of the declared model on the same seed without the effect (the model's residual
carries propagated input noise, so the floor is not the sensor noise).
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

import fcc_env
from evaluation import discover as d
from fcc_env import effects as fx
from fcc_env.generate import write_dataset

N = 4000


# (effect text, truth parameter name, true value, relative tolerance, seed)
CASES = [
    ("sensor_bias:T_fp,bias=3", "bias", 3.0, 0.1, 0),  # input channel: corrected input
    ("sensor_lag:T_rg1,tau_s=60", "tau_s", 60.0, 0.15, 0),  # output channel: no re-simulation
    ("heat_loss:dilute_general,extra_ua_kw_per_k=0.3", "extra_ua_kw_per_k", 0.3, 0.1, 0),
    ("catalyst_deactivation,loss_per_day=0.1", "loss_per_day", 0.1, 0.15, 0),
]
SLOW_CASES = [
    ("sensor_bias:T_rg2,bias=2", "bias", 2.0, 0.1, 1),
    ("sensor_drift:T_dg,rate_per_h=0.3", "rate_per_h", 0.3, 0.15, 1),
    ("sensor_drift:T_fp,rate_per_h=0.3", "rate_per_h", 0.3, 0.15, 1),
    ("sensor_bias:R_ar,bias=1", "bias", 1.0, 0.15, 1),
    ("feed_coking_drift,rise_per_day=0.05", "rise_per_day", 0.05, 0.15, 1),
    ("afterburn:dilute1,factor=1.3", "factor", 1.3, 0.05, 1),
    ("afterburn:dilute_general,factor=1.3", "factor", 1.3, 0.05, 1),
    ("air_split,delta_alpha1=0.01", "delta_alpha1", 0.01, 0.15, 1),
    ("heat_loss:stage2,extra_ua_kw_per_k=1", "extra_ua_kw_per_k", 1.0, 0.15, 1),
]


def check_detection(text: str, pname: str, truth: float, rel_tol: float, seed: int) -> None:
    effect = fx.parse(text)
    data = d.from_batch(fcc_env.simulate_episodes([seed], N, plant_effects=[effect]))
    floor = d.heldout_rmse(d.from_batch(fcc_env.simulate_episodes([seed], N)))
    rep = d.discover(data, max_effects=2).to_json()
    assert rep["effects"], f"{text}: nothing found; rounds {rep['rounds'][0]['candidates'][:3]}"
    first = rep["effects"][0]
    assert first["id"] == effect.effect_id
    est = first["params"][pname]
    assert est == pytest.approx(truth, rel=rel_tol), (text, est)
    lo, hi = first["ci95"][pname]
    assert lo < est < hi and math.isfinite(first["stderr"][pname])
    gap = {c: rep["rmse_before"][c] - floor[c] for c in floor}
    ch = max(gap, key=gap.get)
    drop = rep["rmse_before"][ch] - rep["rmse_after"][ch]
    assert drop >= 0.8 * gap[ch], (
        text,
        ch,
        rep["rmse_before"][ch],
        rep["rmse_after"][ch],
        floor[ch],
    )
    assert rep["unexplained"] is False


@pytest.mark.parametrize(
    ("text", "pname", "truth", "rel_tol", "seed"), CASES, ids=[c[0] for c in CASES]
)
def test_library_effect_is_found_estimated_and_closes_the_gap(text, pname, truth, rel_tol, seed):
    check_detection(text, pname, truth, rel_tol, seed)


@pytest.mark.slow
@pytest.mark.parametrize(
    ("text", "pname", "truth", "rel_tol", "seed"), SLOW_CASES, ids=[c[0] for c in SLOW_CASES]
)
def test_library_effect_is_found_slow(text, pname, truth, rel_tol, seed):
    check_detection(text, pname, truth, rel_tol, seed)


def test_clean_data_reports_no_effect():
    for seed in (0, 1):
        rep = d.discover(
            d.from_batch(fcc_env.simulate_episodes([seed], N)), max_effects=1
        ).to_json()
        assert rep["effects"] == [] and rep["unexplained"] is False


@pytest.mark.slow
def test_clean_data_false_discovery_rate_over_20_seeds():
    found = 0
    for seed in range(100, 120):
        rep = d.discover(
            d.from_batch(fcc_env.simulate_episodes([seed], N)), max_effects=1
        ).to_json()
        found += bool(rep["effects"])
    assert found <= 1  # at least 95 % of seeds report nothing


def test_two_effects_at_once_are_both_found():
    effects = ["sensor_bias:T_rg2,bias=2", "afterburn:dilute1,factor=1.3"]
    data = d.from_batch(fcc_env.simulate_episodes([1], N, plant_effects=effects))
    rep = d.discover(data).to_json()
    found = {e["id"]: e["params"] for e in rep["effects"]}
    assert set(found) == {"sensor_bias:T_rg2", "afterburn:dilute1"}
    assert found["sensor_bias:T_rg2"]["bias"] == pytest.approx(2.0, rel=0.1)
    assert found["afterburn:dilute1"]["factor"] == pytest.approx(1.3, rel=0.05)
    assert rep["unexplained"] is False


class SineOnStage2:
    """A user effect outside the library: a 2-hour sinusoidal heat input on the stage-2 bed."""

    def d_state(self, t, x, u, params):
        out = np.zeros_like(x)
        out[..., 7] = 2e-3 * np.sin(2 * np.pi * t / 7200.0)  # °C/s on T2
        return out


def test_effect_outside_the_library_is_reported_unexplained():
    # forms="never": the library alone (a form search follows by default: test_discover_forms)
    data = d.from_batch(fcc_env.simulate_episodes([1], N, plant_effects=[SineOnStage2()]))
    rep = d.discover(data, forms="never").to_json()
    assert rep["unexplained"] is True
    assert "T_rg2" in rep["unexplained_channels"]
    # no wrong effect is named with confidence: either none, or flagged as not explaining
    assert all(e["explains_structure"] is False for e in rep["effects"])


def test_user_candidate_is_plugged_in_and_found():
    """A user-added physics candidate (here: a scaled stage-2 heat loss) competes and wins."""

    class StageTwoLoss:
        def __init__(self, scale):
            self.scale = scale

        def param_multipliers(self, t_s, base):
            return {"UA_2": np.full_like(t_s, self.scale, dtype=float)}

    cand = d.PhysicsCandidate(
        "user:ua2_scale",
        (d.ParamInfo("scale", 2.0, 0.5, 10.0, 1.0, "-", (1.0, 1.5, 3.0)),),
        lambda scale: StageTwoLoss(scale),
    )
    data = d.from_batch(
        fcc_env.simulate_episodes([2], 2000, plant_effects=["heat_loss:stage2,extra_ua_kw_per_k=1"])
    )
    rep = d.discover(
        data, candidates=["sensor_bias:T_rg2"], extra_candidates=[cand], max_effects=1
    ).to_json()
    assert rep["effects"][0]["id"] == "user:ua2_scale"
    assert rep["effects"][0]["params"]["scale"] == pytest.approx(1.5, rel=0.05)  # (2+1)/2


def test_output_lag_matches_library_measure():
    eff = fx.make("sensor_lag:T_rg1", tau_s=45.0)
    eff.reset()
    y = np.random.default_rng(0).standard_normal((50, 8)) + 700
    ref = np.array([eff.measure(k * 10.0, y[k])[4] for k in range(50)])
    np.testing.assert_allclose(d.first_order_lag(y[:, 4], 45.0, 10.0), ref, rtol=0, atol=1e-9)


# ---- data access: only measured + commanded -------------------------------------------------------
def test_loader_reads_only_measured_and_commanded_and_ignores_truth(tmp_path):
    path = write_dataset(
        tmp_path / "bias.csv", seeds=[3], n_samples=1500, plant_effects=["sensor_bias:T_rg2,bias=3"]
    )
    data = d.load_measured(path)
    assert set(data.channels) == {*fcc_env.MEASUREMENT_NAMES, "cmd_u_F", "cmd_R_ar"}
    kw = dict(
        candidates=["sensor_bias:T_rg2", "sensor_bias:T_rx", "sensor_lag:T_rg2"], max_effects=1
    )
    rep1 = d.discover(path, out_dir=tmp_path / "a", plots=False, **kw).to_json()
    # corrupt every truth column and the truth sidecar field: nothing may change
    header = path.read_text().splitlines()[0].split(",")
    table = np.loadtxt(path, delimiter=",", skiprows=1)
    truth = [i for i, c in enumerate(header) if c.startswith(("in_", "clean_", "x_", "fault"))]
    table[:, truth] = np.random.default_rng(0).normal(size=(table.shape[0], len(truth))) * 1e3
    np.savetxt(path, table, delimiter=",", header=",".join(header), comments="", fmt="%.10g")
    meta = json.loads(path.with_suffix(".json").read_text())
    meta["truth_plant_effects"] = [{"id": "sensor_bias:T_rx", "params": {"bias": -9}}]
    path.with_suffix(".json").write_text(json.dumps(meta))
    rep2 = d.discover(path, out_dir=tmp_path / "b", plots=False, **kw).to_json()
    assert rep1["effects"][0]["id"] == "sensor_bias:T_rg2"
    assert rep1["effects"] == rep2["effects"] and rep1["rmse_after"] == rep2["rmse_after"]


def test_cli_writes_report_and_plots(tmp_path, capsys):
    path = write_dataset(
        tmp_path / "lag.csv", seeds=[4], n_samples=2000, plant_effects=["sensor_bias:T_dg,bias=3"]
    )
    out = tmp_path / "out"
    argv = ["--data", str(path), "--out", str(out), "--candidates", "sensor_bias:T_dg,air_split"]
    assert d.main(argv) == 0
    rep = json.loads((out / "report.json").read_text())
    for key in (
        "effects",
        "rmse_before",
        "rmse_after",
        "unexplained",
        "tests_before",
        "tests_after",
    ):
        assert key in rep
    assert rep["effects"][0]["id"] == "sensor_bias:T_dg"
    assert rep["rmse_after"]["T_dg"] < 0.5 * rep["rmse_before"]["T_dg"]
    assert (out / "residuals.png").stat().st_size > 0 and (out / "autocorrelation.png").is_file()
    assert not list(out.glob("*.tmp"))
    assert "sensor_bias:T_dg" in capsys.readouterr().out
    assert rep["tests_before"]["T_dg"]["bias"]["passed"] is False  # the 3 °C offset
    assert abs(rep["tests_after"]["T_dg"]["bias"]["estimate"]) < 0.2
    assert "phi_u2_xi" in rep["tests_after"]["T_dg"]["billings_voon"]["T_fp"]


@pytest.mark.parametrize(
    ("argv_extra", "match"),
    [
        (
            ["--train-fraction", "0.95"],
            r"train_fraction=0.95 is outside the allowed range: a number in \(0.2, 0.9\)",
        ),
        (["--candidates", "sensor_bias:T_xx"], r"unknown candidate id\(s\) \['sensor_bias:T_xx'\]"),
        (["--candidates", "sensor_lag:T_fp"], "cannot be inverted"),
        (
            ["--max-effects", "11"],
            r"max_effects=11 is outside the allowed range: an integer in \[0, 10\]",
        ),
    ],
)
def test_cli_bad_arguments_name_value_and_range(tmp_path, capsys, argv_extra, match):
    path = write_dataset(tmp_path / "x.csv", seeds=[0], n_samples=200)
    with pytest.raises(SystemExit) as exc:
        d.main(["--data", str(path), "--out", str(tmp_path / "o"), *argv_extra])
    assert exc.value.code == 2
    import re

    assert re.search(match, capsys.readouterr().err)


def test_bad_files_give_clear_errors(tmp_path):
    with pytest.raises(ValueError, match="does not exist"):
        d.load_measured(tmp_path / "missing.csv")
    with pytest.raises(ValueError, match=r"must be a \.csv"):
        d.load_measured(tmp_path / "x.txt")
    bad = tmp_path / "bad.csv"
    bad.write_text("a,b\n1,2\n")
    with pytest.raises(ValueError, match="no JSON sidecar"):
        d.load_measured(bad)
    bad.with_suffix(".json").write_text('{"format": "other"}')
    with pytest.raises(ValueError, match="not an FCC dataset sidecar"):
        d.load_measured(bad)
    bad.with_suffix(".json").write_text("{oops")
    with pytest.raises(ValueError, match="not valid JSON"):
        d.load_measured(bad)


# ---- the generic input-output (ARX) adapter: candidates are missing measured inputs ---------------
def synthetic(seed: int, gain: float, n: int = 3000) -> d.MeasuredData:
    rng = np.random.default_rng(seed)

    def steps() -> np.ndarray:
        return np.repeat(rng.uniform(-1, 1, n // 30 + 1), 30)[:n]

    u1, u2, u3 = steps(), steps(), steps()
    w = 0.05 * rng.standard_normal(n)  # equation noise: the ARX model class holds
    y = np.zeros(n)
    for k in range(2, n):
        y[k] = 1.5 * y[k - 1] - 0.6 * y[k - 2] + 0.3 * u1[k - 1] + gain * u2[k - 2] + w[k]
    return d.from_arrays({"y": y, "u1": u1, "u2": u2, "u3": u3}, sample_time_s=1.0)


def test_arx_adapter_finds_the_missing_input_and_its_delay():
    model = d.ARXModel({"y": ["u1"]}, na=2, nb=2, candidate_delays=(0, 1, 2, 3, 4))
    data = synthetic(0, gain=0.1)
    rep = d.discover(data, model=model).to_json()
    assert rep["effects"][0]["id"] == "input:u2->y@2"
    assert rep["effects"][0]["params"]["gain"] == pytest.approx(0.1, rel=0.1)
    floor = d.discover(synthetic(0, gain=0.0), model=model, max_effects=0).to_json()["rmse_before"][
        "y"
    ]
    gap = rep["rmse_before"]["y"] - floor
    assert rep["rmse_before"]["y"] - rep["rmse_after"]["y"] >= 0.8 * gap
    assert not any(e["id"].startswith("input:u3") for e in rep["effects"])


def test_arx_adapter_clean_data_finds_nothing():
    model = d.ARXModel({"y": ["u1"]}, na=2, nb=2)
    for seed in range(3):
        assert d.discover(synthetic(seed, gain=0.0), model=model).to_json()["effects"] == []


def test_arx_adapter_on_fcc_data_finds_a_missing_measured_input():
    """T_rx declared from T_fp alone misses the regenerated-catalyst temperature path."""
    data = d.from_batch(fcc_env.simulate_episodes([0], N))
    model = d.ARXModel({"T_rx": ["T_fp"]}, na=2, nb=2)
    rep = d.discover(data, model=model, max_effects=2).to_json()
    assert rep["effects"], "no missing input found"
    assert rep["effects"][0]["id"].split("->")[0] in {
        "input:T_rg1",
        "input:T_rg2",
        "input:R_ar",
        "input:cmd_R_ar",
        "input:T_ar",
    }
    assert rep["rmse_after"]["T_rx"] < rep["rmse_before"]["T_rx"]


# --- effects at any plausible value, not only near the start values (issue item 12) -----------


def check_found_anywhere(text: str, pname: str, truth: float, rel_tol: float, seed: int) -> None:
    effect = fx.parse(text)
    data = d.from_batch(fcc_env.simulate_episodes([seed], N, plant_effects=[effect]))
    rep = d.discover(data, max_effects=1).to_json()
    assert rep["effects"], (
        f"{text} seed {seed}: nothing found; {rep['rounds'][0]['candidates'][:2]}"
    )
    first = rep["effects"][0]
    assert first["id"] == effect.effect_id, (text, seed, first)
    assert first["params"][pname] == pytest.approx(truth, rel=rel_tol, abs=0.05), (text, seed)
    assert rep["unexplained"] is False, (text, seed, rep["unexplained_channels"])


def test_seed_4242_lag_at_120_s_is_found():
    # before the conditional held-out test this lag was fitted exactly (120.1 s, held-out T_rg1
    # error -77 %) but rejected: p 3.6e-4 against the Bonferroni threshold 3.2e-4
    check_found_anywhere("sensor_lag:T_rg1,tau_s=120", "tau_s", 120.0, 0.1, 4242)


ANYWHERE = [
    *[(f"sensor_lag:T_rg1,tau_s={v}", "tau_s", float(v), 0.15) for v in (30, 60, 120, 180, 300)],
    *[(f"sensor_bias:T_rg2,bias={v}", "bias", float(v), 0.15) for v in (-3, -1, 1, 3)],
    *[
        (f"heat_loss:stage2,extra_ua_kw_per_k={v}", "extra_ua_kw_per_k", float(v), 0.15)
        for v in (0.3, 1, 3)
    ],
]


@pytest.mark.slow
@pytest.mark.parametrize("seed", [4242, 7])
@pytest.mark.parametrize(
    ("text", "pname", "truth", "rel_tol"), ANYWHERE, ids=[a[0] for a in ANYWHERE]
)
def test_effect_is_found_across_its_range(text, pname, truth, rel_tol, seed):
    check_found_anywhere(text, pname, truth, rel_tol, seed)


def test_heldout_test_is_not_capped_by_bursty_effects():
    # a correct effect seen only in bursts: the unconditional batch-means t is capped by how
    # unevenly the bursts fall into blocks; the conditional one grows with the effect
    rng = np.random.default_rng(0)
    n = 1600
    s = np.zeros((1, n, 1))
    s[0, ::200, 0] = 1.0
    s = np.apply_along_axis(lambda x: np.convolve(x, np.full(20, 5.0))[:n], 1, s)
    e1 = rng.normal(0.0, 0.3, (1, n, 1))
    cmp = d.heldout_comparison(e1 + s, e1, np.ones(1) / 0.3, 50)
    assert cmp["t_unconditional"] < 4 and cmp["p_value"] < 1e-12 and cmp["t"] > 20
    # the same prediction change on data it does not explain is rejected
    worse = d.heldout_comparison(e1, e1 - s, np.ones(1) / 0.3, 50)
    assert worse["p_value"] > 0.5 and worse["rel_reduction"] < 0


def test_cli_reads_external_data_through_a_manifest(tmp_path, capsys):
    """--external DIR / --manifest FILE: inputs, outputs and sample time from the manifest."""
    from evaluation.discover.cli import main

    write_dataset(tmp_path / "healthy.csv", seeds=[0], n_samples=N,
                  plant_effects=["sensor_bias:T_rg2,bias=2"])  # fmt: skip
    write_dataset(tmp_path / "fault.csv", scenario="f1", seeds=[1], n_samples=200, fault_time=100)
    manifest = {
        "inputs": ["cmd_u_F", "cmd_R_ar", "T_ar", "T_fp"],
        "outputs": ["R_ar", "T_rx", "T_rg1", "T_rg2", "T_d1", "T_dg"],
        "train_files": ["healthy.csv"],
        "test_files": [{"path": "fault.csv", "onset": 100}],
        "sample_time_s": 10,
    }
    (tmp_path / "dataset.json").write_text(json.dumps(manifest))
    argv = ["--out", str(tmp_path / "o"), "--no-plots", "--max-effects", "1"]
    assert main(["--external", str(tmp_path), *argv, "--candidates", "sensor_bias:T_rg2"]) == 0
    rep = json.loads((tmp_path / "o" / "report.json").read_text())
    assert rep["model"] == "fcc-physics" and [e["id"] for e in rep["effects"]] == [
        "sensor_bias:T_rg2"
    ]
    assert rep["data"].startswith("external:") and rep["n_samples"] == N
    # channels that are not the physics model's: a linear ARX model of the outputs
    (tmp_path / "m.json").write_text(json.dumps({**manifest, "inputs": ["cmd_u_F", "T_fp"],
                                                 "outputs": ["T_rx"]}))  # fmt: skip
    assert main(["--manifest", str(tmp_path / "m.json"), *argv]) == 0
    rep = json.loads((tmp_path / "o" / "report.json").read_text())
    assert rep["model"] != "fcc-physics" and rep["channels"] == ["T_rx"]
    with pytest.raises(SystemExit):
        main(["--manifest", str(tmp_path / "nope.json"), *argv])
    assert "nope.json" in capsys.readouterr().err


@pytest.mark.parametrize("fraction", [0.1, 0.95, float("nan")])
def test_heldout_rmse_refuses_a_train_fraction_out_of_range(fraction):
    data = d.from_batch(fcc_env.simulate_episodes([0], 200))
    with pytest.raises(ValueError, match="train_fraction"):
        d.heldout_rmse(data, train_fraction=fraction)
