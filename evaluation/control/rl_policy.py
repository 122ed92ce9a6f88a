"""The PPO agent's policy as a plain object, and its files: ``policy.npz`` and ``policy.json``.

:class:`MLPPolicy` is the deterministic actor of a PPO ``MlpPolicy`` rebuilt from arrays, so
acting needs only NumPy. :func:`save_policy` writes the actor's weights (``policy.npz``, no
pickle) and its configuration (``policy.json``: env id, architecture and activation,
observation scaling, action bounds, the training settings, and the SHA-256 of the weights);
:func:`load_policy` reads them back through :mod:`fcc_common.safe_files` (regular files under a
cap, array headers checked before anything is inflated), runs no code from the files and needs
neither Stable-Baselines3 nor torch. Training, which makes one, is
:mod:`evaluation.control.rl_train`.

A policy directory is anyone's to edit, so every field is checked, and every refusal is one
``ValueError`` naming the file (and the field or array): a wrong type or shape, a missing field,
a non-finite number or weight, an activation other than :data:`ACTIVATIONS`, a policy saved for
another env id, weights whose hash is not the one ``policy.json`` records (the two files of two
policies mixed, or an edited array).
"""

from __future__ import annotations

import hashlib
import io
import itertools
import os
import struct
import zipfile
import zlib
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from fcc_common.io import atomic_write, atomic_write_json
from fcc_common.safe_files import MAX_INFLATED_BYTES, UnsafeFileError, load_npz, read_json
from fcc_common.validation import invalid

__all__ = [
    "ACTIVATIONS",
    "FORMAT",
    "MAX_POLICY_JSON_BYTES",
    "MLPPolicy",
    "load_policy",
    "save_policy",
    "weights_sha256",
]

#: The ``format`` field of ``policy.json`` this module writes and reads. Format 1 (before the
#: weights' hash) is refused: its two files cannot be told from two policies' files mixed.
FORMAT = "fcc-rl-policy/2"
#: The hidden layers' activations a policy may name (SB3's ``MlpPolicy`` uses tanh).
ACTIVATIONS: dict[str, Callable[[np.ndarray], np.ndarray]] = {
    "tanh": np.tanh,
    "relu": lambda h: np.maximum(h, 0),
}
#: Largest ``policy.json`` read: its lists have one number per observation or action.
MAX_POLICY_JSON_BYTES = 16 * 2**20
#: The fields every ``policy.json`` has (``settings``, the training's, is a record only).
_FIELDS = (
    "format",
    "env_id",
    "obs_dim",
    "act_dim",
    "hidden",
    "activation",
    "obs_mean",
    "obs_var",
    "obs_epsilon",
    "obs_clip",
    "action_low",
    "action_high",
)
_NPZ_ERRORS = (ValueError, EOFError, KeyError, zipfile.BadZipFile, zlib.error, struct.error)


@dataclass(frozen=True)
class MLPPolicy:
    """The deterministic actor of a PPO ``MlpPolicy``, rebuilt from arrays (no torch, no pickle).

    ``act(obs)``: scale ``clip((obs - mean) / sqrt(var + eps), ±clip)``, the hidden layers with
    ``config["activation"]``, the action layer (the Gaussian's mean), clipped to
    ``[action_low, action_high]``. The config and weights are checked on construction.
    """

    config: dict[str, Any]
    weights: dict[str, np.ndarray]
    name: str = "PPO agent (Stable-Baselines3)"
    _layers: list[tuple[np.ndarray, np.ndarray]] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "_layers", _check_policy(self.config, self.weights))

    def reset(self, info: Any) -> None:
        pass

    def act(self, obs: np.ndarray, info: Any = None) -> np.ndarray:
        c = self.config
        x = np.asarray(obs, dtype=np.float32)
        mean, var = np.asarray(c["obs_mean"]), np.asarray(c["obs_var"])
        x = np.clip((x - mean) / np.sqrt(var + c["obs_epsilon"]), -c["obs_clip"], c["obs_clip"])
        h = x.astype(np.float32)
        activation = ACTIVATIONS[c["activation"]]
        for i, (w, b) in enumerate(self._layers):
            h = h @ w.T + b
            if i < len(self._layers) - 1:
                h = activation(h)
        return np.clip(h, c["action_low"], c["action_high"]).astype(np.float32)


def _count(config: dict[str, Any], key: str, label: str, lowest: int = 1) -> int:
    value = config[key]
    if isinstance(value, bool) or not isinstance(value, int) or value < lowest:
        raise invalid(f"{label} {key}", value, f"an integer >= {lowest}")
    return value


def _numbers(config: dict[str, Any], key: str, n: int | None, label: str) -> np.ndarray:
    """``config[key]``: ``n`` finite numbers (a list), or one when ``n`` is None."""
    value = config[key]
    items = [value] if n is None else value
    if n is not None and (not isinstance(value, list) or len(value) != n):
        got = f"length {len(value)}" if isinstance(value, list) else type(value).__name__
        raise invalid(f"{label} {key}", got, f"a list of {n} finite numbers")
    if not all(isinstance(v, int | float) and not isinstance(v, bool) for v in items):
        raise invalid(f"{label} {key}", value, "finite numbers")
    arr = np.asarray(items, dtype=float)
    if not np.isfinite(arr).all():
        raise invalid(f"{label} {key}", value, "finite numbers")
    return arr


def _check_config(config: Any, label: str) -> list[int]:
    """The layer widths ``[obs_dim, *hidden, act_dim]`` of a checked ``policy.json``."""
    if not isinstance(config, dict):
        raise invalid(label, type(config).__name__, "a JSON object as save_policy writes")
    missing = [k for k in _FIELDS if k not in config]
    if missing:
        raise ValueError(f"{label} misses the fields {missing}; a saved policy has {list(_FIELDS)}")
    if config["format"] != FORMAT:
        raise invalid(f"{label} format", config["format"], repr(FORMAT), "train the agent again")
    if not isinstance(config["env_id"], str):
        raise invalid(f"{label} env_id", config["env_id"], "a registered env id (a string)")
    if not isinstance(config["activation"], str) or config["activation"] not in ACTIVATIONS:
        raise invalid(f"{label} activation", config["activation"], f"one of {list(ACTIVATIONS)}")
    hidden = config["hidden"]
    if not (isinstance(hidden, list) and all(_is_width(h) for h in hidden)):
        raise invalid(f"{label} hidden", hidden, "a list of layer widths (integers >= 1)")
    dims = [_count(config, "obs_dim", label), *hidden, _count(config, "act_dim", label)]
    for key, n in (("obs_mean", dims[0]), ("obs_var", dims[0])):
        _numbers(config, key, n, label)
    if (np.asarray(config["obs_var"]) < 0).any():
        raise invalid(f"{label} obs_var", config["obs_var"], "variances >= 0")
    for key in ("obs_epsilon", "obs_clip"):
        if not _numbers(config, key, None, label)[0] > 0:
            raise invalid(f"{label} {key}", config[key], "> 0")
    low, high = (_numbers(config, k, dims[-1], label) for k in ("action_low", "action_high"))
    if not (low <= high).all():
        raise invalid(
            f"{label} action_low/action_high", (low.tolist(), high.tolist()), "low <= high"
        )
    return dims


def _names(keys: Any, most: int = 8) -> str:
    """Array names for a message, at most ``most`` of them (a hostile file may hold millions)."""
    names = sorted(keys)
    more = f", ... ({len(names)} in all)" if len(names) > most else ""
    return ", ".join(repr(n) for n in names[:most]) + more


def _is_width(h: Any) -> bool:
    return isinstance(h, int) and not isinstance(h, bool) and h >= 1


def _check_policy(
    config: Any,
    weights: dict[str, np.ndarray],
    json_label: str = "policy.json",
    npz_label: str = "policy.npz",
) -> list[tuple[np.ndarray, np.ndarray]]:
    """The layers as (weight, bias) pairs; refuses a config that is malformed or whose shapes
    disagree with the weights, and weights that are not finite floating-point arrays."""
    dims = _check_config(config, json_label)
    layers = []
    for i, (n_in, n_out) in enumerate(itertools.pairwise(dims)):
        name = f"layer{i}"
        for key, shape in ((f"{name}.weight", (n_out, n_in)), (f"{name}.bias", (n_out,))):
            if key not in weights:
                raise invalid(npz_label, _names(weights), f"an array {key!r} of shape {shape}")
            if weights[key].shape != shape:
                raise invalid(
                    f"{npz_label}[{key!r}].shape",
                    weights[key].shape,
                    f"{shape}",
                    f"{json_label}: obs_dim={config['obs_dim']}, hidden={config['hidden']}, "
                    f"act_dim={config['act_dim']}",
                )
        layers.append((weights[f"{name}.weight"], weights[f"{name}.bias"]))
    expected = {f"layer{i}.{p}" for i in range(len(layers)) for p in ("weight", "bias")}
    extra = set(weights) - expected
    if extra:
        raise invalid(
            f"{npz_label} arrays", _names(extra), f"{len(layers)} layers as {json_label} says"
        )
    for key in sorted(expected):
        a = weights[key]
        if a.dtype.kind != "f":
            raise invalid(f"{npz_label}[{key!r}].dtype", str(a.dtype), "a floating-point type")
        if not np.isfinite(a).all():
            raise ValueError(
                f"{npz_label}[{key!r}] holds {int(np.size(a) - np.isfinite(a).sum())} non-finite "
                "weights (NaN or inf): the training diverged or the file was altered; refusing "
                "the policy"
            )
    return layers


def weights_sha256(weights: dict[str, np.ndarray]) -> str:
    """SHA-256 of the arrays (names, dtypes, shapes, little-endian bytes), in name order:
    what ``policy.json`` records as ``weights_sha256``."""
    h = hashlib.sha256()
    for key in sorted(weights):
        a = np.asarray(weights[key])
        a = np.ascontiguousarray(a, dtype=a.dtype.newbyteorder("<"))
        h.update(f"{key}\0{a.dtype.str}\0{a.shape}\0".encode())
        h.update(a.tobytes())
    return h.hexdigest()


def save_policy(directory: Path, policy: MLPPolicy) -> None:
    """``policy.npz`` (arrays, no pickle) and ``policy.json`` (with the arrays' SHA-256) in
    ``directory``, each written whole."""
    directory.mkdir(parents=True, exist_ok=True)
    buffer = io.BytesIO()
    np.savez(buffer, **policy.weights)
    atomic_write(directory / "policy.npz", buffer.getvalue())
    config = {**policy.config, "weights_sha256": weights_sha256(policy.weights)}
    atomic_write_json(directory / "policy.json", config)


def _read_config(path: Path) -> Any:
    try:
        return read_json(path, max_bytes=MAX_POLICY_JSON_BYTES, allow_nan=False)
    except UnsafeFileError:
        raise
    except ValueError as e:  # JSONDecodeError, UnicodeDecodeError, NaN tokens
        raise ValueError(f"{path} is not valid JSON ({e}); refusing the policy") from None


def _read_weights(path: Path) -> dict[str, np.ndarray]:
    try:
        return load_npz(path, max_inflated_bytes=MAX_INFLATED_BYTES)
    except UnsafeFileError:
        raise
    except _NPZ_ERRORS as e:  # a truncated or corrupted archive, an object array
        reason = " ".join(f"{type(e).__name__}: {e}".split())
        raise ValueError(
            f"{path} is not an archive of arrays that save_policy wrote ({reason}); "
            "refusing the policy"
        ) from None


def load_policy(directory: Path | str, *, env_id: str | None = None) -> MLPPolicy:
    """The policy saved by :func:`save_policy`, checked; never unpickles.

    ``env_id``: the env the policy must have been trained on (default
    :data:`fcc_env.control_task.CONTROL_ENV_ID`). Raises ``FileNotFoundError`` when a file is
    missing, and ``ValueError`` naming the file for anything else wrong (see the module doc).
    """
    if env_id is None:
        from fcc_env.control_task import CONTROL_ENV_ID as env_id
    directory = Path(directory)
    json_path, npz_path = directory / "policy.json", directory / "policy.npz"
    for path in (json_path, npz_path):
        if not os.path.lexists(path):
            raise FileNotFoundError(
                f"--policy {str(directory)!r}: no {path.name} there; train one with "
                "python -m evaluation.control.rl train --out DIR"
            )
    config = _read_config(json_path)
    weights = _read_weights(npz_path)
    _check_policy(config, weights, str(json_path), str(npz_path))
    if config["env_id"] != env_id:
        raise invalid(
            f"{json_path} env_id", config["env_id"], repr(env_id), "a policy of another env"
        )
    recorded = config.get("weights_sha256")
    if not isinstance(recorded, str) or recorded != weights_sha256(weights):
        raise ValueError(
            f"{npz_path} does not match the weights_sha256 {recorded!r} of {json_path}: the "
            "files of two policies mixed, or an array altered; refusing the policy"
        )
    return MLPPolicy(config, weights)
