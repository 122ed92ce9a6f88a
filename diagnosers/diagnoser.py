"""The class every diagnoser derives from: the contract, plus saving and loading.

:class:`Diagnoser` adds persistence to :class:`diagnosers.contract.DiagnoserContract`: a fitted
diagnoser is written as a directory (``config.json`` + ``state.npz``, and ``weights.pt`` for
torch modules) and read back through the registry, so a file never runs code.

Why two classes: :meth:`Diagnoser.load` builds the saved diagnoser by its registered name, so
persistence sits above :mod:`diagnosers.registry`, which itself needs only the contract.
"""

from __future__ import annotations

import json
import os
import zipfile
from abc import abstractmethod
from pathlib import Path

import numpy as np

from diagnosers.contract import DiagnoserContract
from diagnosers.registry import make
from fcc_common.io import atomic_open, atomic_write
from fcc_common.safe_files import (
    MAX_FILE_BYTES,
    UnsafeFileError,
    check_regular,
    check_zip_members,
    load_npz,
    open_regular,
    read_json,
)

__all__ = ["MAX_JSON_BYTES", "SAVE_FORMAT", "SAVE_FORMAT_VERSION", "Diagnoser"]

SAVE_FORMAT = "fcc-diagnoser"
SAVE_FORMAT_VERSION = 1
#: Cap on a saved JSON file (``config.json``, ``models.json``): they hold settings, a few KiB.
#: Array and weight files get :data:`fcc_common.safe_files.MAX_FILE_BYTES` (512 MiB).
MAX_JSON_BYTES = 16 * 2**20


class Diagnoser(DiagnoserContract):
    """Base class of every diagnoser: :class:`~diagnosers.contract.DiagnoserContract` plus
    :meth:`save` and :meth:`load` (and the state hooks they use).

    Conventions follow scikit-learn's estimators: ``__init__`` stores keyword hyperparameters
    verbatim and does nothing else, ``fit`` validates them and returns ``self``, learned
    attributes end in ``_``.
    """

    # ---- persistence ---------------------------------------------------------------------------
    def save(self, path: str | os.PathLike) -> Path:
        """Write the fitted diagnoser to directory ``path``: ``config.json`` + ``state.npz``.

        ``state.npz`` holds plain numeric arrays (``allow_pickle=False`` on load); subclasses with
        torch modules also write ``weights.pt``, a state dict loaded with ``weights_only=True``.
        Files are written to temporaries and renamed, so an interrupted save leaves no torn file.
        A ``path`` that is a symbolic link is refused by name (a save never writes through a link
        to elsewhere); a file inside that is a link is replaced by the file, its target left as
        it was.
        """
        self._check_fitted()
        out = Path(path)
        if out.is_symlink():
            raise ValueError(
                f"{out} is a symbolic link (to {os.readlink(out)!r}); refusing to save through it: "
                "give the directory itself, or remove the link"
            )
        out.mkdir(parents=True, exist_ok=True)
        config = {
            "format": SAVE_FORMAT,
            "format_version": SAVE_FORMAT_VERSION,
            "diagnoser": self.name,
            "class": f"{type(self).__module__}.{type(self).__qualname__}",
            "params": self.get_params(),
            "channels": list(self.channels_),
            "sample_time_s": self.sample_time_s_,
        }
        state = {k: np.asarray(v) for k, v in self._get_state().items()}
        with atomic_open(out / "state.npz", "wb") as fh:
            np.savez(fh, **state)
        self._save_extra(out)
        # config.json last: its presence marks a complete save
        atomic_write(out / "config.json", json.dumps(config, indent=2))
        return out

    @classmethod
    def load(cls, path: str | os.PathLike) -> Diagnoser:
        """Load a diagnoser written by :meth:`save`; never executes code from the files."""
        src = Path(path)
        cfg_path = src / "config.json"
        if not cfg_path.exists():
            raise ValueError(f"{src} is not a saved diagnoser: {cfg_path.name} is missing")
        try:
            # bounded, regular files only: a FIFO or /dev/zero here must not hang the load
            config = read_json(cfg_path, max_bytes=MAX_JSON_BYTES)
        except (json.JSONDecodeError, UnicodeDecodeError) as e:
            raise ValueError(f"{cfg_path} is not valid JSON: {e}") from e
        if not isinstance(config, dict) or config.get("format") != SAVE_FORMAT:
            raise ValueError(
                f"{cfg_path} is not a saved diagnoser of this library "
                f"(expected format {SAVE_FORMAT!r}, got "
                f"{config.get('format') if isinstance(config, dict) else config!r})"
            )
        if config.get("format_version") != SAVE_FORMAT_VERSION:
            raise ValueError(
                f"{cfg_path}: format_version {config.get('format_version')!r} is not supported "
                f"(this library reads version {SAVE_FORMAT_VERSION})"
            )
        # A config with the right format tag can still be hand-edited or truncated: check the
        # fields used below so that it fails with ValueError, not KeyError/TypeError.
        for key, kind in (
            ("diagnoser", str),
            ("params", dict),
            ("channels", list),
            ("sample_time_s", (int, float)),
        ):
            if not isinstance(config.get(key), kind):
                raise ValueError(
                    f"{cfg_path}: field {key!r} is missing or of the wrong type "
                    f"(got {config.get(key)!r}); the file is corrupted"
                )
        if not all(isinstance(c, str) for c in config["channels"]):
            raise ValueError(f"{cfg_path}: channels must be names (str), got {config['channels']}")
        try:
            obj = make(config["diagnoser"], **config["params"])
            # a saved config is checked like constructor arguments before anything is built
            # from it: a hand-edited alpha=5 or n_hidden=1e9 fails here, not in an allocation
            obj.validate_params()
        except (ValueError, TypeError) as e:
            raise ValueError(f"{cfg_path}: {e}") from e
        saved_class = _moved_class(config.get("class"))
        actual_class = f"{type(obj).__module__}.{type(obj).__qualname__}"
        if saved_class is not None and saved_class != actual_class:
            raise ValueError(
                f"{cfg_path}: diagnoser {config['diagnoser']!r} is a {actual_class}, but the "
                f"file was saved by a {saved_class!r}; the config was edited or relabelled"
            )
        if cls is not Diagnoser and not isinstance(obj, cls):
            raise ValueError(
                f"{src} holds a {config['diagnoser']!r} diagnoser, not a {cls.__name__}"
            )
        # every file the hooks will read is checked first: _load_extra reads by name
        _check_files(src)
        state_path = src / "state.npz"
        try:
            state = load_npz(state_path)
        except UnsafeFileError as e:  # not regular, or over a cap: the message names both
            raise UnsafeFileError(f"{e}; the saved diagnoser is corrupted: save it again") from e
        except Exception as e:  # BadZipFile, EOFError, zlib.error...: one clear message
            raise ValueError(
                f"{state_path} is missing, truncated or not a numeric state file "
                f"({type(e).__name__}); the saved diagnoser is corrupted: save it again"
            ) from e
        for key, arr in state.items():
            if arr.dtype.kind in "fc":
                _require_finite(int(np.count_nonzero(~np.isfinite(arr))), arr.size, state_path, key)
        obj.channels_ = tuple(config["channels"])
        obj.sample_time_s_ = float(config["sample_time_s"])
        try:
            obj._set_state(state)
        except KeyError as e:
            raise ValueError(
                f"{state_path} lacks the array {e} that a {config['diagnoser']!r} "
                "diagnoser needs; the directory is corrupted or from another version"
            ) from e
        except (ValueError, TypeError, IndexError) as e:
            raise ValueError(
                f"{state_path} does not fit a {config['diagnoser']!r} diagnoser with the saved "
                f"settings ({e}); the directory is corrupted, edited or relabelled"
            ) from e
        obj._load_extra(src)
        obj._fitted_ = True
        obj.reset()
        return obj

    # ---- hooks ---------------------------------------------------------------------------------
    # A subclass implements _get_state and _set_state; _save_extra and _load_extra are optional.
    @abstractmethod
    def _get_state(self) -> dict[str, np.ndarray]:
        """Learned numeric state as named arrays (everything ``_update`` needs besides params).

        Called by :meth:`save` on a fitted diagnoser. Returns ``{name: array}`` of plain numbers
        (no objects: the file is read with ``allow_pickle=False``); scalars become 0-d arrays.
        Streaming state (filter memories) is not learned state and stays out.
        """

    @abstractmethod
    def _set_state(self, state: dict[str, np.ndarray]) -> None:
        """Inverse of :meth:`_get_state`: restore the learned attributes from ``state``.

        Called by :meth:`load` on a fresh instance built with the saved hyperparameters, after
        ``channels_`` and ``sample_time_s_`` are set; must also set ``signal_names_``. Returns
        nothing; a missing key raises ``KeyError`` (reported by ``load`` as a corrupted file).
        :meth:`load` calls :meth:`~diagnosers.contract.DiagnoserContract.reset` afterwards.
        """

    def _save_extra(self, directory: Path) -> None:
        """Write extra files (e.g. torch ``weights.pt``) into ``directory``."""

    def _load_extra(self, directory: Path) -> None:
        """Read what :meth:`_save_extra` wrote; torch files with ``weights_only=True``."""


# ---- checks of the files of a saved directory ------------------------------------------------
#: modules that moved into sub-packages (0.x, issue 41): a model saved before the move names
#: its class by the old path, which is the same class
_MOVED_MODULES = {
    "diagnosers.lrgf_mem": "diagnosers.lrgf.lrgf_mem",
    "diagnosers.lrgf_glr": "diagnosers.lrgf.lrgf_glr",
    "diagnosers.lrgf_presets": "diagnosers.lrgf.lrgf_presets",
    "diagnosers.bank_detector": "diagnosers.lrgf.bank_detector",
    "diagnosers.isolation": "diagnosers.isolation.isolating_detector",
    "diagnosers.isolators": "diagnosers.isolation.isolators",
}


def _moved_class(saved: object) -> object:
    """A saved class path read through :data:`_MOVED_MODULES` (anything else unchanged)."""
    if not isinstance(saved, str) or "." not in saved:
        return saved
    module, _, name = saved.rpartition(".")
    return f"{_MOVED_MODULES.get(module, module)}.{name}"


def _require_finite(n_bad: int, size: int, path: Path, key: str) -> None:
    """A NaN or inf in learned state makes a detector that never alarms: refuse it by name."""
    if n_bad:
        raise ValueError(
            f"{path}: array {key!r} holds {n_bad} non-finite value(s) (NaN or inf) of {size}; "
            "learned state must be finite: the file is corrupted or edited, save the diagnoser "
            "again"
        )


def _check_files(directory: Path) -> None:
    """Check every file in ``directory`` before any hook reads it.

    :meth:`Diagnoser._load_extra` hooks read their files by name (``models.json``, and
    ``weights.pt`` through ``torch.load``), so the one place that sees them all is here: each
    must be a regular file under its cap; a zip (``.npz``, ``.pt``) must not inflate past
    :data:`~fcc_common.safe_files.MAX_INFLATED_BYTES`; torch weights must be finite.
    Subdirectories are saved diagnosers of their own, checked when they are loaded.
    """
    for entry in sorted(directory.iterdir()):
        if entry.is_dir():
            continue
        suffix = entry.suffix
        try:
            check_regular(entry, max_bytes=MAX_JSON_BYTES if suffix == ".json" else MAX_FILE_BYTES)
        except FileNotFoundError:
            continue  # a dangling symlink: the hook that needs the file reports it missing
        if suffix == ".pt":
            _check_weights(entry)


def _check_weights(path: Path) -> None:
    import torch  # only diagnosers with torch modules write .pt files

    with open_regular(path) as fh:
        if zipfile.is_zipfile(fh):  # torch's format since 1.6; older files are not zips
            check_zip_members(fh, name=path)
        fh.seek(0)
        try:
            tensors = torch.load(fh, weights_only=True, map_location="cpu")
        except Exception:  # torch raises many types on a bad file
            return  # not a weights file: the hook that reads it refuses it by name
    if not isinstance(tensors, dict):
        return
    for key, value in tensors.items():
        if isinstance(value, torch.Tensor) and (value.is_floating_point() or value.is_complex()):
            n_bad = int((~torch.isfinite(value)).sum())
            _require_finite(n_bad, value.numel(), path, str(key))
