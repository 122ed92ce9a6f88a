"""Issue 32: a manifest reads only files inside its data directory, compares resolved paths,
and refuses a delimiter that is not one character."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest

from evaluation.sweep.dataset_loaders import load_manifest


def _write(path: Path, n: int = 120, seed: int = 0) -> None:
    rng = np.random.default_rng(seed)
    u = rng.uniform(-1, 1, n)
    rows = "\n".join(f"{a:.5f},{2 * a + rng.normal(0, 0.1):.5f}" for a in u)
    path.write_text("u,y\n" + rows + "\n")


def _manifest(d: Path, train: str, test: str, **extra) -> Path:
    spec = {
        "inputs": ["u"],
        "outputs": ["y"],
        "train_files": [train],
        "test_files": [{"path": test, "onset": None}],
        **extra,
    }
    (d / "dataset.json").write_text(json.dumps(spec))
    return d


@pytest.fixture
def data_dir(tmp_path: Path) -> Path:
    d = tmp_path / "data"
    d.mkdir()
    _write(d / "healthy.csv")
    _write(d / "test.csv", seed=1)
    _write(tmp_path / "outside.csv", seed=2)
    return d


@pytest.mark.parametrize(
    "train",
    ["../outside.csv", "ABSOLUTE", "sub/../../outside.csv"],
)
def test_a_file_outside_the_directory_is_refused(data_dir: Path, train: str) -> None:
    if train == "ABSOLUTE":
        train = str(data_dir.parent / "outside.csv")
    with pytest.raises(ValueError, match="outside the allowed range: a file inside the data"):
        load_manifest(_manifest(data_dir, train, "test.csv"))


def test_a_link_leading_out_is_refused_and_its_target_never_echoed(data_dir: Path) -> None:
    secret = data_dir.parent / "secret.csv"
    secret.write_text("TOP-SECRET-FIRST-LINE\n1,2\n")
    os.symlink(secret, data_dir / "link.csv")
    with pytest.raises(ValueError, match="outside the allowed range") as e:
        load_manifest(_manifest(data_dir, "link.csv", "test.csv"))
    assert "TOP-SECRET" not in str(e.value)


@pytest.mark.parametrize("alias", ["./healthy.csv", "sub/../healthy.csv", "alias.csv"])
def test_train_test_overlap_is_found_through_aliases(data_dir: Path, alias: str) -> None:
    (data_dir / "sub").mkdir()
    os.symlink(data_dir / "healthy.csv", data_dir / "alias.csv")
    with pytest.raises(ValueError, match="both training and test records"):
        load_manifest(_manifest(data_dir, "healthy.csv", alias))


@pytest.mark.parametrize("delimiter", ["", ";;", 5])
def test_delimiter_must_be_one_character(data_dir: Path, delimiter) -> None:
    with pytest.raises(ValueError, match=r"delimiter=.* one character"):
        load_manifest(_manifest(data_dir, "healthy.csv", "test.csv", delimiter=delimiter))


def test_a_link_inside_the_directory_is_followed(data_dir: Path) -> None:
    os.symlink(data_dir / "test.csv", data_dir / "linked_test.csv")
    data, _ = load_manifest(_manifest(data_dir, "healthy.csv", "linked_test.csv"))
    assert len(data.train_episodes()) == 1
