"""Pictures of FCC episodes (matplotlib, Agg backend; nothing is shown on screen)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from fcc_env.params import MEASUREMENTS

_ONSET_STYLE = {"color": "tab:red", "linestyle": "--", "linewidth": 1.0}


def _figure(width_in: float, height_in: float):
    # An explicit Agg canvas: no pyplot state, safe in worker processes and without a display.
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width_in, height_in), dpi=80)
    FigureCanvasAgg(fig)
    return fig


def trend_title(
    k_now: int, sample_time_s: float, scenario: str | None, fault_onset: int | None
) -> str:
    """The title of the trend frame at sample ``k_now`` : the time and, for a scenario, whether and since when the fault is on."""
    hours = sample_time_s / 3600.0
    title = f"FCC-v0, sample {k_now}, t = {k_now * hours:.2f} h"
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
    scenario: str | None = None,
    fault_onset: int | None = None,
):
    """The env's trend frame as a matplotlib Figure: the recent measurements ``y`` (n, 8).

    ``y`` ends at sample ``k_now``. The title names the scenario and the time (sample and
    hours); the fault onset is a dashed line once it has happened (``k_now >= fault_onset``),
    and the title says since when. ``fault_onset=None``: no fault (or none known).
    """
    fig = _figure(8, 6)
    fig.set_layout_engine("constrained")
    axes = fig.subplots(4, 2, sharex=True)
    n = y.shape[0]
    hours = sample_time_s / 3600.0
    t_h = (np.arange(k_now - n + 1, k_now + 1)) * hours
    onset_seen = fault_onset is not None and k_now >= fault_onset
    for i, ax in enumerate(axes.T.ravel()):
        m = MEASUREMENTS[i]
        ax.plot(t_h, y[:, i], lw=0.8, label="measurement")
        ax.set_ylabel(f"{m.name} [{m.unit}]", fontsize=7)
        ax.tick_params(labelsize=6)
        if onset_seen and fault_onset >= k_now - n + 1:  # the onset lies in the window
            ax.axvline(fault_onset * hours, **_ONSET_STYLE, label="fault onset")
    for ax in axes[-1]:
        ax.set_xlabel("time [h]", fontsize=7)
    fig.suptitle(trend_title(k_now, sample_time_s, scenario, fault_onset), fontsize=9)
    if onset_seen:
        handles, labels = axes[0, 0].get_legend_handles_labels()
        if "fault onset" in labels:
            i = labels.index("fault onset")
            fig.legend([handles[i]], [labels[i]], loc="outside lower center", fontsize=7)
    return fig


def trend_image(
    y: np.ndarray,
    k_now: int,
    sample_time_s: float,
    *,
    scenario: str | None = None,
    fault_onset: int | None = None,
) -> np.ndarray:
    """RGB array (H, W, 3) uint8 of :func:`trend_figure` (same arguments)."""
    fig = trend_figure(y, k_now, sample_time_s, scenario=scenario, fault_onset=fault_onset)
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
