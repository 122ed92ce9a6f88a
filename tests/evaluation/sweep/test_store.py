"""Result store: atomic cell files, resume checks, clear errors on corrupted or foreign files."""

from __future__ import annotations

import json

import pytest

from evaluation.sweep import store as store_mod
from evaluation.sweep.store import ResultStore, StoreError, canonical_hash, check_name

KEY = {"kind": "test", "n_samples": 100, "train_seeds": [1000, 1001]}
RECORD = {"diagnoser": "limits", "scenario": "f1", "seed": 3, "r_fd": 0.01, "t_dt": float("nan")}


def test_open_creates_manifest_and_reopens(tmp_path) -> None:
    root = tmp_path / "s"
    st = ResultStore.open(root, KEY)
    manifest = json.loads((root / "sweep.json").read_text())
    assert manifest["format"] == store_mod.STORE_FORMAT
    assert manifest["version"] == store_mod.STORE_VERSION
    assert manifest["data_hash"] == canonical_hash(KEY) == st.data_hash
    assert ResultStore.open(root, dict(KEY)).data_hash == st.data_hash


def test_open_refuses_other_sweep(tmp_path) -> None:
    ResultStore.open(tmp_path / "s", KEY)
    with pytest.raises(StoreError, match="different sweep"):
        ResultStore.open(tmp_path / "s", {**KEY, "n_samples": 200})


def test_open_refuses_non_store_directory(tmp_path) -> None:
    (tmp_path / "notes.txt").write_text("mine")
    with pytest.raises(StoreError, match="not a result store"):
        ResultStore.open(tmp_path, KEY)
    assert (tmp_path / "notes.txt").read_text() == "mine"
    assert not (tmp_path / "sweep.json").exists()


@pytest.mark.parametrize(
    ("content", "match"),
    [("{not json", "not valid JSON"), (json.dumps({"format": "other"}), "foreign")],
)
def test_open_refuses_bad_manifest(tmp_path, content: str, match: str) -> None:
    (tmp_path / "sweep.json").write_text(content)
    with pytest.raises(StoreError, match=match) as e:
        ResultStore.open(tmp_path, KEY)
    assert "sweep.json" in str(e.value)
    assert (tmp_path / "sweep.json").read_text() == content  # left alone


def test_cell_roundtrip_nan_becomes_null(tmp_path) -> None:
    st = ResultStore.open(tmp_path, KEY)
    assert st.read_cell("limits", "f1", 3, "h1") is None
    path = st.write_cell("limits", "f1", 3, "h1", RECORD)
    assert path == tmp_path / "cells" / "limits" / "f1" / "seed-3.json"
    raw = json.loads(path.read_text())  # strict JSON: NaN is written as null
    assert raw["record"]["t_dt"] is None and raw["format"] == store_mod.CELL_FORMAT
    rec = st.read_cell("limits", "f1", 3, "h1")
    assert rec["r_fd"] == 0.01 and rec["t_dt"] is None
    assert list(st.iter_cell_files()) == [path]
    # no temporary file is left next to it
    assert [p.name for p in path.parent.iterdir()] == ["seed-3.json"]


def test_write_never_overwrites(tmp_path) -> None:
    st = ResultStore.open(tmp_path, KEY)
    path = st.write_cell("limits", "f1", 3, "h1", RECORD)
    before = path.read_text()
    with pytest.raises(StoreError, match="never overwrites"):
        st.write_cell("limits", "f1", 3, "h1", {**RECORD, "r_fd": 0.5})
    assert path.read_text() == before


def test_interrupted_write_leaves_no_cell(tmp_path, monkeypatch) -> None:
    st = ResultStore.open(tmp_path, KEY)

    def killed(src, dst):  # the process dies between writing the temp file and renaming it
        raise KeyboardInterrupt

    monkeypatch.setattr(store_mod.os, "replace", killed)
    with pytest.raises(KeyboardInterrupt):
        st.write_cell("limits", "f1", 3, "h1", RECORD)
    monkeypatch.undo()
    assert st.read_cell("limits", "f1", 3, "h1") is None  # no torn file counts as finished
    st.write_cell("limits", "f1", 3, "h1", RECORD)  # and the re-run can write it
    assert st.read_cell("limits", "f1", 3, "h1")["seed"] == 3


@pytest.mark.parametrize(
    ("content", "match"),
    [
        ('{"format": "fcc-sweep-cell", "vers', "not valid JSON"),
        (json.dumps({"format": "someone-else", "version": 1}), "foreign"),
        (json.dumps({"format": "fcc-sweep-cell", "version": 99, "hash": "h1"}), "version 99"),
        (
            json.dumps({"format": "fcc-sweep-cell", "version": 1, "hash": "zz", "record": {}}),
            "other diagnoser settings",
        ),
        (json.dumps({"format": "fcc-sweep-cell", "version": 1, "hash": "h1"}), "no 'record'"),
    ],
)
def test_bad_cell_file_is_a_clear_error(tmp_path, content: str, match: str) -> None:
    st = ResultStore.open(tmp_path, KEY)
    path = st.cell_path("limits", "f1", 3)
    path.parent.mkdir(parents=True)
    path.write_text(content)
    with pytest.raises(StoreError, match=match) as e:
        st.read_cell("limits", "f1", 3, "h1")
    assert str(path) in str(e.value) and "delete" in str(e.value)
    assert path.read_text() == content


def test_models(tmp_path) -> None:
    st = ResultStore.open(tmp_path, KEY)
    assert not st.has_model("pca", "m1")
    d = st.write_model("pca", "m1", {"config.json": b"{}", "sub/w.bin": b"\x00\x01"}, {"x": 1})
    assert st.has_model("pca", "m1")
    assert (d / "sub" / "w.bin").read_bytes() == b"\x00\x01"
    with pytest.raises(StoreError, match="other diagnoser settings"):
        st.has_model("pca", "m2")
    # the same model written again (a concurrent sweep on this store) is accepted as it is
    assert st.write_model("pca", "m1", {}, {}) == d
    assert (d / "sub" / "w.bin").read_bytes() == b"\x00\x01"
    with pytest.raises(StoreError, match="other diagnoser settings"):
        st.write_model("pca", "m2", {}, {})
    # a model directory without its spec (e.g. copied by hand) is refused, not trusted
    (tmp_path / "models" / "lim").mkdir()
    with pytest.raises(StoreError, match=r"no spec\.json"):
        st.has_model("lim", "m1")
    with pytest.raises(ValueError, match="escapes"):
        st.write_model("bad", "m1", {"../evil": b""}, {})
    assert not (tmp_path / "models" / "bad").exists()
    assert not [p for p in (tmp_path / "models").iterdir() if p.name.endswith(".tmp")]


@pytest.mark.parametrize("name", ["../x", "a/b", ".hidden", "", "a b"])
def test_check_name_rejects_unsafe(name: str) -> None:
    with pytest.raises(ValueError, match="path component"):
        check_name("scenario", name)


def test_canonical_hash_is_order_free_and_sensitive() -> None:
    assert canonical_hash({"a": 1, "b": [1, 2]}) == canonical_hash({"b": [1, 2], "a": 1})
    assert canonical_hash({"a": 1}) != canonical_hash({"a": 2})
    assert len(canonical_hash({})) == 64
