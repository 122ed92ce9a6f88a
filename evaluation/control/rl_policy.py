"""The PPO agent's policy as a plain object, and its files: ``policy.npz`` and ``policy.json``.

:class:`MLPPolicy` is the deterministic actor of a PPO ``MlpPolicy`` rebuilt from arrays, so
acting needs only NumPy. :func:`save_policy` writes the actor's weights (``policy.npz``, no
pickle) and its configuration (``policy.json``: architecture, observation scaling, action
bounds, the training settings); :func:`load_policy` reads them back, checked, running no code
from the files and needing neither Stable-Baselines3 nor torch. Training, which makes one, is
:mod:`evaluation.control.rl_train`.
"""

from __future__ import annotations

import itertools
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from fcc_common.io import atomic_write_json
from fcc_common.validation import invalid

__all__ = ["FORMAT", "MLPPolicy", "load_policy", "save_policy"]

#: The ``format`` field of ``policy.json`` this module writes and reads.
FORMAT = "fcc-rl-policy/1"


@dataclass(frozen=True)
class MLPPolicy:
    """The deterministic actor of a PPO ``MlpPolicy``, rebuilt from arrays (no torch, no pickle).

    ``act(obs)``: scale ``clip((obs - mean) / sqrt(var + eps), ±clip)``, the tanh layers,
    the action layer (the Gaussian's mean), clipped to ``[action_low, action_high]``.
    """

    config: dict[str, Any]
    weights: dict[str, np.ndarray]
    name: str = "PPO agent (Stable-Baselines3)"
    _layers: list[tuple[np.ndarray, np.ndarray]] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "_layers", _check_shapes(self.config, self.weights))

    def reset(self, info: Any) -> None:
        pass

    def act(self, obs: np.ndarray, info: Any = None) -> np.ndarray:
        c = self.config
        x = np.asarray(obs, dtype=np.float32)
        mean, var = np.asarray(c["obs_mean"]), np.asarray(c["obs_var"])
        x = np.clip((x - mean) / np.sqrt(var + c["obs_epsilon"]), -c["obs_clip"], c["obs_clip"])
        h = x.astype(np.float32)
        for i, (w, b) in enumerate(self._layers):
            h = h @ w.T + b
            if i < len(self._layers) - 1:
                h = np.tanh(h)
        return np.clip(h, c["action_low"], c["action_high"]).astype(np.float32)


def _check_shapes(config: dict[str, Any], weights: dict[str, np.ndarray]) -> list[tuple]:
    """The layers as (weight, bias) pairs; refuses a config whose shapes disagree with them."""
    if config.get("format") != FORMAT:
        raise invalid("policy.json format", config.get("format"), repr(FORMAT))
    dims = [config["obs_dim"], *config["hidden"], config["act_dim"]]
    layers = []
    for i, (n_in, n_out) in enumerate(itertools.pairwise(dims)):
        name = f"layer{i}"
        for key, shape in ((f"{name}.weight", (n_out, n_in)), (f"{name}.bias", (n_out,))):
            if key not in weights:
                raise invalid("policy.npz", sorted(weights), f"an array {key!r} of shape {shape}")
            if weights[key].shape != shape:
                raise invalid(
                    f"policy.npz[{key!r}].shape",
                    weights[key].shape,
                    f"{shape}",
                    f"policy.json: obs_dim={config['obs_dim']}, hidden={config['hidden']}, "
                    f"act_dim={config['act_dim']}",
                )
        layers.append((weights[f"{name}.weight"], weights[f"{name}.bias"]))
    extra = sorted(
        set(weights) - {f"layer{i}.{p}" for i in range(len(layers)) for p in ("weight", "bias")}
    )
    if extra:
        raise invalid("policy.npz arrays", extra, f"{len(layers)} layers as policy.json says")
    for key, n in (("obs_mean", dims[0]), ("obs_var", dims[0])):
        if np.shape(config[key]) != (n,):
            raise invalid(f"policy.json {key} shape", np.shape(config[key]), f"({n},) = obs_dim")
    for key in ("action_low", "action_high"):
        if np.shape(config[key]) != (dims[-1],):
            raise invalid(f"policy.json {key} shape", np.shape(config[key]), f"({dims[-1]},)")
    return layers


def save_policy(directory: Path, policy: MLPPolicy) -> None:
    """``policy.npz`` (float32 arrays, no pickle) and ``policy.json`` in ``directory``."""
    directory.mkdir(parents=True, exist_ok=True)
    np.savez(directory / "policy.npz", **policy.weights)
    atomic_write_json(directory / "policy.json", policy.config)


def load_policy(directory: Path | str) -> MLPPolicy:
    """The policy saved by :func:`save_policy`, checked; never unpickles."""
    directory = Path(directory)
    for name in ("policy.json", "policy.npz"):
        if not (directory / name).is_file():
            raise FileNotFoundError(
                f"--policy {str(directory)!r}: no {name} there; train one with "
                "python -m evaluation.control.rl train --out DIR"
            )
    config = json.loads((directory / "policy.json").read_text(encoding="utf-8"))
    with np.load(directory / "policy.npz", allow_pickle=False) as data:
        weights = {k: data[k] for k in data.files}
    return MLPPolicy(config, weights)
