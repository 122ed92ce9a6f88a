"""The paper's network configurations and the persistence of the torch modules.

:func:`paper_lrgf` and :func:`paper_mem` build the paper's nominal model and model error model;
:func:`export_module` / :func:`build_module` split a module into a JSON-able config and a tensor
state dict and back (loaded with ``torch.load(..., weights_only=True)``, so a file never runs code);
:func:`save_bank` / :func:`load_bank` write and read a diagnoser's bank of them as
``models.json`` and ``weights.pt``.
"""

from __future__ import annotations

import copy
import json
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import torch

from diagnosers.networks.lrgf_net import LRGF
from diagnosers.networks.mem_net import NNARXErrorModel
from fcc_common.io import atomic_open, atomic_write
from fcc_common.safe_files import UnsafeFileError, check_zip_members, open_regular, read_json

#: The config entries that size a module's tensors.
_SIZES = ("n_inputs", "n_hidden", "order", "n_outputs", "n_linear", "input_delays", "output_delays")

#: Largest ``models.json`` read (a bank's configs are a few kB).
MAX_CONFIG_BYTES = 16 * 2**20

__all__ = ["build_module", "export_module", "load_bank", "paper_lrgf", "paper_mem", "save_bank"]


# ---- paper configurations ----------------------------------------------------------------------
def paper_lrgf(*, seed: int = 0, **overrides: Any) -> LRGF:
    """The paper's nominal model of ``T_rx`` (Sec. 5.1): inputs ``(T_rg2, T_fp)``, ``v = 3``, ``r = 2``, tanh."""
    kwargs: dict[str, Any] = {
        "n_inputs": 2,
        "n_hidden": 3,
        "order": 2,
        "n_outputs": 1,
        "seed": seed,
    }
    kwargs.update(overrides)
    return LRGF(**kwargs)


def paper_mem(*, seed: int = 0, **overrides: Any) -> NNARXErrorModel:
    """The paper's model error model (Sec. 5.2): 5 tanh hidden neurons, 15 input and output delays.

    The output activation stays linear by default (see
    :class:`diagnosers.networks.mem_net.OutputActivation`); pass ``output_activation="tanh"`` for the
    paper's literal choice.
    """
    kwargs: dict[str, Any] = {
        "n_inputs": 2,
        "n_outputs": 1,
        "n_hidden": 5,
        "input_delays": 15,
        "output_delays": 15,
        "seed": seed,
    }
    kwargs.update(overrides)
    return NNARXErrorModel(**kwargs)


# ---- persistence -------------------------------------------------------------------------------
_KINDS: dict[str, type[LRGF] | type[NNARXErrorModel]] = {"lrgf": LRGF, "nnarx_mem": NNARXErrorModel}


def export_module(module: LRGF | NNARXErrorModel) -> tuple[dict[str, Any], dict[str, torch.Tensor]]:
    """Split a module into a JSON-able config and a tensor state dict (scaler included).

    The state dict holds only tensors, so ``torch.save`` it and read it back with
    ``torch.load(path, weights_only=True)``.
    """
    if not isinstance(module, LRGF | NNARXErrorModel):
        raise TypeError(f"expected an LRGF or NNARXErrorModel, got {type(module).__name__}")
    return module.get_config(), {
        k: v.detach().cpu().clone() for k, v in module.state_dict().items()
    }


def build_module(config: dict[str, Any], state: dict[str, torch.Tensor]) -> LRGF | NNARXErrorModel:
    """Inverse of :func:`export_module`: rebuild the module from its config and load ``state``."""
    kind = config.get("kind")
    if kind not in _KINDS:
        raise ValueError(f"unknown module kind {kind!r}. Available: {sorted(_KINDS)}")
    # Sizes in a config (n_hidden, order...) decide what the constructor allocates, and every
    # unit of size owns at least one weight: a size above the number of saved weights (which the
    # file's size cap bounds) is an edited file, refused before it can allocate gigabytes.
    n_saved = sum(int(v.numel()) for v in state.values())
    for key in _SIZES:
        size = config.get(key)
        sizes = size if isinstance(size, list) else [size]
        if any(isinstance(v, int) and not isinstance(v, bool) and v > n_saved for v in sizes):
            raise ValueError(
                f"the {kind} module's config gives {key}={size!r}, more than the {n_saved} saved "
                "weights can hold; the model file was edited or is not from this library"
            )
    module = _KINDS[kind].from_config(copy.deepcopy(config))
    module.load_state_dict(state)
    return module


Module = LRGF | NNARXErrorModel


def save_bank(directory: Path, bank: Sequence[Mapping[str, Module]]) -> None:
    """Write a bank of modules into ``directory``: per relation a mapping of part name to module
    (``{"lrgf": ..., "mem": ...}``), as ``models.json`` (the configs) and ``weights.pt`` (tensors
    only), each written atomically."""
    configs: list[dict[str, Any]] = []
    tensors: dict[str, torch.Tensor] = {}
    for j, parts in enumerate(bank):
        configs.append({})
        for part, module in parts.items():
            config, state = export_module(module)
            configs[j][part] = config
            tensors.update({f"{j}.{part}.{k}": v for k, v in state.items()})
    atomic_write(directory / "models.json", json.dumps(configs, indent=2))
    with atomic_open(directory / "weights.pt", "wb") as fh:
        torch.save(tensors, fh)


def load_bank(directory: Path) -> list[dict[str, Module]]:
    """Inverse of :func:`save_bank`: the bank's modules, in evaluation mode.

    ``weights.pt`` is read with ``weights_only=True``: a file never runs code. Raises ValueError
    naming the file when either is missing, corrupted or not written by :func:`save_bank`.
    """
    try:
        configs = read_json(directory / "models.json", max_bytes=MAX_CONFIG_BYTES)
    except UnsafeFileError:
        raise
    except (OSError, json.JSONDecodeError, UnicodeDecodeError) as e:
        raise ValueError(f"{directory / 'models.json'} is missing or not valid JSON: {e}") from e
    weights = directory / "weights.pt"
    try:
        with open_regular(weights) as fh:  # a FIFO or device never reaches torch
            check_zip_members(fh, name=weights)
            fh.seek(0)
            tensors = torch.load(fh, weights_only=True)
    except UnsafeFileError:
        raise
    except Exception as e:
        # torch's text for a refused pickle suggests weights_only=False, i.e. executing the
        # file: never relay that advice about a file that may have been tampered with.
        raise ValueError(
            f"{weights} is not a valid model file of this library ({type(e).__name__}); "
            "it is corrupted or was not written by Diagnoser.save: save the diagnoser again"
        ) from None
    if not (
        isinstance(tensors, dict)
        and isinstance(configs, list)
        and all(isinstance(parts, dict) for parts in configs)
    ):
        raise ValueError(f"{weights} is not a valid model file of this library")
    bank: list[dict[str, Module]] = []
    for j, parts in enumerate(configs):
        bank.append({})
        for part, config in parts.items():
            prefix = f"{j}.{part}."
            state = {k[len(prefix) :]: v for k, v in tensors.items() if k.startswith(prefix)}
            try:
                module = build_module(config, state)
            except Exception as e:
                raise ValueError(
                    f"{directory}: models.json and weights.pt do not describe a valid model "
                    f"({type(e).__name__}: {e})"
                ) from None
            module.eval()
            bank[j][part] = module
    return bank
