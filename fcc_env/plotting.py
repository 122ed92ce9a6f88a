"""Pictures of FCC episodes (matplotlib, Agg backend; nothing is shown on screen)."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from fcc_env.closed_loop import CLOSED_LOOP_CHANNELS
from fcc_env.params import MEASUREMENTS
from fcc_env.regulatory import SETPOINT_NAMES

_ONSET_STYLE = {"color": "tab:red", "linestyle": "--", "linewidth": 1.0}


def _figure(width_in: float, height_in: float):
    # An explicit Agg canvas: no pyplot state, safe in worker processes and without a display.
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width_in, height_in), dpi=80)
    FigureCanvasAgg(fig)
    return fig


#: The closed-loop frame, row by row: the two loops' held temperatures, each with its set point
#: (dashed); under each its manipulated input (the slide-valve command u_F, the air R_ar) and the
#: measured disturbance that reaches it first (feed and air temperature); the third column the
#: regenerator's other temperatures. Channels a closed-loop env adds (the control task's reward)
#: follow on a row of their own.
CLOSED_LOOP_ROWS: tuple[tuple[tuple[str, ...], ...], ...] = (
    (("T_rx", "T_rx_sp"), ("T_rg1", "T_rg1_sp"), ("T_rg2",)),
    (("u_F",), ("R_ar",), ("T_d1",)),
    (("T_fp",), ("T_ar",), ("T_dg",)),
)
#: Column headings of the closed-loop frame.
CLOSED_LOOP_HEADINGS = (
    "riser loop: T_rx held by the valve command u_F",
    "regenerator loop: T_rg1 held by the air R_ar",
    "regenerator",
)
_SETPOINT_STYLE = {"color": "0.35", "linestyle": (0, (4, 2)), "linewidth": 0.9}
#: The open-loop frame's channels (the columns of its data) and their units: Table 1.
TABLE1_CHANNELS: dict[str, str] = {m.name: m.unit for m in MEASUREMENTS}

#: One panel of a frame: the channels it draws (the first solid, a set point dashed), or None for
#: an empty slot.
Panel = tuple[str, ...] | None


def trend_layout(channels: Sequence[str]) -> list[list[Panel]]:
    """The frame's grid, row by row, for the columns ``channels`` of the data.

    With the closed loop's channels (:data:`fcc_env.closed_loop.CLOSED_LOOP_CHANNELS`):
    :data:`CLOSED_LOOP_ROWS`, then one row for the channels beyond them. Otherwise (Table 1) a
    panel per channel, two columns, filled column by column.
    """
    names = list(channels)
    if set(CLOSED_LOOP_CHANNELS) <= set(names):
        rows = [list(r) for r in CLOSED_LOOP_ROWS]
        width = len(rows[0])
        extra = [(c,) for c in names if c not in CLOSED_LOOP_CHANNELS]
        for i in range(0, len(extra), width):
            rows.append(extra[i : i + width] + [None] * (width - len(extra[i : i + width])))
        return rows
    n_rows = math.ceil(len(names) / 2)
    cols = [[(c,) for c in names[j * n_rows : (j + 1) * n_rows]] for j in range(2)]
    return [[col[i] if i < len(col) else None for col in cols] for i in range(n_rows)]


def trend_title(
    k_now: int,
    sample_time_s: float,
    scenario: str | None,
    fault_onset: int | None,
    env_id: str | None = None,
) -> str:
    """The title of the trend frame at sample ``k_now``: the env id (if given), the time and,
    for a scenario, whether and since when the fault is on."""
    hours = sample_time_s / 3600.0
    title = f"sample {k_now}, t = {k_now * hours:.2f} h"
    title = title if env_id is None else f"{env_id}, {title}"
    if scenario is None:
        return title
    if fault_onset is not None and k_now >= fault_onset:
        what = (
            f"scenario {scenario}, fault since sample {fault_onset} ({fault_onset * hours:.2f} h)"
        )
    elif fault_onset is None:
        what = f"scenario {scenario}, no fault"
    else:
        what = f"scenario {scenario}, no fault yet"
    return f"{title}\n{what}"


def trend_figure(
    y: np.ndarray,
    k_now: int,
    sample_time_s: float,
    *,
    channels: Mapping[str, str] | None = None,
    env_id: str | None = None,
    scenario: str | None = None,
    fault_onset: int | None = None,
):
    """The env's trend frame as a matplotlib Figure: the recent data ``y`` (n, c).

    ``channels`` names the columns of ``y`` with their units, in order (``None``: the eight
    Table 1 measurements, :data:`fcc_env.params.MEASUREMENTS`); the panels are
    :func:`trend_layout`'s, each value axis labelled ``name [unit]`` (a held temperature and its
    set point share one). Every line carries its channel's name as its ``gid``. ``y`` ends at
    sample ``k_now``. The title names the env (``env_id``), the scenario and the time (sample
    and hours); the fault onset is a dashed line once it has happened (``k_now >= fault_onset``),
    and the title says since when. ``fault_onset=None``: no fault (or none known).
    """
    units = dict(TABLE1_CHANNELS if channels is None else channels)
    if y.ndim != 2 or y.shape[1] != len(units):
        raise ValueError(f"y has shape {y.shape}; its columns are the {len(units)} {list(units)}")
    column = {c: i for i, c in enumerate(units)}
    rows = trend_layout(list(units))
    closed = set(CLOSED_LOOP_CHANNELS) <= set(units)
    n_cols = len(rows[0])
    fig = _figure(8.0 if n_cols == 2 else 10.5, 6.0 + 1.5 * max(0, len(rows) - 4))
    fig.set_layout_engine("constrained")
    grid = fig.add_gridspec(len(rows), n_cols)
    n = y.shape[0]
    hours = sample_time_s / 3600.0
    t_h = (np.arange(k_now - n + 1, k_now + 1)) * hours
    onset_seen = fault_onset is not None and k_now >= fault_onset
    onset_in_window = onset_seen and fault_onset >= k_now - n + 1
    first = None
    bottom = {j: max(i for i, row in enumerate(rows) if row[j]) for j in range(n_cols)}
    for i, row in enumerate(rows):  # row by row: fig.axes lists the panels in this order
        for j, panel in enumerate(row):
            if panel is None:
                continue
            ax = fig.add_subplot(grid[i, j], sharex=first)
            first = first or ax
            for c in panel:
                setpoint = c in SETPOINT_NAMES
                style = _SETPOINT_STYLE if setpoint else {"lw": 0.8}
                label = "set point" if setpoint else c
                ax.plot(t_h, y[:, column[c]], **style, label=label, gid=c)
            ax.set_ylabel(f"{panel[0]} [{units[panel[0]]}]", fontsize=7)
            ax.tick_params(labelsize=6)
            if i == 0 and closed:
                ax.set_title(CLOSED_LOOP_HEADINGS[j], fontsize=7)
            if onset_in_window:
                ax.axvline(fault_onset * hours, **_ONSET_STYLE, label="fault onset")
            if i == bottom[j]:
                ax.set_xlabel("time [h]", fontsize=7)
            else:
                ax.tick_params(labelbottom=False)
    fig.suptitle(trend_title(k_now, sample_time_s, scenario, fault_onset, env_id), fontsize=9)
    entries = {}
    for ax in fig.axes:
        for handle, label in zip(*ax.get_legend_handles_labels(), strict=True):
            if label in ("set point", "fault onset"):
                entries.setdefault(label, handle)
    if entries:
        fig.legend(
            list(entries.values()),
            list(entries),
            loc="outside lower center",
            ncol=len(entries),
            fontsize=7,
        )
    return fig


def trend_image(
    y: np.ndarray,
    k_now: int,
    sample_time_s: float,
    **keywords: Any,
) -> np.ndarray:
    """RGB array (H, W, 3) uint8 of :func:`trend_figure` (same arguments)."""
    fig = trend_figure(y, k_now, sample_time_s, **keywords)
    fig.canvas.draw()
    return np.asarray(fig.canvas.buffer_rgba())[..., :3].copy()


def scenarios_figure(
    episodes: Mapping[str, np.ndarray],
    onsets: Mapping[str, int | None],
    sample_time_s: float,
    channels: Sequence[int] = (3, 4, 5, 6, 7),
    *,
    title: str | None = None,
):
    """One panel per channel, one line per scenario, fault onsets marked (a Figure).

    Every y axis carries its unit; one legend for the figure sits below the panels (it covers no
    data) and names the scenarios and the dashed onset lines.
    """
    fig = _figure(11, 2.2 * len(channels) + 0.8)
    fig.set_layout_engine("constrained")
    axes = fig.subplots(len(channels), 1, sharex=True, squeeze=False)[:, 0]
    for name, y in episodes.items():
        t_h = np.arange(y.shape[0]) * sample_time_s / 3600.0
        for ax, c in zip(axes, channels, strict=True):
            ax.plot(t_h, y[:, c], lw=0.7, label=name)
    # Onsets a few samples apart would overprint labels on the plot: the legend names them.
    known = {name: onset for name, onset in onsets.items() if onset is not None}
    for i, onset in enumerate(sorted(set(known.values()))):
        for ax in axes:
            ax.axvline(
                onset * sample_time_s / 3600.0,
                ls="--",
                lw=0.8,
                color="k",
                alpha=0.5,
                label="_"
                if i
                else "fault onset: "
                + ", ".join(
                    f"{name} {k * sample_time_s / 3600.0:.2f} h" for name, k in known.items()
                ),
            )
    for ax, c in zip(axes, channels, strict=True):
        ax.set_ylabel(f"{MEASUREMENTS[c].name} [{MEASUREMENTS[c].unit}]")
    axes[-1].set_xlabel("time [h]")
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncol=len(labels), fontsize=8)
    fig.suptitle(title or "FCC-v0: the healthy plant and each fault, one line per scenario")
    return fig


def plot_scenarios(
    episodes: Mapping[str, np.ndarray],
    onsets: Mapping[str, int | None],
    sample_time_s: float,
    path: str | Path,
    channels: Sequence[int] = (3, 4, 5, 6, 7),
    *,
    title: str | None = None,
) -> Path:
    """:func:`scenarios_figure` saved as PNG at ``path`` (parent directories are created)."""
    fig = scenarios_figure(episodes, onsets, sample_time_s, channels, title=title)
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out)
    return out
