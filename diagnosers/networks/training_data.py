"""The trainers' data plumbing: episodes checked, standardised and stacked for batched free runs.

Episodes come as ``(T, c)``, ``(B, T, c)`` or a list of ``(T_i, c)`` arrays; equal-length ones are
stacked into :class:`EpisodeGroup` tensors so that one batched free run covers them, with the time
ranges that enter the training and the validation loss (:func:`train_val_split`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import torch

__all__ = [
    "ArrayLike",
    "EpisodeGroup",
    "episode_arrays",
    "make_groups",
    "mean_scale",
    "squared_error_sum",
    "train_val_split",
    "training_pairs",
]

ArrayLike = np.ndarray | Sequence[np.ndarray]


def episode_arrays(x: ArrayLike, n_channels: int, name: str) -> list[np.ndarray]:
    """Normalise ``(T, c)``, ``(B, T, c)`` or a list of ``(T_i, c)`` arrays to a list of float64 2-D arrays."""
    if isinstance(x, np.ndarray | torch.Tensor):
        arr = np.asarray(x, dtype=np.float64)
        if arr.ndim == 2:
            eps = [arr]
        elif arr.ndim == 3:
            eps = list(arr)
        else:
            raise ValueError(
                f"{name} must be (T, {n_channels}), (B, T, {n_channels}) or a list; got {arr.shape}"
            )
    else:
        eps = [np.asarray(e, dtype=np.float64) for e in x]
    if not eps:
        raise ValueError(f"{name} holds no episode")
    for i, e in enumerate(eps):
        if e.ndim != 2 or e.shape[1] != n_channels:
            raise ValueError(f"{name}[{i}] must have shape (T, {n_channels}); got {e.shape}")
        if not np.isfinite(e).all():
            raise ValueError(f"{name}[{i}] contains NaN or inf")
    return eps


def training_pairs(
    u: ArrayLike,
    y: ArrayLike,
    u_val: ArrayLike | None,
    y_val: ArrayLike | None,
    n_in: int,
    n_out: int,
    y_name: str,
) -> tuple[list[np.ndarray], list[np.ndarray], list[np.ndarray] | None, list[np.ndarray] | None]:
    """Training (and optional validation) episodes as checked (input, output) lists."""
    us = episode_arrays(u, n_in, "u")
    ys = episode_arrays(y, n_out, y_name)
    _check_pairs(us, ys, f"u/{y_name}")
    if u_val is None and y_val is None:
        return us, ys, None, None
    if u_val is None or y_val is None:
        raise ValueError(f"give both u_val and {y_name}_val, or neither")
    uvs = episode_arrays(u_val, n_in, "u_val")
    yvs = episode_arrays(y_val, n_out, f"{y_name}_val")
    _check_pairs(uvs, yvs, f"u_val/{y_name}_val")
    return us, ys, uvs, yvs


def _check_pairs(us: list[np.ndarray], ys: list[np.ndarray], names: str) -> None:
    if len(us) != len(ys):
        raise ValueError(f"{names}: {len(us)} input episodes but {len(ys)} output episodes")
    for i, (a, b) in enumerate(zip(us, ys, strict=True)):
        if a.shape[0] != b.shape[0]:
            raise ValueError(
                f"{names}: episode {i} has {a.shape[0]} input and {b.shape[0]} output samples"
            )


def mean_scale(eps: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Per-channel mean and standard deviation over all samples of ``eps`` (the scaler)."""
    cat = np.concatenate(eps, axis=0)
    std = cat.std(axis=0)
    # a constant channel carries no information; scale 1 keeps it finite instead of dividing by 0
    return cat.mean(axis=0), np.where(std > 1e-12 * (1.0 + np.abs(cat.mean(axis=0))), std, 1.0)


@dataclass
class EpisodeGroup:
    """Equal-length episodes stacked for one batched free run."""

    u: torch.Tensor  # (B, T, n) standardised
    y: torch.Tensor  # (B, T, m) standardised
    train: slice  # time range entering the training loss
    val: slice  # time range entering the validation loss


def make_groups(
    us: list[np.ndarray],
    ys: list[np.ndarray],
    u_stats: tuple[np.ndarray, np.ndarray],
    y_stats: tuple[np.ndarray, np.ndarray],
    dtype: torch.dtype,
    split: Callable[[int], tuple[slice, slice]],
) -> list[EpisodeGroup]:
    """Standardise the episodes and stack those of equal length, one group per length."""
    by_len: dict[int, list[int]] = {}
    for i, e in enumerate(us):
        by_len.setdefault(e.shape[0], []).append(i)
    groups = []
    for t_len, idx in sorted(by_len.items()):
        u = np.stack([(us[i] - u_stats[0]) / u_stats[1] for i in idx])
        y = np.stack([(ys[i] - y_stats[0]) / y_stats[1] for i in idx])
        tr, va = split(t_len)
        groups.append(
            EpisodeGroup(torch.as_tensor(u, dtype=dtype), torch.as_tensor(y, dtype=dtype), tr, va)
        )
    return groups


def squared_error_sum(
    pred: torch.Tensor, target: torch.Tensor, sl: slice
) -> tuple[torch.Tensor, int]:
    """Sum of squared errors over the time range ``sl`` and the number of terms in it."""
    d = pred[:, sl] - target[:, sl]
    return (d * d).sum(), d.numel()


def train_val_split(
    val_fraction: float, washout: int, has_val: bool
) -> Callable[[int], tuple[slice, slice]]:
    """A function of an episode length giving its (training, validation) time ranges.

    With validation episodes (``has_val``) or ``val_fraction == 0`` the whole episode after
    ``washout`` trains; otherwise its last ``val_fraction`` validates.
    """

    def split(t_len: int) -> tuple[slice, slice]:
        if has_val or val_fraction == 0.0:
            return slice(washout, t_len), slice(0, 0)
        cut = round(t_len * (1.0 - val_fraction))
        if cut - washout < 1 or cut >= t_len:
            raise ValueError(
                f"episode of {t_len} samples is too short for washout={washout} and "
                f"val_fraction={val_fraction}"
            )
        return slice(washout, cut), slice(cut, t_len)

    return split
