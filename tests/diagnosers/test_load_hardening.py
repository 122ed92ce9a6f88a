"""``Diagnoser.load`` on hostile directories: it neither hangs, nor exhausts memory, nor loads a
detector that can never alarm; every refusal is a ``ValueError`` naming the file.

The campaign by root cause: special files where a saved file belongs (FIFO, ``/dev/zero``),
files over their caps on disk or once inflated, configs outside the diagnosers' own parameter
ranges, and non-finite learned state. Oversized files are sparse (no disk is used) and zip
bombs only *declare* their sizes, so every case runs in milliseconds.
"""

from __future__ import annotations

import io
import json
import os
import shutil
import struct
import zipfile
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
import torch

import diagnosers
from diagnosers import Diagnoser
from fcc_common.safe_files import (
    MAX_FILE_BYTES,
    MAX_INFLATED_BYTES,
    UnsafeFileError,
    check_zip_members,
    load_npz,
    read_bytes,
)


@pytest.fixture(scope="module")
def saved(
    tmp_path_factory: pytest.TempPathFactory, fast_fitted: dict[str, Diagnoser]
) -> dict[str, Path]:
    """Every registered diagnoser, fitted with its fast parameters (tests/diagnosers/conftest.py)
    and saved once."""
    root = tmp_path_factory.mktemp("saved")
    return {name: d.save(root / name) for name, d in fast_fitted.items()}


def _copy(saved: dict[str, Path], name: str, tmp_path: Path) -> Path:
    return Path(shutil.copytree(saved[name], tmp_path / name))


def _fifo(p: Path) -> None:
    p.unlink()
    os.mkfifo(p)


def _dev_zero(p: Path) -> None:
    p.unlink()
    p.symlink_to("/dev/zero")


def _sparse(size: int) -> Callable[[Path], None]:
    def make(p: Path) -> None:
        with p.open("r+b") as fh:
            fh.truncate(size)  # a hole: no disk used, but stat reports the size

    return make


def _dir(p: Path) -> None:
    p.unlink()
    p.mkdir()


# ---- special files and files over their caps -------------------------------------------------
SPECIAL = [
    ("limits", "state.npz", _fifo, "FIFO"),
    ("limits", "config.json", _fifo, "FIFO"),
    ("lrgf-mem", "weights.pt", _fifo, "FIFO"),
    ("lrgf-mem", "models.json", _fifo, "FIFO"),
    ("lrgf-mem", "models.json", _dev_zero, "character device"),
    ("lrgf-mem", "weights.pt", _dev_zero, "character device"),
    ("limits", "config.json", _dev_zero, "character device"),
    ("limits", "state.npz", _dev_zero, "character device"),
    ("limits", "state.npz", _dir, "directory"),
    ("limits", "state.npz", _sparse(MAX_FILE_BYTES + 1), "over the cap"),
    ("lrgf-mem", "weights.pt", _sparse(MAX_FILE_BYTES + 1), "over the cap"),
    ("lrgf-mem", "models.json", _sparse(16 * 2**20 + 1), "over the cap"),
    ("limits", "config.json", _sparse(16 * 2**20 + 1), "over the cap"),
]


@pytest.mark.parametrize(
    ("name", "file", "spoil", "match"),
    SPECIAL,
    ids=[f"{n}-{f}-{m.replace(' ', '_')}" for n, f, _, m in SPECIAL],
)
def test_special_or_oversized_files_are_refused_without_reading(
    saved: dict[str, Path], tmp_path: Path, name: str, file: str, spoil, match: str
) -> None:
    path = _copy(saved, name, tmp_path)
    spoil(path / file)
    with pytest.raises(ValueError, match=match) as e:
        Diagnoser.load(path)
    assert file in str(e.value)


def test_a_file_over_the_cap_is_named_with_its_size_and_the_cap(tmp_path: Path) -> None:
    p = tmp_path / "big.bin"
    p.write_bytes(b"12345")
    with pytest.raises(UnsafeFileError, match=r"big\.bin is 5 bytes, over the cap of 4 bytes"):
        read_bytes(p, max_bytes=4)


# ---- decompression bombs ---------------------------------------------------------------------
def _declare_size(zip_bytes: bytes, size: int) -> bytes:
    """The archive with every member's uncompressed size (local and central header) set to
    ``size``: a bomb's declaration, without a bomb's payload."""
    data = bytearray(zip_bytes)
    for sig, offset in ((b"PK\x03\x04", 22), (b"PK\x01\x02", 24)):
        start = 0
        while (i := data.find(sig, start)) >= 0:
            struct.pack_into("<I", data, i + offset, size)
            start = i + 4
    return bytes(data)


def _npz_bytes(**arrays: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.savez_compressed(buf, **arrays)
    return buf.getvalue()


@pytest.mark.parametrize("declared", [MAX_INFLATED_BYTES + 1, 3 * 2**30, 2**32 - 1])
def test_an_npz_declaring_more_than_the_cap_is_refused_before_inflating(
    saved: dict[str, Path], tmp_path: Path, declared: int
) -> None:
    path = _copy(saved, "limits", tmp_path)
    bomb = _declare_size((path / "state.npz").read_bytes(), declared)
    (path / "state.npz").write_bytes(bomb)
    with pytest.raises(ValueError, match=rf"state\.npz: member .* declares {declared} bytes"):
        Diagnoser.load(path)


def test_an_array_header_larger_than_its_member_is_refused(tmp_path: Path) -> None:
    # numpy allocates the declared shape before reading: 8 GB for a few bytes of file
    member = io.BytesIO()
    np.lib.format.write_array_header_1_0(
        member, {"descr": "<f8", "fortran_order": False, "shape": (10**9,)}
    )
    p = tmp_path / "x.npz"
    with zipfile.ZipFile(p, "w", zipfile.ZIP_DEFLATED) as zf:
        zf.writestr("big.npy", member.getvalue() + b"\0" * 64)
    with pytest.raises(UnsafeFileError, match=r"'big\.npy' declares an array of shape"):
        load_npz(p)


def test_a_torch_file_declaring_a_bomb_is_refused(saved: dict[str, Path], tmp_path: Path) -> None:
    path = _copy(saved, "lrgf-mem", tmp_path)
    weights = path / "weights.pt"
    weights.write_bytes(_declare_size(weights.read_bytes(), 3 * 2**30))
    with pytest.raises(ValueError, match=r"weights\.pt: member .* over the cap"):
        Diagnoser.load(path)


def test_members_within_the_cap_pass_and_object_arrays_are_refused(tmp_path: Path) -> None:
    p = tmp_path / "ok.npz"
    p.write_bytes(_npz_bytes(a=np.arange(3.0), s=np.array("text")))
    assert [i.filename for i in check_zip_members(p)] == ["a.npy", "s.npy"]
    back = load_npz(p)
    assert back["a"].tolist() == [0.0, 1.0, 2.0] and str(back["s"]) == "text"
    np.savez(tmp_path / "obj.npz", o=np.array([{"x": 1}], dtype=object))
    with pytest.raises(ValueError, match="allow_pickle"):
        load_npz(tmp_path / "obj.npz")


# ---- configs outside the parameters' ranges --------------------------------------------------
CONFIGS = [
    ("lrgf-mem", "n_hidden", 1e9),
    ("lrgf-mem", "n_hidden", 10**9),
    ("lrgf-mem", "n_hidden", -1),
    ("lrgf-mem", "n_hidden", "many"),
    ("lrgf-mem", "max_epochs", 10**12),
    ("limits", "alpha", 5),
    ("limits", "alpha", None),
    ("pca", "alpha", -0.1),
]


@pytest.mark.parametrize(("name", "key", "value"), CONFIGS)
def test_config_values_go_through_the_parameter_validation(
    saved: dict[str, Path], tmp_path: Path, name: str, key: str, value: object
) -> None:
    path = _copy(saved, name, tmp_path)
    cfg = json.loads((path / "config.json").read_text())
    assert key in cfg["params"]
    cfg["params"][key] = value
    (path / "config.json").write_text(json.dumps(cfg))
    with pytest.raises(ValueError, match=rf"config\.json: {key}=.* is outside the allowed range"):
        Diagnoser.load(path)


# ---- non-finite learned state ----------------------------------------------------------------
def _spoil_state(path: Path, value: float) -> str:
    """Set the first element of the first float array of ``state.npz`` to ``value``."""
    state = load_npz(path / "state.npz")
    key = next(k for k, a in state.items() if a.dtype.kind == "f" and a.size)
    arr = state[key].copy()
    arr.flat[0] = value
    state[key] = arr
    np.savez(path / "state.npz", **state)
    return key


@pytest.mark.parametrize("name", diagnosers.available())
def test_nan_in_the_learned_state_is_refused_naming_the_array(
    saved: dict[str, Path], tmp_path: Path, name: str
) -> None:
    path = _copy(saved, name, tmp_path)
    key = _spoil_state(path, np.nan)
    with pytest.raises(ValueError, match=rf"state\.npz: array '{key}' holds 1 non-finite"):
        Diagnoser.load(path)


@pytest.mark.parametrize("value", [np.inf, -np.inf])
def test_inf_in_the_learned_state_is_refused(
    saved: dict[str, Path], tmp_path: Path, value: float
) -> None:
    path = _copy(saved, "pca", tmp_path)
    key = _spoil_state(path, value)
    with pytest.raises(ValueError, match=rf"array '{key}' holds 1 non-finite"):
        Diagnoser.load(path)


@pytest.mark.parametrize("name", ["lrgf-mem", "lrgf-glr"])
def test_nan_in_torch_weights_is_refused_naming_the_tensor(
    saved: dict[str, Path], tmp_path: Path, name: str
) -> None:
    path = _copy(saved, name, tmp_path)
    tensors = torch.load(path / "weights.pt", weights_only=True)
    key = next(k for k, v in tensors.items() if v.is_floating_point() and v.numel())
    tensors[key].view(-1)[0] = float("nan")
    torch.save(tensors, path / "weights.pt")
    with pytest.raises(ValueError, match=rf"weights\.pt: array '{key}' holds 1 non-finite"):
        Diagnoser.load(path)


def test_the_nested_detector_of_an_isolator_is_checked_too(
    saved: dict[str, Path], tmp_path: Path
) -> None:
    path = _copy(saved, "lrgf-iso", tmp_path)
    _fifo(path / "detector" / "weights.pt")
    with pytest.raises(ValueError, match=r"detector/weights\.pt is a FIFO"):
        Diagnoser.load(path)


# ---- valid directories load as before --------------------------------------------------------
@pytest.mark.parametrize("name", diagnosers.available())
def test_an_untouched_save_loads_and_a_symlinked_file_is_followed(
    saved: dict[str, Path], tmp_path: Path, name: str
) -> None:
    path = _copy(saved, name, tmp_path)
    real = tmp_path / "elsewhere.npz"
    (path / "state.npz").rename(real)
    (path / "state.npz").symlink_to(real)  # a link to a regular file is a regular file
    back = Diagnoser.load(path)
    assert back.name == name and back.channels_


@pytest.mark.parametrize("size", [10**9, 2 * 10**9])
def test_a_huge_size_in_models_json_is_refused_before_allocating(
    saved: dict[str, Path], tmp_path: Path, size: int
) -> None:
    """``models.json`` sizes (n_hidden...) are checked against the number of saved weights
    before anything is built, so an edited size allocates nothing."""
    import json

    path = _copy(saved, "lrgf-mem", tmp_path)
    configs = json.loads((path / "models.json").read_text())
    configs[0]["lrgf"]["n_hidden"] = size
    (path / "models.json").write_text(json.dumps(configs))
    with pytest.raises(ValueError, match=r"more than the \d+ saved weights can hold"):
        Diagnoser.load(path)
