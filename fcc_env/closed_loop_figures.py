"""The closed-loop report's figures (:mod:`fcc_env.closed_loop_report` computes, this draws):
responses to set-point and disturbance steps, and faulty − healthy closed against open loop.
Units on every axis come from :data:`fcc_env.closed_loop.CHANNEL_UNITS`."""

from __future__ import annotations

import io
from collections.abc import Sequence
from typing import Any

import numpy as np

from fcc_env.closed_loop import CHANNEL_UNITS, CLOSED_LOOP_CHANNELS, visibility_threshold
from fcc_env.regulatory import SETPOINT_NAMES

__all__ = ["FIGURE_CHANNELS", "closed_minus_open_figure", "responses_figure"]

#: The columns of both figures.
FIGURE_CHANNELS = ("T_rx", "T_rg1", "u_F", "R_ar")


def _grid(n_rows: int) -> tuple[Any, Any]:
    # An explicit Agg canvas: no pyplot state, no display needed (as fcc_env.plotting).
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(12, 2.3 * n_rows), dpi=90, layout="constrained")
    FigureCanvasAgg(fig)
    return fig, fig.subplots(n_rows, len(FIGURE_CHANNELS), sharex=True, squeeze=False)


def _finish(fig: Any, axes: Any, ylabel: str, xlabel: str) -> bytes:
    """Units on every axis; the PNG bytes."""
    for ax, c in zip(axes.ravel(), FIGURE_CHANNELS * axes.shape[0], strict=True):
        ax.set_ylabel(ylabel.format(c=c, unit=CHANNEL_UNITS[c]), fontsize=8)
        ax.ticklabel_format(axis="y", useOffset=False)  # absolute values on the axis
        ax.tick_params(labelsize=7)
    for ax in axes[-1]:
        ax.set_xlabel(xlabel, fontsize=8)
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    return buf.getvalue()


def responses_figure(responses: Sequence[Any]) -> bytes:
    """PNG: one row per response, columns T_rx, T_rg1, u_F, R_ar (set points dashed)."""
    fig, axes = _grid(len(responses))
    for row, r in zip(axes, responses, strict=True):
        for ax, c in zip(row, FIGURE_CHANNELS, strict=True):
            ax.plot(r.time_h, r.y[:, CLOSED_LOOP_CHANNELS.index(c)], lw=1.0)
            sp = f"{c}_sp"
            if sp in SETPOINT_NAMES:
                ax.plot(r.time_h, r.y[:, CLOSED_LOOP_CHANNELS.index(sp)], "k--", lw=0.8)
            ax.axvline(r.step_at_h, color="tab:red", ls=":", lw=0.8)
        row[0].set_title(r.title, fontsize=9, loc="left")
    return _finish(fig, axes, "{c} [{unit}]", "time [h]")


def closed_minus_open_figure(runs: Sequence[Any]) -> bytes:
    """PNG: per fault a row of Δ (faulty − healthy) on T_rx, T_rg1, u_F, R_ar, closed and open
    loop overlaid (episode means), ±3σ dotted; hours after onset."""
    by = {(r.fault, r.loop): r for r in runs}
    faults = list(dict.fromkeys(r.fault for r in runs))
    fig, axes = _grid(len(faults))
    for row, f in zip(axes, faults, strict=True):
        for ax, c in zip(row, FIGURE_CHANNELS, strict=True):
            for loop, color in (("open", "tab:gray"), ("closed", "tab:blue")):
                r = by[(f, loop)]
                t_h = (np.arange(r.deltas[c].shape[1]) - r.onset) * r.sample_time_s / 3600.0
                ax.plot(t_h, r.mean(c), color=color, lw=1.0, label=f"{loop} loop")
            thr = visibility_threshold(c)
            ax.axhline(thr, color="k", ls=":", lw=0.6, label="±3σ")
            ax.axhline(-thr, color="k", ls=":", lw=0.6)
            ax.set_xlim(-0.5, None)  # half an hour before onset: the differences are 0 there
        row[0].set_title(f"{f}: faulty − healthy", fontsize=9, loc="left")
    axes[0, 0].legend(fontsize=7)
    return _finish(fig, axes, "Δ{c} [{unit}]", "time after onset [h]")
