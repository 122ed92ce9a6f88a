"""External data: CSV records as a sweep data source, the Santander FCCU loader, bad input."""

from __future__ import annotations

import dataclasses
import importlib.util
import math
from pathlib import Path

import numpy as np
import pytest

from evaluation.sweep import DiagnoserSpec, SweepConfig, run_sweep
from evaluation.sweep.dataset_loaders import SANTANDER_ONSET, load_santander
from evaluation.sweep.external_data import ExternalData, ExternalFile, read_table

SANTANDER = Path(__file__).resolve().parents[4] / "shared" / "data" / "fccu-santander-mlpse"
COLS = ("u", "y1", "y2")


def _record(rng: np.random.Generator, n: int, step_at: int | None = None) -> np.ndarray:
    """Three channels: an input u and two outputs following it, plus noise; optional y1 step."""
    u = np.repeat(rng.uniform(-1, 1, n // 50 + 1), 50)[:n]
    y1 = 2.0 * u + rng.normal(0, 0.1, n)
    y2 = -u + rng.normal(0, 0.1, n)
    if step_at is not None:
        # y1 stays within ±2.3 when healthy; +10 puts it far outside any healthy limit
        y1[step_at:] += 10.0
    return np.column_stack([np.arange(n), u, y1, y2])


def _write_csv(path: Path, data: np.ndarray, header: bool) -> None:
    text = ",".join(("t", *COLS)) + "\n" if header else ""
    text += "\n".join(",".join(f"{v:.6g}" for v in row) for row in data) + "\n"
    path.write_text(text)


@pytest.fixture
def csv_dir(tmp_path) -> Path:
    rng = np.random.default_rng(7)
    _write_csv(tmp_path / "healthy_a.csv", _record(rng, 400), header=True)
    _write_csv(tmp_path / "healthy_b.csv", _record(rng, 400), header=True)
    _write_csv(tmp_path / "normal_run.csv", _record(rng, 300), header=True)
    _write_csv(tmp_path / "fault_step.csv", _record(rng, 300, step_at=120), header=True)
    return tmp_path


def _data(d: Path, **kw) -> ExternalData:
    base = dict(
        directory=str(d),
        inputs=("u",),
        outputs=("y1", "y2"),
        train_files=("healthy_a.csv", "healthy_b.csv"),
        test_files=(ExternalFile("normal_run.csv"), ExternalFile("fault_step.csv", 120, "step")),
        sample_time_s=2.0,
    )
    return ExternalData(**{**base, **kw})


def test_csv_sweep_trains_on_healthy_and_scores_faults(csv_dir) -> None:
    data = _data(csv_dir)
    assert data.cells() == [("normal_run", 0), ("step", 0)]
    eps = data.train_episodes()
    assert [ep.n_samples for ep in eps] == [400, 400] and eps[0].channels == ("u", "y1", "y2")
    cfg = SweepConfig(diagnosers=(DiagnoserSpec("limits", {"channels": ["y1"]}),), data=data)
    res = run_sweep(cfg, csv_dir / "store", n_workers=0, progress=False)
    normal, step = res.records
    assert normal.scenario == "normal_run" and normal.fault_onset is None
    assert normal.r_fd < 0.05 and math.isnan(normal.r_td)
    assert step.scenario == "step" and step.fault_onset == 120 and step.n_fault_samples == 180
    # the step leaves the healthy range: detected at once, always in alarm after it
    assert step.t_dt == 0.0 and step.r_td > 0.95 and step.r_fd < 0.05
    assert step.t_dt_s == 0.0 and step.sample_time_s == 2.0


def test_headerless_csv_with_column_names(tmp_path) -> None:
    rng = np.random.default_rng(1)
    _write_csv(tmp_path / "h.csv", _record(rng, 50), header=False)
    y = read_table(tmp_path / "h.csv", ("y2", "u"), column_names=("t", *COLS))
    ref = np.loadtxt(tmp_path / "h.csv", delimiter=",")
    np.testing.assert_allclose(y, ref[:, [3, 1]])


def test_changed_file_changes_the_store_key(csv_dir) -> None:
    before = _data(csv_dir).store_key()
    with (csv_dir / "fault_step.csv").open("a") as fh:
        fh.write("300,0,0,0\n")
    assert _data(csv_dir).store_key()["sha256"] != before["sha256"]


@pytest.mark.parametrize(
    ("change", "match"),
    [
        ({"directory": "/no/such/dir"}, "does not exist or is not a directory"),
        ({"train_files": ("missing.csv",)}, "missing.csv.* does not exist"),
        ({"train_files": ()}, "at least one healthy"),
        ({"outputs": ()}, "at least one column"),
        ({"outputs": ("u", "y1")}, "distinct"),
        ({"train_files": ("healthy_a.csv", "normal_run.csv")}, "both training and test"),
        ({"test_files": (ExternalFile("fault_step.csv", -3),)}, "onset=-3"),
        (
            {"test_files": (ExternalFile("normal_run.csv"), ExternalFile("normal_run.csv"))},
            "repeat",
        ),
    ],
)
def test_bad_description(csv_dir, change: dict, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        _data(csv_dir, **change).validate()


def test_bad_files(csv_dir) -> None:
    with pytest.raises(ValueError, match=r"unknown column\(s\) \['zz'\]. Available"):
        read_table(csv_dir / "healthy_a.csv", ("u", "zz"))
    (csv_dir / "text.csv").write_text("t,u\n0,1\n1,abc\n")
    with pytest.raises(ValueError, match="could not read numeric data"):
        read_table(csv_dir / "text.csv", ("u",))
    (csv_dir / "hole.csv").write_text("t,u\n0,1\n1,nan\n")
    with pytest.raises(ValueError, match="non-finite value at data row 1"):
        read_table(csv_dir / "hole.csv", ("u",))
    (csv_dir / "x.txt").write_text("t,u\n0,1\n")
    with pytest.raises(ValueError, match="unsupported file type"):
        read_table(csv_dir / "x.txt", ("u",))
    late = _data(csv_dir, test_files=(ExternalFile("fault_step.csv", 5000),))
    with pytest.raises(ValueError, match="beyond the record's 300 samples"):
        late.load_test("fault_step", 0)
    with pytest.raises(ValueError, match="Unknown test record 'nope'"):
        _data(csv_dir).load_test("nope", 0)


@pytest.mark.skipif(
    importlib.util.find_spec("pyarrow") is not None, reason="pyarrow installed: no error expected"
)
def test_parquet_without_pyarrow_says_so(tmp_path) -> None:
    (tmp_path / "r.parquet").write_bytes(b"PAR1")
    with pytest.raises(ImportError, match="needs pyarrow"):
        read_table(tmp_path / "r.parquet", ("u",))


# ---- the third-party Santander FCCU data ---------------------------------------------------------
needs_santander = pytest.mark.skipif(not SANTANDER.is_dir(), reason=f"{SANTANDER} not present")


@needs_santander
def test_santander_description() -> None:
    data = load_santander(SANTANDER)
    data.validate()
    assert len(data.channels) == 46 and "time" not in data.channels
    assert {"F3", "Tatm", "T1", "V2", "V6"} <= set(data.inputs) and "Tr" in data.outputs
    assert data.train_files == ("NOC_varyingFeedFlow_outputs.csv",)
    onsets = {tf.key: tf.onset for tf in data.test_files}
    assert onsets.pop("NOC_stableFeedFlow") is None
    assert set(onsets) == {
        "CAB_valveLeak",
        "deltaP_increase",
        "UAf_decrease",
        "condEff_decrease",
        "Fhn_sensorDrift",
    }
    assert set(onsets.values()) == {SANTANDER_ONSET}
    assert data.sample_time_s == 60.0


@needs_santander
def test_santander_onset_matches_the_data_evidence() -> None:
    """The documented onset: deltaP's noise-free pressure channels first move at row 120."""
    y = read_table(
        SANTANDER / "deltaP_increase_outputs.csv",
        ("P4", "deltaP"),
        column_names=load_santander(SANTANDER).column_names,
    )
    first_change = [int(np.argmax(y[:, j] != y[0, j])) for j in range(2)]
    assert first_change == [SANTANDER_ONSET, SANTANDER_ONSET]


@needs_santander
def test_santander_sweep(tmp_path) -> None:
    data = load_santander(SANTANDER)
    data = dataclasses.replace(
        data,
        test_files=tuple(
            tf for tf in data.test_files if tf.key in ("NOC_stableFeedFlow", "deltaP_increase")
        ),
    )
    cfg = SweepConfig(diagnosers=(DiagnoserSpec("pca"),), data=data)
    res = run_sweep(cfg, tmp_path / "s", n_workers=0, progress=False)
    healthy, fault = res.records
    assert healthy.n_samples == 2880 and healthy.r_fd < 0.1
    # the pressure-drop fault moves the reactor pressure, constant in training (to round-off,
    # so at scale 1 as in the data set authors' recipe): PCA sees it late, 158 samples (the
    # authors' recipe flags 0.354 of the last 720 samples)
    assert fault.n_samples == 1440 and fault.t_dt < 200 and fault.r_td > 10 * healthy.r_fd
    bad = load_santander(SANTANDER, onset=5000)
    with pytest.raises(ValueError, match="beyond the record"):
        bad.load_test("CAB_valveLeak", 0)


def test_santander_loader_errors(tmp_path) -> None:
    with pytest.raises(ValueError, match="does not exist"):
        load_santander(tmp_path / "nope")
    with pytest.raises(ValueError, match=r"no columns\.csv"):
        load_santander(tmp_path)


def test_manifest_directory_end_to_end(tmp_path):
    """A user's own directory, described by dataset.json, through the leaderboard CLI."""
    import json

    from evaluation.leaderboard import main
    from evaluation.sweep.dataset_loaders import load_external

    rng = np.random.default_rng(3)
    header = "u,y1,y2"
    for name, step in (("healthy.csv", None), ("normal.csv", None), ("fault.csv", 200)):
        np.savetxt(tmp_path / name, _record(rng, 400, step), delimiter=",", header=header,
                   comments="")  # fmt: skip
    manifest = {
        "inputs": ["u"],
        "outputs": ["y1", "y2"],
        "train_files": ["healthy.csv"],
        "test_files": [{"path": "normal.csv", "onset": None}, {"path": "fault.csv", "onset": 200}],
        "sample_time_s": 1.0,
        "diagnoser_params": {"arx-band": {"output": "y1", "inputs": ["u"]}},
    }
    (tmp_path / "dataset.json").write_text(json.dumps(manifest))
    data, params = load_external(tmp_path)
    assert data.channels == ("u", "y1", "y2") and params["arx-band"]["output"] == "y1"
    out = tmp_path / "out"
    assert main(["--external", str(tmp_path), "--diagnosers", "limits,arx-band", "--out",
                 str(out), "--no-figures", "--no-progress"]) == 0  # fmt: skip
    rows = (out / "leaderboard.csv").read_text().splitlines()
    assert any(r.startswith("arx-band,fault") for r in rows)


@pytest.mark.parametrize(
    ("content", "match"),
    [
        ("{", "is not valid JSON"),
        ('{"inputs": []}', r"missing field\(s\)"),
        (
            '{"inputs": [], "outputs": [], "train_files": [], "test_files": [], "x": 1}',
            "unknown field",
        ),
    ],
)
def test_bad_manifest(tmp_path, content, match):
    from evaluation.sweep.dataset_loaders import load_external

    (tmp_path / "dataset.json").write_text(content)
    with pytest.raises(ValueError, match=match):
        load_external(tmp_path)


def test_directory_without_manifest(tmp_path):
    from evaluation.sweep.dataset_loaders import load_external

    with pytest.raises(ValueError, match=r"neither a dataset\.json manifest"):
        load_external(tmp_path)


def _generated_dir(tmp_path: Path) -> Path:
    """Two of the project's own multi-episode files described by a manifest."""
    import json

    from fcc_env.generate import write_dataset

    write_dataset(tmp_path / "train.csv", seeds=[10, 11, 12], n_samples=50)
    write_dataset(tmp_path / "test.csv", scenario="f2", seeds=[1, 2], n_samples=50, fault_time=20)
    manifest = {
        "inputs": ["cmd_u_F", "cmd_R_ar", "T_ar", "T_fp"],
        "outputs": ["R_ar", "T_rx", "T_rg1", "T_rg2", "T_d1", "T_dg"],
        "train_files": ["train.csv"],
        "test_files": [{"path": "test.csv", "onset": 20, "name": "f2"}],
        "sample_time_s": 10,
    }
    (tmp_path / "dataset.json").write_text(json.dumps(manifest))
    return tmp_path


def test_episode_column_splits_a_multi_episode_file(tmp_path) -> None:
    from evaluation.sweep.dataset_loaders import load_external

    data, _ = load_external(_generated_dir(tmp_path))
    train = data.train_episodes()
    assert [ep.n_samples for ep in train] == [50, 50, 50] and [ep.seed for ep in train] == [0, 1, 2]
    assert data.cells() == [("f2", 0), ("f2", 1)]
    loaded = data.load_test("f2", 1)
    assert loaded.episode.n_samples == 50 and loaded.episode.fault_onset == 20
    import fcc_env

    batch = fcc_env.simulate_episodes([2], 50, fault=fcc_env.FaultSpec(scenario="f2", onset=20))
    j = data.channels.index("T_rx")
    np.testing.assert_allclose(
        loaded.episode.y[:, j], batch.observations[0, :, fcc_env.MEASUREMENT_NAMES.index("T_rx")],
        rtol=1e-9,
    )  # fmt: skip
    with pytest.raises(ValueError, match="has no episode 5"):
        data.load_test("f2", 5)
    # without the episode column the file is one record, as before
    one = dataclasses.replace(data, episode_column=None)
    assert one.cells() == [("f2", 0)] and [ep.n_samples for ep in one.train_episodes()] == [150]
    assert data.store_key()["episode_column"] == "episode" and one.store_key() != data.store_key()


def test_manifest_episode_column_must_be_a_name(tmp_path) -> None:
    import json

    from evaluation.sweep.dataset_loaders import load_manifest

    d = _generated_dir(tmp_path)
    spec = json.loads((d / "dataset.json").read_text())
    (d / "other.json").write_text(json.dumps({**spec, "episode_column": 3}))
    with pytest.raises(ValueError, match=r"other\.json: episode_column=3 is outside"):
        load_manifest(d / "other.json")
    (d / "other.json").write_text(json.dumps({**spec, "episode_column": None}))
    data, _ = load_manifest(d / "other.json")  # a manifest file of any name
    assert data.episode_column is None and data.directory == str(d)
