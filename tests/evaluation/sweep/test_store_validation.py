"""The result store checks what it reads and confines what it writes.

The campaign by root cause: cell records out of range or filed in the wrong folder, a reused
model whose ``config.json`` was edited under an unchanged hash, symbolic links inside the store
that would send new files outside it, and special files where a store file belongs.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

import diagnosers
from diagnosers.conformance import default_episodes
from evaluation.sweep.store import ResultStore, StoreError

KEY = {"kind": "test", "n_samples": 100}
GOOD = {
    "diagnoser": "limits",
    "diagnoser_name": "limits",
    "scenario": "f1",
    "seed": 3,
    "fault_onset": 50,
    "n_samples": 100,
    "n_samples_planned": 100,
    "n_fault_samples": 50,
    "terminated_at": None,
    "termination_reason": None,
    "r_fd": 0.0,
    "r_td": 1.0,
    "t_dt": 0.0,
    "t_dt_s": 0.0,
    "n_alarms": 50,
    "sample_time_s": 10.0,
    "detect_wall_s": 0.01,
    "t_it": None,
    "cdr": None,
}


def _store_with_cell(tmp_path: Path, text_edit: tuple[str, str] | None = None, **edit) -> Path:
    st = ResultStore.open(tmp_path / "s", KEY)
    path = st.write_cell("limits", "f1", 3, "h1", {**GOOD, **edit})
    if text_edit is not None:  # tokens json.dumps never writes for a valid record
        path.write_text(path.read_text().replace(*text_edit))
    return path


def test_a_valid_record_with_undefined_scores_is_read_back(tmp_path: Path) -> None:
    _store_with_cell(tmp_path, r_td=None, t_dt=float("nan"))
    rec = ResultStore.open(tmp_path / "s", KEY).read_cell("limits", "f1", 3, "h1")
    assert rec is not None and rec["t_dt"] is None and rec["r_fd"] == 0.0


OUT_OF_RANGE = [
    ({"r_fd": 5}, "r_fd=5 is outside"),
    ({"r_fd": -3}, "r_fd=-3 is outside"),
    ({"r_td": 1.5}, "r_td=1.5 is outside"),
    ({"cdr": -0.01}, "cdr=-0.01 is outside"),
    ({"t_dt": -1.0}, "t_dt=-1.0 is outside"),
    ({"t_dt_s": -10.0}, "t_dt_s=-10.0 is outside"),
    ({"n_alarms": -2}, "n_alarms=-2 is outside"),
    ({"n_samples": 1.5}, "n_samples=1.5 is outside"),
    ({"fault_onset": -5}, "fault_onset=-5 is outside"),
    ({"sample_time_s": 0.0}, "sample_time_s=0.0 is outside"),
    ({"detect_wall_s": -1.0}, "detect_wall_s=-1.0 is outside"),
]


@pytest.mark.parametrize(("edit", "match"), OUT_OF_RANGE, ids=[m for _, m in OUT_OF_RANGE])
def test_scores_out_of_range_are_refused_naming_file_and_value(
    tmp_path: Path, edit: dict, match: str
) -> None:
    path = _store_with_cell(tmp_path, **edit)
    st = ResultStore.open(tmp_path / "s", KEY)
    with pytest.raises(StoreError, match=match) as e:
        st.read_cell("limits", "f1", 3, "h1")
    assert str(path) in str(e.value) and "delete" in str(e.value)


@pytest.mark.parametrize("token", ["NaN", "Infinity", "-Infinity"], ids=["nan", "inf", "minus-inf"])
def test_non_standard_number_tokens_are_refused(tmp_path: Path, token: str) -> None:
    # the writer stores nan as null: a NaN token was written by someone else
    _store_with_cell(tmp_path, text_edit=('"r_fd": 0.0', f'"r_fd": {token}'))
    st = ResultStore.open(tmp_path / "s", KEY)
    with pytest.raises(StoreError, match=f"non-standard JSON number {token}"):
        st.read_cell("limits", "f1", 3, "h1")


@pytest.mark.parametrize(
    ("edit", "match"),
    [
        ({"scenario": "f2"}, "scenario='f2' does not match"),
        ({"seed": 4}, "seed=4 does not match"),
        ({"seed": True}, "seed=True does not match"),
        ({"diagnoser": "pca"}, "diagnoser='pca' does not match"),
    ],
)
def test_a_record_filed_in_another_folder_is_refused(
    tmp_path: Path, edit: dict, match: str
) -> None:
    _store_with_cell(tmp_path, **edit)
    with pytest.raises(StoreError, match=match):
        ResultStore.open(tmp_path / "s", KEY).read_cell("limits", "f1", 3, "h1")


def test_a_moved_cell_file_is_refused(tmp_path: Path) -> None:
    path = _store_with_cell(tmp_path)
    other = path.parent.parent / "f2" / "seed-3.json"
    other.parent.mkdir()
    path.rename(other)
    with pytest.raises(StoreError, match="scenario='f1' does not match"):
        ResultStore.open(tmp_path / "s", KEY).read_cell("limits", "f2", 3, "h1")


@pytest.mark.parametrize("kind", ["fifo", "dev-zero"])
def test_a_special_file_in_place_of_a_store_file_is_refused(tmp_path: Path, kind: str) -> None:
    st = ResultStore.open(tmp_path / "s", KEY)
    spec = tmp_path / "s" / "models" / "pca" / "spec.json"
    spec.parent.mkdir(parents=True)
    if kind == "fifo":
        os.mkfifo(spec)
    else:
        spec.symlink_to("/dev/zero")
    with pytest.raises(StoreError, match=r"spec\.json is a (FIFO|character device)"):
        st.has_model("pca", "m1")


# ---- a reused model must still be the model its hash stands for ------------------------------
@pytest.fixture(scope="module")
def limits_files() -> dict[str, bytes]:
    train, _, _ = default_episodes(n_train=600, n_test=300)
    d = diagnosers.make("limits").fit(train)
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        d.save(tmp)
        return {p.name: p.read_bytes() for p in Path(tmp).iterdir()}


SPEC = {"name": "limits", "params": {}, "label": "limits"}


def _edit_config(d: Path, edit) -> None:
    cfg = json.loads((d / "config.json").read_text())
    edit(cfg)
    (d / "config.json").write_text(json.dumps(cfg))


@pytest.mark.parametrize(
    ("edit", "match"),
    [
        (lambda c: c["params"].update(alpha=0.2), "hyperparameters .* are not those"),
        (lambda c: c["params"].update(alpha=5), "alpha=5 is outside the allowed range"),
        (lambda c: c.update(diagnoser="pca"), "'pca' is not the 'limits'"),
        (lambda c: c["params"].update(bogus=1), r"Unknown hyperparameter\(s\) \['bogus'\]"),
        (lambda c: c.pop("params"), "params None are missing"),
    ],
    ids=["other-alpha", "alpha-out-of-range", "renamed", "unknown-param", "no-params"],
)
def test_an_edited_model_config_is_not_reused(
    tmp_path: Path, limits_files: dict[str, bytes], edit, match: str
) -> None:
    st = ResultStore.open(tmp_path / "s", KEY)
    d = st.write_model("limits", "m1", limits_files, SPEC)
    assert st.has_model("limits", "m1")
    _edit_config(d, edit)
    with pytest.raises(StoreError, match=match) as e:
        st.has_model("limits", "m1")
    assert "config.json" in str(e.value) and "retrain" in str(e.value)


def test_a_model_without_config_is_not_reused(
    tmp_path: Path, limits_files: dict[str, bytes]
) -> None:
    st = ResultStore.open(tmp_path / "s", KEY)
    d = st.write_model("limits", "m1", limits_files, SPEC)
    (d / "config.json").unlink()
    with pytest.raises(StoreError, match=r"has no config\.json"):
        st.has_model("limits", "m1")


def test_the_same_values_in_another_json_form_are_still_the_same_model(
    tmp_path: Path, limits_files: dict[str, bytes]
) -> None:
    st = ResultStore.open(tmp_path / "s", KEY)
    alpha = json.loads(limits_files["config.json"])["params"]["alpha"]
    d = st.write_model("limits", "m1", limits_files, {**SPEC, "params": {"alpha": alpha}})
    _edit_config(d, lambda c: c.update(params={}))  # defaults spelt out or left out: same
    assert st.has_model("limits", "m1")


# ---- every path the store uses stays below its root ------------------------------------------
@pytest.mark.parametrize(
    "link", ["cells", "cells/limits", "cells/limits/f1", "detections/limits", "models"]
)
def test_a_symlinked_directory_inside_the_store_is_refused_by_name(
    tmp_path: Path, link: str
) -> None:
    st = ResultStore.open(tmp_path / "s", KEY)
    outside = tmp_path / "outside"
    outside.mkdir()
    where = tmp_path / "s" / link
    where.parent.mkdir(parents=True, exist_ok=True)
    where.symlink_to(outside, target_is_directory=True)
    with pytest.raises(StoreError, match=rf"{where} is a symbolic link inside the store"):
        if link.startswith("cells"):
            st.write_cell("limits", "f1", 3, "h1", GOOD)
        elif link.startswith("detections"):
            st.write_detection("limits", "f1", 3, "h1", {})
        else:
            st.write_model("limits", "m1", {"config.json": b"{}"}, {})
    assert not any(outside.iterdir())  # nothing landed outside the store


def test_a_symlinked_cell_file_is_not_read(tmp_path: Path) -> None:
    st = ResultStore.open(tmp_path / "s", KEY)
    foreign = st.write_cell("limits", "f1", 4, "h1", {**GOOD, "seed": 4})
    link = foreign.with_name("seed-3.json")
    link.symlink_to(foreign)
    with pytest.raises(StoreError, match="is a symbolic link inside the store"):
        st.read_cell("limits", "f1", 3, "h1")


def test_a_store_reached_through_a_symlinked_root_works(tmp_path: Path) -> None:
    (tmp_path / "real").mkdir()
    (tmp_path / "alias").symlink_to(tmp_path / "real", target_is_directory=True)
    st = ResultStore.open(tmp_path / "alias", KEY)
    path = st.write_cell("limits", "f1", 3, "h1", GOOD)
    assert path.resolve().is_relative_to((tmp_path / "real").resolve())
    assert st.read_cell("limits", "f1", 3, "h1") == GOOD
