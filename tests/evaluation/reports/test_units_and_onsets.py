"""Units travel from the data to every figure and table; assumed onsets are marked (issue 34)."""

from __future__ import annotations

import csv
import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

import diagnosers
import fcc_env
from diagnosers.detection import Detection
from diagnosers.episode.record import Episode
from evaluation.reports.outputs import figure_cells, write_outputs
from evaluation.reports.plots import ASSUMED_ONSET_LABEL, ONSET_LABEL, axis_label, detection_figure
from evaluation.reports.tables import ASSUMED_MARK, ASSUMED_TEXT, table_legend
from evaluation.sweep import DiagnoserSpec, SweepConfig, run_sweep
from evaluation.sweep.dataset_loaders import load_manifest, load_santander
from evaluation.sweep.external_data import ExternalFile
from evaluation.sweep.records import CellResult, pack_detection, unpack_detection
from evaluation.sweep.sources import LoadedEpisode
from fcc_env.closed_loop import RegulatoryLayer
from fcc_env.generate import write_dataset
from fcc_env.plant import PlantConfig

SANTANDER = Path("/work/shared/data/fccu-santander-mlpse")
COLS = ("Frgc", "T2", "Tr", "flag")  # flag: a column the manifest gives no unit


def _ylabels(fig) -> list[str]:
    return [ax.get_ylabel() for ax in fig.get_axes()[:-1]]  # the last axes is the alarm strip


def _legend(fig) -> list[str]:
    return [t.get_text() for leg in fig.legends for t in leg.get_texts()]


def _limits_detection(train: list[Episode], test: Episode, channels: list[str]) -> Detection:
    return diagnosers.make("limits", channels=channels).fit(train).detect(test)


# ---- FCC episodes ---------------------------------------------------------------------------
def test_fcc_figure_takes_its_units_from_the_episode() -> None:
    plant = PlantConfig(regulatory=RegulatoryLayer())
    train = diagnosers.Episode.from_batch(fcc_env.simulate_episodes([1000], 80, plant=plant))
    [test] = diagnosers.Episode.from_batch(fcc_env.simulate_episodes([0], 80, plant=plant))
    assert test.channel_units["u_F"] == "kg/s" and test.channel_units["T_rx"] == "°C"
    det = _limits_detection(train, test, ["R_ar", "T_rx", "u_F"])
    fig = detection_figure(test, det, max_signals=3)
    assert _ylabels(fig) == ["R_ar [t/h]", "T_rx [°C]", "u_F [kg/s]"]
    # units are presentation: the same detection without them
    bare = _limits_detection(
        [dataclasses.replace(e, units=None) for e in train],
        dataclasses.replace(test, units=None),
        ["R_ar", "T_rx", "u_F"],
    )
    np.testing.assert_array_equal(bare.signal, det.signal)
    np.testing.assert_array_equal(bare.alarm, det.alarm)


def test_dataset_files_carry_the_sidecar_units(tmp_path) -> None:
    path = write_dataset(tmp_path / "d.csv", seeds=[0], n_samples=20)
    [ep] = Episode.from_dataset(path)
    assert ep.channel_units["R_ar"] == "t/h" and ep.channel_units["T_dg"] == "°C"


# ---- a Santander-like external directory (°F) -----------------------------------------------
def _write(path: Path, rng: np.random.Generator, n: int, step_at: int | None = None) -> None:
    tr = 969.0 + rng.normal(0, 0.5, n)
    if step_at is not None:
        tr[step_at:] += 20.0
    data = np.column_stack(
        [rng.normal(30, 0.2, n), 600 + rng.normal(0, 0.5, n), tr, rng.normal(0, 1, n)]
    )
    np.savetxt(path, data, delimiter=",", header=",".join(COLS), comments="")


@pytest.fixture
def degf_dir(tmp_path) -> Path:
    rng = np.random.default_rng(3)
    _write(tmp_path / "healthy.csv", rng, 300)
    _write(tmp_path / "normal.csv", rng, 200)
    _write(tmp_path / "leak.csv", rng, 200, step_at=120)
    manifest = {
        "inputs": ["Frgc"],
        "outputs": ["T2", "Tr", "flag"],
        "train_files": ["healthy.csv"],
        "test_files": [
            {"path": "normal.csv", "onset": None},
            {"path": "leak.csv", "onset": 120, "name": "leak", "onset_assumed": True},
        ],
        "sample_time_s": 60,
        "units": {"Frgc": "lb/s", "T2": "°F", "Tr": "degF"},
    }
    (tmp_path / "dataset.json").write_text(json.dumps(manifest))
    return tmp_path


def test_external_figures_are_labelled_in_the_data_units(degf_dir) -> None:
    data, _ = load_manifest(degf_dir)
    assert data.assumed_onsets == ("leak",)
    test = data.load_test("leak", 0).episode
    assert test.units == ("lb/s", "°F", "degF", "")  # flag: unknown, not guessed
    det = _limits_detection(data.train_episodes(), test, ["T2", "Tr", "flag"])
    labels = _ylabels(detection_figure(test, det, max_signals=3))
    assert labels == ["T2 [°F]", "Tr [°F]", "flag"]
    # a band view names its outputs "[°C]" (diagnosers.lrgf.bank_detector): the data's unit wins
    y = test.channel("Tr")[:, None]
    bands = Detection(np.zeros(test.n_samples, bool), y, y - 1, y + 1, 0 * y, ("Tr [°C]",))
    assert _ylabels(detection_figure(test, bands, decisions=det)) == ["Tr [°F]"]
    # Hotelling's T² shares the name of the T2 temperature but is not its values: no °F
    stat = np.abs(y - 969.0) + 1.0
    t2 = Detection(np.zeros(test.n_samples, bool), stat, -np.inf + 0 * y, 9 + 0 * y, stat, ("T2",))
    assert _ylabels(detection_figure(test, t2)) == ["T² [-]"]
    for lab in [*labels, "Tr [°F]"]:
        assert "°C" not in lab and "[?]" not in lab


def test_a_channel_without_a_unit_gets_no_bracket() -> None:
    assert axis_label("flag") == "flag"
    assert axis_label("flag", {"flag": ""}) == "flag"
    assert axis_label("Tr [°C]", {"Tr": ""}) == "Tr"  # a diagnoser's guess is not kept either
    assert axis_label("Tr", {"Tr": "degF"}) == "Tr [°F]"


def test_assumed_onset_is_marked_in_figures_tables_and_records(degf_dir) -> None:
    data, _ = load_manifest(degf_dir)
    test = data.load_test("leak", 0).episode
    det = _limits_detection(data.train_episodes(), test, ["Tr"])
    assert ASSUMED_ONSET_LABEL in _legend(detection_figure(test, det, onset_assumed=True))
    plain = _legend(detection_figure(test, det))
    assert ONSET_LABEL in plain and ASSUMED_ONSET_LABEL not in plain
    assert ASSUMED_TEXT in table_legend(60.0, onset_assumed=True)
    assert ASSUMED_MARK not in table_legend(60.0)

    cfg = SweepConfig(diagnosers=(DiagnoserSpec("limits", {"channels": ["Tr"]}),), data=data)
    res = run_sweep(
        cfg, degf_dir / "store", n_workers=0, progress=False, figure_cells=figure_cells(cfg)
    )
    out = degf_dir / "out"
    written = write_outputs(res, out)
    md = (out / "leaderboard.md").read_text()
    assert f"leak{ASSUMED_MARK} r_td" in md and ASSUMED_TEXT in md
    assert "Assumed fault onsets, not stated by the data: leak (sample 120)" in md
    assert "r_fd (normal)" in md and f"normal{ASSUMED_MARK}" not in md
    with (out / "results.csv").open() as fh:
        flags = {r["scenario"]: r["onset_assumed"] for r in csv.DictReader(fh)}
    assert flags == {"normal": "False", "leak": "True"}
    records = json.loads((out / "results.json").read_text())["records"]
    assert {r["scenario"]: r["onset_assumed"] for r in records} == {"normal": False, "leak": True}
    assert any(p.name == "limits.png" for p in written)


def test_units_and_assumed_onsets_leave_the_store_key_and_old_records_alone(degf_dir) -> None:
    data, _ = load_manifest(degf_dir)
    plain = dataclasses.replace(
        data,
        units=None,
        test_files=tuple(dataclasses.replace(tf, onset_assumed=False) for tf in data.test_files),
    )
    assert plain.store_key() == data.store_key()  # existing stores stay readable
    with pytest.raises(ValueError, match="onset_assumed"):  # a healthy record has no onset
        dataclasses.replace(
            data, test_files=(ExternalFile("normal.csv", onset_assumed=True),)
        ).validate()
    # a record stored before the field existed reads as not assumed
    old = {f.name: getattr(_record(), f.name) for f in dataclasses.fields(CellResult)}
    del old["onset_assumed"]
    assert CellResult.from_json(old).onset_assumed is False
    # figure arrays stored before episodes carried units read back without units
    ep = data.load_test("leak", 0).episode
    det = _limits_detection(data.train_episodes(), ep, ["Tr"])
    arrays = pack_detection(LoadedEpisode(ep, 120, ep.n_samples), det)
    assert unpack_detection(arrays)[0].units == ep.units
    del arrays["units"]
    assert unpack_detection(arrays)[0].units is None


def _record() -> CellResult:
    nan = float("nan")
    return CellResult("limits", "limits", "leak", 0, 120, 200, 200, 80, None, None, 0.0, 1.0,
                      0.0, 0.0, 80, 60.0, 0.01, "", nan, nan, nan, nan)  # fmt: skip


def test_episode_units_are_checked() -> None:
    y = np.zeros((3, 2))
    with pytest.raises(ValueError, match=r"units has 1 entries \['°C'\] for 2 channels"):
        Episode(y, ("a", "b"), 1.0, units=("°C",))
    with pytest.raises(ValueError, match="a sequence of unit strings"):
        Episode(y, ("a", "b"), 1.0, units="°C")
    with pytest.raises(ValueError, match="a sequence of unit strings"):
        Episode(y, ("a", "b"), 1.0, units=("°C", 1))
    assert Episode(y, ("a", "b"), 1.0).units is None  # the default: no units recorded
    assert Episode(y, ("a", "b"), 1.0, units=["°C", ""]).channel_units == {"a": "°C", "b": ""}


# ---- the real Santander data set -----------------------------------------------------------
@pytest.mark.skipif(not (SANTANDER / "columns.csv").is_file(), reason="Santander data absent")
def test_santander_units_come_from_columns_csv() -> None:
    data = load_santander(SANTANDER, outputs=["Tr", "Treg"])
    assert (
        set(data.assumed_onsets) == {tf.key for tf in data.test_files if tf.onset is not None}
        and len(data.assumed_onsets) == 5
    )
    ep = data.load_test(data.assumed_onsets[0], 0).episode
    units = ep.channel_units
    assert units["Tr"] == "degF" and units["F3"] == "lb/s"
    assert axis_label("Tr [°C]", units) == "Tr [°F]"
    assert 900 < float(np.median(ep.channel("Tr"))) < 1100  # °F, not °C
