"""The paper's network configurations and the persistence of the torch modules.

:func:`paper_lrgf` and :func:`paper_mem` build the paper's nominal model and model error model;
:func:`export_module` / :func:`build_module` split a module into a JSON-able config and a tensor
state dict and back (loaded with ``torch.load(..., weights_only=True)``, so a file never runs code).
"""

from __future__ import annotations

import copy
from typing import Any

import torch

from diagnosers.lrgf import LRGF
from diagnosers.mem import NNARXErrorModel

__all__ = ["build_module", "export_module", "paper_lrgf", "paper_mem"]


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

    The output activation stays linear by default (see :class:`diagnosers.mem.OutputActivation`);
    pass ``output_activation="tanh"`` for the paper's literal choice.
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
    module = _KINDS[kind].from_config(copy.deepcopy(config))
    module.load_state_dict(state)
    return module
