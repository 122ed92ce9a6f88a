"""Bounded readers for files that may have been tampered with: regular files only, under a cap.

A saved diagnoser or a result store is a directory anyone can edit, so every file read from one
goes through this module. Three ways a plain ``open``/``np.load`` goes wrong on a hostile file,
each closed here once:

* **Hang.** ``open`` on a FIFO blocks until a writer appears. :func:`open_regular` opens with
  ``O_NONBLOCK`` (which makes a FIFO open return at once) and refuses anything whose ``fstat``
  (of the opened descriptor, so after symlinks are resolved and without a check-then-open race)
  is not a regular file: FIFOs, sockets, ``/dev/zero`` and other devices, directories.
* **Unbounded read.** A regular file larger than its cap is refused before a byte is read.
* **Decompression bomb.** An ``.npz`` (or torch zip) member inflates to far more than it
  occupies on disk. :func:`check_zip_members` compares each member's declared uncompressed size
  with a cap before anything is inflated, and :func:`load_npz` also checks each array's declared
  shape against its member, because numpy allocates the declared shape before it reads.

Caps (bytes): :data:`MAX_FILE_BYTES` for a file on disk, :data:`MAX_INFLATED_BYTES` for the
uncompressed members of one archive together. The largest saved diagnoser of this library is a
few MiB, so 512 MiB leaves two orders of magnitude of headroom while still refusing the
gigabytes a hostile file would ask for.

>>> import tempfile, pathlib
>>> p = pathlib.Path(tempfile.mkdtemp()) / "x.json"
>>> _ = p.write_text('{"a": 1}')
>>> read_json(p)
{'a': 1}
>>> read_json(p, max_bytes=4)
Traceback (most recent call last):
...
fcc_common.safe_files.UnsafeFileError: ...x.json is 8 bytes, over the cap of 4 bytes ...
"""

from __future__ import annotations

import io
import json
import math
import os
import stat
import zipfile
from pathlib import Path
from typing import IO, Any

import numpy as np
from numpy.lib import format as npy_format

__all__ = [
    "MAX_FILE_BYTES",
    "MAX_INFLATED_BYTES",
    "UnsafeFileError",
    "check_regular",
    "check_zip_members",
    "load_npz",
    "open_regular",
    "read_bytes",
    "read_json",
    "read_text",
]

#: Largest file (bytes on disk) any reader of this module accepts by default: 512 MiB.
MAX_FILE_BYTES = 512 * 2**20
#: Largest total declared uncompressed size of an archive's members (and so of any one): 512 MiB.
MAX_INFLATED_BYTES = 512 * 2**20


class UnsafeFileError(ValueError):
    """A file is not a regular file, or is larger (on disk or inflated) than its cap."""


def _kind(mode: int) -> str:
    for test, name in (
        (stat.S_ISFIFO, "a FIFO (named pipe)"),
        (stat.S_ISCHR, "a character device"),
        (stat.S_ISBLK, "a block device"),
        (stat.S_ISSOCK, "a socket"),
        (stat.S_ISDIR, "a directory"),
    ):
        if test(mode):
            return name
    return "not a regular file"


def _check_stat(path: Path, st: os.stat_result, max_bytes: int) -> int:
    if not stat.S_ISREG(st.st_mode):
        raise UnsafeFileError(
            f"{path} is {_kind(st.st_mode)}, not a regular file (after resolving symlinks); "
            "refusing to read it: replace it with the file that belongs there"
        )
    if st.st_size > max_bytes:
        raise UnsafeFileError(
            f"{path} is {st.st_size} bytes, over the cap of {max_bytes} bytes for this file; "
            "refusing to read it: it is not a file this library wrote"
        )
    return int(st.st_size)


def check_regular(path: str | os.PathLike, *, max_bytes: int = MAX_FILE_BYTES) -> int:
    """Size in bytes of ``path`` if it is a regular file (symlinks followed) of at most
    ``max_bytes``; raise :class:`UnsafeFileError` naming the file otherwise.

    ``os.stat`` never blocks, even on a FIFO. For a file another library then opens by name
    (``torch.load``) this is the check that can be made; prefer :func:`open_regular`.
    Raises ``FileNotFoundError`` when the file does not exist.
    """
    p = Path(path)
    return _check_stat(p, os.stat(p), max_bytes)


def open_regular(path: str | os.PathLike, *, max_bytes: int = MAX_FILE_BYTES) -> IO[bytes]:
    """Open ``path`` for binary reading if it is a regular file of at most ``max_bytes``.

    Checked twice: ``os.stat`` before opening (a device is never even opened), ``os.fstat`` of
    the opened descriptor after (the file read is the file checked). ``O_NONBLOCK`` keeps the
    open of a FIFO swapped in between from blocking; it has no effect on regular files.
    Raises :class:`UnsafeFileError`, or ``FileNotFoundError`` when the file does not exist.
    """
    p = Path(path)
    check_regular(p, max_bytes=max_bytes)
    fd = os.open(p, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    try:
        _check_stat(p, os.fstat(fd), max_bytes)
        return os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise


def read_bytes(path: str | os.PathLike, *, max_bytes: int = MAX_FILE_BYTES) -> bytes:
    """The content of a regular file of at most ``max_bytes`` (see :func:`open_regular`)."""
    with open_regular(path, max_bytes=max_bytes) as fh:
        data = fh.read(max_bytes + 1)  # +1: a file that grew after the check is still refused
    if len(data) > max_bytes:
        raise UnsafeFileError(f"{path} grew past the cap of {max_bytes} bytes while being read")
    return data


def read_text(path: str | os.PathLike, *, max_bytes: int = MAX_FILE_BYTES) -> str:
    """:func:`read_bytes` decoded as UTF-8 (``UnicodeDecodeError`` on other bytes)."""
    return read_bytes(path, max_bytes=max_bytes).decode("utf-8")


def _refuse_constant(token: str) -> Any:
    raise ValueError(f"the non-standard JSON number {token} (allowed: finite numbers or null)")


def read_json(
    path: str | os.PathLike, *, max_bytes: int = MAX_FILE_BYTES, allow_nan: bool = True
) -> Any:
    """Parse a regular file of at most ``max_bytes`` as JSON.

    ``allow_nan=False`` refuses the ``NaN``/``Infinity`` tokens Python's ``json`` accepts but
    strict JSON (and this project's writer, which stores ``nan`` as ``null``) never produces.
    Raises ``json.JSONDecodeError``/``UnicodeDecodeError``/``ValueError`` on bad content.
    """
    text = read_text(path, max_bytes=max_bytes)
    if allow_nan:
        return json.loads(text)
    return json.loads(text, parse_constant=_refuse_constant)


def check_zip_members(
    source: str | os.PathLike | IO[bytes],
    *,
    max_inflated_bytes: int = MAX_INFLATED_BYTES,
    name: str | os.PathLike | None = None,
) -> list[zipfile.ZipInfo]:
    """The members of the zip archive ``source`` if their declared uncompressed sizes
    (``ZipInfo.file_size``) add up to at most ``max_inflated_bytes``.

    Only the central directory is read: nothing is inflated. A member that claims less than it
    holds cannot bomb either: ``zipfile`` stops inflating at the declared size (and then fails
    its CRC check). Raises :class:`UnsafeFileError` naming the member, or
    ``zipfile.BadZipFile``.
    """
    label = name if name is not None else source
    with zipfile.ZipFile(source) as zf:
        infos = zf.infolist()
    total = 0
    for info in infos:
        total += info.file_size
        if total > max_inflated_bytes:
            raise UnsafeFileError(
                f"{label}: member {info.filename!r} declares {info.file_size} bytes "
                f"uncompressed ({total} bytes with the members before it), over the cap of "
                f"{max_inflated_bytes} bytes; refusing to inflate it (a decompression bomb or "
                "not a file this library wrote)"
            )
    return infos


def _check_npy_header(zf: zipfile.ZipFile, info: zipfile.ZipInfo, label: str) -> None:
    """Refuse a member whose array header declares more bytes than the member holds: numpy
    would allocate the declared shape before finding out."""
    with zf.open(info) as fh:
        try:
            version = npy_format.read_magic(fh)
            if version == (1, 0):
                shape, _, dtype = npy_format.read_array_header_1_0(fh)
            elif version == (2, 0):
                shape, _, dtype = npy_format.read_array_header_2_0(fh)
            else:  # rare UTF-8 headers: the member's own size cap still bounds the data
                return
        except ValueError as e:
            raise UnsafeFileError(f"{label}: member {info.filename!r} is not an array: {e}") from e
    declared = math.prod(shape) * dtype.itemsize
    if declared > info.file_size:
        raise UnsafeFileError(
            f"{label}: member {info.filename!r} declares an array of shape {shape} "
            f"({declared} bytes) but holds {info.file_size} bytes; the file is corrupted"
        )


def load_npz(
    path: str | os.PathLike,
    *,
    max_bytes: int = MAX_FILE_BYTES,
    max_inflated_bytes: int = MAX_INFLATED_BYTES,
) -> dict[str, np.ndarray]:
    """Every array of the ``.npz`` file ``path``, read within the caps, never unpickling.

    The file must be a regular file of at most ``max_bytes``; its members' declared sizes must
    add up to at most ``max_inflated_bytes`` and each array's header must fit its member.
    Raises :class:`UnsafeFileError`, ``FileNotFoundError``, or whatever ``np.load`` raises on a
    corrupted file (``zipfile.BadZipFile``, ``ValueError`` for object arrays, ...).
    """
    with open_regular(path, max_bytes=max_bytes) as fh:
        data = io.BytesIO(fh.read(max_bytes + 1))
    if len(data.getbuffer()) > max_bytes:
        raise UnsafeFileError(f"{path} grew past the cap of {max_bytes} bytes while being read")
    infos = check_zip_members(data, max_inflated_bytes=max_inflated_bytes, name=path)
    with zipfile.ZipFile(data) as zf:
        for info in infos:
            _check_npy_header(zf, info, str(path))
    data.seek(0)
    with np.load(data, allow_pickle=False) as npz:
        return {k: npz[k] for k in npz.files}
