"""Result store of a sweep: one JSON file per finished cell, written atomically.

Layout of a store directory (everything is plain JSON or a :meth:`Diagnoser.save` directory)::

    <root>/sweep.json                                 manifest: format tag, version, data hash
    <root>/models/<label>/                            trained diagnoser (Diagnoser.save) + spec.json
    <root>/cells/<label>/<scenario>/seed-<seed>.json  one finished cell
    <root>/detections/<label>/<scenario>/seed-<seed>.npz  the whole detection of a figure cell

Why it is built like this:

* **Atomic writes.** Every file is written to a temporary file in the same directory and moved into
  place with :func:`os.replace`, so a sweep killed at any instant leaves either the complete file
  or none; a re-run finds every finished cell and computes only the missing ones.
* **Hashes, not trust.** The manifest holds the hash of what defines the data (simulation options,
  training seeds or external files); every model and cell file holds the hash of its diagnoser
  specification *and* that data hash. Test seeds and scenarios are deliberately left out of the
  hashes, so a sweep extended with more seeds or another diagnoser reuses what is already there.
* **Never overwrite silently.** A file that is not valid JSON, has another format tag, another
  version or another hash raises :class:`StoreError` naming the file and what to do; the store
  never replaces an existing cell file.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import shutil
import tempfile
import time
import zipfile
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from fcc_common.io import TMP_SUFFIX, atomic_open, atomic_write_json, remove_stale_tmp

__all__ = [
    "CELL_FORMAT",
    "MODEL_SPEC_FORMAT",
    "STORE_FORMAT",
    "STORE_VERSION",
    "ResultStore",
    "StoreError",
    "canonical_hash",
    "check_name",
]

STORE_FORMAT = "fcc-sweep-store"
CELL_FORMAT = "fcc-sweep-cell"
MODEL_SPEC_FORMAT = "fcc-sweep-model"
STORE_VERSION = 1

MANIFEST = "sweep.json"
#: Temporary files and model directories older than this (seconds) are left over from a killed
#: sweep and removed when the store is opened; younger ones may belong to a sweep still running.
STALE_TMP_AGE_S = 3600.0
_NAME_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._+-]*$")


class StoreError(RuntimeError):
    """A store file is corrupted, foreign or from another sweep; the message says what to do."""


def check_name(kind: str, name: str) -> str:
    """Return ``name`` if it is safe as one path component, else raise ``ValueError``.

    Labels and scenario names become directory names, so they must not contain separators or
    start with a dot (``..`` would escape the store).
    """
    if not isinstance(name, str) or not _NAME_RE.match(name):
        raise ValueError(
            f"{kind} {name!r} cannot be used as a store path component: use letters, digits "
            "and . _ + - only, starting with a letter or digit"
        )
    return name


def _json_default(obj: Any) -> Any:
    # numpy scalars and tuples reach here from configs; keep the hash stable across both.
    if hasattr(obj, "item"):
        return obj.item()
    raise TypeError(f"{type(obj).__name__} is not JSON-serialisable: {obj!r}")


def canonical_hash(obj: Any) -> str:
    """SHA-256 (hex) of the canonical JSON of ``obj`` (sorted keys, no whitespace)."""
    text = json.dumps(obj, sort_keys=True, separators=(",", ":"), default=_json_default)
    return hashlib.sha256(text.encode()).hexdigest()


def _atomic_write_json(path: Path, obj: Any) -> None:
    atomic_write_json(path, obj, indent=1, sort_keys=True, default=None)


def _read_json(path: Path, what: str, remedy: str) -> dict[str, Any]:
    try:
        obj = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise StoreError(
            f"{path} is not valid JSON ({e}): the {what} is corrupted; {remedy}"
        ) from e
    if not isinstance(obj, dict):
        raise StoreError(f"{path} does not hold a JSON object: the {what} is corrupted; {remedy}")
    return obj


def _check_tag(obj: dict[str, Any], path: Path, fmt: str, what: str, remedy: str) -> None:
    if obj.get("format") != fmt:
        raise StoreError(
            f"{path} is not a {what} of this library (format {obj.get('format')!r}, expected "
            f"{fmt!r}); it is a foreign file, so it is left alone: {remedy}"
        )
    if obj.get("version") != STORE_VERSION:
        raise StoreError(
            f"{path} has store version {obj.get('version')!r}; this library reads version "
            f"{STORE_VERSION}: {remedy}"
        )


class ResultStore:
    """A directory of finished cells and trained models of one sweep's data (see module doc).

    Open it with :meth:`open`; all methods validate what they read.
    """

    def __init__(self, root: Path, data_hash: str) -> None:
        self.root = root
        self.data_hash = data_hash

    # ---- opening -----------------------------------------------------------------------------
    @classmethod
    def open(cls, root: str | os.PathLike, data_key: Mapping[str, Any]) -> ResultStore:
        """Open (or create) the store at ``root`` for data described by ``data_key``.

        Raises:
            StoreError: ``root`` is a non-empty directory that is not a store, its manifest is
                corrupted or foreign, or it holds results of different data (another hash).
        """
        root = Path(root)
        data_hash = canonical_hash(dict(data_key))
        manifest = root / MANIFEST
        if root.exists() and not root.is_dir():
            raise StoreError(f"{root} exists and is not a directory; choose another store path")
        if manifest.is_file():
            remedy = f"delete {root} to start a new sweep there, or choose another directory"
            obj = _read_json(manifest, "store manifest", remedy)
            _check_tag(obj, manifest, STORE_FORMAT, "result store manifest", remedy)
            if obj.get("data_hash") != data_hash:
                raise StoreError(
                    f"{root} holds results of a different sweep (data hash "
                    f"{str(obj.get('data_hash'))[:12]}..., this sweep {data_hash[:12]}...): the "
                    f"simulation options, training seeds or data files differ; {remedy}"
                )
            store = cls(root, data_hash)
            store.remove_stale_tmp()
            return store
        if root.is_dir() and any(root.iterdir()):
            raise StoreError(
                f"{root} is not empty and has no {MANIFEST}, so it is not a result store; "
                "refusing to write into it. Choose an empty or new directory"
            )
        root.mkdir(parents=True, exist_ok=True)
        _atomic_write_json(
            manifest,
            {
                "format": STORE_FORMAT,
                "version": STORE_VERSION,
                "data_hash": data_hash,
                "data": dict(data_key),
            },
        )
        return cls(root, data_hash)

    def remove_stale_tmp(self, min_age_s: float = STALE_TMP_AGE_S) -> list[Path]:
        """Delete the temporary files and model directories a killed sweep left behind.

        Only names of the store's own temporaries (``.<name>.<random>.tmp``) last modified at
        least ``min_age_s`` seconds ago are removed. Returns what was removed.
        """
        removed = remove_stale_tmp(self.root, min_age_s=min_age_s)
        models = self.root / "models"
        if models.is_dir():
            now = time.time()
            for d in models.glob(f".*{TMP_SUFFIX}"):
                if d.is_dir() and now - d.stat().st_mtime >= min_age_s:
                    shutil.rmtree(d, ignore_errors=True)
                    removed.append(d)
        return removed

    # ---- cells -------------------------------------------------------------------------------
    def cell_path(self, label: str, scenario: str, seed: int) -> Path:
        check_name("diagnoser label", label)
        check_name("scenario", scenario)
        return self.root / "cells" / label / scenario / f"seed-{int(seed)}.json"

    def read_cell(
        self, label: str, scenario: str, seed: int, cell_hash: str
    ) -> dict[str, Any] | None:
        """The stored record of a cell, or ``None`` if the cell has not been computed yet.

        Raises:
            StoreError: the file is corrupted, foreign, or was computed with other settings.
        """
        path = self.cell_path(label, scenario, seed)
        if path.exists() and not path.is_file():
            raise StoreError(
                f"{path} is a directory or special file where a cell file belongs; remove it, "
                "then re-run to compute this cell"
            )
        if not path.is_file():
            return None
        remedy = f"delete {path} to recompute this cell"
        obj = _read_json(path, "cell result", remedy)
        _check_tag(obj, path, CELL_FORMAT, "cell result", remedy)
        if obj.get("hash") != cell_hash:
            raise StoreError(
                f"{path} was computed with other diagnoser settings (hash "
                f"{str(obj.get('hash'))[:12]}..., expected {cell_hash[:12]}...); give the "
                f"diagnoser another label, or {remedy}"
            )
        record = obj.get("record")
        if not isinstance(record, dict):
            raise StoreError(f"{path} has no 'record' object: the file is corrupted; {remedy}")
        return record

    def write_cell(
        self, label: str, scenario: str, seed: int, cell_hash: str, record: Mapping[str, Any]
    ) -> Path:
        """Write a finished cell atomically; refuses to replace an existing file."""
        path = self.cell_path(label, scenario, seed)
        if path.exists():
            raise StoreError(
                f"{path} already exists; a store never overwrites a finished cell. Delete it "
                "first if it must be recomputed"
            )
        _atomic_write_json(
            path,
            {
                "format": CELL_FORMAT,
                "version": STORE_VERSION,
                "hash": cell_hash,
                "data_hash": self.data_hash,
                "record": dict(record),
            },
        )
        return path

    def iter_cell_files(self) -> Iterator[Path]:
        """Every cell file present, sorted (including cells of other labels or seeds)."""
        yield from sorted((self.root / "cells").glob("*/*/seed-*.json"))

    # ---- detections of figure cells ----------------------------------------------------------
    def detection_path(self, label: str, scenario: str, seed: int) -> Path:
        check_name("diagnoser label", label)
        check_name("scenario", scenario)
        return self.root / "detections" / label / scenario / f"seed-{int(seed)}.npz"

    def read_detection(
        self, label: str, scenario: str, seed: int, cell_hash: str
    ) -> dict[str, np.ndarray] | None:
        """The stored arrays of a figure cell, or ``None`` when absent or of other settings
        (then the cell's detection is simply computed again; figures are never stale)."""
        path = self.detection_path(label, scenario, seed)
        if not path.is_file():
            return None
        try:
            with np.load(path, allow_pickle=False) as z:
                arrays = {k: z[k] for k in z.files}
        except (OSError, ValueError, zipfile.BadZipFile) as e:
            raise StoreError(
                f"{path} is not a readable detection file ({type(e).__name__}: {e}); delete it "
                "to recompute this figure cell"
            ) from e
        if str(arrays.pop("cell_hash", "")) != cell_hash:
            return None
        return arrays

    def write_detection(
        self, label: str, scenario: str, seed: int, cell_hash: str, arrays: Mapping[str, Any]
    ) -> Path:
        """Write a figure cell's arrays atomically (numeric and text arrays, no pickles)."""
        path = self.detection_path(label, scenario, seed)
        with atomic_open(path, "wb") as fh:
            np.savez_compressed(fh, cell_hash=np.array(cell_hash), **dict(arrays))
        return path

    # ---- models ------------------------------------------------------------------------------
    def model_dir(self, label: str) -> Path:
        return self.root / "models" / check_name("diagnoser label", label)

    def has_model(self, label: str, model_hash: str) -> bool:
        """Whether a trained model for ``label`` is stored; raises if it is foreign/other."""
        d = self.model_dir(label)
        if not d.exists():
            return False
        spec = d / "spec.json"
        remedy = f"delete {d} to retrain this diagnoser"
        if not spec.is_file():
            raise StoreError(f"{d} exists but has no spec.json: it is incomplete; {remedy}")
        obj = _read_json(spec, "model spec", remedy)
        _check_tag(obj, spec, MODEL_SPEC_FORMAT, "trained-model spec", remedy)
        if obj.get("hash") != model_hash:
            raise StoreError(
                f"{d} was trained with other diagnoser settings (hash "
                f"{str(obj.get('hash'))[:12]}..., expected {model_hash[:12]}...); give the "
                f"diagnoser another label, or {remedy}"
            )
        return True

    def write_model(
        self, label: str, model_hash: str, files: Mapping[str, bytes], spec: Mapping[str, Any]
    ) -> Path:
        """Store the files of a :meth:`Diagnoser.save` directory as ``models/<label>``.

        The files go to a temporary sibling directory that is renamed into place at the end, so
        a crash leaves no half-written model (only a ``.tmp`` directory that is ignored).
        """
        final = self.model_dir(label)
        if final.exists():
            # Another sweep on this store may have trained the same model meanwhile: accept it.
            if self.has_model(label, model_hash):  # raises if it is another model
                return final
        final.parent.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(dir=final.parent, prefix=f".{label}.", suffix=".tmp"))
        try:
            for rel, data in files.items():
                target = (tmp / rel).resolve()
                if tmp.resolve() not in target.parents:
                    raise ValueError(f"model file name {rel!r} escapes the model directory")
                target.parent.mkdir(parents=True, exist_ok=True)
                target.write_bytes(data)
            _atomic_write_json(
                tmp / "spec.json",
                {
                    "format": MODEL_SPEC_FORMAT,
                    "version": STORE_VERSION,
                    "hash": model_hash,
                    "data_hash": self.data_hash,
                    "spec": dict(spec),
                },
            )
            try:
                os.rename(tmp, final)
            except OSError:
                # a concurrent sweep renamed its copy first: keep it if it is this model
                if not final.is_dir() or not self.has_model(label, model_hash):
                    raise
                shutil.rmtree(tmp, ignore_errors=True)
        except BaseException:
            shutil.rmtree(tmp, ignore_errors=True)
            raise
        return final
