"""Pictures of FCC episodes (matplotlib, Agg backend; nothing is shown on screen)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from fcc_env.params import MEASUREMENTS


def _figure(width_in: float, height_in: float):
    # An explicit Agg canvas: no pyplot state, safe in worker processes and without a display.
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width_in, height_in), dpi=80)
    FigureCanvasAgg(fig)
    return fig


def trend_image(y: np.ndarray, k_now: int, sample_time_s: float) -> np.ndarray:
    """RGB array (H, W, 3) uint8 of the recent measurements ``y`` (n, 8) ending at sample k_now."""
    fig = _figure(8, 6)
    axes = fig.subplots(4, 2, sharex=True)
    n = y.shape[0]
    t_h = (np.arange(k_now - n + 1, k_now + 1)) * sample_time_s / 3600.0
    for i, ax in enumerate(axes.T.ravel()):
        m = MEASUREMENTS[i]
        ax.plot(t_h, y[:, i], lw=0.8)
        ax.set_ylabel(f"{m.name} [{m.unit}]", fontsize=7)
        ax.tick_params(labelsize=6)
    for ax in axes[-1]:
        ax.set_xlabel("time [h]", fontsize=7)
    fig.tight_layout()
    fig.canvas.draw()
    return np.asarray(fig.canvas.buffer_rgba())[..., :3].copy()


def plot_scenarios(
    episodes: Mapping[str, np.ndarray],
    onsets: Mapping[str, int | None],
    sample_time_s: float,
    path: str | Path,
    channels: Sequence[int] = (3, 4, 5, 6, 7),
) -> Path:
    """One panel per channel, one line per scenario, fault onsets marked; saved as PNG."""
    fig = _figure(11, 2.2 * len(channels))
    axes = fig.subplots(len(channels), 1, sharex=True, squeeze=False)[:, 0]
    for name, y in episodes.items():
        t_h = np.arange(y.shape[0]) * sample_time_s / 3600.0
        for ax, c in zip(axes, channels, strict=True):
            ax.plot(t_h, y[:, c], lw=0.7, label=name)
    for name, onset in onsets.items():
        if onset is not None:
            for ax in axes:
                ax.axvline(onset * sample_time_s / 3600.0, ls="--", lw=0.8, color="k", alpha=0.5)
            axes[0].annotate(
                f"{name} onset",
                (onset * sample_time_s / 3600.0, 1.0),
                xycoords=("data", "axes fraction"),
                fontsize=7,
                rotation=90,
                va="top",
            )
    for ax, c in zip(axes, channels, strict=True):
        ax.set_ylabel(f"{MEASUREMENTS[c].name} [{MEASUREMENTS[c].unit}]")
    axes[0].legend(ncol=len(episodes), fontsize=8, loc="upper left")
    axes[-1].set_xlabel("time [h]")
    fig.tight_layout()
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out)
    return out
