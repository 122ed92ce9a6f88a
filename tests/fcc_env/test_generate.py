"""Dataset export: content equals the batch simulation, sidecar roles, CLI errors."""

from __future__ import annotations

import json

import numpy as np
import pytest

import fcc_env
from fcc_env.generate import main, parse_seeds, read_dataset, write_dataset


def test_write_and_read_dataset_round_trip(tmp_path):
    path = write_dataset(
        tmp_path / "f4.csv", scenario="f4", seeds=[3, 5], n_samples=120, fault_time=60
    )
    meta, cols = read_dataset(path)
    assert meta["scenario"] == "f4" and meta["seeds"] == [3, 5]
    assert meta["fault_onsets"] == [60, 60] and meta["model_version"] == fcc_env.MODEL_VERSION
    assert meta["roles"]["measured"] == list(fcc_env.MEASUREMENT_NAMES)
    assert meta["roles"]["commanded"] == ["cmd_u_F", "cmd_R_ar"]
    assert "fault_active" in meta["roles"]["truth"]
    batch = fcc_env.simulate_episodes([3, 5], 120, fault=fcc_env.FaultSpec(scenario="f4", onset=60))
    for i, name in enumerate(fcc_env.MEASUREMENT_NAMES):
        got = cols[name].reshape(2, 120)
        np.testing.assert_allclose(got, batch.observations[:, :, i], rtol=1e-9)
    np.testing.assert_array_equal(cols["fault_active"].reshape(2, 120), batch.fault_active)
    np.testing.assert_allclose(cols["in_T_fp"].reshape(2, 120), batch.inputs[:, :, 3])
    assert not list(tmp_path.glob("*.tmp"))


def test_cli_writes_files(tmp_path, capsys):
    out = tmp_path / "nominal.csv"
    argv = ["--out", str(out), "--seeds", "0-1", "--samples", "30", "--states"]
    assert main([*argv, "--plant-effect", "sensor_bias:T_rx,bias=2"]) == 0
    meta = json.loads(out.with_suffix(".json").read_text())
    assert meta["truth_plant_effects"] == [{"id": "sensor_bias:T_rx", "params": {"bias": 2.0}}]
    assert "x_W_sp" in meta["columns"] and meta["n_samples"] == 30
    assert "wrote" in capsys.readouterr().out


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (
            ["--seeds", "a-b"],
            "seeds='a-b' is outside the allowed range: integers and ranges like '0-9,20' (bad piece 'a-b')",
        ),
        (["--scenario", "f7"], "scenario='f7' is outside the allowed range: one of ['nominal'"),
        (["--samples", "1"], "n_samples=1 is outside the allowed range: an integer in [2, inf)"),
        (["--fault-magnitude", "2", "--scenario", "f1"], "fault_magnitude=2.0 is outside"),
        (["--plant-effect", "heat_loss:riser"], "Unknown plant effect 'heat_loss:riser'"),
    ],
)
def test_cli_bad_input(tmp_path, capsys, argv, message):
    with pytest.raises(SystemExit) as e:
        main(["--out", str(tmp_path / "x.csv"), *argv])
    assert e.value.code == 2
    assert message in capsys.readouterr().err


def test_parse_seeds_and_read_errors(tmp_path):
    assert parse_seeds("0-3,7") == [0, 1, 2, 3, 7]
    with pytest.raises(ValueError, match="does not exist"):
        read_dataset(tmp_path / "missing.csv")
    (tmp_path / "a.csv").write_text("x\n1\n")
    (tmp_path / "a.json").write_text('{"format": "other"}')
    with pytest.raises(ValueError, match="not an FCC dataset sidecar"):
        read_dataset(tmp_path / "a.csv")
    # .parquet is a dataset format now (test_parquet_dataset_equals_the_csv_one)
    with pytest.raises(
        ValueError,
        match=r"a\.xlsx' is outside the allowed range: a file name ending in one of "
        r"\['\.csv', '\.parquet', '\.pq'\]",
    ):
        write_dataset(tmp_path / "a.xlsx")


def test_sidecar_records_fault_and_plant_and_null_for_no_termination(tmp_path):
    spec = fcc_env.FaultSpec(scenario="f2", onset=10, profile="incipient", ramp_samples=5)
    plant = fcc_env.PlantConfig.build(noise_scale=0.0)
    path = write_dataset(tmp_path / "d.csv", fault=spec, plant=plant, seeds=[1], n_samples=20)
    meta, cols = read_dataset(path)
    assert meta["terminated_at"] == [None]
    assert meta["fault"] == spec.to_json() and meta["scenario"] == "f2"
    assert meta["plant"]["noise_scale"] == 0.0 and meta["plant"]["params"] is None
    ref = fcc_env.simulate_episodes([1], 20, fault=fcc_env.FaultSpec(scenario="f2", onset=10, profile="incipient", ramp_samples=5), plant=fcc_env.PlantConfig.build(noise_scale=0.0))  # fmt: skip
    np.testing.assert_array_equal(cols["fault_active"], ref.fault_active[0])


def test_parse_seeds_rejects_negative_seeds():
    with pytest.raises(ValueError, match=r"seeds=\[-1\] is outside the allowed range: a non-empty"):
        parse_seeds("-1")


# --- data formats (issue "A library people can plug into", item 4) ----------------------------

needs_pyarrow = pytest.mark.skipif(
    __import__("importlib").util.find_spec("pyarrow") is None, reason="pyarrow not installed"
)


def test_sidecar_columns_give_unit_description_role_and_null_for_none(tmp_path):
    path = write_dataset(tmp_path / "n.csv", seeds=[0, 1], n_samples=40, include_states=True)
    meta, cols = read_dataset(path)
    assert meta["format_version"] == 2
    assert list(meta["columns"]) == list(cols)  # names, in file order, as before
    assert meta["columns"]["T_rx"]["unit"] == "°C" and meta["columns"]["T_rx"]["role"] == "measured"
    assert meta["columns"]["R_ar"]["unit"] == "t/h"
    assert meta["columns"]["cmd_u_F"]["role"] == "commanded"
    assert meta["columns"]["x_C1"] == {
        "unit": "kg/kg",
        "description": "state: stage-1 coke on catalyst",
        "role": "truth",
    }
    for name, info in meta["columns"].items():
        assert set(info) == {"unit", "description", "role"} and info["description"], name
        if info["role"] != "index":
            assert name in meta["roles"][info["role"]], name
    # one convention for "none": null, never -1 (nor 0 for a magnitude)
    assert meta["fault_onsets"] == [None, None] and meta["fault_magnitudes"] == [None, None]
    assert meta["terminated_at"] == [None, None]

    def values(o):
        if isinstance(o, dict):
            for v in o.values():
                yield from values(v)
        elif isinstance(o, list):
            for v in o:
                yield from values(v)
        else:
            yield o

    assert -1 not in list(values(meta))


def test_generated_files_get_normal_permissions(tmp_path):
    import os

    old = os.umask(0o022)
    try:
        main(["--out", str(tmp_path / "p.csv"), "--samples", "20"])
    finally:
        os.umask(old)
    for f in (tmp_path / "p.csv", tmp_path / "p.json"):
        assert f.stat().st_mode & 0o777 == 0o644, (f, oct(f.stat().st_mode))


@needs_pyarrow
def test_parquet_dataset_equals_the_csv_one(tmp_path, capsys):
    import os

    from diagnosers.episode.record import Episode
    from evaluation.discover import load_measured

    kw = dict(scenario="f1", seeds=[2, 4], n_samples=60, fault_time=30)
    csv_meta, csv_cols = read_dataset(write_dataset(tmp_path / "a.csv", **kw))
    old = os.umask(0o022)
    try:
        assert main(["--out", str(tmp_path / "a.parquet"), "--scenario", "f1", "--seeds", "2,4",
                     "--samples", "60", "--fault-time", "30"]) == 0  # fmt: skip
    finally:
        os.umask(old)
    assert "a.parquet" in capsys.readouterr().out
    assert (tmp_path / "a.parquet").stat().st_mode & 0o777 == 0o644
    pq_meta, pq_cols = read_dataset(tmp_path / "a.parquet")
    assert pq_meta == csv_meta and list(pq_cols) == list(csv_cols)
    for n in csv_cols:
        np.testing.assert_allclose(pq_cols[n], csv_cols[n], rtol=1e-9, err_msg=n)
    eps = Episode.from_dataset(tmp_path / "a.parquet")
    assert [e.seed for e in eps] == [2, 4] and eps[0].fault_onset == 30
    m = load_measured(tmp_path / "a.parquet")
    assert m.n_episodes == 2 and m.n_samples == 60


def test_parquet_without_pyarrow_names_the_file_and_the_extra(tmp_path, monkeypatch, capsys):
    import sys

    monkeypatch.setitem(sys.modules, "pyarrow", None)
    monkeypatch.setitem(sys.modules, "pyarrow.parquet", None)
    out = tmp_path / "x.parquet"
    with pytest.raises(SystemExit):
        main(["--out", str(out), "--samples", "20"])
    err = capsys.readouterr().err
    assert f"writing {out} needs pyarrow" in err and "fcc-fault-diagnosis[parquet]" in err
    assert not out.exists() and not out.with_suffix(".json").exists()


def test_unknown_table_suffix_is_refused(tmp_path, capsys):
    with pytest.raises(SystemExit):
        main(["--out", str(tmp_path / "x.xlsx"), "--samples", "20"])
    assert "x.xlsx" in capsys.readouterr().err


def test_closed_loop_dataset_records_the_valve_and_the_set_points(tmp_path, capsys):
    """``--closed-loop``: the columns FCC-closedloop-v0 observes, with roles ``manipulated``
    and ``setpoint``, the env id and the regulatory layer in the sidecar; open-loop sidecars
    have no ``regulatory`` field."""
    path = tmp_path / "cl.csv"
    argv = ["--closed-loop", "--scenario", "f1", "--fault-time", "60", "--seeds", "2,4"]
    assert main([*argv, "--samples", "150", "--out", str(path)]) == 0
    meta, cols = read_dataset(path)
    assert meta["env_id"] == fcc_env.CLOSED_LOOP_ENV_ID
    assert meta["roles"]["manipulated"] == ["u_F", "R_ar"]
    assert meta["roles"]["setpoint"] == ["T_rx_sp", "T_rg1_sp"]
    assert meta["columns"]["u_F"]["role"] == "manipulated" and meta["columns"]["u_F"]["unit"]
    assert meta["plant"]["regulatory"]["T_rx_gain"] == fcc_env.RegulatoryLayer().T_rx_gain
    batch = fcc_env.simulate_episodes(
        [2, 4],
        150,
        fault=fcc_env.FaultSpec(scenario="f1", onset=60),
        plant=fcc_env.PlantConfig.build(regulatory=True),
    )
    for name in ("T_rx", "u_F", "T_rx_sp", "T_rg1_sp"):
        got = cols[name].reshape(2, 150)
        want = batch.observations[:, :, batch.channels.index(name)]
        np.testing.assert_allclose(got, want, rtol=1e-9)
    open_meta, _ = read_dataset(write_dataset(tmp_path / "open.csv", n_samples=20))
    assert "regulatory" not in open_meta["plant"] and "manipulated" not in open_meta["roles"]


def test_closed_loop_dataset_reads_back_as_the_env_observes(tmp_path):
    """``Episode.from_dataset`` of a closed-loop file gives the 11 channels of
    FCC-closedloop-v0 (Table 1, the valve command, the set points), as ``from_batch`` does."""
    from diagnosers import Episode

    path = write_dataset(
        tmp_path / "cl.csv", seeds=[3], n_samples=80, scenario="f2", fault_time=40, regulatory=True
    )
    [ep] = Episode.from_dataset(path)
    [want] = Episode.from_batch(
        fcc_env.simulate_episodes(
            [3],
            80,
            fault=fcc_env.FaultSpec(scenario="f2", onset=40),
            plant=fcc_env.PlantConfig.build(regulatory=True),
        )
    )
    assert ep.channels == want.channels == fcc_env.closed_loop.CLOSED_LOOP_CHANNELS
    np.testing.assert_allclose(ep.y, want.y, rtol=1e-9)
    assert ep.y_clean.shape == ep.y.shape and ep.fault_onset == 40
