"""Result store of a sweep: one JSON file per finished cell, written atomically.

Layout of a store directory (everything is plain JSON or a :meth:`Diagnoser.save` directory)::

    <root>/sweep.json                                 manifest: format tag, version, data hash
    <root>/models/<label>/                            trained diagnoser (Diagnoser.save) + spec.json
    <root>/cells/<label>/<scenario>/seed-<seed>.json  one finished cell
    <root>/detections/<label>/<scenario>/seed-<seed>.npz  the whole detection of a figure cell
    <root>/inner/<label>/<scenario>/seed-<seed>.npz   a detector's detection, for the isolators
                                                      that wrap it (keyed by its cell hash)

Why it is built like this:

* **Atomic writes.** Every file is written to a temporary file in the same directory and moved into
  place with :func:`os.replace`, so a sweep killed at any instant leaves either the complete file
  or none; a re-run finds every finished cell and computes only the missing ones.
* **Hashes, not trust.** The manifest holds the hash of what defines the data (simulation options,
  training seeds or external files); every model and cell file holds the hash of its diagnoser
  specification *and* that data hash. Test seeds and scenarios are deliberately left out of the
  hashes, so a sweep extended with more seeds or another diagnoser reuses what is already there.
* **Validate what is read.** A cell's scores must be in range (rates in [0, 1], times >= 0, counts
  >= 0; ``null`` where the format says undefined) and its label, scenario and seed must match its
  folder; a reused model's ``config.json`` must still describe the diagnoser its ``spec.json``
  was trained for; every file is read bounded and only if it is a regular file.
* **Confined.** Every path the store reads or writes lies below the store root after
  :meth:`Path.resolve`; a symbolic link inside the store is refused by name, so a re-run never
  writes outside ``--out``.
* **Never overwrite silently.** A file that is not valid JSON, has another format tag, another
  version or another hash raises :class:`StoreError` naming the file and what to do; the store
  never replaces an existing cell file.
"""

from __future__ import annotations

import hashlib
import json
import math
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

from diagnosers.registry import make
from fcc_common.io import TMP_SUFFIX, atomic_open, atomic_write_json, remove_stale_tmp
from fcc_common.safe_files import UnsafeFileError, load_npz, read_json
from fcc_common.validation import Constraint, Integer, Real, check

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
#: Cap on one JSON file of the store (manifest, cell, model spec): each holds a few KiB.
MAX_JSON_BYTES = 64 * 2**20

#: Allowed values of a cell record's fields (``evaluation.sweep.records.CellResult``): ``None``
#: in a tuple allows ``null``, which is how the writer stores an undefined (``nan``) score.
_RATE = (Real(0, 1), None)
_TIME = (Real(0, math.inf), None)
_COUNT = (Integer(0, math.inf),)
_RECORD_CONSTRAINTS: dict[str, tuple[Constraint | None, ...]] = {
    **dict.fromkeys(("r_fd", "r_td", "r_ti", "r_fi", "cdr"), _RATE),
    **dict.fromkeys(("t_dt", "t_dt_s", "t_it", "detect_wall_s"), _TIME),
    **dict.fromkeys(("n_samples", "n_samples_planned", "n_fault_samples", "n_alarms"), _COUNT),
    **dict.fromkeys(("fault_onset", "terminated_at"), (Integer(0, math.inf), None)),
    "sample_time_s": (Real(0, math.inf, closed="right"),),
}


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
        # strict JSON: the writer stores nan as null, so a NaN/Infinity token is an edit
        obj = read_json(path, max_bytes=MAX_JSON_BYTES, allow_nan=False)
    except UnsafeFileError as e:
        raise StoreError(f"{e}: the {what} is not a file of this store; {remedy}") from e
    except ValueError as e:  # JSONDecodeError, UnicodeDecodeError, NaN tokens
        raise StoreError(
            f"{path} is not valid JSON ({e}): the {what} is corrupted; {remedy}"
        ) from e
    if not isinstance(obj, dict):
        raise StoreError(f"{path} does not hold a JSON object: the {what} is corrupted; {remedy}")
    return obj


def _check_record(
    record: dict[str, Any], path: Path, label: str, scenario: str, seed: int, remedy: str
) -> None:
    """Refuse a cell record out of range or filed under another label, scenario or seed."""
    for key, folder in (("diagnoser", label), ("scenario", scenario), ("seed", seed)):
        if key in record and (record[key] != folder or isinstance(record[key], bool)):
            raise StoreError(
                f"{path}: {key}={record[key]!r} does not match its place in the store "
                f"({key} {folder!r}); the file was moved or edited; {remedy}"
            )
    for key, constraints in _RECORD_CONSTRAINTS.items():
        value = record.get(key)
        # types are CellResult.from_json's to report; ranges are checked here, on every read
        if isinstance(value, int | float) and not isinstance(value, bool):
            try:
                check(key, value, *constraints)
            except ValueError as e:
                raise StoreError(f"{path}: {e}; the file is corrupted or edited; {remedy}") from e


def _resolved_params(name: Any, params: Any, where: Path, remedy: str) -> str:
    """Hash of the hyperparameters a diagnoser ``name`` built from ``params`` resolves to."""
    if not isinstance(name, str) or not isinstance(params, dict):
        raise StoreError(
            f"{where}: diagnoser name {name!r} / params {params!r} are missing or of the wrong "
            f"type; {remedy}"
        )
    try:
        diagnoser = make(name, **params)
        diagnoser.validate_params()
        return canonical_hash(diagnoser.result_params())
    except (ValueError, TypeError) as e:
        raise StoreError(f"{where}: {e}; {remedy}") from e


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


def _same_result(a: Mapping[str, Any] | None, b: Mapping[str, Any]) -> bool:
    """Two records of one cell agree but for their wall times (``*_wall_s``), which no two runs
    share; compared as canonical JSON, where NaN equals NaN."""

    def canon(r: Mapping[str, Any]) -> str:
        kept = {k: v for k, v in r.items() if not str(k).endswith("wall_s")}
        return json.dumps(kept, sort_keys=True, default=_json_default)

    return a is not None and canon(a) == canon(b)


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
        return self._confined(self.root / "cells" / label / scenario / f"seed-{int(seed)}.json")

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
        _check_record(record, path, label, scenario, int(seed), remedy)
        return record

    def write_cell(
        self, label: str, scenario: str, seed: int, cell_hash: str, record: Mapping[str, Any]
    ) -> Path:
        """Write a finished cell atomically; refuses to replace an existing file.

        A file found in its place that holds the same record was written by another run of the
        same sweep on this store (both computed the cell): it is kept, and this is no error.
        """
        path = self.cell_path(label, scenario, seed)
        if path.exists():
            found = self.read_cell(label, scenario, seed, cell_hash)  # raises if it is foreign
            if _same_result(found, record):
                return path
            raise StoreError(
                f"{path} was written meanwhile by another run on this store (same settings, "
                "another result: a diagnoser that is not deterministic?); a store never "
                "overwrites a finished cell. Let one run at a time use this --out, or give "
                "each run its own"
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
    def detection_path(self, label: str, scenario: str, seed: int, inner: bool = False) -> Path:
        """Where a figure cell's arrays are, or (``inner``) a detector's bare detection that
        the isolators wrapping it read instead of detecting again."""
        check_name("diagnoser label", label)
        check_name("scenario", scenario)
        folder = "inner" if inner else "detections"
        return self._confined(self.root / folder / label / scenario / f"seed-{int(seed)}.npz")

    def read_detection(
        self, label: str, scenario: str, seed: int, cell_hash: str, inner: bool = False
    ) -> dict[str, np.ndarray] | None:
        """The stored arrays of a figure cell, or ``None`` when absent or of other settings
        (then the cell's detection is simply computed again; figures are never stale).
        ``inner``: the bare detection of an isolator's inner detector (:meth:`detection_path`)."""
        path = self.detection_path(label, scenario, seed, inner)
        if not path.is_file():
            return None
        try:
            arrays = load_npz(path)
        except (OSError, ValueError, zipfile.BadZipFile) as e:
            raise StoreError(
                f"{path} is not a readable detection file ({type(e).__name__}: {e}); delete it "
                "to recompute this figure cell"
            ) from e
        if str(arrays.pop("cell_hash", "")) != cell_hash:
            return None
        return arrays

    def write_detection(
        self,
        label: str,
        scenario: str,
        seed: int,
        cell_hash: str,
        arrays: Mapping[str, Any],
        inner: bool = False,
    ) -> Path:
        """Write a figure cell's arrays (or ``inner``: a bare detection) atomically (numeric and
        text arrays, no pickles)."""
        path = self.detection_path(label, scenario, seed, inner)
        with atomic_open(path, "wb") as fh:
            np.savez_compressed(fh, cell_hash=np.array(cell_hash), **dict(arrays))
        return path

    # ---- models ------------------------------------------------------------------------------
    def model_dir(self, label: str) -> Path:
        return self._confined(self.root / "models" / check_name("diagnoser label", label))

    def has_model(self, label: str, model_hash: str) -> bool:
        """Whether a trained model for ``label`` is stored; raises if it is foreign/other."""
        d = self.model_dir(label)
        if not d.exists():
            return False
        spec = d / "spec.json"
        remedy = f"delete {d} to retrain this diagnoser"
        if not spec.exists():  # a special file is not missing: _read_json refuses it by name
            raise StoreError(f"{d} exists but has no spec.json: it is incomplete; {remedy}")
        obj = _read_json(spec, "model spec", remedy)
        _check_tag(obj, spec, MODEL_SPEC_FORMAT, "trained-model spec", remedy)
        if obj.get("hash") != model_hash:
            raise StoreError(
                f"{d} was trained with other diagnoser settings (hash "
                f"{str(obj.get('hash'))[:12]}..., expected {model_hash[:12]}...); give the "
                f"diagnoser another label, or {remedy}"
            )
        self._check_model_config(d, obj.get("spec"), remedy)
        return True

    def _check_model_config(self, d: Path, spec: Any, remedy: str) -> None:
        """The saved ``config.json`` must resolve to the hyperparameters of the spec the hash
        in ``spec.json`` was made from: an edited ``config.json`` keeps that hash.

        Only for models of a sweep (a spec with ``name`` and ``params``); the comparison is of
        :meth:`~diagnosers.contract.DiagnoserContract.result_params`, as the hash is.
        """
        if not (isinstance(spec, dict) and "name" in spec and "params" in spec):
            return
        cfg_path = d / "config.json"
        if not cfg_path.exists():
            raise StoreError(f"{d} has no config.json: the trained model is incomplete; {remedy}")
        cfg = _read_json(cfg_path, "trained model's config", remedy)
        if cfg.get("diagnoser") != spec["name"]:
            raise StoreError(
                f"{cfg_path}: diagnoser {cfg.get('diagnoser')!r} is not the {spec['name']!r} "
                f"this model was trained as; the file was edited; {remedy}"
            )
        saved = _resolved_params(cfg["diagnoser"], cfg.get("params"), cfg_path, remedy)
        if saved != _resolved_params(spec["name"], spec["params"], d / "spec.json", remedy):
            raise StoreError(
                f"{cfg_path}: the hyperparameters {cfg.get('params')!r} are not those this model "
                f"was trained with ({spec['params']!r} in spec.json); the file was edited; "
                f"{remedy}"
            )

    def _confined(self, path: Path) -> Path:
        """``path`` (below :attr:`root`) if no component below the root is a symbolic link and
        it resolves inside the root; raise :class:`StoreError` naming the link otherwise."""
        cur = self.root
        for part in path.relative_to(self.root).parts:
            cur = cur / part
            if cur.is_symlink():
                raise StoreError(
                    f"{cur} is a symbolic link inside the store {self.root} (to "
                    f"{os.readlink(cur)!r}); the store reads and writes only below its root: "
                    "replace the link with a real directory or file"
                )
        root = self.root.resolve()
        if not path.resolve().is_relative_to(root):
            raise StoreError(f"{path} resolves outside the store root {root}; refusing it")
        return path

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
