"""Figures of the control study: one episode per baseline, where a person sees what it did.

For one episode (a fault at the paper's size and onset, one test seed) and each policy: the
cumulative return, the set points, and the margins to the constraint regions of the reward
(:mod:`fcc_env.control_task`: the afterburn ΔT against its warning, the stage-2 bed against its
maximum, the stage-1 bed against its minimum), with the fault onset marked. Units on every axis
come from the quantities drawn (USD, °C, hours).
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from evaluation.reports.plots import save_png
from fcc_env.control_task import EconomicReward
from fcc_env.plant import AFTERBURN_WARNING_C

__all__ = ["episode_figure"]

_T_RG1, _T_RG2, _T_D1 = 4, 7, 9


def episode_figure(
    traces: Mapping[str, Mapping[str, Sequence[Any]]],
    sample_time_s: float,
    path: str | os.PathLike,
    *,
    title: str,
    economics: EconomicReward | None = None,
) -> Path:
    """Write the figure of ``traces`` (policy name → the ``trace`` of
    :func:`evaluation.control.returns.run_episode`) to ``path`` (PNG); returns the path."""
    e = EconomicReward() if economics is None else economics
    fig = Figure(figsize=(10, 9), layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(4, 1, sharex=True)
    hours = sample_time_s / 3600.0
    onset = None
    for name, tr in traces.items():
        reward = np.asarray(tr["reward"], dtype=float)
        t_h = np.arange(1, reward.size + 1) * hours
        sp = np.asarray(tr["setpoints"], dtype=float)
        x = np.asarray(tr["state"], dtype=float)
        (line,) = axes[0].plot(t_h, np.cumsum(reward), lw=1.0, label=name)
        c = line.get_color()
        axes[1].plot(t_h, sp[:, 0], lw=0.9, color=c)
        axes[1].plot(t_h, sp[:, 1], lw=0.9, color=c, ls="--")
        axes[2].plot(t_h, x[:, _T_D1] - x[:, _T_RG1], lw=0.9, color=c)
        axes[3].plot(t_h, e.regenerator_max_C - x[:, _T_RG2], lw=0.9, color=c)
        axes[3].plot(t_h, x[:, _T_RG1] - e.regenerator_min_C, lw=0.9, color=c, ls="--")
        onset = tr.get("onset", [None])[0] if onset is None else onset
    axes[2].axhline(AFTERBURN_WARNING_C, color="tab:red", lw=0.8, ls=":", label="afterburn warning")
    axes[3].axhline(0.0, color="tab:red", lw=0.8, ls=":", label="limit")
    if onset is not None:
        for ax in axes:
            ax.axvline(onset * hours, color="k", lw=0.8, ls="--", alpha=0.6)
        axes[0].plot([], [], color="k", ls="--", alpha=0.6, label="fault onset")
    axes[0].set_ylabel("cumulative return [USD]")
    axes[1].set_ylabel("set point [°C]")
    axes[2].set_ylabel("T_d1 − T_rg1 [°C]")
    axes[3].set_ylabel("margin to limit [°C]")
    axes[1].plot([], [], color="grey", label="T_rx_sp")
    axes[1].plot([], [], color="grey", ls="--", label="T_rg1_sp")
    axes[3].plot([], [], color="grey", label=f"T_rg2 below {e.regenerator_max_C:g} °C")
    axes[3].plot([], [], color="grey", ls="--", label=f"T_rg1 above {e.regenerator_min_C:g} °C")
    axes[1].legend(fontsize=8, loc="center right")
    axes[3].legend(fontsize=8, loc="upper right")
    axes[-1].set_xlabel("time [h]")
    axes[0].legend(fontsize=8, loc="upper left")
    axes[2].legend(fontsize=8, loc="upper left")
    fig.suptitle(title, fontsize=10)
    return save_png(fig, path, dpi=90)
